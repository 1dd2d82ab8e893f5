"""The catalogue declares every effect's parameters and presets without PyTorch, and each effect
class takes its declarations from it."""

from __future__ import annotations

import inspect
import subprocess
import sys

import pytest

from wise import effects
from wise.effects.catalogue import NAMES, check_name, entry
from wise.errors import WiseError


@pytest.mark.parametrize("name", NAMES)
def test_each_effect_class_declares_what_the_catalogue_holds(name: str) -> None:
    cls = effects.effect_class(name)
    declared = entry(name)
    assert cls.name == name
    assert cls.param_specs is declared.param_specs and cls.presets is declared.presets
    assert inspect.getdoc(cls).splitlines()[0] == declared.summary


def test_unknown_names_are_refused_with_what_there_is() -> None:
    with pytest.raises(WiseError, match="unknown effect 'oil'; available effects: cartoon, oilpaint"):
        check_name("oil")
    with pytest.raises(WiseError, match="has no preset 'x'; its presets: portrait"):
        entry("xdog").check_preset("x")
    with pytest.raises(WiseError, match="has no parameter 'x'; its parameters: brightness"):
        entry("cartoon").spec("x")
    assert sorted(NAMES) == effects.available()


def test_names_parameters_and_presets_load_without_pytorch() -> None:
    program = (
        "import sys\n"
        "from wise.effects.catalogue import NAMES, entry\n"
        "import wise.effects, wise.io, wise.batch, wise.optimize\n"
        "assert [entry(n).param_names for n in NAMES]\n"
        "print('torch' in sys.modules)\n"
    )
    done = subprocess.run([sys.executable, "-c", program], capture_output=True, text=True, check=True)
    assert done.stdout.strip() == "False"
