"""The smoothed structure tensor and the edge tangent flow derived from it."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from wise.filters import fused
from wise.filters._checks import ParamLike, as_map, check_image, resolution_scale
from wise.filters.gaussian import gaussian_blur
from wise.filters.sampling import sample, tap_sum

# The eight neighbours of a 3x3 Sobel stencil: (dx, dy, weight of d/dx, weight of d/dy)
_SOBEL_TAPS = (
    (-1, -1, -1.0, -1.0),
    (0, -1, 0.0, -2.0),
    (1, -1, 1.0, -1.0),
    (-1, 0, -2.0, 0.0),
    (1, 0, 2.0, 0.0),
    (-1, 1, -1.0, 1.0),
    (0, 1, 0.0, 2.0),
    (1, 1, 1.0, 1.0),
)
_SOBEL_NORM = 8.0
_WHOLE_PIXEL_TOLERANCE = 1e-6
_ATAN_EPS = 1e-9


def structure_tensor(image: torch.Tensor, sigma: ParamLike = 1.0, scale: float | None = None) -> torch.Tensor:
    """Structure tensor from Sobel derivatives taken ``sigma`` apart (Brox et al. 2006).

    Derivatives come from a 3x3 Sobel stencil whose neighbours lie ``sigma`` pixels
    from the centre (bilinearly sampled), so ``sigma`` sets the derivative scale and may
    vary per pixel. Channels are summed (Di Zenzo's multi-channel tensor).

    Args:
        image: ``(B, C, H, W)``.
        sigma: neighbour distance in pixels of a 512-pixel short side; float, ``(B,)`` or ``(B, 1, H, W)``.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, 3, H, W)`` with the components ``(fx*fx, fx*fy, fy*fy)``.
    """
    check_image(image)
    s = resolution_scale(image) if scale is None else scale
    if isinstance(sigma, (int, float)) and not fused.enabled(image):  # the fused kernel is faster still
        pixels = float(sigma) * s
        if pixels >= 1.0 and abs(pixels - round(pixels)) < _WHOLE_PIXEL_TOLERANCE:
            fx, fy = _sobel_at_whole_pixels(image, round(pixels))
            return _tensor_components(fx, fy)
    distance = (as_map(sigma, image, "sigma") * s).clamp_min(1e-3)
    b, _, h, w = image.shape
    distance = distance.expand(b, 1, h, w)

    if fused.enabled(image, distance):
        from wise.filters.fused.structure import StructureTensor

        return StructureTensor.apply(image, distance, _fused_weights(image.dtype))

    def tap(k: int, image: torch.Tensor, distance: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        dx, dy, wx, wy = _SOBEL_TAPS[k]
        offset = torch.cat((distance * dx, distance * dy), dim=1)
        value = sample(image, offset)
        return value * (wx / _SOBEL_NORM), value * (wy / _SOBEL_NORM)

    fx, fy = tap_sum(tap, len(_SOBEL_TAPS), image, distance)
    fx = fx / distance
    fy = fy / distance
    return _tensor_components(fx, fy)


def _fused_weights(dtype: torch.dtype) -> torch.Tensor:
    """The Sobel weights of d/dx and d/dy as the fused kernel reads them: ``(2, 3, 3)`` by ``(dy + 1, dx + 1)``."""
    weights = torch.zeros(2, 3, 3, dtype=dtype)
    for dx, dy, weight_x, weight_y in _SOBEL_TAPS:
        weights[:, dy + 1, dx + 1] = torch.tensor((weight_x, weight_y), dtype=dtype) / _SOBEL_NORM
    return weights


def _tensor_components(fx: torch.Tensor, fy: torch.Tensor) -> torch.Tensor:
    return torch.stack(((fx * fx).sum(1), (fx * fy).sum(1), (fy * fy).sum(1)), dim=1)


def _sobel_at_whole_pixels(image: torch.Tensor, distance: int) -> tuple[torch.Tensor, torch.Tensor]:
    """The Sobel derivatives of :func:`structure_tensor` for a whole-pixel neighbour distance:
    its bilinear samples are then shifted copies of the border-replicated image, taken here
    by slicing instead of sampling (the same values, several times faster with backward)."""
    h, w = image.shape[-2:]
    padded = F.pad(image, (distance, distance, distance, distance), mode="replicate")
    fx = fy = torch.zeros((), dtype=image.dtype, device=image.device)
    for dx, dy, weight_x, weight_y in _SOBEL_TAPS:
        top, left = distance * (1 + dy), distance * (1 + dx)
        neighbour = padded[..., top : top + h, left : left + w]
        fx = fx + weight_x * neighbour if weight_x else fx
        fy = fy + weight_y * neighbour if weight_y else fy
    norm = _SOBEL_NORM * distance
    return fx / norm, fy / norm


def coarse_structure_tensor(
    image: torch.Tensor, sigma_blur: float, sigma_derivative: ParamLike = 1.0, scale: float | None = None
) -> torch.Tensor:
    """:func:`structure_tensor` of ``image`` blurred by ``sigma_blur`` (reference pixels): the
    structure at a coarse scale, the slow shading of a surface rather than its noise. ``(B, 3, H, W)``."""
    s = resolution_scale(image) if scale is None else scale
    return structure_tensor(gaussian_blur(image, sigma_blur, scale=s), sigma_derivative, s)


def smoothed_structure_tensor(
    image: torch.Tensor, sigma_derivative: ParamLike = 1.0, sigma_smoothing: ParamLike = 2.0, scale: float | None = None
) -> torch.Tensor:
    """:func:`structure_tensor` followed by Gaussian smoothing (Kyprianidis & Döllner 2008). ``(B, 3, H, W)``."""
    tensor = structure_tensor(image, sigma_derivative, scale)
    return gaussian_blur(tensor, sigma_smoothing, scale=resolution_scale(image) if scale is None else scale)


def edge_tangent_flow(tensor: torch.Tensor) -> torch.Tensor:
    """Edge tangent flow: the minor eigenvector of the structure tensor (Kang et al. 2009).

    Args:
        tensor: ``(B, 3, H, W)`` structure tensor ``(fx*fx, fx*fy, fy*fy)``.

    Returns:
        ``(B, 2, H, W)`` unit vectors (x, y) along edges, in image coordinates (y down).
        Where the tensor vanishes the direction is arbitrary but finite.
    """
    check_image(tensor, name="structure tensor", channels=3)
    if fused.enabled(tensor):
        from wise.filters.fused.structure import edge_tangent_flow as fused_flow

        return fused_flow(tensor, _ATAN_EPS)
    xx, xy, yy = tensor.unbind(dim=1)
    angle = 0.5 * torch.atan2(-2.0 * xy + _ATAN_EPS, yy - xx)
    return torch.stack((torch.cos(angle), torch.sin(angle)), dim=1)


def gradient_direction(tangent: torch.Tensor) -> torch.Tensor:
    """The unit direction across the flow: ``tangent`` rotated by 90 degrees. ``(B, 2, H, W)``."""
    return torch.stack((tangent[:, 1], -tangent[:, 0]), dim=1)


def anisotropy(tensor: torch.Tensor) -> torch.Tensor:
    """The difference of the eigenvalues of a structure tensor, ``sqrt((xx - yy)^2 + 4 xy^2)``: how
    strongly one direction dominates. ``(B, 1, H, W)``."""
    xx, xy, yy = tensor[:, 0:1], tensor[:, 1:2], tensor[:, 2:3]
    return torch.sqrt((xx - yy) ** 2 + 4.0 * xy * xy + _ATAN_EPS)


def unit_deviator(tensor: torch.Tensor) -> torch.Tensor:
    """The direction of a structure tensor at unit strength: its traceless part divided by its
    anisotropy, ``(T - tr(T)/2 I) / a``. It has the eigenvectors of ``T`` and eigenvalues
    ``+-1/2``, so adding it to another tensor turns that one's flow towards ``T``'s by a fixed
    amount however weak ``T`` is. ``(B, 3, H, W)``."""
    half_difference = 0.5 * (tensor[:, 0:1] - tensor[:, 2:3])
    strength = anisotropy(tensor)
    return torch.cat((half_difference, tensor[:, 1:2], -half_difference), dim=1) / strength


def relaxed_structure_tensor(
    tensor: torch.Tensor,
    coarse: torch.Tensor,
    sigma: float,
    threshold: float,
    gain: float,
    wide_sigma: float,
    scale: float | None = None,
) -> torch.Tensor:
    """A structure tensor relaxed where it is weak, so that the flow is calm in flat regions
    and follows the picture's form (after the flow relaxation of Semmo et al. 2016, "Image
    stylization by interactive oil paint filtering", which relaxes the flow from the image's
    own structure at a larger scale).

    With the confidence ``c = a / (a + threshold)`` of the anisotropy ``a``, the strong
    structure is spread over a neighbourhood, ``N = G_sigma * (c S)``, and the structure at a
    coarse scale ``S_c`` (the tensor of the blurred picture, where noise has averaged out),
    with the strong local structure, over a wider one, ``W = G_wide * (S_c + gain c S)``;
    both are added where the local structure
    is weak:

        S' = S + (1 - c) (gain N + threshold U(W))

    where ``U`` is :func:`unit_deviator`. Near edges ``S'`` is the local tensor; in flat
    regions the flow follows the strong edges nearby, and where there are none the direction
    of the picture's structure at the wide scale (the form of a face, the lighting
    of a wall), at a fixed strength however weak it is. No direction is preferred, so the
    flow of a mirrored picture is the mirrored flow.

    Args:
        tensor: ``(B, 3, H, W)`` structure tensor in (value per reference pixel)^2, e.g.
            :func:`smoothed_structure_tensor` times ``scale ** 2``.
        coarse: ``(B, 3, H, W)`` structure tensor of the picture blurred at a coarse scale, in
            the same units.
        sigma: reach of the strong edges in pixels of a 512-pixel short side.
        threshold: anisotropy at which the local structure counts half (same units as ``tensor``).
        gain: weight of the spread strong structure against the weak local one.
        wide_sigma: scale of the picture's structure that sets the flow where no strong edge
            is near, in pixels of a 512-pixel short side.
        scale: pixels per reference pixel (default ``min(H, W) / 512``).

    Returns:
        ``(B, 3, H, W)``.
    """
    check_image(tensor, name="structure tensor", channels=3)
    check_image(coarse, name="coarse structure tensor", channels=3)
    s = resolution_scale(tensor) if scale is None else scale
    confidence = anisotropy(tensor)
    confidence = confidence / (confidence + threshold)
    near = gaussian_blur(confidence * tensor, sigma, scale=s)
    wide = unit_deviator(gaussian_blur(coarse + gain * confidence * tensor, wide_sigma, scale=s))
    return tensor + (1.0 - confidence) * (gain * near + threshold * wide)
