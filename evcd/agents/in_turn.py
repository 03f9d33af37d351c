"""The guided EVs of one fleet tick decided in turn, each seeing where the ones before it were sent.

At a tick of the fleet (:mod:`evcd.env.fleet`) every guided EV due observes ``[D, N, Z, H]`` as it
was before any of them acted: EVs that decide side by side do not see each other's new choices, and
several can pick the same short queue together. A dispatcher that decides them *in turn* corrects
the observation of each EV for the choices made before it at the same tick:

- an EV sent to station ``s`` counts one more guided EV heading to ``s`` (``H[s] + 1``) for every EV
  after it;
- if it was counted elsewhere before the tick (heading to station ``c``: in the others' ``H[c]``;
  waiting in ``c``'s car park: in their ``Z[c]``), that count loses one;
- an EV that keeps its station changes nothing (it is already counted there).

The fleet's ``G`` (the guided EVs due at a station before this one) follows the same choices where
the layout also holds ``T`` (an EV's time to each station): an EV sent to ``s`` counts in ``G[s]`` of
every later EV whose ``T[s]`` is longer than its own ``T[s]``, and one leaving the station ``c`` it was
heading to leaves ``G[c]`` where it was counted. Without ``T``, ``G`` stays as observed; the other
options' blocks always do.

Where an EV was counted comes from the dispatcher's memory of where it sent it at its previous
decision and, for an EV waiting in a car park, from its observation (``D == 0`` there). At an EV's
first decision the dispatcher does not know where it was heading (its trip's own station, in the
others' ``H``), so that count stays: one vehicle too many there for the EVs after it at that tick.
:class:`~evcd.agents.fleet_rules.CentralAgent` does the same bookkeeping on its own estimates; a
learner does it on its network's inputs (``DQNConfig.in_turn``).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np


def counted_at(d: np.ndarray, episodes: Sequence[Any]) -> np.ndarray:
    """Per EV (rows of ``d``), the station it is counted at as far as the dispatcher knows (-1:
    unknown): where it waits (``D == 0``: in that station's ``Z``; ``D`` in any unit), else the
    ``station`` its episode state says it was last sent to (``None``: unknown)."""
    waiting = d == 0.0
    last = np.array([-1 if e.station is None else e.station for e in episodes], dtype=np.int64)
    return np.where(waiting.any(axis=1), np.argmax(waiting, axis=1), last)


def decide_in_turn(
    obs: np.ndarray,
    counted: np.ndarray,
    vehicle: np.ndarray,
    order: Sequence[int] | np.ndarray,
    choose: Callable[[int, np.ndarray], int],
    layout: str = "DNZH",
) -> tuple[np.ndarray, np.ndarray]:
    """Decide the rows of ``obs`` one after the other, each on its observation corrected for the
    choices before it (module docstring).

    Args:
        obs: the ``k`` EVs' fleet observations ``[D, N, Z, H]`` (and the observation options' blocks
            after them, left as they are), shape ``(k, 4m)`` (or wider), in the env's units.
        counted: per EV, the station it is counted at before the tick (-1: unknown; :func:`counted_at`):
            in its ``Z`` if the EV waits in a car park (``D == 0`` there), else in its ``H``.
        vehicle: per station, what one vehicle is in the observation's ``Z`` and ``H`` units (1, or
            ``1 / points`` for a normalised observation), shape ``(m,)``.
        order: the rows in the order they decide (a permutation of ``range(k)``).
        choose: ``choose(row, seen)`` -> the station of EV ``row`` given the observation it sees.
        layout: the rows' blocks (:func:`~evcd.env.observation.check_layout`): with ``G`` and ``T``,
            ``G`` is corrected too (module docstring).

    Returns:
        The ``k`` stations (int64) and the observations the EVs decided on (``(k, 4m)``, float32).

    Raises:
        ValueError: ``obs`` is not ``(k, 4m)``, or ``order`` is not a permutation of its rows.
    """
    seen = np.array(obs, dtype=np.float32)
    m = len(vehicle)
    if seen.ndim != 2 or seen.shape[1] % m or seen.shape[1] < 4 * m:
        raise ValueError(f"observations of shape {seen.shape}: expected (k, 4m), [D, N, Z, H] per row")
    k = len(seen)
    if sorted(int(j) for j in order) != list(range(k)):
        raise ValueError(f"order {list(order)}: must be a permutation of the {k} rows")
    waiting = (seen[:, :m] == 0.0).any(axis=1)
    moved_z = np.zeros(m)  # vehicles that left each car park at this tick so far
    moved_h = np.zeros(m)  # guided EVs heading to each station: added (+) and removed (-) so far
    g, t = (layout.index("G") * m, layout.index("T") * m) if "G" in layout and "T" in layout else (-1, -1)
    moves: list[tuple[int, float, float]] = []  # G's corrections: (station, the EV's T there, +1 / -1)
    stations = np.empty(k, dtype=np.int64)
    for j in order:
        row = seen[j]
        row[2 * m : 3 * m] = np.maximum(0.0, row[2 * m : 3 * m] + moved_z * vehicle)
        row[3 * m : 4 * m] = np.maximum(0.0, row[3 * m : 4 * m] + moved_h * vehicle)
        for st, due, sign in moves:
            if due < row[t + st]:
                row[g + st] = max(0.0, row[g + st] + sign * vehicle[st])
        s = int(choose(int(j), row))
        stations[j] = s
        c = int(counted[j])
        if c != s:
            moved_h[s] += 1.0
            if g >= 0:
                moves.append((s, float(row[t + s]), 1.0))
            if c >= 0:
                (moved_z if waiting[j] else moved_h)[c] -= 1.0
                if g >= 0 and not waiting[j]:
                    moves.append((c, float(row[t + c]), -1.0))
    return stations, seen


def learner_tick(
    obs: np.ndarray,
    episodes: Sequence[Any],
    vehicle: np.ndarray,
    q_values: Callable[[np.ndarray], np.ndarray],
    choose: Callable[[int, int], int],
    store: Callable[[Any, Any], None],
    layout: str = "DNZH",
    keep: Callable[[np.ndarray, int], int] | None = None,
) -> np.ndarray:
    """A learner's tick in turn: the rows of ``obs`` (``(k, 4m)``) in order of their best Q-value on
    the tick's observations (the soonest expected charge first; ties to the lower row), each deciding
    on its observation corrected for the stations chosen before it (:func:`decide_in_turn`).

    Each episode (a :class:`~evcd.agents.dqn_episode.DQNEpisode`) keeps its station and the
    observation it decided on (``seen``); its transition held since its previous decision (``held``,
    :func:`hold`) goes to ``store(transition, episode)`` now, its next observation being the one it
    decides on here (what its next action was chosen on).

    Args:
        q_values: the network's Q-values of a row or a batch.
        choose: ``choose(row, greedy)`` -> the action of EV ``row`` (exploration included).
        layout: the rows' blocks (:func:`decide_in_turn`).
        keep: ``keep(q, current)`` -> the greedy station of an EV given its Q-values and the station it
            is counted at (-1: unknown; a switching margin, :mod:`evcd.agents.switching`); ``None``:
            the argmax.

    Raises:
        ValueError: ``obs`` is not ``(k, 4m)`` with one row per episode.
    """
    batch = np.asarray(obs, dtype=np.float32)
    if batch.ndim != 2 or len(batch) != len(episodes):
        raise ValueError(f"observations of shape {batch.shape} for {len(episodes)} episodes: one row each")
    order = np.argsort(-q_values(batch).max(axis=1), kind="stable")
    counted = counted_at(batch[:, : len(vehicle)], episodes)
    greedy = (lambda q, c: int(q.argmax())) if keep is None else keep
    pick = lambda j, row: choose(j, greedy(q_values(row), int(counted[j])))  # noqa: E731
    stations, seen = decide_in_turn(batch, counted, vehicle, order, pick, layout)
    for episode, s, row in zip(episodes, stations, seen, strict=True):
        episode.station, episode.seen = int(s), row
        if episode.held is not None:
            store(episode.held._replace(next_obs=row), episode)
            episode.held = None
    return stations


def hold(transition: Any, episode: Any, store: Callable[[Any, Any], None]) -> None:
    """A learner's transition of an EV decided in turn: its observation becomes the one the EV decided
    on; a last transition (terminated or truncated) goes to ``store`` at once, any other waits in
    ``episode.held`` for the observation of the EV's next decision (:func:`learner_tick`).

    A last transition keeps the tick's observation as the env gave it: the EV decides no more, so no
    EV decides before it at that tick, and the uncorrected observation is exactly what an EV deciding
    first sees (the same kind of input as every other next observation). It only matters for a
    truncation (stuck, time cap), which bootstraps from it; a termination does not. An EV that could
    no longer be observed gets no last transition; its held one is stored at ``end_episode`` with the
    next observation it had."""
    transition = transition._replace(obs=episode.seen)
    episode.seen = None
    if transition.terminated or transition.truncated:
        store(transition, episode)
    else:
        episode.held = transition
