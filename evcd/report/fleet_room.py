"""Where the room is on the fleet: the clairvoyant bound beside the dispatchers of the fleet table.

A ``fleet_bound`` job (:mod:`evcd.loops.fleet_bound`) plays the same evaluation fleet episodes as every
other job of its seed and cell, and gives per episode the solver's proven lower bound of the planner's
model and the model's best plan played in SUMO (its ``guided_travel``, the column ``fleet_bound`` of
the table). Three tables come of it (:func:`room_markdown`):

- **the share of the greedy -> bound gap** each dispatcher closes (from the seed means, with a paired
  bootstrap interval over seeds, :func:`~evcd.report.seed_stats.gap_share`);
- **from the strongest rule to the bound**: per cell the rule with the lowest mean (learners and the
  bound's played plan are not rules), its distance to the played plan and to the proven bound in
  seconds per guided EV, paired by episode within each seed, then over seeds with a t interval;
- **below the bound**: per dispatcher the episodes on which its guided EVs' mean travel time was below
  the episode's proven bound, and by how much. The bound is one of the model, not of SUMO: an episode
  below it is one where the model is not exact (its drive times are the routes' estimates at each
  request) or where the dispatcher's mean leaves truncated EVs out.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from evcd.report.markdown import format_stat, markdown_table
from evcd.report.paired import PairedStat, paired_cell, paired_stat
from evcd.report.seed_stats import MIN_GAP_S, GapShare, gap_share, seed_interval

Cell = tuple[str, int, float]  # (regime, evs, guided_share)


class FleetJob(Protocol):
    """What the room tables read of a fleet job (:class:`evcd.report.fleet_table.FleetJob`)."""

    regime: str
    agent: str
    evs: int
    guided_share: float
    seed: int
    guided_travel: float
    bound: float
    train_episodes: int
    per_episode: tuple[tuple[int, int, float, float], ...]
    per_episode_bound: tuple[tuple[int, int, float], ...]


#: The clairvoyant bound's jobs (``agent=fleet_bound``): their travel time is the played plan's, a column
#: like a dispatcher's; their ``bound`` the proven lower bound of the model.
BOUND_AGENT = "fleet_bound"
#: The bootstrap of the gap shares draws from this seed (the same table from the same jobs).
ROOM_SEED = 0
#: An episode counts as below the bound when a dispatcher's mean is more than this under it (s).
BELOW_S = 0.05

Episode = tuple[int, int]  # (episode index, day)


def _in_cell(job: FleetJob, cell: Cell) -> bool:
    return (job.regime, job.evs, job.guided_share) == cell


def _seed_means(
    jobs: Sequence[FleetJob], cell: Cell, agent: str, measure: str = "guided_travel"
) -> dict[int, float]:
    return {j.seed: getattr(j, measure) for j in jobs if _in_cell(j, cell) and j.agent == agent}


def _episodes(job: FleetJob) -> dict[Episode, float]:
    """The guided EVs' mean travel time per evaluation episode of ``job``."""
    return {(e[0], e[1]): e[2] for e in job.per_episode}


def _bounds(job: FleetJob) -> dict[Episode, float]:
    """The proven bound per evaluation episode of a ``fleet_bound`` job."""
    return {(e[0], e[1]): e[2] for e in job.per_episode_bound}


def _pairs(jobs: Sequence[FleetJob], cell: Cell, agent: str, to_bound: bool) -> dict[int, list[float]]:
    """Per seed, ``agent`` minus the bound's played plan (``to_bound`` false) or its proven bound, per
    episode both have a finite value for."""
    mine = {j.seed: j for j in jobs if _in_cell(j, cell) and j.agent == agent}
    bound = {j.seed: j for j in jobs if _in_cell(j, cell) and j.agent == BOUND_AGENT}
    diffs: dict[int, list[float]] = {}
    for seed in sorted(set(mine) & set(bound)):
        other = _bounds(bound[seed]) if to_bound else _episodes(bound[seed])
        diffs[seed] = [a - other[k] for k, a in _episodes(mine[seed]).items()
                       if k in other and math.isfinite(a) and math.isfinite(other[k])]  # fmt: skip
    return diffs


def to_bound(jobs: Sequence[FleetJob], cell: Cell, agent: str, proven: bool = True) -> PairedStat | None:
    """``agent`` minus the proven bound (``proven``) or minus the played plan in ``cell``, paired by
    episode within each seed, then over seeds (``None`` if no seed has both)."""
    return paired_stat(_pairs(jobs, cell, agent, proven))


def is_rule(jobs: Sequence[FleetJob], agent: str) -> bool:
    """A dispatcher that neither learns nor is the bound (its jobs trained on no episode)."""
    return agent != BOUND_AGENT and all(j.train_episodes == 0 for j in jobs if j.agent == agent)


def strongest_rule(jobs: Sequence[FleetJob], cell: Cell) -> str | None:
    """The rule with the lowest mean over seeds of the guided EVs' mean travel time in ``cell``."""
    means = {}
    for agent in sorted({j.agent for j in jobs if _in_cell(j, cell)}):
        values = [v for v in _seed_means(jobs, cell, agent).values() if math.isfinite(v)]
        if values and is_rule(jobs, agent):
            means[agent] = float(np.mean(values))
    return min(means, key=means.__getitem__) if means else None


def below_bound(jobs: Sequence[FleetJob], cell: Cell, agent: str) -> tuple[int, int, float]:
    """``(episodes below, episodes compared, largest margin in s)``: the episodes of ``cell`` on which
    ``agent``'s guided EVs' mean was more than :data:`BELOW_S` under the proven bound."""
    every = [d for diffs in _pairs(jobs, cell, agent, True).values() for d in diffs]
    below = [-d for d in every if d < -BELOW_S]
    return len(below), len(every), max(below, default=0.0)


def _share_text(share: GapShare) -> str:
    if share.gap.n == 0:
        return "—"
    if not share.room:
        return "no room"
    if share.gap.n == 1:
        return f"{share.share:.2f} n=1"
    return f"{share.share:.2f} [{share.low:.2f}, {share.high:.2f}] n={share.gap.n}"


def _below_text(below: int, compared: int, margin: float) -> str:
    if not compared:
        return "—"
    return f"{below} of {compared}" + (f" (up to {margin:.1f} s)" if below else "")


def room_markdown(
    jobs: Sequence[FleetJob],
    cells: Sequence[Cell],
    labels: dict[Cell, list[str]],
    head: list[str],
    agents: Sequence[str],
) -> list[str]:
    """The three tables of the module docstring (Markdown lines; none without ``fleet_bound`` and
    ``greedy`` jobs). ``labels``: each cell's first cells of a row; ``head`` their titles."""
    names = {j.agent for j in jobs}
    if BOUND_AGENT not in names or "greedy" not in names:
        return []
    rng = np.random.default_rng(ROOM_SEED)
    others = [a for a in agents if a != "greedy"]
    dispatchers = [a for a in agents if a != BOUND_AGENT]
    shares, from_rule, below = [], [], []
    for c in cells:
        bound, greedy = _seed_means(jobs, c, BOUND_AGENT, "bound"), _seed_means(jobs, c, "greedy")
        gaps = [gap_share(greedy, _seed_means(jobs, c, a), bound, rng) for a in others]
        shares.append([*labels[c], format_stat(seed_interval(bound.values())), *map(_share_text, gaps)])
        rule = strongest_rule(jobs, c)
        if rule is not None:
            to_plan, to_proven = to_bound(jobs, c, rule, proven=False), to_bound(jobs, c, rule)
            gap = (gaps[others.index(rule)] if rule in others
                   else gap_share(greedy, _seed_means(jobs, c, rule), bound, rng))  # fmt: skip
            from_rule.append([
                *labels[c], rule, format_stat(seed_interval(_seed_means(jobs, c, rule).values())),
                paired_cell(to_plan) if to_plan else "—", paired_cell(to_proven) if to_proven else "—",
                f"{1.0 - gap.share:.2f}" if gap.room else _share_text(gap),
            ])  # fmt: skip
        below.append([*labels[c], *(_below_text(*below_bound(jobs, c, a)) for a in dispatchers),
                      _below_text(*below_bound(jobs, c, BOUND_AGENT))])  # fmt: skip
    return [
        "## Room: the clairvoyant bound and the share of the greedy -> bound gap closed (guided EVs)",
        "",
        f"bound: the solver's proven lower bound of the planner's model ({BOUND_AGENT} jobs; s, mean over "
        "seeds [95% Student-t interval]); its played plan is the column "
        f"`{BOUND_AGENT}` above. Per dispatcher (G - A) / (G - B) of the seed means, G greedy, B the bound "
        f"[95% paired bootstrap interval over seeds]; *no room*: G - B below {MIN_GAP_S:g} s or its interval "
        "includes 0.",
        "",
        *markdown_table([*head, "bound (s)", *others], shares),
        "",
        "## From the strongest rule to the bound (s per guided EV)",
        "",
        "The rule with the lowest mean in each cell; its mean (s, over seeds [95% t interval]); rule - "
        "played plan and rule - proven bound, paired by episode within each seed, then over seeds [95% t "
        "interval] n=seeds; rule faster / other faster of the episodes; left: the share of the greedy -> "
        "bound gap the rule leaves, 1 - (G - R) / (G - B).",
        "",
        *markdown_table([*head, "rule", "rule (s)", "rule - played plan", "rule - bound", "left"], from_rule),
        "",
        "## Below the bound",
        "",
        "Per dispatcher, the episodes on which its guided EVs' mean travel time was below that episode's "
        "proven bound (of the episodes compared; by how much at most). The bound is one of the model, not "
        "of SUMO: the model's drive times are the routes' estimates at each request, and a dispatcher's "
        "mean leaves its truncated EVs out.",
        "",
        *markdown_table([*head, *dispatchers, f"{BOUND_AGENT} (played plan)"], below),
        "",
    ]
