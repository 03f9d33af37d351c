"""Where an evaluation's world differs from the one a saved policy was trained in.

``scripts/evaluate.py agent.checkpoint=...`` may put a trained policy anywhere: another regime, a
perturbed world, other days. That is a legitimate experiment, but one a reader of its numbers must
know about, and the easiest mistake to make unseen (the README regime's policy evaluated without its
morning window is a different experiment). Every checkpoint of the trainers holds its run's config;
this compares the world it describes with the evaluation's and names each difference, and the days
the evaluation shares with the training or tuning days. A run's ``best/`` folder is compared through
the run's latest checkpoint; a file holding an agent state alone says nothing.

    report = trained_world(saved_config, cfg)   # {"differences": [...], "training_days": [...], ...}
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

from hydra.utils import to_absolute_path

from evcd.loops.best_policy import BEST_DIR
from evcd.loops.run_files import CHECKPOINTS
from evcd.loops.train_state import config_diff
from evcd.report.sweep import day_list
from evcd.utils.checkpoint import has_checkpoint, load_checkpoint

#: The top-level blocks that shape the world an agent meets, on either task.
WORLD_BLOCKS = ("scenario", "evs", "perturbations", "task", "fleet")

#: ``env`` settings that do not change what the agent meets: where caches live, the GUI, how the
#: snapshots are taken and which simulation protocol plays them (the same travel times), how the
#: observation is scaled (a saved policy reads what it was trained on either way), and the days
#: (compared on their own: an evaluation on other days is the point).
ENV_FREE = frozenset({"cache_dir", "gui", "snapshot_every", "protocol", "normalize_obs", "demand_seeds",
                      "forecast_days"})  # fmt: skip


def trained_world(saved: Mapping[str, Any] | None, current: Mapping[str, Any]) -> dict[str, Any] | None:
    """How the evaluation config ``current`` stands to the training run's config ``saved``.

    Returns ``None`` when nothing is known of the training (``saved`` is ``None``), else a dict:
    ``differences`` (``"key: trained -> now"`` for every world setting that differs, nested keys
    dotted), ``training_days`` and ``tuning_days`` (the evaluated days, ``env.demand_seeds``, that
    the run trained on or validated on) and ``forecast_days`` (``"trained -> now"`` when the policy
    observes a forecast learnt from other days than the ones it trained with, else ``None``).
    """
    if saved is None:
        return None
    trained_env, env = _mapping(saved.get("env")), _mapping(current.get("env"))
    before = {k: _resolved(k, saved.get(k, "<missing>")) for k in WORLD_BLOCKS}
    now = {k: _resolved(k, current.get(k, "<missing>")) for k in WORLD_BLOCKS}
    before["env"] = {k: v for k, v in trained_env.items() if k not in ENV_FREE}
    now["env"] = {k: v for k, v in env.items() if k not in ENV_FREE}
    days = _mapping(saved.get("days"))
    trained_on = list(day_list(days.get("train", trained_env.get("demand_seeds"))))
    evaluated = set(day_list(env.get("demand_seeds")))
    return {
        "differences": config_diff(before, now, what="the trained policy"),
        "training_days": sorted(evaluated & set(trained_on)),
        "tuning_days": sorted(evaluated & set(day_list(days.get("tuning")))),
        "forecast_days": _forecast_days(trained_env, env, trained_on),
    }


def run_config(path: str | Path, saved: Mapping[str, Any] | None) -> Mapping[str, Any] | None:
    """The config of the run a policy at ``path`` came from: ``saved`` (its checkpoint's own), or for a
    run's ``best/`` folder (which holds the networks alone) that of the run's latest checkpoint."""
    path = Path(path)
    if saved is not None or path.name != BEST_DIR or not has_checkpoint(path.parent / CHECKPOINTS):
        return saved
    config = load_checkpoint(path.parent / CHECKPOINTS).get("config")
    return config if isinstance(config, Mapping) else None


def warnings(report: Mapping[str, Any] | None) -> list[str]:
    """One line per thing a reader of the evaluation should know (empty: the training's world)."""
    if report is None:
        return []
    out = []
    if report["differences"]:
        out.append("the world differs from the policy's training: " + "; ".join(report["differences"]))
    if report["training_days"]:
        out.append(f"evaluated on days the policy trained on: {report['training_days']}")
    if report["tuning_days"]:
        out.append(f"evaluated on the training run's tuning days (its validation): {report['tuning_days']}")
    if report["forecast_days"]:
        out.append(f"the forecast it observes learns from other days than in training: "
                   f"{report['forecast_days']}")  # fmt: skip
    return out


def _forecast_days(
    trained_env: Mapping[str, Any], env: Mapping[str, Any], trained_on: list[int]
) -> str | None:
    """The forecast's learning days, trained -> now, where the policy observes a forecast and they
    differ (a run with ``forecast_days: null`` learnt from its training days, ``trained_on``)."""
    if "forecast" not in (trained_env.get("observe") or ()):
        return None
    before = trained_env.get("forecast_days")
    before = list(day_list(before)) if before is not None else trained_on
    now = list(day_list(env.get("forecast_days")))
    return None if sorted(before) == sorted(now) else f"{sorted(before)} -> {sorted(now)}"


def _resolved(block: str, value: Any) -> Any:
    """The scenario block with its folder as an absolute path (both runs are taken to start in the
    same folder, as the scripts' relative paths are)."""
    if block != "scenario" or not isinstance(value, Mapping) or not value.get("path"):
        return value
    return {**value, "path": str(Path(to_absolute_path(str(value["path"]))).resolve())}


def _mapping(value: Any) -> Mapping[str, Any]:
    return value if isinstance(value, Mapping) else {}
