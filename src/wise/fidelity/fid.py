"""FID, the Fréchet Inception Distance of Heusel et al. 2017 ("GANs Trained by a Two Time-Scale Update
Rule Converge to a Local Nash Equilibrium").

The distance between two image sets is the Fréchet (2-Wasserstein) distance between Gaussians fitted to
their Inception pool features: ``|mu1 - mu2|^2 + tr(S1 + S2 - 2 (S1 S2)^(1/2))``. The features come from
:mod:`wise.fidelity.inception`, with the weights ``pt_inception-2015-12-05`` of pytorch-fid as a
safetensors file (see there how to convert the ``.pth`` release on your own machine). Published FIDs use
50 000 images; with fewer the estimate is biased upwards, so only compare FIDs of equally many images.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator

import numpy as np
import torch

from wise.errors import WiseError
from wise.fidelity.inception import check_images, load_inception
from wise.pretrained import PathLike

DEFAULT_BATCH_SIZE = 32
SQRT_EPS = 1e-6
"""Added to both covariances' diagonals when the matrix square root fails (as pytorch-fid does)."""
MIN_IMAGES = 2
"""A covariance needs at least two images."""

Features = Callable[[torch.Tensor], torch.Tensor]
"""A network mapping images ``(B, 3, H, W)`` to features ``(B, D)``, like :class:`FIDInception`."""
Images = torch.Tensor | Iterable[torch.Tensor]
"""A tensor ``(N, 3, H, W)`` or an iterable of batches ``(B, 3, H, W)`` or single images ``(3, H, W)``."""


def _batches(images: Images, batch_size: int) -> Iterator[torch.Tensor]:
    """``images`` as batches of at most ``batch_size`` images."""
    items = (images,) if isinstance(images, torch.Tensor) else images
    for item in items:
        batch = item[None] if isinstance(item, torch.Tensor) and item.dim() == 3 else item
        check_images(batch)
        yield from batch.split(batch_size)


def _device(network: Features) -> torch.device | None:
    if isinstance(network, torch.nn.Module):
        for parameter in network.parameters():
            return parameter.device
    return None


class _Moments:
    """Running sum and sum of outer products of feature vectors, in float64, about the first batch's mean."""

    def __init__(self) -> None:
        self.count = 0
        self.origin: np.ndarray | None = None
        self.total: np.ndarray | None = None
        self.outer: np.ndarray | None = None

    def add(self, features: np.ndarray) -> None:
        """Add features ``(B, D)``."""
        if self.origin is None:
            self.origin = features.mean(axis=0)
            self.total = np.zeros_like(self.origin)
            self.outer = np.zeros((features.shape[1], features.shape[1]))
        centred = features - self.origin
        self.total += centred.sum(axis=0)
        self.outer += centred.T @ centred
        self.count += features.shape[0]

    def mean_and_covariance(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean ``(D,)`` and unbiased covariance ``(D, D)`` (divided by N - 1, as ``np.cov``)."""
        if self.count < MIN_IMAGES or self.origin is None:
            raise WiseError(f"FID needs at least {MIN_IMAGES} images per set, got {self.count}; pass more images")
        offset = self.total / self.count
        covariance = (self.outer - self.count * np.outer(offset, offset)) / (self.count - 1)
        return self.origin + offset, (covariance + covariance.T) / 2


def feature_statistics(
    images: Images, network: Features, batch_size: int = DEFAULT_BATCH_SIZE
) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(D,)`` and covariance ``(D, D)``, float64, of ``network``'s features of ``images`` in [0, 1].

    ``images`` is a tensor ``(N, 3, H, W)`` or an iterable of batches ``(B, 3, H, W)`` or images
    ``(3, H, W)``, so that large sets can stream; at least 2 images in all. With fewer images than
    features (2048 for Inception) the covariance is singular; :func:`frechet_distance` still gives a number.
    """
    moments = _Moments()
    device = _device(network)
    with torch.no_grad():
        for batch in _batches(images, batch_size):
            features = network(batch if device is None else batch.to(device))
            moments.add(features.reshape(batch.shape[0], -1).double().cpu().numpy())
    return moments.mean_and_covariance()


def _check_gaussian(mu: np.ndarray, sigma: np.ndarray, which: str) -> None:
    if mu.ndim != 1 or sigma.shape != (mu.shape[0], mu.shape[0]):
        raise WiseError(
            f"the {which} statistics have a mean of shape {list(mu.shape)} and a covariance of shape "
            f"{list(sigma.shape)}; pass a mean (D,) and a covariance (D, D)"
        )
    if not (np.isfinite(mu).all() and np.isfinite(sigma).all()):
        raise WiseError(f"the {which} statistics hold non-finite values (NaN or infinity); compute them again")


def _trace_sqrt_product(sigma1: np.ndarray, sigma2: np.ndarray) -> float:
    """``tr((S1 S2)^(1/2))`` for symmetric positive semi-definite ``S1``, ``S2``.

    With ``S1 = R R^T`` (R from the eigenvectors of positive eigenvalues), ``S1 S2`` has the nonzero
    eigenvalues of the symmetric ``R^T S2 R``, so the trace is the sum of their square roots: real and
    exact, without the complex parts that a general matrix square root can produce. Eigenvalues of ``S1``
    below the rounding level (``np.linalg.matrix_rank``'s tolerance) count as 0: a singular ``S1`` then
    gives a small ``R^T S2 R`` and no noise from the null space.
    """
    values, vectors = np.linalg.eigh(sigma1)
    positive = values > values.max(initial=0.0) * values.size * np.finfo(values.dtype).eps
    root = vectors[:, positive] * np.sqrt(values[positive])
    inner = root.T @ sigma2 @ root
    eigenvalues = np.linalg.eigvalsh((inner + inner.T) / 2)
    return float(np.sqrt(np.clip(eigenvalues, 0.0, None)).sum())


def _robust_trace_sqrt_product(sigma1: np.ndarray, sigma2: np.ndarray, eps: float) -> float:
    """:func:`_trace_sqrt_product`, retried with ``eps`` added to both diagonals should it fail."""
    try:
        trace = _trace_sqrt_product(sigma1, sigma2)
    except np.linalg.LinAlgError:
        trace = float("nan")
    if np.isfinite(trace):
        return trace
    offset = eps * np.eye(sigma1.shape[0])
    return _trace_sqrt_product(sigma1 + offset, sigma2 + offset)


def frechet_distance(
    mu1: np.ndarray, sigma1: np.ndarray, mu2: np.ndarray, sigma2: np.ndarray, eps: float = SQRT_EPS
) -> float:
    """Fréchet distance ``|mu1 - mu2|^2 + tr(S1 + S2 - 2 (S1 S2)^(1/2))`` between two Gaussians.

    Means ``(D,)``, covariances ``(D, D)``, symmetric positive semi-definite; singular ones (fewer samples
    than dimensions) are fine. Computed in float64 by eigen-decomposition; should that fail, ``eps`` is added
    to both diagonals. Rounding below 0 is reported as 0.
    """
    mu1, mu2 = np.asarray(mu1, np.float64), np.asarray(mu2, np.float64)
    sigma1, sigma2 = np.asarray(sigma1, np.float64), np.asarray(sigma2, np.float64)
    _check_gaussian(mu1, sigma1, "first")
    _check_gaussian(mu2, sigma2, "second")
    if mu1.shape != mu2.shape:
        raise WiseError(f"the statistics have {mu1.shape[0]} and {mu2.shape[0]} dimensions; compute both alike")
    sigma1, sigma2 = (sigma1 + sigma1.T) / 2, (sigma2 + sigma2.T) / 2
    difference = mu1 - mu2
    trace = _robust_trace_sqrt_product(sigma1, sigma2, eps)
    distance = float(difference @ difference + np.trace(sigma1) + np.trace(sigma2) - 2 * trace)
    return max(distance, 0.0)


def fid(
    images_a: Images,
    images_b: Images,
    weights: PathLike | None = None,
    batch_size: int = DEFAULT_BATCH_SIZE,
    device: str | torch.device = "cpu",
) -> float:
    """FID between two image sets (see :func:`feature_statistics` for the forms ``images_a`` may take).

    ``weights`` is the safetensors file of ``pt_inception-2015-12-05`` (default
    ``~/.cache/wise/pt_inception-2015-12-05.safetensors``). Any number of images from 2 up works; with
    fewer than 2048 per set the covariances are singular and the result is still a finite number, but
    larger than with many images (FID is biased by the set size).
    """
    network = load_inception(weights).to(device)
    mu1, sigma1 = feature_statistics(images_a, network, batch_size)
    mu2, sigma2 = feature_statistics(images_b, network, batch_size)
    return frechet_distance(mu1, sigma1, mu2, sigma2)
