"""Keep the policy of the best periodic validation, and evaluate it instead of the last one.

A learner's validation curve need not end at its best: in the paper's world the policy that swept
one whole training day can be worse on the validation episodes than the one before it
(docs/RESULTS.md). With ``train.validation.select_best`` the trainers keep, after every
validation that is the best so far (:meth:`~evcd.loops.validation.ValidationRecord.best`), the
policy's networks in ``<run_dir>/best/`` (a checkpoint folder of its own, written atomically), and
load them before the evaluation. This is model selection on the validation episodes (tuning days):
the evaluation days stay unseen. Training is untouched: the last checkpoint still holds the last
weights, so ``resume`` and the training stream are the same with or without it.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from evcd.agents.base import Agent
from evcd.loops.validation import ValidationPoint, ValidationRecord, ValidationSettings
from evcd.utils.checkpoint import CheckpointError, has_checkpoint, load_checkpoint, save_checkpoint

log = logging.getLogger(__name__)

#: The folder of the best validated policy in a run directory.
BEST_DIR = "best"
BEST_FORMAT = "evcd.best_policy/1"


def keep_if_best(run_dir: Path, agent: Agent, settings: ValidationSettings, record: ValidationRecord) -> bool:
    """After a validation: with ``settings.select_best``, save ``agent``'s policy as the run's best
    if the latest validation point is the best one.

    Returns:
        Whether it was saved.
    """
    if not (settings.select_best and record.points) or record.best() is not record.points[-1]:
        return False
    point = record.points[-1]
    payload = {"format": BEST_FORMAT, "episodes_done": point.episodes_done,
               "agent": agent.policy_state_dict()}  # fmt: skip
    save_checkpoint(run_dir / BEST_DIR, payload, f"best_{point.episodes_done:07d}")
    log.info("best validation so far (%.1f s after %d episodes): policy kept in %s", point.mean,
             point.episodes_done, run_dir / BEST_DIR)  # fmt: skip
    return True


def load_best(run_dir: Path, agent: Agent, record: ValidationRecord) -> ValidationPoint:
    """Load the policy of ``record``'s best validation into ``agent`` (its networks only).

    Raises:
        CheckpointError: no validation yet, or ``<run_dir>/best`` is missing, damaged, or holds
            another validation's policy than the record's best.
    """
    best = record.best()
    folder = run_dir / BEST_DIR
    if best is None or not has_checkpoint(folder):
        raise CheckpointError(f"select_best: {folder} holds no validated policy (a run that validated "
                              "with train.validation.select_best=true writes one)")  # fmt: skip
    payload = load_checkpoint(folder)
    saved = payload.get("episodes_done") if payload.get("format") == BEST_FORMAT else None
    if saved != best.episodes_done:
        raise CheckpointError(f"select_best: {folder} holds the policy after {saved} episodes, but the "
                              f"best validation is after {best.episodes_done}")  # fmt: skip
    agent.load_state_dict(payload["agent"], policy_only=True)
    last = record.points[-1]
    log.info("evaluating the best validated policy: after %d episodes (%.1f s on the validation "
             "episodes; the last, after %d, had %.1f s)", best.episodes_done, best.mean,
             last.episodes_done, last.mean)  # fmt: skip
    return best


def policy_to_evaluate(
    run_dir: Path, agent: Any, settings: ValidationSettings, record: ValidationRecord, episodes: int
) -> int:
    """Before a trainer's evaluation: with ``settings.select_best`` (and training), load the best
    validated policy into ``agent``. Returns the training episodes after which the evaluated policy
    stood (``episodes``: the last)."""
    if not (settings.select_best and episodes):
        return episodes
    return load_best(run_dir, agent, record).episodes_done


def check_learned(agent: Any, episodes: int) -> None:
    """Refuse to evaluate a learner that trained for ``episodes`` without one gradient step (its
    network is the untrained one: ``learning_starts`` above every transition the run saw).

    Raises:
        ValueError: naming the transitions seen and ``learning_starts`` (the checkpoint is kept).
    """
    if not episodes or not hasattr(agent, "stats") or not agent.learns:
        return
    stats = agent.stats()
    if stats.get("gradient_steps", 1) == 0:
        config = getattr(agent, "config", None)
        starts = getattr(config, "learning_starts", None)
        rollout = getattr(config, "rollout_steps", None)
        needs = f"learner.learning_starts={starts}" if starts is not None else "its own threshold"
        if rollout is not None:
            needs = f"agent.rollout_steps={rollout}"
        seen = int(stats.get("transitions", 0))
        raise ValueError(f"the learner took no gradient step in {episodes} training episodes "
                         f"({seen} transitions, {needs}): "
                         "its network is untrained, so it is not evaluated; lower that setting or "
                         "train longer (the checkpoint is kept)")  # fmt: skip
