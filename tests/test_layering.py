"""The layering rule a newcomer reads off the tree, checked on every module's imports.

pipeline -> (ingest, calib, sim, train) -> data_schema -> core: a package imports only
packages below it (and itself); train/ stands on core/ and data_schema/ alone; the domain
packages may use each other only without a cycle; and no two modules import each other,
directly or round a longer loop, not even through an import hidden inside a function.
Outside pipeline/ our modules are imported at the module top, where a reader sees them.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
LAYER = {"core": 0, "data_schema": 1, "ingest": 2, "sync": 2, "extract": 2, "split": 2,
         "sim": 2, "train": 2, "pipeline": 3}
ONLY = {"train": {"core", "data_schema", "train"}}     # narrower than its layer allows
# Imports inside functions, allowed only here: the commands load their stage when run (so
# `pipeline --help` stays fast), and `from train import Predictor` loads torch on demand.
LAZY = ("pipeline", "train")


def _modules() -> dict[str, Path]:
    out = {}
    for package in LAYER:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
            out[name] = path
    return out


MODULES = _modules()


def _imports(name: str, path: Path, nodes: list[ast.AST] | None = None) -> set[str]:
    """Our modules that ``name`` imports anywhere in its source (top level or in functions),
    or in ``nodes`` of it."""
    found = set()
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    tree = ast.parse(path.read_text(), str(path))
    for node in nodes if nodes is not None else ast.walk(tree):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                up = package.split(".")[: len(package.split(".")) - node.level + 1]
                base = ".".join([*up, base] if base else up)
            targets = [f"{base}.{a.name}" for a in node.names] + [base]
        else:
            continue
        for target in targets:
            # the longest prefix that is one of our modules (``from x import name`` or ``x``)
            parts = target.split(".")
            for k in range(len(parts), 0, -1):
                candidate = ".".join(parts[:k])
                if candidate in MODULES:
                    found.add(candidate)
                    break
    found.discard(name)
    return found


GRAPH = {name: _imports(name, path) for name, path in MODULES.items()}


def _package(module: str) -> str:
    return module.split(".")[0]


def test_every_layer_has_modules():
    assert {_package(m) for m in MODULES} == set(LAYER)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_imports_run_downward(module):
    own = _package(module)
    allowed = ONLY.get(own)
    for target in sorted(GRAPH[module]):
        other = _package(target)
        if allowed is not None:
            assert other in allowed, f"{module} imports {target}: {own}/ stands on {allowed}"
        ok = other == own or LAYER[other] < LAYER[own] or (
            LAYER[other] == LAYER[own] and own != "pipeline")
        assert ok, f"{module} imports {target}, which is above it"


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _package(m) not in LAZY))
def test_imports_at_module_top(module):
    path = MODULES[module]
    inner = [n for f in ast.walk(ast.parse(path.read_text())) if isinstance(
        f, ast.FunctionDef | ast.AsyncFunctionDef) for n in ast.walk(f)]
    hidden = _imports(module, path, inner)
    assert not hidden, f"{module} imports {sorted(hidden)} inside a function"


def test_domain_packages_form_no_cycle():
    edges = {(_package(a), _package(b)) for a, targets in GRAPH.items() for b in targets
             if _package(a) != _package(b)}
    cycle = _find_cycle({p: {b for a, b in edges if a == p} for p in LAYER})
    assert cycle is None, "packages import each other: " + " -> ".join(cycle)


def test_no_module_imports_round_a_circle():
    cycle = _find_cycle(GRAPH)
    assert cycle is None, "modules import each other: " + " -> ".join(cycle)


def _find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One cycle of ``graph`` (as the list of nodes round it), or None."""
    state: dict[str, int] = {}
    stack: list[str] = []

    def visit(node: str) -> list[str] | None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state and (found := visit(nxt)):
                return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state and (found := visit(node)):
            return found
    return None


def test_the_checks_can_fail():
    """The cycle finder finds a planted loop, and the import parser sees hidden imports."""
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b"}, "b": set()}) is None
    assert "ingest.mcap_io" in GRAPH["sync.sync_stage"]
