"""TensorBoard curves of a training run (``tensorboard --logdir outputs/``).

Tags, all at ``global_step`` = transitions seen (so that a resumed run can purge what the
interrupted one wrote after its last checkpoint):

- ``charts/travel_time``, ``charts/episodic_return``, ``charts/queue_wait``, ``charts/switches``,
  ``charts/truncated`` (per training episode), ``charts/epsilon``, ``charts/learning_rate``,
  ``charts/transitions_per_second``;
- ``losses/td_loss`` and ``losses/q_values``: means over the gradient steps of the episode (the DQN
  learners); an agent's own :meth:`~evcd.agents.Agent.scalars` under their tags (PPO:
  ``losses/policy``, ``losses/value``, ``losses/entropy``, ``charts/approx_kl``,
  ``charts/clip_fraction``);
- ``eval/travel_time`` (the agent), and per baseline rule ``eval/<rule>_travel_time`` and
  ``eval/paired_difference_<rule>`` (agent minus rule on the same episodes);
- the periodic held-out validation (:mod:`evcd.loops.validation`): ``eval/validation_travel_time``
  (the policy without exploration) and ``eval/validation_<rule>`` (the rules on the same episodes);
- a fleet run (:class:`~evcd.loops.tasks.FleetTask`), per training fleet episode: ``charts/guided_travel``,
  ``charts/all_travel``, ``charts/queue_wait``, ``charts/herding``, ``charts/switches`` (per guided
  EV), ``charts/truncated`` (guided EVs), with the same epsilon, speed and losses; its validation
  and evaluation use the ``eval/`` tags above (guided EVs' mean travel time);
- the run's resolved configuration as text (``config``).
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from torch.utils.tensorboard import SummaryWriter

from evcd.loops.validation import ValidationRecord


class TrainLog:
    """A TensorBoard writer for one run directory.

    Args:
        log_dir: the event files' folder.
        purge_step: on resume, the global step of the checkpoint: events the interrupted run wrote
            at or after it are hidden, so every curve shows each step once.
    """

    def __init__(self, log_dir: str | Path, purge_step: int | None = None) -> None:
        self.writer = SummaryWriter(str(log_dir), purge_step=purge_step)
        self._totals: tuple[float, float, float] | None = None

    def config(self, config: Mapping[str, Any], agent: str) -> None:
        """Record the resolved configuration and the agent's description as text."""
        text = json.dumps(config, indent=2, default=str)
        self.writer.add_text("config", f"agent: `{agent}`\n\n```\n{text}\n```", 0)

    def start(self, stats: Mapping[str, float]) -> None:
        """Take the agent's cumulative counters as the origin of the per-episode loss means."""
        self._totals = self._read(stats)

    @staticmethod
    def _read(stats: Mapping[str, float]) -> tuple[float, float, float]:
        return (stats.get("gradient_steps", 0.0), stats.get("loss_total", 0.0), stats.get("q_total", 0.0))

    def episode(
        self,
        row: Any,
        stats: Mapping[str, float],
        step: int,
        wall_s: float,
        scalars: Mapping[str, float] | None = None,
    ) -> None:
        """Log one training episode of either task (``row.charts()``: an
        :class:`~evcd.env.runners.base.EpisodeRow` or a fleet episode,
        :class:`~evcd.env.runners.fleet.FleetEpisode`); ``stats`` and ``scalars``: the agent's
        :meth:`~evcd.agents.Agent.stats` and :meth:`~evcd.agents.Agent.scalars` after it."""
        for key, value in row.charts().items():
            self.writer.add_scalar(f"charts/{key}", value, step)
        self._learner(stats, step, wall_s, scalars)

    def _learner(
        self, stats: Mapping[str, float], step: int, wall_s: float, scalars: Mapping[str, float] | None
    ) -> None:
        """Exploration, speed, the losses over the gradient steps since the last call (an agent
        counting ``loss_total``: the DQN learners) and the agent's own scalars."""
        for tag, value in (scalars or {}).items():
            self.writer.add_scalar(tag, value, step)
        w = self.writer
        if "epsilon" in stats:
            w.add_scalar("charts/epsilon", stats["epsilon"], step)
        if "lr" in stats:
            w.add_scalar("charts/learning_rate", stats["lr"], step)
        if wall_s > 0:
            w.add_scalar("charts/transitions_per_second", step / wall_s, step)
        now = self._read(stats)
        before = self._totals if self._totals is not None else now
        steps = now[0] - before[0]
        if steps > 0 and "loss_total" in stats:
            w.add_scalar("losses/td_loss", (now[1] - before[1]) / steps, step)
            w.add_scalar("losses/q_values", (now[2] - before[2]) / steps, step)
        self._totals = now

    def scalars(
        self, value: float, baselines: Mapping[str, float], paired: Mapping[str, Mapping[str, Any]], step: int
    ) -> None:
        """Log an evaluation (either task: :meth:`evcd.loops.tasks.Task.score` of each summary): the
        agent's mean travel time, each baseline's and each paired difference."""
        if math.isfinite(value):
            self.writer.add_scalar("eval/travel_time", value, step)
        for name, base in baselines.items():
            if math.isfinite(base):
                self.writer.add_scalar(f"eval/{name}_travel_time", base, step)
            difference = paired[name]["mean_difference"]
            if math.isfinite(difference):
                self.writer.add_scalar(f"eval/paired_difference_{name}", difference, step)

    def validation(self, record: ValidationRecord, step: int) -> None:
        """Log the latest validation point and the rules' means on the same episodes at ``step``."""
        if not record.points:
            return
        mean = record.points[-1].mean
        if math.isfinite(mean):
            self.writer.add_scalar("eval/validation_travel_time", mean, step)
        for name, rule_mean in record.to_dict()["rule_means"].items():
            if rule_mean is not None:
                self.writer.add_scalar(f"eval/validation_{name}", rule_mean, step)

    def flush(self) -> None:
        """Write pending events to disk."""
        self.writer.flush()

    def close(self) -> None:
        """Flush and close."""
        self.writer.close()
