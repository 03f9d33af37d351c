"""Statistics across seeds: a mean with its Student-t interval, and the share of a gap an agent closes.

    stat = seed_interval([402.0, 396.5, 410.2])  # SeedStat(mean, low, high, n)

- :func:`seed_interval`: the mean of one value per seed with its 95% interval across seeds (Student t,
  n - 1 degrees of freedom). The t quantile is computed here (:func:`t_quantile`, exact for integer
  degrees of freedom; no scipy).
- :func:`gap_share`: the share ``(G - A) / (G - H)`` of the greedy -> hindsight gap an agent closes,
  from the seed means, with a paired bootstrap interval over seeds (all agents of a seed are evaluated
  on the same episodes).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np

#: Level of every interval.
LEVEL = 0.95
#: Below this greedy - hindsight difference (s) there is no gap to close.
MIN_GAP_S = 1.0


@dataclass(frozen=True)
class SeedStat:
    """Mean over seeds with its Student-t interval (NaN bounds for fewer than 2 values)."""

    mean: float
    low: float
    high: float
    n: int


@dataclass(frozen=True)
class GapShare:
    """Share of the greedy -> hindsight gap an agent closes, over the seeds all three have.

    Attributes:
        share: ``(G - A) / (G - H)`` of the seed means (NaN without room).
        low, high: its paired bootstrap interval over seeds.
        gap: ``G - H`` over seeds (paired by seed) with its t interval.
        room: ``G - H`` is at least :data:`MIN_GAP_S` and its interval excludes 0.
    """

    share: float
    low: float
    high: float
    gap: SeedStat
    room: bool


# ---------------------------------------------------------------------------------------- Student t
def _t_central(theta: float, df: int) -> float:
    """P(|T| < sqrt(df) tan(theta)) for T ~ Student t with integer ``df`` (finite series in cos(theta))."""
    c2 = math.cos(theta) ** 2
    if df % 2 == 0:
        term = total = 1.0
        for k in range(1, df // 2):
            term *= (2 * k - 1) / (2 * k) * c2
            total += term
        return math.sin(theta) * total
    total = 0.0
    if df > 1:
        term = total = math.cos(theta)
        for k in range(1, (df - 1) // 2):
            term *= (2 * k) / (2 * k + 1) * c2
            total += term
    return 2.0 / math.pi * (theta + math.sin(theta) * total)


def _check_df(df: int) -> int:
    if isinstance(df, bool) or int(df) != df or df < 1:
        raise ValueError(f"df={df!r}: must be an integer >= 1")
    return int(df)


def t_cdf(t: float, df: int) -> float:
    """The CDF of Student's t with ``df`` (integer >= 1) degrees of freedom at ``t``."""
    df = _check_df(df)
    central = _t_central(math.atan(abs(t) / math.sqrt(df)), df)
    return 0.5 + math.copysign(0.5 * central, t)


def t_quantile(p: float, df: int) -> float:
    """The ``p`` quantile of Student's t with ``df`` (integer >= 1) degrees of freedom.

    Exact up to float precision: bisection on the angle of the closed-form CDF series for integer
    degrees of freedom. ``t_quantile(0.975, 4)`` is 2.776.

    Raises:
        ValueError: ``p`` outside (0, 1) or ``df`` not an integer >= 1.
    """
    if not 0.0 < p < 1.0:
        raise ValueError(f"p={p!r}: must be in (0, 1)")
    df = _check_df(df)
    if p < 0.5:
        return -t_quantile(1.0 - p, df)
    target, lo, hi = 2.0 * p - 1.0, 0.0, math.pi / 2
    for _ in range(200):
        mid = 0.5 * (lo + hi)
        if mid in (lo, hi):
            break
        if _t_central(mid, df) < target:
            lo = mid
        else:
            hi = mid
    return math.sqrt(df) * math.tan(0.5 * (lo + hi))


# ---------------------------------------------------------------------------------------- across seeds
def seed_interval(values: Iterable[float], level: float = LEVEL) -> SeedStat:
    """Mean of the finite ``values`` with its Student-t interval (n - 1 degrees of freedom)."""
    x = np.array([v for v in values if math.isfinite(v)], dtype=np.float64)
    if x.size == 0:
        return SeedStat(math.nan, math.nan, math.nan, 0)
    mean = float(x.mean())
    if x.size < 2:
        return SeedStat(mean, math.nan, math.nan, 1)
    half = t_quantile(0.5 + level / 2, x.size - 1) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return SeedStat(mean, mean - half, mean + half, int(x.size))


def gap_share(
    greedy: Mapping[int, float],
    agent: Mapping[int, float],
    hindsight: Mapping[int, float],
    rng: np.random.Generator,
    resamples: int = 10_000,
    level: float = LEVEL,
) -> GapShare:
    """The share of the greedy -> hindsight gap ``agent`` closes (each argument: seed -> mean travel time).

    Only seeds with a finite value for all three enter. The interval is a paired percentile bootstrap:
    seeds are resampled with replacement and the share recomputed from the resampled means (resamples
    whose ``G - H`` is not positive have no share and are left out).
    """
    seeds = sorted(s for s in set(greedy) & set(agent) & set(hindsight)
                   if all(math.isfinite(m[s]) for m in (greedy, agent, hindsight)))  # fmt: skip
    g, a, h = (np.array([m[s] for s in seeds], dtype=np.float64) for m in (greedy, agent, hindsight))
    gap = seed_interval(g - h, level)
    includes_zero = gap.n >= 2 and gap.low <= 0.0 <= gap.high
    room = gap.n > 0 and gap.mean >= MIN_GAP_S and not includes_zero
    if not room:
        return GapShare(math.nan, math.nan, math.nan, gap, False)
    share = float((g.mean() - a.mean()) / (g.mean() - h.mean()))
    if len(seeds) < 2:
        return GapShare(share, math.nan, math.nan, gap, True)
    idx = rng.integers(len(seeds), size=(resamples, len(seeds)))
    gb, ab, hb = g[idx].mean(axis=1), a[idx].mean(axis=1), h[idx].mean(axis=1)
    ok = gb - hb > 0
    shares = (gb[ok] - ab[ok]) / (gb[ok] - hb[ok])
    alpha = (1.0 - level) / 2
    lo, hi = np.quantile(shares, [alpha, 1.0 - alpha]) if shares.size else (math.nan, math.nan)
    return GapShare(share, float(lo), float(hi), gap, True)
