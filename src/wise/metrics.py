"""Image similarity metrics on ``(B, C, H, W)`` tensors in [0, 1]."""

from __future__ import annotations

import math

import torch
import torch.nn.functional as F

SSIM_SIGMA = 1.5
SSIM_RADIUS = 5
SSIM_K1, SSIM_K2 = 0.01, 0.03


def l1(image: torch.Tensor, reference: torch.Tensor) -> float:
    """Mean absolute difference."""
    return float((image - reference).abs().mean())


def psnr(image: torch.Tensor, reference: torch.Tensor) -> float:
    """Peak signal-to-noise ratio in dB for a peak of 1 (inf for identical images)."""
    mse = float(((image - reference) ** 2).mean())
    return math.inf if mse == 0.0 else 10.0 * math.log10(1.0 / mse)


def ssim(image: torch.Tensor, reference: torch.Tensor) -> float:
    """Structural similarity (Wang et al. 2004) with an 11x11 Gaussian window of sigma 1.5,
    averaged over pixels and channels; images in [0, 1]."""
    offsets = torch.arange(-SSIM_RADIUS, SSIM_RADIUS + 1, dtype=image.dtype, device=image.device)
    kernel = torch.exp(-offsets * offsets / (2 * SSIM_SIGMA**2))
    kernel = kernel / kernel.sum()
    channels = image.shape[1]
    window = (kernel[:, None] * kernel[None, :]).expand(channels, 1, -1, -1)

    def local_mean(x: torch.Tensor) -> torch.Tensor:
        return F.conv2d(x, window, groups=channels)

    mu_x, mu_y = local_mean(image), local_mean(reference)
    var_x = local_mean(image * image) - mu_x * mu_x
    var_y = local_mean(reference * reference) - mu_y * mu_y
    cov = local_mean(image * reference) - mu_x * mu_y
    c1, c2 = SSIM_K1**2, SSIM_K2**2
    score = ((2 * mu_x * mu_y + c1) * (2 * cov + c2)) / ((mu_x * mu_x + mu_y * mu_y + c1) * (var_x + var_y + c2))
    return float(score.mean())
