"""The house: each folder of ``evcd/`` is one layer and imports run one way, from the top down
(shared/DESIGN.md section 5):

    utils < scenario < sim < forecast, planner < env < agents < loops < report, bench, experiments
          < cli (< scripts)

A module imports ``evcd`` modules of its own layer or of layers below it, never above it nor a
sibling (``report``, ``bench`` and ``experiments`` do not import each other), and no module reaches
itself through its imports (no circle, inside a folder or across folders). Checked on the source
(every ``import`` statement of every module, including those inside functions and under
``TYPE_CHECKING``) and on a fresh interpreter (what importing a module actually loads); each check is
shown to fail on a planted reverse import or circle.
"""

from __future__ import annotations

import ast
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "evcd"

#: Each folder's rank: a module may import evcd modules of a lower rank or of its own folder.
RANKS = {
    "utils": 0, "scenario": 1, "sim": 2, "forecast": 3, "planner": 3, "env": 4, "agents": 5, "loops": 6,
    "report": 7, "bench": 7, "experiments": 7, "cli": 8,
}  # fmt: skip
#: Third-party modules a layer must not import.
FORBIDDEN_LIBRARIES = {
    "scenario": ("libsumo", "traci", "torch"),
    "sim": ("torch",),
    "forecast": ("libsumo", "traci", "torch"),
    "planner": ("libsumo", "traci", "torch"),
    "env": ("torch",),
    "agents": ("libsumo", "traci"),
}
#: A module is one concept, split where a concept ends, not at a line count: this cap, well above the
#: largest module (the DQN learner, which a reader follows top to bottom), only catches a junk drawer.
MAX_LINES = 650


def imported_modules(path: Path) -> set[str]:
    tree = ast.parse(path.read_text())
    names: set[str] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            names.add(node.module)
            names.update(f"{node.module}.{alias.name}" for alias in node.names)
    return names


def module_name(path: Path, package: Path) -> str:
    """The dotted name of the module at ``path`` in ``package`` (a package's ``__init__`` is its folder)."""
    parts = list(path.relative_to(package.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(package: Path) -> dict[str, set[str]]:
    """Each module of ``package`` and the modules of ``package`` its import statements name (absolute
    and relative; ``from a import b`` names ``a.b`` where that is a module, else ``a``)."""
    paths = {module_name(p, package): p for p in package.rglob("*.py")}
    graph: dict[str, set[str]] = {}
    for name, path in paths.items():
        here = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        targets: set[str] = set()
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Import):
                targets.update(alias.name for alias in node.names)
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parent = here[: len(here) - node.level + 1]
                    base = ".".join([*parent, *([node.module] if node.module else [])])
                targets.update(f"{base}.{alias.name}" for alias in node.names)
                targets.add(base)
        deps = set()
        for target in targets:
            while target and target not in paths:
                target = target.rpartition(".")[0]
            if target and target != name:
                deps.add(target)
        graph[name] = deps
    return graph


def circles(package: Path) -> list[list[str]]:
    """The circles of imports in ``package``: every set of modules that reach each other through their
    imports (strongly connected components of :func:`import_graph` with more than one module; Tarjan)."""
    graph = import_graph(package)
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = [stack.pop()]
            while component[-1] != v:
                component.append(stack.pop())
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def layer_of(name: str) -> str | None:
    """The layer (top folder of evcd) a dotted module name belongs to, if it is one of evcd's."""
    parts = name.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "evcd" and parts[1] in RANKS else None


def violations(package: Path) -> list[str]:
    """Every import of ``package`` that runs against the layering."""
    bad = []
    for path in sorted(package.rglob("*.py")):
        rel = path.relative_to(package)
        if len(rel.parts) == 1:  # evcd/__init__.py: registers the environment by name only
            continue
        layer = rel.parts[0]
        for name in imported_modules(path):
            other = layer_of(name)
            if other is not None and other != layer and RANKS[other] >= RANKS[layer]:
                bad.append(f"{rel} ({layer}) imports {name} ({other})")
            if any(name == lib or name.startswith(lib + ".") for lib in FORBIDDEN_LIBRARIES.get(layer, ())):
                bad.append(f"{rel} ({layer}) imports {name}")
    return bad


def test_every_folder_is_a_layer_and_the_root_holds_only_the_package_init():
    folders = {p.name for p in PACKAGE.iterdir() if p.is_dir() and p.name != "__pycache__"}
    assert folders == set(RANKS)
    assert [p.name for p in PACKAGE.glob("*.py")] == ["__init__.py"]
    for folder in folders:
        assert (PACKAGE / folder / "__init__.py").is_file(), folder


@pytest.mark.slow
def test_imports_run_one_way():
    assert violations(PACKAGE) == []


@pytest.mark.slow
@pytest.mark.parametrize(
    ("planted", "code"),
    [
        ("utils/planted.py", "from evcd.loops.train import train_and_evaluate\n"),
        ("env/planted.py", "def f():\n    import evcd.agents.dqn\n"),
        ("report/planted.py", "from evcd.bench import engines\n"),
        ("scenario/planted.py", "import libsumo\n"),
    ],
)
def test_a_planted_reverse_import_is_caught(tmp_path, planted, code):
    copy = tmp_path / "evcd"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    assert violations(copy) == []
    (copy / planted).write_text(code)
    found = violations(copy)
    assert found and all(v.startswith(planted) for v in found), found


def test_no_circle_of_imports():
    assert circles(PACKAGE) == []


@pytest.mark.slow
@pytest.mark.parametrize(
    "planted",
    [
        # two modules of one folder (the layering ranks folders and cannot see this)
        {"loops/planted_a.py": "from evcd.loops.planted_b import b\na = 1\n",
         "loops/planted_b.py": "from evcd.loops import planted_a\nb = 2\n"},
        # through an import only a type checker runs, and a relative one
        {"loops/planted_a.py": "import typing\n\nif typing.TYPE_CHECKING:\n    from .tasks import Task\n",
         "loops/tasks.py": "+from evcd.loops import planted_a\n"},
        # a module and its own package's __init__, inside a function
        {"utils/planted_a.py": "def f():\n    from evcd.utils import check_int\n",
         "utils/__init__.py": "+from evcd.utils.planted_a import f\n"},
    ],
)  # fmt: skip
def test_a_planted_circle_is_caught(tmp_path, planted):
    """Each plant makes one circle (a ``+`` appends its line to the module, else the text is the
    module); the check names every module of it."""
    copy = tmp_path / "evcd"
    shutil.copytree(PACKAGE, copy, ignore=shutil.ignore_patterns("__pycache__"))
    assert circles(copy) == []
    for rel, code in planted.items():
        path = copy / rel
        path.write_text(path.read_text() + code[1:] if code.startswith("+") else code)
    found = circles(copy)
    expected = {module_name(copy / rel, copy) for rel in planted}
    assert len(found) == 1 and expected <= set(found[0]), found


def test_no_module_is_over_the_size_a_reader_holds():
    long = {str(p.relative_to(PACKAGE)): n for p in PACKAGE.rglob("*.py")
            if (n := len(p.read_text().splitlines())) > MAX_LINES}  # fmt: skip
    assert long == {}


def loaded_after(statement: str) -> set[str]:
    code = f"import sys\n{statement}\nprint('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_importing_the_package_registers_the_env_without_loading_it():
    mods = loaded_after("import evcd, gymnasium\nassert 'evcd/ChargingNav-v1' in gymnasium.registry")
    assert "evcd.env" not in mods and "libsumo" not in mods and "torch" not in mods


def test_the_simulation_layer_does_not_pull_in_the_environment():
    mods = loaded_after("import evcd.sim.snapshots")
    assert "evcd.sim.snapshots" in mods and "evcd.env" not in mods and "evcd.agents" not in mods


def test_the_environment_and_its_runners_do_not_pull_in_agents_or_torch():
    mods = loaded_after("import evcd.env.runners")
    assert "evcd.env.charging_nav" in mods and "evcd.env.runners.batched" in mods
    assert not {m for m in mods if m.startswith(("evcd.agents", "evcd.loops"))}
    assert "torch" not in mods


def test_the_heuristics_do_not_pay_for_torch():
    mods = loaded_after("import evcd.agents\nfrom evcd.agents import make_agent")
    assert "torch" not in mods


def test_reading_a_sweep_does_not_pay_for_torch():
    mods = loaded_after("import evcd.report.sweep")
    assert "evcd.report.sweep" in mods and "torch" not in mods
