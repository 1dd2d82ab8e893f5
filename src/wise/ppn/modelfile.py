"""Trained parameter prediction networks in safetensors files (no pickle).

A model file holds the network's weights (float32 or float16) and string metadata:

``format``        ``"wise-ppn"``
``version``       ``"1"``
``effect``        the effect whose parameters it predicts
``kind``          ``"global"``
``architecture``  a name of :data:`wise.ppn.ARCHITECTURES`
``parameters``    JSON list of the parameter names, in the order of the outputs
``ranges``        JSON list of ``[min, max]`` per parameter (real units, for information)
``size``          the working size: both images are resized to this short side
``render_size``   the short side the training examples were rendered at
``settings``      JSON of the training command's settings
``wise_version``  the package version that wrote it

Built-in models live in ``wise/ppn/models/<effect>.safetensors``.
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import torch
from safetensors.torch import save as _st_save
from torch import nn

import wise
from wise import effects
from wise.errors import WiseError
from wise.files import MAX_MODEL_BYTES, read_safetensors, read_safetensors_header, safetensors_path
from wise.io import atomic_path
from wise.ppn import ARCHITECTURES, create

FORMAT = "wise-ppn"
VERSION = "1"
KIND = "global"
WHAT = "model file"
TRAIN_ONE = "train one with 'wise train global'"
BUILTIN_PACKAGE = "wise.ppn.models"


@dataclass
class ModelInfo:
    """What a model file says about its network."""

    effect: str
    architecture: str
    parameters: list[str]
    size: int
    render_size: int
    settings: dict = field(default_factory=dict)
    wise_version: str = ""
    source: str = ""
    """The file it was read from (or ``builtin:<effect>``)."""


def save_model(path: str | os.PathLike[str], network: nn.Module, info: ModelInfo, half: bool = False) -> None:
    """Write ``network``'s weights and ``info`` to ``path`` atomically (float16 with ``half``)."""
    if info.architecture not in ARCHITECTURES:
        raise WiseError(f"unknown architecture {info.architecture!r}")
    effect = effects.create(info.effect)
    dtype = torch.float16 if half else torch.float32
    tensors = {name: value.detach().to("cpu", dtype).contiguous() for name, value in network.state_dict().items()}
    metadata = {
        "format": FORMAT,
        "version": VERSION,
        "effect": info.effect,
        "kind": KIND,
        "architecture": info.architecture,
        "parameters": json.dumps(info.parameters),
        "ranges": json.dumps([[s.min, s.max] for s in effect.param_specs]),
        "size": str(info.size),
        "render_size": str(info.render_size),
        "settings": json.dumps(info.settings, sort_keys=True),
        "wise_version": wise.__version__,
    }
    data = _st_save(tensors, metadata=metadata)
    try:
        with atomic_path(path) as tmp:
            Path(tmp).write_bytes(data)
    except OSError as e:
        raise WiseError(f"{path}: cannot write the model ({e.strerror or e})") from None


def builtin_model_path(effect: str) -> Path:
    """The model shipped for ``effect``; refuses an effect without one."""
    effects.create(effect)
    path = Path(str(resources.files(BUILTIN_PACKAGE) / f"{effect}.safetensors"))
    if not path.is_file():
        raise WiseError(f"no built-in model for {effect!r}; pass --model FILE ({TRAIN_ONE})")
    return path


def _number(path: Path, metadata: dict[str, str], key: str) -> int:
    try:
        value = int(metadata.get(key, ""))
    except ValueError:
        value = 0
    if not 8 <= value <= 4096:
        raise WiseError(f"{path}: the model's {key} {metadata.get(key)!r} is not a size of 8 to 4096 pixels")
    return value


def _info(path: Path, metadata: dict[str, str], effect: str | None) -> ModelInfo:
    fmt = metadata.get("format")
    if fmt != FORMAT:
        found = "no wise metadata" if fmt is None else f"format {fmt!r}"
        raise WiseError(f"{path}: not a wise model file ({found}, expected {FORMAT!r}); {TRAIN_ONE}")
    if metadata.get("version") != VERSION or metadata.get("kind") != KIND:
        raise WiseError(
            f"{path}: unsupported model (version {metadata.get('version')!r}, kind {metadata.get('kind')!r}); "
            f"this wise reads version {VERSION!r} {KIND} models"
        )
    model_effect = metadata.get("effect", "")
    if effect is not None and model_effect != effect:
        raise WiseError(f"{path}: a model for {model_effect!r}, not {effect!r}; pass a model of {effect!r}")
    known = effects.create(effect or model_effect)
    architecture = metadata.get("architecture", "")
    if architecture not in ARCHITECTURES:
        raise WiseError(f"{path}: unknown architecture {architecture!r}; use one of {', '.join(ARCHITECTURES)}")
    try:
        parameters = json.loads(metadata.get("parameters", ""))
        settings = json.loads(metadata.get("settings", "{}"))
    except json.JSONDecodeError:
        raise WiseError(f"{path}: the model's metadata is not valid JSON; {TRAIN_ONE}") from None
    if parameters != known.param_names:
        raise WiseError(
            f"{path}: the model predicts other parameters than {known.name!r} has now; retrain it ({TRAIN_ONE})"
        )
    return ModelInfo(
        effect=known.name,
        architecture=architecture,
        parameters=parameters,
        size=_number(path, metadata, "size"),
        render_size=_number(path, metadata, "render_size"),
        settings=settings if isinstance(settings, dict) else {},
        wise_version=metadata.get("wise_version", ""),
        source=str(path),
    )


def model_info(path: str | os.PathLike[str], effect: str | None = None) -> ModelInfo:
    """The checked metadata of a model file, reading no weights; with ``effect``, refuses a
    model of another effect."""
    path = safetensors_path(path, WHAT)
    _, metadata = read_safetensors_header(path, WHAT, MAX_MODEL_BYTES)
    return _info(path, metadata, effect)


def load_model(path: str | os.PathLike[str], effect: str | None = None) -> tuple[nn.Module, ModelInfo]:
    """The network of a model file (float32, evaluation mode) and its metadata. Every weight's
    name and shape is checked against the architecture before anything is loaded."""
    path = safetensors_path(path, WHAT)
    entries, metadata = read_safetensors_header(path, WHAT, MAX_MODEL_BYTES)
    info = _info(path, metadata, effect)
    network = create(info.architecture, len(info.parameters))
    expected = network.state_dict()
    missing = sorted(set(expected) - set(entries))
    unexpected = sorted(set(entries) - set(expected))
    if missing or unexpected:
        names = ", ".join((missing or unexpected)[:3])
        raise WiseError(
            f"{path}: the weights do not fit the {info.architecture!r} architecture "
            f"({'missing' if missing else 'unexpected'}: {names}); {TRAIN_ONE}"
        )
    for name, value in expected.items():
        if tuple(entries[name].shape) != tuple(value.shape):
            raise WiseError(
                f"{path}: {name} has the shape {tuple(entries[name].shape)}, the architecture expects "
                f"{tuple(value.shape)}; {TRAIN_ONE}"
            )
    tensors, _ = read_safetensors(path, WHAT, MAX_MODEL_BYTES)
    state = {}
    for name, value in tensors.items():
        if not value.is_floating_point() or not torch.isfinite(value).all():
            raise WiseError(f"{path}: {name} holds non-finite or non-float values; {TRAIN_ONE}")
        state[name] = value.to(torch.float32)
    network.load_state_dict(state)
    return network.eval(), info


def resolve_model(model: str | os.PathLike[str] | None, effect: str) -> Path:
    """``model`` (checked to be a model of ``effect``) or the built-in model of ``effect``."""
    path = builtin_model_path(effect) if model is None else Path(model)
    model_info(path, effect)
    return path
