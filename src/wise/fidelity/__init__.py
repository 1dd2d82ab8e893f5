"""Image-set fidelity metrics with user-provided safetensors weights: FID (Heusel et al. 2017) and LPIPS
(Zhang et al. 2018). Nothing is downloaded and no pickle is loaded.

Note that the functions :func:`fid` and :func:`lpips` take the names of their modules as attributes of
this package; import module contents with ``from wise.fidelity.lpips import ...``.
"""

from wise.fidelity.fid import feature_statistics, fid, frechet_distance
from wise.fidelity.inception import FIDInception, load_inception
from wise.fidelity.lpips import LPIPS, load_lpips, lpips

__all__ = [
    "FIDInception",
    "LPIPS",
    "feature_statistics",
    "fid",
    "frechet_distance",
    "load_inception",
    "load_lpips",
    "lpips",
]
