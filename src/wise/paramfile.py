"""Effect parameters in safetensors files (no pickle).

A parameter file holds one float32 tensor ``params``, shaped ``(P,)`` for
global parameters or ``(P, h, w)`` for local masks, and string metadata:

``format``      ``"wise-params"``
``version``     ``"1"``
``effect``      the effect name
``parameters``  JSON list of the parameter names, in the order of the tensor
``space``       ``"normalized"`` or ``"real"`` (real units)
``kind``        ``"global"`` or ``"local"``
``ranges``      JSON list of ``[min, max]`` per parameter, for information
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import torch
from safetensors import SafetensorError
from safetensors.torch import load as _st_load
from safetensors.torch import save as _st_save

from wise import params as P
from wise.effects.base import Effect
from wise.errors import WiseError
from wise.io import PathLike, atomic_path

FORMAT = "wise-params"
VERSION = "1"
SPACES = ("normalized", "real")
TENSOR_KEY = "params"


def _as_batched(params: torch.Tensor, effect: Effect) -> torch.Tensor:
    """Validate ``params`` and return them as ``(1, P)`` or ``(1, P, h, w)``."""
    n = len(effect.param_specs)
    if not isinstance(params, torch.Tensor):
        raise WiseError(f"parameters must be a torch.Tensor, got {type(params).__name__}")
    if params.dim() in (1, 3):
        params = params.unsqueeze(0)
    if params.dim() not in (2, 4) or params.shape[0] != 1 or params.shape[1] != n:
        raise WiseError(
            f"parameters for {effect.name!r} must have shape ({n},), (1, {n}), ({n}, h, w) or (1, {n}, h, w); "
            f"got {tuple(params.shape)}"
        )
    if params.dim() == 4 and min(params.shape[-2:]) == 0:
        raise WiseError(f"parameter masks are empty: shape {tuple(params.shape)}")
    if not params.is_floating_point():
        raise WiseError(f"parameters must be floating point, got {params.dtype}")
    return params.detach().to("cpu", torch.float32)


def _check_finite(values: torch.Tensor, names: list[str], where: str) -> None:
    for i, name in enumerate(names):
        if not torch.isfinite(values[i]).all():
            raise WiseError(f"{where}: parameter {name!r} has NaN or infinite values")


def save_params(path: PathLike, effect: Effect, params: torch.Tensor, space: str = "normalized") -> None:
    """Save normalized ``params`` of ``effect`` to a safetensors file, atomically.

    ``params`` is ``(P,)``, ``(1, P)``, ``(P, h, w)`` or ``(1, P, h, w)``. With
    ``space="real"`` the values are stored in real units.
    """
    if space not in SPACES:
        raise WiseError(f"space must be one of {', '.join(SPACES)}; got {space!r}")
    batched = _as_batched(params, effect)
    _check_finite(batched[0], effect.param_names, str(path))
    if space == "real":
        batched = P.to_real(batched, effect.param_specs)
    metadata = {
        "format": FORMAT,
        "version": VERSION,
        "effect": effect.name,
        "parameters": json.dumps(effect.param_names),
        "space": space,
        "kind": "local" if batched.dim() == 4 else "global",
        "ranges": json.dumps([[s.min, s.max] for s in effect.param_specs]),
    }
    data = _st_save({TENSOR_KEY: batched[0].contiguous()}, metadata=metadata)
    try:
        with atomic_path(path) as tmp:
            tmp.write_bytes(data)
    except OSError as e:
        raise WiseError(f"{path}: cannot write the parameter file ({e.strerror or e})") from None


def _read(path: Path) -> tuple[dict[str, torch.Tensor], dict[str, str]]:
    if not path.exists():
        raise WiseError(f"{path}: no such file")
    if path.is_dir():
        raise WiseError(f"{path}: is a directory, not a parameter file")
    try:
        data = path.read_bytes()
    except OSError as e:
        raise WiseError(f"{path}: cannot read the file ({e.strerror or e})") from None
    try:
        tensors = _st_load(data)
        header_len = int.from_bytes(data[:8], "little")
        header: dict[str, Any] = json.loads(data[8 : 8 + header_len])
    except (SafetensorError, ValueError, RuntimeError, TypeError, OverflowError):
        raise WiseError(f"{path}: not a safetensors file or unreadable") from None
    metadata = header.get("__metadata__") or {}
    return tensors, metadata if isinstance(metadata, dict) else {}


def _parse_names(path: Path, metadata: dict[str, str]) -> list[str]:
    try:
        names = json.loads(metadata.get("parameters", ""))
    except ValueError:
        names = None
    if not isinstance(names, list) or not all(isinstance(n, str) for n in names):
        raise WiseError(f"{path}: the 'parameters' metadata is not a JSON list of names")
    duplicates = sorted({n for n in names if names.count(n) > 1})
    if duplicates:
        raise WiseError(f"{path}: parameter(s) listed twice: {', '.join(duplicates)}")
    return names


def load_params(path: PathLike, effect: Effect) -> torch.Tensor:
    """Load a parameter file for ``effect`` as normalized ``(1, P)`` or ``(1, P, h, w)``.

    Parameters are reordered by name to the effect's order and real-space files
    are converted. Raises :class:`WiseError` with a one-line reason otherwise.
    """
    path = Path(path)
    tensors, metadata = _read(path)
    if metadata.get("format") != FORMAT:
        raise WiseError(f"{path}: not a wise parameter file (no 'format: {FORMAT}' metadata)")
    if metadata.get("version") != VERSION:
        raise WiseError(
            f"{path}: unsupported wise parameter file version {metadata.get('version')!r}; expected {VERSION!r}"
        )
    made_for = metadata.get("effect")
    if made_for != effect.name:
        raise WiseError(f"{path}: parameters made for effect {made_for!r}, not for {effect.name!r}")
    names = _parse_names(path, metadata)
    expected = effect.param_names
    missing = [n for n in expected if n not in names]
    extra = [n for n in names if n not in expected]
    problems = []
    if missing:
        problems.append(f"missing parameter(s) {', '.join(missing)}")
    if extra:
        problems.append(f"unknown parameter(s) {', '.join(extra)}")
    if problems:
        raise WiseError(f"{path}: {'; '.join(problems)} for effect {effect.name!r}")
    space = metadata.get("space")
    if space not in SPACES:
        raise WiseError(f"{path}: unknown value space {space!r}; expected one of {', '.join(SPACES)}")
    if set(tensors) != {TENSOR_KEY}:
        found = ", ".join(sorted(tensors)) or "none"
        raise WiseError(f"{path}: expected exactly one tensor named {TENSOR_KEY!r}, found: {found}")
    values = tensors[TENSOR_KEY]
    n = len(names)
    if values.dim() not in (1, 3) or values.shape[0] != n or (values.dim() == 3 and min(values.shape[1:]) == 0):
        raise WiseError(f"{path}: wrong tensor shape {tuple(values.shape)}; expected ({n},) or ({n}, h, w)")
    kind = metadata.get("kind")
    actual_kind = "local" if values.dim() == 3 else "global"
    if kind is not None and kind != actual_kind:
        raise WiseError(
            f"{path}: metadata says {kind!r} parameters but the tensor shape {tuple(values.shape)} is {actual_kind}"
        )
    if not values.is_floating_point():
        raise WiseError(f"{path}: parameters must be floating point, found {values.dtype}")
    values = values.to(torch.float32)
    _check_finite(values, names, str(path))
    values = values[[names.index(name) for name in expected]].unsqueeze(0)
    if space == "real":
        values = P.to_normalized(values, effect.param_specs)
        _check_finite(values[0], expected, str(path))
    return values.contiguous()


def describe(path: PathLike) -> dict[str, str]:
    """The metadata of a parameter file (without validating it against an effect)."""
    _, metadata = _read(Path(path))
    return dict(metadata)


__all__ = ["save_params", "load_params", "describe", "FORMAT", "VERSION"]
