"""Image similarity metrics on ``(B, C, H, W)`` tensors in [0, 1], and measures of stylized faces."""

from __future__ import annotations

import math

import numpy as np
import torch
import torch.nn.functional as F

from wise.filters.color import rgb_to_lab
from wise.filters.gaussian import gaussian_blur

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


FAR_COLOUR = 30.0
"""CIE Lab distance (ΔE 1976) beyond which a colour reads as another colour."""


def far_colour_share(image: torch.Tensor, reference: torch.Tensor, far: float = FAR_COLOUR) -> float:
    """Share of pixels whose colour is more than ``far`` ΔE (CIE Lab) from the reference's, both
    ``(1, 3, H, W)`` blurred by 1 px first so that texture and half-pixel shifts do not count."""
    if image.shape != reference.shape:
        raise ValueError(f"image {tuple(image.shape)} and reference {tuple(reference.shape)} differ in size")

    def lab(picture: torch.Tensor) -> torch.Tensor:
        return rgb_to_lab(gaussian_blur(picture.clamp(0.0, 1.0), 1.0, scale=1.0))

    return float(((lab(image) - lab(reference)).norm(dim=1) > far).float().mean())


MARK_SIGMA = 2.0
"""Sigma (pixels) of the blur whose difference from the lightness is a picture's thin structure."""
MARK_CONTRAST = 8.0
"""CIE L* by which a thin structure must be darker or lighter than the reference's to count as a mark."""


def marks(image: torch.Tensor, reference: torch.Tensor) -> tuple[float, float]:
    """Shares of pixels on thin structures of ``image`` that the ``reference`` does not have
    (dashes, scratches, streaks): darker, lighter. Both ``(1, 3, H, W)`` in [0, 1].

    A picture's thin structure is its CIE lightness minus that lightness blurred by
    :data:`MARK_SIGMA` pixels. A pixel is a mark where ``image``'s structure is more than
    :data:`MARK_CONTRAST` L* darker (or lighter) than its surroundings, than the reference's
    structure there and than the reference's pixel: a dark line where the reference has none or a
    fainter one. Lines the
    reference has count as well matched; lines it has and ``image`` lacks are no marks."""
    if image.shape != reference.shape:
        raise ValueError(f"image {tuple(image.shape)} and reference {tuple(reference.shape)} differ in size")

    def lightness(picture: torch.Tensor) -> torch.Tensor:
        return rgb_to_lab(picture.clamp(0.0, 1.0))[:, :1]

    def structure(lightness: torch.Tensor) -> torch.Tensor:
        return lightness - gaussian_blur(lightness, MARK_SIGMA, scale=1.0)

    own, theirs = lightness(image), lightness(reference)
    own_structure = structure(own)
    unmatched = own_structure - structure(theirs)
    difference = own - theirs  # the pixels beside a dark line are lighter than its blur, not than the reference
    darker = (own_structure < -MARK_CONTRAST) & (unmatched < -MARK_CONTRAST) & (difference < -MARK_CONTRAST)
    lighter = (own_structure > MARK_CONTRAST) & (unmatched > MARK_CONTRAST) & (difference > MARK_CONTRAST)
    return float(darker.float().mean()), float(lighter.float().mean())


def stroke_orientation(image: torch.Tensor, sigma: float = 4.0) -> torch.Tensor:
    """The dominant orientation of the strokes of an image as a doubled-angle field.

    The luminance's smoothed structure tensor (derivatives by central differences, Gaussian
    smoothing of ``sigma`` pixels) gives ``(xx - yy, 2 xy)``, which points at twice the
    gradient angle and has the strength of the orientation as its length; the sign of a
    direction does not matter in this form.

    Args:
        image: ``(B, C, H, W)``.
        sigma: smoothing in pixels (not reference pixels).

    Returns:
        ``(B, 2, H, W)``.
    """
    grey = image.mean(dim=1, keepdim=True)
    gy, gx = torch.gradient(grey, dim=(2, 3))
    tensor = gaussian_blur(torch.cat((gx * gx, gx * gy, gy * gy), dim=1), sigma, scale=1.0)
    return torch.cat((tensor[:, 0:1] - tensor[:, 2:3], 2.0 * tensor[:, 1:2]), dim=1)


def orientation_agreement(first: torch.Tensor, second: torch.Tensor, sigma: float = 4.0) -> torch.Tensor:
    """``cos(2 Δθ)`` per pixel between the stroke orientations of two images (see
    :func:`stroke_orientation`): 1 where the strokes are parallel, -1 where they cross at a
    right angle, 0 on average for unrelated orientations. ``(B, 1, H, W)``."""
    a, b = stroke_orientation(first, sigma), stroke_orientation(second, sigma)
    dot = (a * b).sum(dim=1, keepdim=True)
    return dot / (a.norm(dim=1, keepdim=True) * b.norm(dim=1, keepdim=True) + 1e-12)


BLOWN_LIGHTNESS = 95.0
LIT_PHOTO_LIGHTNESS = 88.0
FEATURE_SHARE = 0.05
FEATURE_BLUR = 1.0


def lightness(image: np.ndarray) -> np.ndarray:
    """CIE L* of an (H, W, 3) uint8 picture."""
    from skimage import color  # here, not at the top: scikit-image's import would slow every command's start

    return color.rgb2lab(image.astype(np.float64) / 255.0)[..., 0]


def face_measures(rendered: np.ndarray, photo: np.ndarray, box: tuple[int, int, int, int]) -> dict[str, float]:
    """How a stylized face keeps the photo's, on the (top, bottom, left, right) ``box`` of two
    (H, W, 3) uint8 pictures, in CIE L*:

    - ``blown``: the share of the face's pixels above L* 95 where the photo is below 88 (skin
      washed to white);
    - ``shift``: mean L* of the render minus the photo's (a brighter or darker face);
    - ``contrast``: the photo's darkest 5 % of the face (eyes, brows, nostrils, the line of the
      lips), both pictures blurred by sigma 1 px, the face's median minus the mean of those
      pixels, render over photo: 1 means the features are as defined as in the photo.
    """
    from skimage.filters import gaussian  # as in lightness()

    top, bottom, left, right = box
    photo_l, render_l = lightness(photo), lightness(rendered)
    face_photo, face_render = photo_l[top:bottom, left:right], render_l[top:bottom, left:right]
    blown = float(((face_render > BLOWN_LIGHTNESS) & (face_photo < LIT_PHOTO_LIGHTNESS)).mean())
    shift = float(face_render.mean() - face_photo.mean())
    blurred_photo = gaussian(photo_l, FEATURE_BLUR, preserve_range=True)[top:bottom, left:right]
    blurred_render = gaussian(render_l, FEATURE_BLUR, preserve_range=True)[top:bottom, left:right]
    features = blurred_photo <= np.quantile(blurred_photo, FEATURE_SHARE)
    photo_contrast = np.median(blurred_photo) - blurred_photo[features].mean()
    render_contrast = np.median(blurred_render) - blurred_render[features].mean()
    return {"blown": blown, "shift": shift, "contrast": float(render_contrast / photo_contrast)}
