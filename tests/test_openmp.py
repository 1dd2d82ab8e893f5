"""OpenMP's threads wait passively when wise is imported before torch, unless the user chose."""

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

PROGRAM = "import os, sys\n{imports}\nprint(os.environ.get('OMP_WAIT_POLICY'))"


def _policy(imports: str, **env: str) -> str:
    environment = {k: v for k, v in os.environ.items() if k != "OMP_WAIT_POLICY"} | env
    done = subprocess.run(
        [sys.executable, "-c", PROGRAM.format(imports=imports)],
        env=environment,
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout.strip()


@pytest.mark.parametrize("imports", ["import wise", "from wise.filters import gaussian_blur", "import wise.cli"])
def test_importing_wise_first_makes_the_waiting_passive(imports: str) -> None:
    # set by the import, before any PyTorch that loads after it reads it
    assert _policy(imports) == "PASSIVE"


def test_a_policy_the_user_chose_is_kept() -> None:
    assert _policy("import wise", OMP_WAIT_POLICY="ACTIVE") == "ACTIVE"


def test_after_torch_it_is_left_alone() -> None:
    # OpenMP has read its policy already: setting one now would only mislead
    assert _policy("import torch\nimport wise") == "None"


BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _first_import_line(source: str, package: str) -> int | None:
    pattern = re.compile(rf"^(import|from) {package}(\.| |$)", re.MULTILINE)
    match = pattern.search(source)
    return None if match is None else source.count("\n", 0, match.start())


@pytest.mark.parametrize("script", sorted(BENCHMARKS.glob("*.py")), ids=lambda path: path.name)
def test_benchmarks_measure_what_the_command_line_runs(script: Path) -> None:
    # a benchmark that loads torch first times spinning OpenMP threads no user of wise has
    source = script.read_text()
    torch_line = _first_import_line(source, "torch")
    if torch_line is None:
        return
    wise_line = _first_import_line(source, "wise")
    assert wise_line is not None and wise_line < torch_line, f"{script.name}: import wise before torch"
