"""The house: each folder of ``evcd/`` is one layer and imports run one way, from the top down
(shared/DESIGN.md section 5):

    utils < scenario < sim < env < agents < loops < report, bench, experiments < cli (< scripts)

A module imports ``evcd`` modules of its own layer or of layers below it, never above it nor a
sibling (``report``, ``bench`` and ``experiments`` do not import each other). Checked on the source
(every ``import`` statement of every module, including those inside functions) and on a fresh
interpreter (what importing a module actually loads); the check is shown to fail on a planted reverse
import.
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
    "utils": 0, "scenario": 1, "sim": 2, "forecast": 3, "env": 4, "agents": 5, "loops": 6, "report": 7,
    "bench": 7, "experiments": 7, "cli": 8,
}  # fmt: skip
#: Third-party modules a layer must not import.
FORBIDDEN_LIBRARIES = {
    "scenario": ("libsumo", "traci", "torch"),
    "sim": ("torch",),
    "forecast": ("libsumo", "traci", "torch"),
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


def test_imports_run_one_way():
    assert violations(PACKAGE) == []


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


def test_no_module_is_over_the_size_a_reader_holds():
    long = {str(p.relative_to(PACKAGE)): n for p in PACKAGE.rglob("*.py")
            if (n := len(p.read_text().splitlines())) > MAX_LINES}  # fmt: skip
    assert long == {}


def loaded_after(statement: str) -> set[str]:
    code = f"import sys\n{statement}\nprint('\\n'.join(sorted(sys.modules)))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    return set(out.stdout.split())


def test_importing_the_package_registers_the_env_without_loading_it():
    mods = loaded_after("import evcd, gymnasium\nassert 'evcd/ChargingNav-v0' in gymnasium.registry")
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
