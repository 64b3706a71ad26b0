"""One word for each idea: no two classes in our packages share a name (a reader who meets
``Press`` must not have to ask which of four it is)."""

from __future__ import annotations

import ast
from collections import defaultdict
from pathlib import Path

from core.packages import PACKAGES

ROOT = Path(__file__).resolve().parents[2]


def class_places(root: Path) -> dict[str, list[str]]:
    """Each class name defined anywhere in the packages under ``root`` -> where (file:line)."""
    places: dict[str, list[str]] = defaultdict(list)
    for package in PACKAGES:
        for path in sorted((root / package).rglob("*.py")):
            for node in ast.walk(ast.parse(path.read_text(), str(path))):
                if isinstance(node, ast.ClassDef):
                    places[node.name].append(f"{path.relative_to(root)}:{node.lineno}")
    return places


def test_no_class_name_is_defined_twice() -> None:
    twice = {name: where for name, where in class_places(ROOT).items() if len(where) > 1}
    assert not twice, f"class names defined more than once: {twice}"


def test_the_check_finds_a_name_defined_twice(tmp_path: Path) -> None:
    for package in PACKAGES:
        (tmp_path / package).mkdir()
    (tmp_path / "sync" / "a.py").write_text("class Press:\n    pass\n")
    (tmp_path / "live" / "b.py").write_text("def f():\n    class Press:\n        pass\n")
    assert class_places(tmp_path)["Press"] == ["sync/a.py:1", "live/b.py:2"]
