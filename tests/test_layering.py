"""The layering and the folder-per-stage rule a newcomer reads off the tree and off
docs/ARCHITECTURE.md, checked on every module's imports.

pipeline -> (the stage packages) -> data_schema -> core: a package imports only packages below
it (and itself); train/ stands on core/ and data_schema/ alone, and the phantom twin uses none
of the stages it is there to check; the stage packages may use each other only without a
cycle; and no two modules import each other, directly or round a longer loop, not even
through an import hidden inside a function. Outside pipeline/ our modules are imported at the
module top, where a reader sees them.

Each command has one row in ARCHITECTURE.md's stage table: its math, its runner
(``<command>_stage.py:run_<command>``), its view (``<command>_view.py`` beside the runner) and
what it writes. Every path there exists, every runner and view in the tree is there, each
command module calls its runner, and no command module writes, records provenance or logs to
rerun itself.

One runner contract: every ``run_*`` of a ``*_stage.py`` takes ``(inputs, out, params, rrd)``
and nothing else, and only the runners open outputs (``core.atomic``) and record provenance
(``core.provenance``), whose parameters are ``asdict`` of the params; the math returns data or
writes to the temporary paths it is given. The packages given a layer here are
``core/packages.py``'s, and what setuptools installs.
"""

from __future__ import annotations

import ast
import re
import tomllib
from pathlib import Path

import pytest

from core.packages import PACKAGES
from pipeline.cli import COMMANDS

ROOT = Path(__file__).resolve().parents[1]
ARCHITECTURE = ROOT / "docs" / "ARCHITECTURE.md"
LAYER = {"core": 0, "data_schema": 1, "ingest": 2, "calib": 2, "sync": 2, "extract": 2, "split": 2,
         "sim": 2, "sim.twin": 2, "sim.msm": 2, "sim.solid": 2, "train": 2, "live": 2,
         "live.protocol": 2, "live.session": 2, "live.replay": 2, "pipeline": 3}
# narrower than their layer allows: train/ is used without the lab stages; the twin checks
# sync and extract against its truth, so it must not share their code; live/'s protocol is the
# ground of its two commands, and the replay uses nothing of the live session
ONLY = {"train": {"core", "data_schema", "train"},
        "sim.twin": {"core", "data_schema", "ingest", "sim", "sim.twin"},
        "live.protocol": {"core", "data_schema", "ingest", "live.protocol"},
        "live.replay": {"core", "data_schema", "ingest", "live.protocol", "live.replay"}}
# Imports inside functions, allowed only here: the commands load their stage when run (so
# `pipeline --help` stays fast), and `from train import Predictor` loads torch on demand.
LAZY = ("pipeline", "train")
ORCHESTRATION = {"demo"}            # commands that run other commands: no stage of their own
WRITERS = {"core.atomic", "core.provenance"}
# what of the writers opens an output or records provenance (``same_path``, ``sha256_file`` and
# ``code_version`` only read)
WRITING = {"core.atomic": {"atomic_output", "atomic_outputs"},
           "core.provenance": {"make_provenance"}}
# Below the stage packages, or file-format writers that are atomic on their own: a runner
# calls them on the temporary path it opened, tests call them to make lab files.
WRITES_ALSO = {
    "core": "the ground: core.recording writes a recording atomically, for the views",
    "data_schema.hdf5": "write_h5, the one schema-driven HDF5 writer every runner uses",
    "ingest.mcap_io": "write_raw_mcap: ingest's runner writes its temporary MCAP with it",
    "ingest.ati_cal": "write_ati_cal: the twin's runner writes the .cal on its temporary path",
    "ingest.qtm_mat": "write_qtm_mat / write_mat73: lab MAT files, for the twin and the tests",
    "pipeline.stage_cache": "the demo's stamps beside its outputs: orchestration, no stage",
}
RUNNER_ARGS = ["inputs", "out", "params", "rrd"]


def _modules() -> dict[str, Path]:
    out = {}
    for top in sorted({p.split(".")[0] for p in LAYER}):
        for path in sorted((ROOT / top).rglob("*.py")):
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
    """The package of ``module`` in :data:`LAYER`: the longest one it lies in."""
    return max((p for p in LAYER if module == p or module.startswith(p + ".")), key=len)


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


# -- the folder-per-stage rule, against ARCHITECTURE.md ---------------------------------------

def _stage_table(text: str) -> dict[str, dict[str, list[str]]]:
    """The stage table's rows: command -> {math, runner, view, writes} -> backticked items."""
    section = text.split("\n## Stages\n", 1)[1].split("\n## ", 1)[0]
    rows = {}
    for line in section.splitlines():
        if not line.startswith("| `"):
            continue
        cells = [c.strip() for c in line.strip().strip("|").split("|")]
        command, math, runner, view, writes = (re.findall(r"`([^`]+)`", c) for c in cells)
        rows[command[0]] = {"math": math, "runner": runner, "view": view, "writes": writes}
    return rows


TABLE = _stage_table(ARCHITECTURE.read_text())
STAGES = sorted(set(COMMANDS) - ORCHESTRATION)


def _module_of(path: str) -> str:
    return path.removesuffix(".py").replace("/", ".")


def _defines(path: Path, function: str) -> bool:
    return any(isinstance(n, ast.FunctionDef) and n.name == function
               for n in ast.parse(path.read_text()).body)


def test_every_command_has_one_stage_row():
    assert sorted(TABLE) == STAGES


@pytest.mark.parametrize("command", STAGES)
def test_stage_row_names_modules_that_exist(command):
    row = TABLE[command]
    for path in row["math"] + row["view"]:
        assert (ROOT / path).is_file(), f"{command}: {path} does not exist"
    assert len(row["runner"]) == 1 and len(row["view"]) <= 1, row


@pytest.mark.parametrize("command", STAGES)
def test_runner_and_view_are_named_for_the_command(command):
    stem = command.replace("-", "_")
    path, _, function = TABLE[command]["runner"][0].partition(":")
    assert Path(path).name == f"{stem}_stage.py" and function == f"run_{stem}", path
    assert _defines(ROOT / path, function), f"{path} defines no {function}()"
    assert _package(_module_of(path)) not in ("core", "data_schema", "pipeline"), path
    for view in TABLE[command]["view"]:
        assert Path(view) == Path(path).with_name(f"{stem}_view.py"), view


def test_every_runner_and_view_is_in_the_table():
    listed = {p.partition(":")[0] for row in TABLE.values() for p in row["runner"] + row["view"]}
    found = {str(path.relative_to(ROOT)) for name, path in MODULES.items()
             if _package(name) != "pipeline" and path.stem.endswith(("_stage", "_view"))}
    assert found == listed


@pytest.mark.parametrize("command", STAGES)
def test_command_calls_its_runner(command):
    module = COMMANDS[command].partition(":")[0]
    path, _, function = TABLE[command]["runner"][0].partition(":")
    tree = ast.parse(MODULES[module].read_text())
    assert any(isinstance(n, ast.ImportFrom) and n.module == _module_of(path)
               and function in {a.name for a in n.names} for n in ast.walk(tree)), \
        f"{module} does not call {function} of {path}"


@pytest.mark.parametrize("module", sorted({c.partition(":")[0] for c in COMMANDS.values()}))
def test_commands_leave_writing_to_their_runner(module):
    recording = {m for m in MODULES if m.endswith("_view") and "core.recording" in GRAPH[m]}
    done_here = GRAPH[module] & (WRITERS | recording)
    assert not done_here, f"{module} writes itself through {sorted(done_here)}"


def _writing(path: Path) -> set[str]:
    """The writers (``core.atomic.atomic_outputs``, ``core.provenance.make_provenance``, ...)
    that the module at ``path`` imports, anywhere in it."""
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module in WRITING:
            found |= {f"{node.module}.{a.name}" for a in node.names
                      if a.name in WRITING[node.module]}
        elif isinstance(node, ast.Import):
            found |= {a.name for a in node.names if a.name in WRITING}
    return found


def _allowed_to_write(module: str) -> bool:
    return module.rpartition(".")[2].endswith("_stage") or any(
        module == m or module.startswith(m + ".") for m in WRITES_ALSO)


@pytest.mark.parametrize("module", sorted(MODULES))
def test_only_runners_open_outputs_and_record_provenance(module):
    writing = _writing(MODULES[module])
    assert not writing or _allowed_to_write(module), (
        f"{module} imports {sorted(writing)}: only a runner (*_stage.py) opens outputs and "
        "records provenance; return the data, or write to the temporary path the runner gives")


@pytest.mark.parametrize("module", sorted(m for m in WRITES_ALSO if m in MODULES
                                           and not MODULES[m].name == "__init__.py"))
def test_every_exception_still_writes(module):
    assert _writing(MODULES[module]), f"{module} writes no more: drop it from WRITES_ALSO"


def _runners() -> list[tuple[str, ast.FunctionDef]]:
    """Every ``run_*`` function at the top of a ``*_stage.py`` module."""
    return [(f"{name}:{node.name}", node) for name, path in sorted(MODULES.items())
            if path.stem.endswith("_stage")
            for node in ast.parse(path.read_text()).body
            if isinstance(node, ast.FunctionDef) and node.name.startswith("run_")]


RUNNERS = _runners()


@pytest.mark.parametrize("runner", [r for r, _ in RUNNERS])
def test_runners_take_inputs_out_params_rrd(runner):
    node = dict(RUNNERS)[runner]
    a = node.args
    names = [x.arg for x in a.posonlyargs + a.args]
    assert names == RUNNER_ARGS and not a.kwonlyargs and not a.vararg and not a.kwarg, (
        f"{runner}({', '.join(names)}): a runner takes ({', '.join(RUNNER_ARGS)}) and nothing "
        "else; its settings are fields of one frozen <Command>Params")
    rrd_default = a.defaults[-1] if a.defaults else None
    assert isinstance(rrd_default, ast.Constant) and rrd_default.value is None, \
        f"{runner}: rrd defaults to None"


def test_provenance_records_the_params_and_nothing_else():
    """Every ``make_provenance`` call records ``asdict`` of the run's ``<Command>Params``: no
    setting left out, nothing recorded beside them (the inputs have their own record)."""
    calls = []               # (module, call, its arguments): called, or handed to a pool
    for name, path in MODULES.items():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "make_provenance":
                calls.append((name, node, node.args))
            elif isinstance(node, ast.Call) and node.args and \
                    getattr(node.args[0], "id", None) == "make_provenance":
                calls.append((name, node, node.args[1:]))
    assert {name for name, _, _ in calls} >= {"ingest.ingest_stage", "sync.sync_stage"}
    for name, call, args in calls:
        params = args[1] if len(args) > 1 else next(
            (k.value for k in call.keywords if k.arg == "params"), None)
        assert isinstance(params, ast.Call) and getattr(params.func, "id", None) == "asdict" \
            and len(params.args) == 1, \
            f"{name}:{call.lineno} records {params and ast.unparse(params)}"


def test_every_package_is_listed_packaged_and_hashed():
    """The packages given a layer here are core/packages.py's list (which the demo's stage
    cache hashes: a change in them reruns its steps), and exactly those are what setuptools
    installs from pyproject.toml's find rule."""
    tops = {p.split(".")[0] for p in LAYER}
    assert tops == set(PACKAGES)
    find = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"][
        "packages"]["find"]
    assert find.get("namespaces") is False, "a stray folder would become a namespace package"
    setuptools = pytest.importorskip("setuptools")
    found = setuptools.find_packages(str(ROOT), exclude=find.get("exclude", ()))
    assert {p.split(".")[0] for p in found} == set(PACKAGES)


def test_every_package_is_in_the_architecture():
    text = ARCHITECTURE.read_text()
    for package in LAYER:
        assert f"{package.replace('.', '/')}/" in text, package


def test_the_checks_can_fail():
    """The cycle finder finds a planted loop, the import parser sees hidden imports, and the
    table parser reads a row."""
    assert _find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert _find_cycle({"a": {"b"}, "b": set()}) is None
    assert "ingest.mcap_io" in GRAPH["sync.sync_stage"]
    assert _package("sim.twin.twin") == "sim.twin" and _package("sim.cone") == "sim"
    assert "core.atomic.atomic_outputs" in _writing(MODULES["sync.sync_stage"])
    assert not _writing(MODULES["pipeline.options"])           # same_path only reads
    assert {r for r, _ in RUNNERS} >= {"sync.sync_stage:run_sync",
                                       "sim.msm.simulate_stage:run_merge"}
    row = _stage_table("\n## Stages\n| `x` | `a.py`, `b.py` | `p/x_stage.py:run_x` | — | f |\n")
    assert row == {"x": {"math": ["a.py", "b.py"], "runner": ["p/x_stage.py:run_x"],
                         "view": [], "writes": []}}


# train/ by job: what a job may import of another (docs/ARCHITECTURE.md, "train/ by job"); the
# modules at train/'s top (its data and the paper's settings) are the ground of every job
TRAIN_JOBS = {"train.model": {"train.model"},
              "train.intervals": {"train.model", "train.intervals"},
              "train.training": {"train.model", "train.intervals", "train.training"},
              "train.evaluation": {"train.model", "train.intervals", "train.training",
                                   "train.evaluation"},
              "train.inference": {"train.model", "train.intervals", "train.training",
                                  "train.inference"}}


def _job(module: str) -> str | None:
    return next((j for j in TRAIN_JOBS if module == j or module.startswith(j + ".")), None)


@pytest.mark.parametrize("module", sorted(m for m in MODULES if _job(m)))
def test_train_jobs_import_downward(module):
    allowed = TRAIN_JOBS[_job(module)]
    for target in sorted(GRAPH[module]):
        job = _job(target)
        assert job is None or job in allowed, f"{module} imports {target}: {_job(module)} " \
                                              f"stands on {sorted(allowed)}"


def test_train_ground_imports_no_job():
    ground = [m for m in MODULES if m.startswith("train.") and _job(m) is None]
    assert ground, "train/ has modules beside its jobs (data, paper)"
    for module in ground:
        assert not {t for t in GRAPH[module] if _job(t)}, f"{module} imports a job of train/"
