"""The rules' estimate as a learner's input: per station, the seconds to the start of charging that a
rule reads off the observation, one more block beside the observation (``DQNConfig.rule_estimate``).

    estimate = RuleEstimate(n_stations=5, layout="DNZHPTG", points=2, normalized=False)
    block = estimate(obs)          # (..., 5) float32: the rule's seconds / ESTIMATE_UNIT_S

What the rule computes in one line (``max(drive, backlog)``, :class:`~evcd.agents.heuristics.
QueueAwareAgent`) a network must otherwise learn from ``D, N, Z, ...`` alone: a ratio of the vehicles
ahead to the points in service, a maximum with the drive time. Given the estimate as an input, the
learner starts from the rule's answer and has to learn only where it is wrong (the charging times that
differ from the rule's nominal one, the background traffic that joins a queue, the drive guess).

Which rule: :class:`~evcd.agents.heuristics.QueueAwareAgent` on the single target (``D, N, Z`` and,
where observed, ``P`` and ``T``); :class:`~evcd.agents.fleet_rules.ReservationAgent` on the fleet (it
also counts the other guided EVs: ``Z + G`` where the observation holds ``G``, else ``Z + H``), both
with their default settings. The block is a function of the observation alone, so it tells the
network nothing the observation does not hold: the replay keeps the observation, the block is
computed wherever the network reads one, and the fleet's in-turn corrections (:mod:`evcd.agents.
in_turn`) reach it. Seconds are capped at :data:`ESTIMATE_CAP_S` (a station with no point in service
scores the rules' closed-station value) and read in units of :data:`ESTIMATE_UNIT_S`.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from evcd.agents.fleet_rules import ReservationAgent
from evcd.agents.heuristics import QueueAwareAgent

#: The estimate's cap (s): two hours, beyond any start of charging a dispatcher should choose.
ESTIMATE_CAP_S = 7200.0
#: The network reads the estimate in thousands of seconds (the other blocks' inputs are near 1 too).
ESTIMATE_UNIT_S = 1000.0


class RuleEstimate:
    """The rule's estimated seconds to the start of charging at each station, as a network's input block.

    Args:
        n_stations: stations.
        layout: the observation's blocks (e.g. ``"DNZ"``, the fleet's ``"DNZHPTG"``): with ``H``
            (the fleet) the reservation rule's estimate, else queue_aware's.
        points: each station's charging points (one number for all).
        normalized: whether the environment normalises its observations.

    Raises:
        ValueError: ``points`` is ``None`` (the estimate reads ``Z`` in vehicles) or not one per station.
    """

    def __init__(
        self, n_stations: int, layout: str, points: int | Sequence[int] | None, normalized: bool
    ) -> None:
        if points is None:
            raise ValueError("rule_estimate=True needs the stations' charging points (points=...): the "
                             "rule reads the queues in vehicles")  # fmt: skip
        rule = ReservationAgent if "H" in layout else QueueAwareAgent
        # a rule is deterministic: its generator is never drawn from
        self.rule = rule(n_stations, np.random.default_rng(0), points=points, normalized=normalized)
        self.rule.layout = layout

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """The block for ``obs`` (one observation or a batch): ``(..., m)`` float32, the estimate in
        :data:`ESTIMATE_UNIT_S`, capped at :data:`ESTIMATE_CAP_S`."""
        seconds = self.rule.estimate(np.asarray(obs))
        return (np.minimum(seconds, ESTIMATE_CAP_S) / ESTIMATE_UNIT_S).astype(np.float32)
