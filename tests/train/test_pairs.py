"""Paired images for conditional-GAN training: both layouts, the checks and the training jitter."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import numpy as np
import pytest
import torch
from PIL import Image
from torch.utils.data import DataLoader

from wise.errors import WiseError
from wise.train.pairs import MAX_NAMED, Pair, PairDataset, check_pairs, pair_files

HEIGHT, WIDTH = 24, 32
NAMES = ("b", "a", "c")


def _photo(seed: int, height: int = HEIGHT, width: int = WIDTH) -> np.ndarray:
    """Random 8-bit RGB pixels: every position tells itself apart, so flips and shifts show."""
    return np.random.default_rng(seed).integers(0, 256, (height, width, 3), dtype=np.uint8)


def _save(array: np.ndarray, path: Path) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(array).save(path)
    return path


def _separate(root: Path, split: str = "train", regions: bool = False) -> Path:
    """Pairs in A/ and B/ whose target is 1 - photo (and region the photo's red channel)."""
    for seed, name in enumerate(NAMES):
        photo = _photo(seed)
        _save(photo, root / split / "A" / f"{name}.png")
        _save(255 - photo, root / split / "B" / f"{name}.png")
        if regions:
            _save(photo[..., 0], root / split / "regions" / f"{name}.png")
    return root


def _aligned(root: Path, split: str = "train") -> Path:
    """The pairs of :func:`_separate` as AB images."""
    for seed, name in enumerate(NAMES):
        photo = _photo(seed)
        _save(np.concatenate([photo, 255 - photo], axis=1), root / split / f"{name}.png")
    return root


def _close(a: torch.Tensor, b: torch.Tensor) -> bool:
    return a.shape == b.shape and bool(torch.allclose(a, b, atol=1e-5))


def test_both_layouts_read_the_same_pairs(tmp_path: Path) -> None:
    separate = pair_files(_separate(tmp_path / "separate"), "train")
    aligned = pair_files(_aligned(tmp_path / "aligned"), "train")
    assert [p.name for p in separate] == [p.name for p in aligned] == ["a", "b", "c"]
    assert separate[0] == Pair("a", tmp_path / "separate/train/A/a.png", tmp_path / "separate/train/B/a.png", None)
    assert aligned[0].target is None and aligned[0].photo == tmp_path / "aligned/train/a.png"
    check_pairs(separate)
    check_pairs(aligned)
    for one, other in zip(PairDataset(separate, None, None, False), PairDataset(aligned, None, None, False)):
        assert one["photo"].shape == (3, HEIGHT, WIDTH) and one["photo"].dtype == torch.float32
        assert torch.equal(one["photo"], other["photo"]) and torch.equal(one["target"], other["target"])
        assert _close(one["target"], 1.0 - one["photo"]) and "region" not in one


def test_pairs_match_by_stem_across_extensions_and_list_regions_and_params(tmp_path: Path) -> None:
    photo = _photo(0)
    _save(photo, tmp_path / "val/A/x.jpg")
    _save(photo, tmp_path / "val/B/x.png")
    _save(photo[..., 0], tmp_path / "val/regions/x.png")
    (tmp_path / "val/params").mkdir()
    (tmp_path / "val/params/x.safetensors").write_bytes(b"{}")
    (tmp_path / "val/A/.hidden.png").write_bytes(b"")
    (pair,) = pair_files(tmp_path, "val")
    assert (pair.photo.name, pair.target.name, pair.region.name) == ("x.jpg", "x.png", "x.png")
    assert pair.params == tmp_path / "val/params/x.safetensors"
    check_pairs([pair])


def test_unmatched_files_are_named_with_their_count(tmp_path: Path) -> None:
    root = _separate(tmp_path)
    for index in range(MAX_NAMED + 2):
        _save(_photo(index), root / "train/A" / f"only-a-{index}.png")
    _save(_photo(9), root / "train/B/only-b.jpg")
    with pytest.raises(WiseError) as caught:
        pair_files(root, "train")
    message = str(caught.value)
    assert "\n" not in message
    assert (
        "7 photos in A/ without a target in B/ (only-a-0, only-a-1, only-a-2, only-a-3, only-a-4 and 2 more)" in message
    )
    assert "1 target in B/ without a photo in A/ (only-b)" in message


@pytest.mark.parametrize(
    ("make", "split", "match"),
    [
        (lambda root: None, "train", "not a directory of image pairs"),
        (lambda root: _separate(root, "test"), "train", "no train/ folder \\(it has test\\)"),
        (lambda root: (root / "train/A").mkdir(parents=True), "train", "has A/ but no B/"),
        (lambda root: [(root / "train" / side).mkdir(parents=True) for side in "AB"], "train", "no images in A/"),
        (lambda root: (root / "train").mkdir(parents=True), "train", "train: no images"),
        (lambda root: _separate(root), "training", "unknown split 'training'"),
    ],
)
def test_missing_and_empty_splits_are_refused(
    tmp_path: Path, make: Callable[[Path], object], split: str, match: str
) -> None:
    root = tmp_path / "pairs"
    make(root)
    with pytest.raises(WiseError, match=match):
        pair_files(root, split)


def test_duplicate_stems_odd_widths_and_partial_regions_are_refused(tmp_path: Path) -> None:
    root = _separate(tmp_path / "dup")
    _save(_photo(0), root / "train/B/a.jpg")
    with pytest.raises(WiseError, match="B: 1 name used by two files \\(a.jpg and a.png\\); keep one file per name"):
        pair_files(root, "train")
    odd = _aligned(tmp_path / "odd")
    _save(_photo(0, width=2 * WIDTH + 1), odd / "train/z.png")
    with pytest.raises(WiseError, match=f"1 AB image of odd width \\(z.png \\({2 * WIDTH + 1}x{HEIGHT}\\)\\)"):
        pair_files(odd, "train")
    partial = _separate(tmp_path / "partial", regions=True)
    (partial / "train/regions/b.png").unlink()
    with pytest.raises(WiseError, match="1 pair without a region mask \\(b\\)"):
        pair_files(partial, "train")
    with pytest.raises(WiseError, match="unknown direction"):
        pair_files(root, "train", direction="AB")


def test_unreadable_files_and_differing_sizes_are_refused_by_the_check(tmp_path: Path) -> None:
    root = _separate(tmp_path)
    (root / "train/A/a.png").write_text("not an image")
    _save(_photo(1, height=HEIGHT + 2), root / "train/B/b.png")
    pairs = pair_files(root, "train")  # file names only: no reading here
    with pytest.raises(WiseError) as caught:
        check_pairs(pairs)
    message = str(caught.value)
    assert "\n" not in message
    assert f"1 unreadable image: {root / 'train/A/a.png'} (not an image in a supported format" in message
    assert f"1 pair of differing sizes: b (photo {WIDTH}x{HEIGHT}, target {WIDTH}x{HEIGHT + 2})" in message
    with pytest.raises(WiseError, match="a pair of differing sizes"):
        PairDataset(pairs, None, None, False)[1]


def test_crops_keep_photo_target_and_region_aligned_through_flips(tmp_path: Path) -> None:
    pairs = pair_files(_separate(tmp_path, regions=True), "train")
    check_pairs(pairs)
    # enlarged: photo and region go through the same bilinear resize, so the region stays the red channel
    enlarged = PairDataset(pairs, load_size=36, crop_size=20, flip=True, seed=3)
    reduced = PairDataset(pairs, load_size=16, crop_size=12, flip=True, seed=3)
    flips = set()
    for epoch in range(4):
        enlarged.set_epoch(epoch)
        reduced.set_epoch(epoch)
        for index in range(len(pairs)):
            item = enlarged[index]
            assert item["photo"].shape == item["target"].shape == (3, 20, 20) and item["region"].shape == (1, 20, 20)
            assert _close(item["target"], 1.0 - item["photo"]) and _close(item["region"][0], item["photo"][0])
            whole = PairDataset([pairs[index]], 36, None, False)[0]["photo"]
            top, left = item["origin"].tolist()
            window = whole[:, top : top + 20, left : left + 20]
            flips.add(torch.equal(item["photo"], window))
            small = reduced[index]
            assert small["photo"].shape == (3, 12, 12) and _close(small["target"], 1.0 - small["photo"])
            assert 0.0 <= float(small["region"].min()) and float(small["region"].max()) <= 1.0
    assert flips == {True, False}  # both flipped and unflipped crops were drawn


def test_scale_and_origin_locate_the_crop_in_the_resized_picture(tmp_path: Path) -> None:
    pairs = pair_files(_separate(tmp_path), "train")
    whole = PairDataset(pairs, load_size=48, crop_size=None, flip=False)[0]
    assert whole["photo"].shape == (3, 48, 64) and whole["scale"] == 1.0  # below 512: the reference scale
    assert whole["origin"].tolist() == [0, 0] and whole["name"] == "a"
    assert PairDataset(pairs, None, None, False)[0]["scale"] == 1.0
    assert PairDataset(pairs, 768, None, False)[0]["scale"] == 768 / 512
    mirrored = whole["photo"].flip(-1)
    dataset = PairDataset(pairs, load_size=48, crop_size=16, flip=True, seed=1)
    seen = set()
    for epoch in range(8):
        dataset.set_epoch(epoch)
        item = dataset[0]
        top, left = item["origin"].tolist()
        assert item["origin"].dtype == torch.int64 and 0 <= top <= 48 - 16 and 0 <= left <= 64 - 16
        plain = torch.equal(item["photo"], whole["photo"][:, top : top + 16, left : left + 16])
        flipped = torch.equal(item["photo"], mirrored[:, top : top + 16, left : left + 16])
        assert plain != flipped  # the window at origin of the picture, or of the mirrored picture after a flip
        seen.add(flipped)
        assert item["scale"] == 1.0
    assert seen == {True, False}
    with pytest.raises(WiseError, match="larger than the load size"):
        PairDataset(pairs, 16, 24, False)
    with pytest.raises(WiseError, match="smaller than the crop size 30"):
        PairDataset(pairs, None, 30, False)[0]


def test_jitter_is_reproducible_from_seed_epoch_and_index(tmp_path: Path) -> None:
    pairs = pair_files(_separate(tmp_path), "train")

    def draw(seed: int, epoch: int) -> list[tuple[list[int], torch.Tensor]]:
        dataset = PairDataset(pairs, load_size=40, crop_size=16, flip=True, seed=seed)
        dataset.set_epoch(epoch)
        return [(dataset[i]["origin"].tolist(), dataset[i]["photo"]) for i in range(len(pairs))]

    def same(one: list, other: list) -> bool:
        return all(a[0] == b[0] and torch.equal(a[1], b[1]) for a, b in zip(one, other))

    first = draw(0, 0)
    assert same(first, draw(0, 0))
    assert not same(first, draw(0, 1)) and not same(first, draw(1, 0))


def test_persistent_workers_follow_the_epoch(tmp_path: Path) -> None:
    pairs = pair_files(_separate(tmp_path), "train")
    dataset = PairDataset(pairs, load_size=40, crop_size=16, flip=True)
    loader = DataLoader(dataset, batch_size=3, num_workers=1, persistent_workers=True)
    origins = []
    for epoch in range(2):
        dataset.set_epoch(epoch)
        (batch,) = list(loader)
        origins.append(batch["origin"])
        expected = torch.stack([dataset[i]["origin"] for i in range(len(pairs))])
        assert torch.equal(batch["origin"], expected) and batch["name"] == ["a", "b", "c"]
    assert not torch.equal(origins[0], origins[1])


def test_direction_b_to_a_swaps_photo_and_target_once(tmp_path: Path) -> None:
    for root in (_separate(tmp_path / "separate"), _aligned(tmp_path / "aligned")):
        forward = PairDataset(pair_files(root, "train"), None, None, False)[0]
        backward = PairDataset(pair_files(root, "train"), None, None, False, direction="BtoA")[0]
        listed = pair_files(root, "train", direction="BtoA")
        both = PairDataset(listed, None, None, False, direction="BtoA")[0]
        assert torch.equal(backward["photo"], forward["target"]) and torch.equal(backward["target"], forward["photo"])
        assert torch.equal(both["photo"], backward["photo"]) and torch.equal(both["target"], backward["target"])
    assert listed[0].direction == "BtoA"
    swapped = pair_files(tmp_path / "separate", "train", direction="BtoA")[0]
    assert swapped.photo.parent.name == "B" and swapped.target.parent.name == "A"
    with pytest.raises(WiseError, match="unknown direction"):
        PairDataset(listed, None, None, False, direction="both")
