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

Files are read through :func:`wise.files.read_safetensors`: only regular files of
at most :data:`~wise.files.MAX_PARAMS_BYTES`, with the header checked before any
tensor data is read.

Value policy on loading: NaN or infinite values are refused. Finite values outside
the effect's declared range are clamped to it, with one warning per file naming the
parameters, how many values were out of range and the range in real units. The
range a file may hold is widened to where masks fitted to a reference may go (the colour
offsets' reach) and to the presets that deliberately sit outside the declared range, so
fitted masks and saved presets load and render as made (:func:`accepted_span`). Deviations below
:data:`RANGE_TOLERANCE` (rounding in a real-space file) are clamped without a
warning.
"""

from __future__ import annotations

import json
import warnings
from pathlib import Path

import torch
from safetensors.torch import save as _st_save

from wise import params as P
from wise.effects.base import Effect
from wise.errors import WiseError, WiseWarning
from wise.files import MAX_PARAMS_BYTES, PARAMS_WHAT, read_safetensors, read_safetensors_header
from wise.io import PathLike, atomic_path

FORMAT = "wise-params"
VERSION = "1"
SPACES = ("normalized", "real")
TENSOR_KEY = "params"
WHAT = PARAMS_WHAT
RANGE_TOLERANCE = 1e-4
"""Normalized distance outside [-0.5, 0.5] clamped without a warning (float rounding of real-space files)."""
MAKE_ONE = "make one with wise optimize, the editor's Save params or wise.paramfile.save_params"


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


def _check_format(path: Path, metadata: dict[str, str]) -> None:
    """Refuse a file without wise metadata or of another format or version."""
    fmt = metadata.get("format")
    if fmt is None:
        raise WiseError(f"{path}: not a wise parameter file (no wise metadata); {MAKE_ONE}")
    if fmt != FORMAT:
        raise WiseError(f"{path}: not a wise parameter file (format {fmt!r}, expected {FORMAT!r}); {MAKE_ONE}")
    if metadata.get("version") != VERSION:
        raise WiseError(
            f"{path}: unsupported wise parameter file version {metadata.get('version')!r}; expected {VERSION!r}"
        )


def _effect_name(path: Path, metadata: dict[str, str]) -> str:
    name = metadata.get("effect")
    if not name:
        raise WiseError(f"{path}: not a wise parameter file (no effect in its metadata); {MAKE_ONE}")
    return name


def accepted_span(effect: Effect) -> tuple[torch.Tensor, torch.Tensor]:
    """Per parameter, the normalized values a file may hold: the declared range [-0.5, 0.5],
    widened to where fitted masks may go (:func:`wise.params.mask_bounds`) and to the presets that
    deliberately sit outside it (so a saved preset loads as authored)."""
    low, high = (bound.flatten() for bound in P.mask_bounds(effect.param_specs, torch.zeros(())))
    for name in effect.presets:
        preset = effect.preset(name).to(torch.float32)
        low, high = torch.minimum(low, preset), torch.maximum(high, preset)
    return low, high


def _clamp(values: torch.Tensor, effect: Effect, path: Path) -> tuple[torch.Tensor, str | None]:
    """Normalized ``(1, P[, h, w])`` values clamped to :func:`accepted_span`, and the warning
    text if any were outside it."""
    low, high = accepted_span(effect)
    shape = (1, -1) + (1,) * (values.dim() - 2)
    clamped = torch.maximum(torch.minimum(values, high.view(shape)), low.view(shape))
    parts = []
    for i, spec in enumerate(effect.param_specs):
        outside = (values[0, i] < low[i] - RANGE_TOLERANCE) | (values[0, i] > high[i] + RANGE_TOLERANCE)
        count = int(outside.sum())
        if count:
            real_low, real_high = spec.to_real(float(low[i])), spec.to_real(float(high[i]))
            values_text = f"{count} value{'s' if count != 1 else ''}"
            parts.append(f"{values_text} of {spec.name} outside [{real_low:g}, {real_high:g}]")
    if not parts:
        return clamped, None
    listed = ", ".join(parts[:-1]) + " and " + parts[-1] if len(parts) > 1 else parts[0]
    ranges = "the range" if len(parts) == 1 else "their ranges"
    return clamped, f"{path}: {listed} clamped to {ranges}"


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


def load_params(path: PathLike, effect: Effect, notes: list[str] | None = None) -> torch.Tensor:
    """Load a parameter file for ``effect`` as normalized ``(1, P)`` or ``(1, P, h, w)``.

    Parameters are reordered by name to the effect's order and real-space files
    are converted. Values outside the declared ranges are clamped (see the module
    docstring): the warning text is appended to ``notes`` when it is a list, and
    otherwise emitted as a :class:`WiseWarning`. Raises :class:`WiseError` with a
    one-line reason for anything else.
    """
    path = Path(path)
    tensors, metadata = read_safetensors(path, WHAT, MAX_PARAMS_BYTES)
    _check_format(path, metadata)
    made_for = _effect_name(path, metadata)
    if made_for != effect.name:
        raise WiseError(f"{path}: parameters made for effect {made_for!r}, not for {effect.name!r}")
    names = _parse_names(path, metadata)
    expected = effect.param_names
    missing = [n for n in expected if n not in names and n not in effect.added_params]
    defaulted = [n for n in expected if n not in names and n in effect.added_params]
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
    values = _with_defaults(values, names, defaulted, effect, space)
    names = names + defaulted
    values = values[[names.index(name) for name in expected]].unsqueeze(0)
    if space == "real":
        values = P.to_normalized(values, effect.param_specs)
        _check_finite(values[0], expected, str(path))
    values, note = _clamp(values, effect, path)
    if defaulted:
        added = (
            f"{path}: made before the parameter(s) {', '.join(defaulted)} existed; "
            "they take their default (the look the file was made with)"
        )
        note = added if note is None else f"{added}; {note}"
    if note is not None:
        if notes is not None:
            notes.append(note)
        else:
            warnings.warn(note, WiseWarning, stacklevel=2)
    return values.contiguous()


def _with_defaults(
    values: torch.Tensor, names: list[str], defaulted: list[str], effect: Effect, space: str
) -> torch.Tensor:
    """``values`` ``(n, ...)`` with a row per name of ``defaulted`` appended, each the
    parameter's default in the file's ``space``, filled to the values' shape."""
    if not defaulted:
        return values
    rows = []
    for name in defaulted:
        spec = effect.spec(name)
        default = spec.default if space == "real" else float(P.from_dict((spec,), {})[0])
        rows.append(torch.full_like(values[:1], default))
    return torch.cat([values, *rows])


def effect_of(path: PathLike) -> str:
    """The name of the effect a parameter file was made for, read from its checked header."""
    path = Path(path)
    _, metadata = read_safetensors_header(path, WHAT, MAX_PARAMS_BYTES)
    _check_format(path, metadata)
    return _effect_name(path, metadata)


def describe(path: PathLike) -> dict[str, str]:
    """The metadata of a parameter file (without validating it against an effect)."""
    _, metadata = read_safetensors_header(Path(path), WHAT, MAX_PARAMS_BYTES)
    return dict(metadata)


__all__ = ["save_params", "load_params", "effect_of", "describe", "FORMAT", "VERSION", "RANGE_TOLERANCE"]
