"""Labelled contact sheets of the README's pictures: rows of pictures, each with a caption."""

from __future__ import annotations

from PIL import Image, ImageDraw, ImageFont

GAP = 6
LABEL_HEIGHT = 22


def fit_height(picture: Image.Image, height: int) -> Image.Image:
    """``picture`` scaled to ``height`` pixels, its aspect kept."""
    return picture.resize((round(picture.width * height / picture.height), height), Image.Resampling.LANCZOS)


def labelled_sheet(rows: list[list[tuple[str, Image.Image]]], cell: int) -> Image.Image:
    """Rows of ``(caption, picture)``, every picture scaled to ``cell`` pixels high, its caption above it."""
    cells = [[(label, fit_height(picture, cell)) for label, picture in row] for row in rows]
    width = max(sum(p.width for _, p in row) + GAP * (len(row) - 1) for row in cells)
    sheet = Image.new("RGB", (width, len(cells) * (cell + LABEL_HEIGHT + GAP)), "white")
    pen = ImageDraw.Draw(sheet)
    font = ImageFont.load_default()
    for r, row in enumerate(cells):
        x, y = 0, r * (cell + LABEL_HEIGHT + GAP)
        for label, picture in row:
            pen.text((x + 2, y + 4), label, fill="black", font=font)
            sheet.paste(picture, (x, y + LABEL_HEIGHT))
            x += picture.width + GAP
    return sheet
