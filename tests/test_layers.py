"""The package's rooms import downwards only and no module imports itself through others."""

from __future__ import annotations

import ast
from pathlib import Path

import wise

SOURCE = Path(wise.__file__).parent
_TOP = ("wise.cli", "wise.editor", "wise.predict")
FORBIDDEN = {
    "wise.filters": ("wise.effects", "wise.optimize", "wise.ppn", "wise.train", *_TOP),
    "wise.effects": ("wise.optimize", "wise.ppn", "wise.train", *_TOP),
    "wise.ppn": ("wise.optimize", "wise.train", *_TOP),
    "wise.optimize": ("wise.train", *_TOP),
    "wise.train": _TOP,
    "wise.editor": ("wise.cli",),
}
"""For each room, the rooms above it, which it must not import (at the top or inside a function)."""


def _module_name(path: Path) -> str:
    parts = path.relative_to(SOURCE.parent).with_suffix("").parts
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _imports() -> dict[str, set[str]]:
    found: dict[str, set[str]] = {}
    for path in SOURCE.rglob("*.py"):
        names: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                names.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names.add(node.module)
                names.update(f"{node.module}.{alias.name}" for alias in node.names)
        found[_module_name(path)] = {name for name in names if name.startswith("wise.")}
    return found


def test_no_room_imports_a_room_above_it() -> None:
    wrong = []
    for module, names in _imports().items():
        for room, above in FORBIDDEN.items():
            if module == room or module.startswith(room + "."):
                wrong += [f"{module} imports {name}" for name in names if name.startswith(above)]
    assert not wrong, wrong


def test_no_import_circles_between_modules() -> None:
    imports = _imports()
    modules = set(imports)
    edges = {m: {n for n in imports[m] if n in modules and n != m and not m.startswith(n + ".")} for m in modules}

    def reaches(start: str, goal: str) -> bool:
        seen, stack = set(), [start]
        while stack:
            node = stack.pop()
            if node == goal:
                return True
            if node not in seen:
                seen.add(node)
                stack.extend(edges[node])
        return False

    circles = sorted({tuple(sorted((a, b))) for a in modules for b in edges[a] if reaches(b, a)})
    assert not circles, circles
