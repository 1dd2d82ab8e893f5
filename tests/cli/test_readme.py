"""The README's parameter tables are those of ``wise effects --markdown``."""

from __future__ import annotations

from pathlib import Path

import pytest

import wise
from wise.cli import main
from wise.cli.effects import markdown_table
from wise.effects.catalogue import entry

README = Path(__file__).resolve().parents[2] / "README.md"


@pytest.mark.skipif(not README.is_file(), reason="README.md is not beside the tests (installed package)")
@pytest.mark.parametrize("name", wise.effects.available())
def test_readme_table_matches_the_effect(name: str) -> None:
    text = README.read_text(encoding="utf-8")
    section = text.split(f"### `{name}`", 1)[1].split("\n### ", 1)[0]
    table = markdown_table(entry(name))
    assert table in section, f"regenerate the README table of {name} with: wise effects {name} --markdown"


def test_markdown_lists_every_parameter(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["effects", "xdog", "--markdown"]) == 0
    out = capsys.readouterr().out
    for spec in wise.effects.create("xdog").param_specs:
        assert f"| {spec.name} | " in out
