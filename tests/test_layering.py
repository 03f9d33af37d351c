"""Data flows one way: scenario -> sim -> env -> agents -> train/evaluate (shared/DESIGN.md section 5).

Each layer imports only what lies below it: checked on the source (every ``import`` statement of
every module) and on a fresh interpreter (what importing a module actually loads).
"""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "evcd"

#: layer -> modules (prefixes) it must not import
FORBIDDEN = {
    "scenario": (
        "evcd.sim",
        "evcd.env",
        "evcd.agents",
        "evcd.train",
        "evcd.evaluate",
        "libsumo",
        "traci",
        "torch",
    ),
    "sim": ("evcd.env", "evcd.agents", "evcd.train", "evcd.evaluate", "torch"),
    "env": ("evcd.agents", "evcd.train", "evcd.evaluate", "torch"),
    "agents": ("evcd.sim", "evcd.scenario", "evcd.train", "evcd.evaluate", "libsumo", "traci"),
}


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


@pytest.mark.parametrize("layer", sorted(FORBIDDEN))
def test_no_module_imports_a_layer_above_it(layer):
    files = sorted((PACKAGE / layer).glob("*.py"))
    assert files
    bad = []
    for path in files:
        for name in imported_modules(path):
            if any(name == f or name.startswith(f + ".") for f in FORBIDDEN[layer]):
                bad.append(f"{path.name} imports {name}")
    assert not bad, bad


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


def test_the_environment_does_not_pull_in_agents_or_torch():
    mods = loaded_after("import evcd.env")
    assert "evcd.env.charging_nav" in mods
    assert not {m for m in mods if m.startswith(("evcd.agents", "evcd.train", "evcd.evaluate"))}
    assert "torch" not in mods


def test_the_heuristics_do_not_pay_for_torch():
    mods = loaded_after("import evcd.agents\nfrom evcd.agents import make_agent")
    assert "torch" not in mods
