"""Trained parameter prediction networks in safetensors files (no pickle).

A model file holds the network's weights (float32 or float16) and string metadata:

``format``        ``"wise-ppn"``
``version``       ``"1"``
``effect``        the effect whose parameters it predicts
``kind``          ``"global"`` (parameters from photo and example) or ``"local"`` (parameter
                  masks from the photo alone)
``architecture``  a name of :data:`wise.ppn.ARCHITECTURES` (global) or
                  :data:`wise.ppn.LOCAL_ARCHITECTURES` (local), or ``translator``: a local
                  model with a post-processing CNN, a fixed preset or no effect
                  (:mod:`wise.ppn.translation`; its effect may be ``none``)
``network``       JSON of the architecture's options (a local network's depth and widths; a
                  translator's :func:`wise.ppn.translation.translator_options`)
``parameters``    JSON list of the parameter names, in the order of the outputs
``ranges``        JSON list of ``[min, max]`` per parameter (real units, for information)
``size``          the working size: the images are resized to this short side
``render_size``   the short side the training examples were rendered at
``settings``      JSON of the training command's settings
``wise_version``  the package version that wrote it

Built-in models live in ``wise/ppn/models/``: ``<effect>.safetensors`` (global) and
``<effect>-<task>.safetensors`` (local, named ``builtin:<task>`` on the command line).
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
from wise.ppn.registry import ARCHITECTURES, LOCAL_ARCHITECTURES, create, create_local
from wise.ppn.translation import ARCHITECTURE as TRANSLATOR
from wise.ppn.translation import NO_EFFECT, build_translator

FORMAT = "wise-ppn"
VERSION = "1"
KINDS = ("global", "local")
WHAT = "model file"
TRAIN_ONE = "train one with 'wise train global' or 'wise train local'"
BUILTIN_PACKAGE = "wise.ppn.models"
BUILTIN_PREFIX = "builtin:"


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
    kind: str = "global"
    network: dict = field(default_factory=dict)
    """The architecture's options (a local network's ``depth``, ``width``, ``max_width``)."""


def build_network(info: ModelInfo) -> nn.Module:
    """An untrained network of the architecture and options ``info`` names."""
    if info.kind == "local" and info.architecture == TRANSLATOR:
        return build_translator(info.effect, info.network)
    if info.kind == "local":
        return create_local(info.architecture, len(info.parameters), **info.network)
    return create(info.architecture, len(info.parameters))


def save_model(path: str | os.PathLike[str], network: nn.Module, info: ModelInfo, half: bool = False) -> None:
    """Write ``network``'s weights and ``info`` to ``path`` atomically (float16 with ``half``)."""
    if info.kind not in KINDS or info.architecture not in _architectures(info.kind):
        raise WiseError(f"unknown {info.kind} architecture {info.architecture!r}")
    specs = () if info.effect == NO_EFFECT else effects.create(info.effect).param_specs
    dtype = torch.float16 if half else torch.float32
    tensors = {name: value.detach().to("cpu", dtype).contiguous() for name, value in network.state_dict().items()}
    metadata = {
        "format": FORMAT,
        "version": VERSION,
        "effect": info.effect,
        "kind": info.kind,
        "architecture": info.architecture,
        "network": json.dumps(info.network, sort_keys=True),
        "parameters": json.dumps(info.parameters),
        "ranges": json.dumps([[s.min, s.max] for s in specs]),
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


def _architectures(kind: str) -> dict[str, object]:
    return {**LOCAL_ARCHITECTURES, TRANSLATOR: build_translator} if kind == "local" else dict(ARCHITECTURES)


def builtin_model_path(effect: str, task: str | None = None) -> Path:
    """The global model shipped for ``effect``, or its local model for ``task``; refuses a
    model that is not shipped, naming those that are."""
    effects.create(effect)
    name = effect if task is None else f"{effect}-{task}"
    path = Path(str(resources.files(BUILTIN_PACKAGE) / f"{name}.safetensors"))
    if not path.is_file():
        shipped = sorted(
            BUILTIN_PREFIX + p.name[len(effect) + 1 : -len(".safetensors")]
            for p in Path(str(resources.files(BUILTIN_PACKAGE))).glob(f"{effect}-*.safetensors")
        )
        what = f"built-in model for {effect!r}" if task is None else f"built-in model {BUILTIN_PREFIX}{task}"
        others = f" (built-in local models of {effect}: {', '.join(shipped)})" if shipped else ""
        raise WiseError(f"no {what}{others}; pass --model FILE ({TRAIN_ONE})")
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
    kind = metadata.get("kind", "")
    if metadata.get("version") != VERSION or kind not in KINDS:
        raise WiseError(
            f"{path}: unsupported model (version {metadata.get('version')!r}, kind {kind!r}); "
            f"this wise reads version {VERSION!r} models of the kinds {', '.join(KINDS)}"
        )
    model_effect = metadata.get("effect", "")
    if effect is not None and model_effect != effect:
        raise WiseError(f"{path}: a model for {model_effect!r}, not {effect!r}; pass a model of {effect!r}")
    architecture = metadata.get("architecture", "")
    if (effect or model_effect) == NO_EFFECT and architecture != TRANSLATOR:
        raise WiseError(f"{path}: only a translator (CNN) model may have no effect; {TRAIN_ONE}")
    known = None if (effect or model_effect) == NO_EFFECT else effects.create(effect or model_effect)
    known_architectures = _architectures(kind)
    if architecture not in known_architectures:
        raise WiseError(
            f"{path}: unknown {kind} architecture {architecture!r}; use one of {', '.join(known_architectures)}"
        )
    try:
        parameters = json.loads(metadata.get("parameters", ""))
        settings = json.loads(metadata.get("settings", "{}"))
        network = json.loads(metadata.get("network", "{}"))
    except json.JSONDecodeError:
        raise WiseError(f"{path}: the model's metadata is not valid JSON; {TRAIN_ONE}") from None
    if not isinstance(network, dict) or not all(
        isinstance(k, str) and isinstance(v, (int, str)) and (architecture == TRANSLATOR or not isinstance(v, bool))
        for k, v in network.items()
    ):
        raise WiseError(f"{path}: the model's network options are not whole numbers or names by name; {TRAIN_ONE}")
    known_names = known.param_names if known is not None else []
    # a global model trained before a parameter was added predicts the others (the predictor
    # gives the added one its default)
    older_names = [name for name in known_names if known is None or name not in known.added_params]
    if parameters != known_names and not (kind == "global" and parameters == older_names):
        raise WiseError(
            f"{path}: the model predicts other parameters than {model_effect!r} has now; retrain it ({TRAIN_ONE})"
        )
    return ModelInfo(
        effect=known.name if known is not None else NO_EFFECT,
        architecture=architecture,
        parameters=parameters,
        size=_number(path, metadata, "size"),
        render_size=_number(path, metadata, "render_size"),
        settings=settings if isinstance(settings, dict) else {},
        wise_version=metadata.get("wise_version", ""),
        source=str(path),
        kind=kind,
        network=network,
    )


def _check_kind(path: Path, info: ModelInfo, kind: str | None) -> ModelInfo:
    if kind is not None and info.kind != kind:
        how = "from photo and example" if info.kind == "global" else "as masks from the photo alone"
        needs = "--target" if info.kind == "global" else "no --target"
        raise WiseError(
            f"{path}: a {info.kind} model (it predicts parameters {how}), not a {kind} one; "
            f"a {info.kind} model takes {needs}"
        )
    return info


def model_info(path: str | os.PathLike[str], effect: str | None = None, kind: str | None = None) -> ModelInfo:
    """The checked metadata of a model file, reading no weights; with ``effect`` or ``kind``,
    refuses a model of another effect or kind."""
    path = safetensors_path(path, WHAT)
    _, metadata = read_safetensors_header(path, WHAT, MAX_MODEL_BYTES)
    return _check_kind(path, _info(path, metadata, effect), kind)


def load_model(
    path: str | os.PathLike[str], effect: str | None = None, kind: str | None = None
) -> tuple[nn.Module, ModelInfo]:
    """The network of a model file (float32, evaluation mode) and its metadata. Every weight's
    name and shape is checked against the architecture before anything is loaded."""
    path = safetensors_path(path, WHAT)
    entries, metadata = read_safetensors_header(path, WHAT, MAX_MODEL_BYTES)
    info = _check_kind(path, _info(path, metadata, effect), kind)
    try:
        network = build_network(info)
    except (TypeError, WiseError) as e:
        raise WiseError(f"{path}: the model's network options do not make a network ({e}); {TRAIN_ONE}") from None
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


def model_path(model: str | os.PathLike[str] | None, effect: str) -> Path:
    """The file ``model`` names: None is the built-in global model of ``effect``,
    ``builtin:<task>`` its built-in local model for a task (``builtin:<effect>`` the global one)."""
    if model is None:
        return builtin_model_path(effect)
    text = os.fspath(model)
    if text.startswith(BUILTIN_PREFIX):
        task = text[len(BUILTIN_PREFIX) :]
        return builtin_model_path(effect, None if task == effect else task)
    return Path(text)


def resolve_model(model: str | os.PathLike[str] | None, effect: str, kind: str | None = None) -> Path:
    """The file of ``model`` (see :func:`model_path`), checked to be a model of ``effect``
    (and of ``kind`` when given)."""
    path = model_path(model, effect)
    model_info(path, effect, kind)
    return path
