"""What the editor starts from, checked before anything heavy loads: the options go together,
the names are known and the files are there (they are read by
:func:`wise.editor.server.initial_session`)."""

from __future__ import annotations

from wise.effects.catalogue import check_name, entry
from wise.errors import WiseError
from wise.files import MAX_PARAMS_BYTES, PARAMS_WHAT, regular_file
from wise.io import check_image_file


def check_start(
    image: str | None = None,
    params: str | None = None,
    effect: str | None = None,
    preset: str | None = None,
    model: str | None = None,
) -> None:
    """Refuse options that do not go together, an unknown effect or preset and missing files."""
    if model is not None and params is None:
        raise WiseError("--model renders the masks it painted: pass them with --params (from 'wise predict')")
    if params is not None and (effect is not None or preset is not None):
        raise WiseError("--params comes with its own effect; leave out --effect and --preset")
    if preset is not None and effect is None:
        raise WiseError("--preset needs --effect, e.g. --effect watercolor --preset " + preset)
    if effect is not None:
        check_name(effect)
        if preset is not None:
            entry(effect).check_preset(preset)
    if params is not None:
        regular_file(params, PARAMS_WHAT, MAX_PARAMS_BYTES)
    if image is not None:
        check_image_file(image)
