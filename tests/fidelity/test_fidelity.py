import importlib
import math
from pathlib import Path

import numpy as np
import pytest
import scipy.linalg
import torch
import torch.nn.functional as F
from safetensors.torch import save_file

from tests.weights import sparse_weights
from wise.errors import WiseError
from wise.fidelity import LPIPS, feature_statistics, fid, frechet_distance, load_inception, load_lpips, lpips
from wise.fidelity.inception import FIDInception
from wise.fidelity.inception import expected_shapes as inception_shapes
from wise.fidelity.lpips import alexnet_shapes, linear_shapes
from wise.fidelity.lpips import expected_shapes as lpips_shapes
from wise.pretrained import cache_file

inception_module = importlib.import_module("wise.fidelity.inception")
lpips_module = importlib.import_module("wise.fidelity.lpips")
fid_module = importlib.import_module("wise.fidelity.fid")

PT_INCEPTION_TENSORS = 472
"""94 convolutions with batch norm (5 tensors each) and fc.weight, fc.bias; no num_batches_tracked."""
PT_INCEPTION_PARAMETERS = 27_161_264 - 3_326_696 + 8 * (2048 + 1)
"""torchvision's inception_v3 has 27 161 264 parameters; AuxLogits hold 3 326 696; 1008 instead of 1000 logits."""
LPIPS_CHANNELS = (64, 192, 384, 256, 256)


def random_weights(shapes: dict[str, tuple[int, ...]], seed: int) -> dict[str, torch.Tensor]:
    """He-initialized weights with these keys; batch norms are the identity (mean 0, var 1, scale 1, shift 0)."""
    generator = torch.Generator().manual_seed(seed)
    state = {}
    for key, shape in shapes.items():
        if key.endswith(("running_var", "bn.weight")):
            state[key] = torch.ones(shape)
        elif key.endswith(("running_mean", "bias")):
            state[key] = torch.zeros(shape)
        else:
            state[key] = torch.randn(shape, generator=generator) * math.sqrt(2.0 / math.prod(shape[1:]))
    return state


def refused(call, *args, **kwargs) -> str:
    """The one-line message of the WiseError that ``call`` raises."""
    with pytest.raises(WiseError) as info:
        call(*args, **kwargs)
    message = str(info.value)
    assert "\n" not in message
    return message


@pytest.fixture(scope="module")
def inception_state() -> dict[str, torch.Tensor]:
    return random_weights(inception_shapes(), seed=0)


@pytest.fixture(scope="module")
def inception_file(tmp_path_factory: pytest.TempPathFactory, inception_state: dict[str, torch.Tensor]) -> Path:
    path = tmp_path_factory.mktemp("inception") / "pt_inception-2015-12-05.safetensors"
    save_file(inception_state, str(path))
    return path


@pytest.fixture(scope="module")
def inception(inception_file: Path) -> FIDInception:
    return load_inception(inception_file)


@pytest.fixture(scope="module")
def lpips_files(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, Path]:
    folder = tmp_path_factory.mktemp("lpips")
    alexnet, linear = folder / "alexnet.safetensors", folder / "lpips-alex.safetensors"
    save_file(random_weights(alexnet_shapes(), seed=1), str(alexnet))
    save_file({k: v.abs() for k, v in random_weights(linear_shapes(), seed=2).items()}, str(linear))
    return alexnet, linear


@pytest.fixture(scope="module")
def lpips_model(lpips_files: tuple[Path, Path]) -> LPIPS:
    return load_lpips(*lpips_files)


def test_the_inception_state_dict_has_the_keys_and_shapes_of_pt_inception() -> None:
    with torch.device("meta"):
        model = FIDInception()
    state = model.state_dict()
    assert {key: tuple(value.shape) for key, value in state.items()} == inception_shapes()
    assert len(state) == PT_INCEPTION_TENSORS
    assert sum(p.numel() for p in model.parameters()) == PT_INCEPTION_PARAMETERS
    assert not any("num_batches_tracked" in key or "AuxLogits" in key for key in state)
    real = {
        "Conv2d_1a_3x3.conv.weight": (32, 3, 3, 3),
        "Conv2d_4a_3x3.bn.running_var": (192,),
        "Mixed_5b.branch_pool.conv.weight": (32, 192, 1, 1),
        "Mixed_5d.branch5x5_2.conv.weight": (64, 48, 5, 5),
        "Mixed_6a.branch3x3.conv.weight": (384, 288, 3, 3),
        "Mixed_6b.branch7x7_2.conv.weight": (128, 128, 1, 7),
        "Mixed_6e.branch7x7dbl_4.conv.weight": (192, 192, 7, 1),
        "Mixed_7a.branch7x7x3_4.conv.weight": (192, 192, 3, 3),
        "Mixed_7b.branch3x3dbl_1.conv.weight": (448, 1280, 1, 1),
        "Mixed_7c.branch3x3_2b.conv.weight": (384, 384, 3, 1),
        "Mixed_7c.branch_pool.bn.bias": (192,),
        "fc.weight": (1008, 2048),
        "fc.bias": (1008,),
    }
    shapes = inception_shapes()
    assert {key: shapes[key] for key in real} == real


def test_half_precision_weights_with_num_batches_tracked_and_aux_logits_load_as_well(
    tmp_path: Path, inception_state: dict[str, torch.Tensor]
) -> None:
    tracked = [key.replace("running_var", "num_batches_tracked") for key in inception_state if "running_var" in key]
    extra = {key: torch.tensor(7) for key in tracked} | {"AuxLogits.fc.weight": torch.zeros(1008, 768)}
    path = tmp_path / "torchvision-style.safetensors"
    save_file({**{key: value.half() for key, value in inception_state.items()}, **extra}, str(path))
    model = load_inception(path)
    expected = inception_state["Mixed_7c.branch_pool.conv.weight"].half().float()
    assert torch.equal(model.Mixed_7c.branch_pool.conv.weight, expected)
    assert model.fc.weight.dtype == torch.float32
    assert not model.training and not any(p.requires_grad for p in model.parameters())


def test_features_are_2048_long_for_any_image_size(inception: FIDInception) -> None:
    torch.manual_seed(0)
    small = torch.rand(2, 3, 64, 80)
    large = torch.rand(1, 3, 299, 299)
    with torch.no_grad():
        features = inception(small)
        assert features.shape == (2, 2048) and inception(large).shape == (1, 2048)
    assert torch.isfinite(features).all() and (features >= 0).all()
    assert not torch.allclose(features[0], features[1])
    with pytest.raises(WiseError, match=r"shape \[3, 64, 80\]"):
        inception(small[0])


class Captured(Exception):
    """Stops the network once the first convolution has seen its input."""


def test_images_are_resized_bilinearly_to_299_and_scaled_to_minus_one_to_one(inception: FIDInception) -> None:
    seen = []

    def capture(module: torch.nn.Module, inputs: tuple[torch.Tensor]) -> None:
        seen.append(inputs[0])
        raise Captured

    handle = inception.Conv2d_1a_3x3.register_forward_pre_hook(capture)
    try:
        torch.manual_seed(7)
        image = torch.rand(1, 3, 64, 80)
        for given in (image, torch.zeros(1, 3, 299, 299), torch.ones(1, 3, 20, 30)):
            with pytest.raises(Captured):
                inception(given)
    finally:
        handle.remove()
    expected = 2 * F.interpolate(image, size=(299, 299), mode="bilinear", align_corners=False) - 1
    assert seen[0].shape == (1, 3, 299, 299) and torch.allclose(seen[0], expected, atol=1e-6)
    assert torch.equal(seen[1], -torch.ones(1, 3, 299, 299)) and torch.allclose(seen[2], torch.ones(1, 3, 299, 299))


def test_pools_and_batch_norm_follow_tensorflow(inception: FIDInception) -> None:
    torch.manual_seed(8)
    x = torch.randn(1, 4, 5, 6)
    average = F.avg_pool2d(x, 3, stride=1, padding=1, count_include_pad=False)
    assert torch.allclose(inception.Mixed_7b.pool(x), average)
    assert torch.equal(inception.Mixed_7c.pool(x), F.max_pool2d(x, 3, stride=1, padding=1))
    assert torch.equal(inception_module._average_pool(torch.ones(1, 1, 5, 5)), torch.ones(1, 1, 5, 5))
    norm = inception_module._FrozenBatchNorm(4)
    norm.running_var.zero_()
    assert torch.allclose(norm(x), x / math.sqrt(1e-3))


def test_fid_is_zero_for_a_set_and_itself_and_grows_when_one_set_is_shifted(
    inception: FIDInception, inception_file: Path
) -> None:
    torch.manual_seed(1)
    images = torch.rand(2, 3, 48, 56)
    shifted = [image for image in (images + 0.3).clamp(0, 1)]
    apart = fid(images, shifted, weights=inception_file, batch_size=1)
    assert math.isfinite(apart) and apart > 0
    mu, sigma = feature_statistics(images, inception)
    assert mu.shape == (2048,) and sigma.shape == (2048, 2048) and mu.dtype == sigma.dtype == np.float64
    assert 0 <= frechet_distance(mu, sigma, mu, sigma) < 1e-6 * apart


def test_frechet_distance_matches_the_closed_form_for_diagonal_gaussians() -> None:
    rng = np.random.default_rng(0)
    mu1, mu2 = rng.normal(size=6), rng.normal(size=6)
    var1, var2 = rng.uniform(0.1, 2.0, size=6), rng.uniform(0.1, 2.0, size=6)
    var2[0] = 0.0  # a singular covariance
    expected = np.sum((mu1 - mu2) ** 2) + np.sum((np.sqrt(var1) - np.sqrt(var2)) ** 2)
    assert frechet_distance(mu1, np.diag(var1), mu2, np.diag(var2)) == pytest.approx(expected, rel=1e-10)
    assert frechet_distance(mu1, np.diag(var1), mu1, np.diag(var1)) == pytest.approx(0.0, abs=1e-12)


def test_frechet_distance_matches_a_matrix_square_root_for_full_covariances() -> None:
    rng = np.random.default_rng(1)
    a, b = rng.normal(size=(8, 8)), rng.normal(size=(8, 8))
    sigma1, sigma2 = a @ a.T + 0.1 * np.eye(8), b @ b.T
    mu1, mu2 = rng.normal(size=8), rng.normal(size=8)
    root = scipy.linalg.sqrtm(sigma1 @ sigma2).real
    expected = np.sum((mu1 - mu2) ** 2) + np.trace(sigma1 + sigma2 - 2 * root)
    assert frechet_distance(mu1, sigma1, mu2, sigma2) == pytest.approx(expected, rel=1e-9)


def test_frechet_distance_retries_with_an_offset_and_refuses_bad_statistics(monkeypatch: pytest.MonkeyPatch) -> None:
    sigma1, sigma2 = np.diag([1.0, 4.0]), np.diag([4.0, 1.0])
    original, calls = fid_module._trace_sqrt_product, []

    def fail_once(s1: np.ndarray, s2: np.ndarray) -> float:
        calls.append(s1.copy())
        if len(calls) == 1:
            raise np.linalg.LinAlgError("did not converge")
        return original(s1, s2)

    monkeypatch.setattr(fid_module, "_trace_sqrt_product", fail_once)
    assert frechet_distance(np.zeros(2), sigma1, np.zeros(2), sigma2, eps=1e-3) == pytest.approx(2.0, abs=1e-2)
    assert len(calls) == 2 and calls[1][0, 0] == pytest.approx(1.001)
    assert "non-finite" in refused(frechet_distance, np.zeros(2), np.diag([1.0, np.nan]), np.zeros(2), sigma2)
    assert "covariance (D, D)" in refused(frechet_distance, np.zeros(3), sigma1, np.zeros(3), sigma2)


def test_feature_statistics_match_np_cov_for_tensors_batches_and_single_images() -> None:
    torch.manual_seed(2)
    images = torch.rand(5, 3, 4, 6)

    def network(x: torch.Tensor) -> torch.Tensor:
        return torch.cat((x.mean(dim=(2, 3)), x.amax(dim=(2, 3))), dim=1)

    features = network(images).double().numpy()
    expected_mu, expected_sigma = features.mean(axis=0), np.cov(features, rowvar=False)
    for given in (images, [images[:2], images[2:]], (image for image in images)):
        mu, sigma = feature_statistics(given, network, batch_size=2)
        assert np.allclose(mu, expected_mu, atol=1e-12) and np.allclose(sigma, expected_sigma, atol=1e-12)
    assert "at least 2 images" in refused(feature_statistics, images[:1], network)
    assert "shape [3, 5, 4, 6]" in refused(feature_statistics, images.transpose(0, 1), network)


def test_lpips_is_zero_for_identical_images_symmetric_and_positive_for_different_ones(lpips_model: LPIPS) -> None:
    torch.manual_seed(3)
    a, b = torch.rand(3, 3, 64, 64), torch.rand(3, 3, 64, 64)
    a.requires_grad_()
    distances = lpips(a, b, lpips_model)
    assert distances.shape == (3,) and (distances > 0).all()
    assert torch.allclose(distances, lpips(b, a, lpips_model), atol=1e-6)
    assert torch.allclose(lpips(a, a, lpips_model), torch.zeros(3), atol=1e-6)
    distances.sum().backward()
    assert torch.isfinite(a.grad).all() and a.grad.abs().sum() > 0
    assert "too small" in refused(lpips_model, a[:, :, :30], b[:, :, :30])
    assert "one shape" in refused(lpips_model, a, b[:2])


def test_lpips_equals_a_direct_computation_of_its_definition(lpips_files: tuple[Path, Path]) -> None:
    """AlexNet's five ReLUs with pools after the first two, unit-normalized, weighted, averaged and summed."""
    alexnet, linear = lpips_files
    state = {**load_lpips(alexnet, linear).state_dict()}
    torch.manual_seed(4)
    a, b = torch.rand(2, 3, 72, 64), torch.rand(2, 3, 72, 64)

    def relus(x: torch.Tensor) -> list[torch.Tensor]:
        shift, scale = torch.tensor([-0.030, -0.088, -0.188]), torch.tensor([0.458, 0.448, 0.450])
        x = ((2 * x - 1) - shift.view(1, 3, 1, 1)) / scale.view(1, 3, 1, 1)
        out = [F.relu(F.conv2d(x, state["features.0.weight"], state["features.0.bias"], stride=4, padding=2))]
        x = F.max_pool2d(out[-1], 3, 2)
        out.append(F.relu(F.conv2d(x, state["features.3.weight"], state["features.3.bias"], padding=2)))
        x = F.max_pool2d(out[-1], 3, 2)
        for index in (6, 8, 10):
            x = F.relu(F.conv2d(x, state[f"features.{index}.weight"], state[f"features.{index}.bias"], padding=1))
            out.append(x)
        return out

    expected = torch.zeros(2)
    for k, (fa, fb) in enumerate(zip(relus(a), relus(b))):
        assert fa.shape[1] == LPIPS_CHANNELS[k]
        na, nb = (
            fa / (fa.pow(2).sum(1, keepdim=True).sqrt() + 1e-10),
            fb / (fb.pow(2).sum(1, keepdim=True).sqrt() + 1e-10),
        )
        expected += F.conv2d((na - nb) ** 2, state[f"lin{k}.model.1.weight"]).mean(dim=(1, 2, 3))
    assert torch.allclose(lpips(a, b, alexnet_weights=alexnet, linear_weights=linear), expected, rtol=1e-5)


def test_lpips_with_zero_linear_weights_is_zero(tmp_path: Path, lpips_files: tuple[Path, Path]) -> None:
    zeros = tmp_path / "zeros.safetensors"
    save_file({key: torch.zeros(shape) for key, shape in linear_shapes().items()}, str(zeros))
    torch.manual_seed(5)
    distances = lpips(torch.rand(2, 3, 40, 40), torch.rand(2, 3, 40, 40), load_lpips(lpips_files[0], zeros))
    assert torch.equal(distances, torch.zeros(2))


def test_one_file_holding_both_key_sets_serves_for_lpips(
    tmp_path: Path, lpips_files: tuple[Path, Path], lpips_model: LPIPS
) -> None:
    merged = tmp_path / "merged.safetensors"
    state = {**lpips_model.state_dict(), "classifier.1.weight": torch.zeros(2, 2)}
    save_file({key: value.contiguous() for key, value in state.items()}, str(merged))
    assert set(lpips_shapes()) < set(state)
    torch.manual_seed(6)
    a, b = torch.rand(2, 3, 48, 48), torch.rand(2, 3, 48, 48)
    expected = lpips_model(a, b)
    assert torch.allclose(lpips(a, b, load_lpips(merged)), expected)
    assert torch.allclose(lpips(a, b, load_lpips(linear_weights=merged)), expected)


def test_missing_unsafe_and_wrong_weight_files_are_refused_naming_the_file(
    tmp_path: Path, lpips_files: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(torch, "load", lambda *args, **kwargs: pytest.fail("torch.load was called"))
    none = tmp_path / "none.safetensors"
    message = refused(load_inception, none)
    assert f"Inception weights not found at {none}" in message and "--inception-weights" in message
    pickle = tmp_path / "pt_inception-2015-12-05-6726825d.pth"
    pickle.write_bytes(b"not loaded")
    for call in (load_inception, load_lpips):
        message = refused(call, pickle)
        assert str(pickle) in message and "never loaded" in message and "safetensors.torch.save_file" in message
    message = refused(load_lpips, lpips_files[0], tmp_path / "lin.pt")
    assert "lin.pt: pickled LPIPS weights" in message
    shapes = inception_shapes()
    partial = sparse_weights(tmp_path / "partial.safetensors", {k: v for k, v in shapes.items() if "Mixed_7" not in k})
    message = refused(load_inception, partial)
    assert message.startswith(f"{partial}: not a state dict of the FID Inception network; missing Mixed_7a.branch3x3_1")
    assert "and more" in message and "pt_inception-2015-12-05" in message
    wrong = sparse_weights(tmp_path / "wrong.safetensors", {**shapes, "fc.weight": (1000, 2048)})
    assert f"{wrong}: weights of the wrong shape" in refused(load_inception, wrong)
    assert "fc.weight is [1000, 2048], expected [1008, 2048]" in refused(load_inception, wrong)
    damaged = tmp_path / "damaged.safetensors"
    state = random_weights(alexnet_shapes(), seed=7)
    state["features.8.bias"][3] = float("nan")
    save_file(state, str(damaged))
    message = refused(load_lpips, damaged, lpips_files[1])
    assert message.startswith(f"{damaged}: features.8.bias holds non-finite values")
    text = tmp_path / "text.safetensors"
    text.write_text("weights")
    assert f"{text}: not a safetensors file" in refused(load_lpips, lpips_files[0], text)


def test_without_weights_the_defaults_are_used_or_named(
    tmp_path: Path, lpips_files: tuple[Path, Path], monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert cache_file("alexnet.safetensors") == tmp_path / "xdg" / "wise" / "alexnet.safetensors"
    cache = tmp_path / "cache" / "wise"
    inception_default = cache / "pt_inception-2015-12-05.safetensors"
    monkeypatch.setattr(inception_module, "DEFAULT_WEIGHTS", inception_default)
    message = refused(load_inception)
    assert message == (
        "FID needs the Inception weights of pytorch-fid (pt_inception-2015-12-05) as safetensors: "
        f"pass --inception-weights FILE or place it at {inception_default}"
    )
    assert f"place it at {inception_default}" in refused(fid, torch.rand(2, 3, 8, 8), torch.rand(2, 3, 8, 8))
    alexnet_default, linear_default = cache / "alexnet.safetensors", cache / "lpips-alex.safetensors"
    monkeypatch.setattr(lpips_module, "DEFAULT_ALEXNET_WEIGHTS", alexnet_default)
    monkeypatch.setattr(lpips_module, "DEFAULT_LINEAR_WEIGHTS", linear_default)
    message = refused(load_lpips)
    assert "LPIPS needs the AlexNet weights of torchvision" in message and str(alexnet_default) in message
    message = refused(load_lpips, lpips_files[0])
    assert "--lpips-weights FILE" in message and message.endswith(f"place it at {linear_default}")
    cache.mkdir(parents=True)
    alexnet_default.symlink_to(lpips_files[0])
    linear_default.symlink_to(lpips_files[1])
    assert torch.equal(load_lpips().lin4.model[1].weight, load_lpips(*lpips_files).lin4.model[1].weight)
