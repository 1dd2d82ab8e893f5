"""Weight files of pretrained networks that the user provides (never downloaded): where they are
looked for, and their checks before any work. Pickled files (``.pth``, ``.pt``) are refused, since
loading them can run code; the messages say how to convert them to safetensors.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import torch

from wise.errors import WiseError
from wise.files import MAX_MODEL_BYTES, TensorEntry, read_safetensors, read_safetensors_header, safetensors_path

PathLike = str | os.PathLike[str]
FLOAT_DTYPES = ("F16", "BF16", "F32", "F64")
PICKLE_SUFFIXES = (".pth", ".pt")
SHOWN_KEYS = 3
"""How many missing keys an error message names."""


def cache_file(name: str) -> Path:
    """``name`` in our cache folder: ``$XDG_CACHE_HOME/wise`` or ``~/.cache/wise``."""
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "wise" / name


@dataclass(frozen=True)
class WeightsKind:
    """How the messages about one kind of weight file name it."""

    what: str
    """The file in a few words, e.g. "Inception weights"."""
    origin: str
    """Where the weights come from, e.g. "the Inception weights of pytorch-fid (pt_inception-2015-12-05)"."""
    user: str
    """What needs them, e.g. "FID"."""
    option: str
    """The command-line option that passes the file."""
    network: str
    """The state dict the file must hold, e.g. "the FID Inception network"."""

    def hint(self) -> str:
        return f"pass {self.option} FILE with {self.origin} as safetensors"


def weights_file(path: PathLike | None, default: Path, kind: WeightsKind) -> Path:
    """The file to read: ``path``, else ``default`` when it exists; pickles and missing files are refused."""
    if path is None:
        if not os.path.lexists(default):
            raise WiseError(
                f"{kind.user} needs {kind.origin} as safetensors: pass {kind.option} FILE or place it at {default}"
            )
        path = default
    file = Path(path)
    if file.suffix.lower() in PICKLE_SUFFIXES:
        raise WiseError(
            f"{file}: pickled {kind.what} are never loaded (they can run code); convert the file to safetensors on "
            "your own machine with safetensors.torch.save_file(torch.load(FILE), 'OUT.safetensors') and pass "
            f"{kind.option} OUT.safetensors"
        )
    if not os.path.lexists(file):
        raise WiseError(f"{kind.what} not found at {file}; {kind.hint()} or place it at {default}")
    return safetensors_path(file, kind.what)


def check_header(file: Path, shapes: dict[str, tuple[int, ...]], kind: WeightsKind) -> dict[str, TensorEntry]:
    """The header entries of ``file`` once it holds every key of ``shapes`` with that shape, as floats.

    No tensor data is read, so that a wrong file fails before any work.
    """
    entries, _ = read_safetensors_header(file, kind.what, MAX_MODEL_BYTES)
    missing = [key for key in shapes if key not in entries]
    if missing:
        more = " and more" if len(missing) > SHOWN_KEYS else ""
        shown = ", ".join(missing[:SHOWN_KEYS])
        raise WiseError(f"{file}: not {kind.network}; missing {shown}{more}; {kind.hint()}")
    for key, shape in shapes.items():
        entry = entries[key]
        if entry.shape != shape:
            raise WiseError(
                f"{file}: weights of the wrong shape for {kind.network} ({key} is {list(entry.shape)}, "
                f"expected {list(shape)}); {kind.hint()}"
            )
        if entry.dtype not in FLOAT_DTYPES:
            raise WiseError(f"{file}: {kind.what} must be floating point ({key} is {entry.dtype}); {kind.hint()}")
    return entries


def read_weights(file: Path, shapes: dict[str, tuple[int, ...]], kind: WeightsKind) -> dict[str, torch.Tensor]:
    """The tensors ``shapes`` of ``file`` (checked by :func:`check_header` first), all finite."""
    check_header(file, shapes, kind)
    state, _ = read_safetensors(file, kind.what, MAX_MODEL_BYTES, keys=shapes)
    for key, tensor in state.items():
        if not bool(torch.isfinite(tensor).all()):
            raise WiseError(
                f"{file}: {key} holds non-finite values (NaN or infinity); the file is damaged, "
                f"convert {kind.origin} again"
            )
    return state
