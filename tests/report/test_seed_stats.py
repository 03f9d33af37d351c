"""evcd.report.seed_stats: the Student t quantile against tables and a numerical integral, the interval across
seeds and the gap share against hand computations."""

from __future__ import annotations

import math
import statistics

import numpy as np
import pytest

from evcd.report.seed_stats import gap_share, seed_interval, t_cdf, t_quantile

T_0975_4 = 2.7764451051977987  # Student t, 97.5% quantile, 4 degrees of freedom
SEEDS = (0, 1, 2, 3, 4)
#: seed s adds SPREAD[s] to every agent: the agents' differences are the same in every seed
SPREAD = (-10.0, -5.0, 0.0, 5.0, 10.0)
#: per-seed noise (summing to 0) on an agent: its gap share gets a real interval
NOISE = (12.0, -7.0, 3.0, -15.0, 7.0)
#: per-seed noise of a few tenths of a second on greedy: the greedy - hindsight gap includes 0
JITTER = (0.5, -0.3, 0.2, 0.1, -0.4)


# ---------------------------------------------------------------------------------------- t quantile
@pytest.mark.parametrize(
    ("p", "df", "expected"),
    [(0.975, 1, 12.7062047362), (0.975, 2, 4.3026527297), (0.975, 3, 3.1824463053), (0.975, 4, T_0975_4),
     (0.975, 5, 2.5705818366), (0.975, 10, 2.2281388520), (0.975, 30, 2.0422724563),
     (0.975, 100, 1.9839715185), (0.995, 4, 4.6040948714), (0.9, 7, 1.4149239277),
     (0.025, 4, -T_0975_4), (0.5, 3, 0.0)],
)  # fmt: skip
def test_t_quantile_matches_tables(p, df, expected):
    assert t_quantile(p, df) == pytest.approx(expected, abs=1e-8)


def test_t_quantile_tends_to_the_normal():
    assert t_quantile(0.975, 20_000) == pytest.approx(1.959964, abs=2e-4)


@pytest.mark.parametrize("df", [1, 2, 3, 6, 9, 25])
def test_t_cdf_agrees_with_integrating_the_density(df):
    """The closed-form series against a naive trapezoid integral of the t density."""
    log_c = math.lgamma((df + 1) / 2) - math.lgamma(df / 2) - 0.5 * math.log(df * math.pi)
    x = np.linspace(0.0, 6.0, 600_001)
    density = np.exp(log_c - (df + 1) / 2 * np.log1p(x**2 / df))
    integral = np.concatenate([[0.0], np.cumsum((density[1:] + density[:-1]) / 2 * np.diff(x))])
    for t in (0.3, 1.0, 2.0, 4.5, 6.0):
        assert t_cdf(t, df) == pytest.approx(0.5 + integral[np.searchsorted(x, t)], abs=1e-7)
        assert t_cdf(-t, df) == pytest.approx(1.0 - t_cdf(t, df), abs=1e-12)
    for p in (0.6, 0.9, 0.975, 0.999):
        assert t_cdf(t_quantile(p, df), df) == pytest.approx(p, abs=1e-12)


@pytest.mark.parametrize(("p", "df"), [(0.0, 3), (1.0, 3), (0.9, 0), (0.9, 2.5), (0.9, True)])
def test_t_quantile_rejects_bad_arguments(p, df):
    with pytest.raises(ValueError):
        t_quantile(p, df)


def test_seed_interval():
    values = [390.0, 395.0, 400.0, 405.0, 410.0]
    stat = seed_interval(values)
    half = T_0975_4 * statistics.stdev(values) / math.sqrt(5)
    assert (stat.mean, stat.n) == (400.0, 5)
    assert (stat.low, stat.high) == pytest.approx((400.0 - half, 400.0 + half))
    one = seed_interval([7.0, math.nan])  # NaN (all episodes truncated) is left out
    assert one.mean == 7.0 and one.n == 1 and math.isnan(one.low)
    assert seed_interval([]).n == 0


# ---------------------------------------------------------------------------------------- gap share
def test_gap_share_half_way():
    rng = np.random.default_rng(0)
    g = {s: 400.0 + SPREAD[s] for s in SEEDS}
    a = {s: 300.0 + SPREAD[s] for s in SEEDS}
    h = {s: 200.0 + SPREAD[s] for s in SEEDS}
    share = gap_share(g, a, h, rng, resamples=500)
    assert share.room and share.share == pytest.approx(0.5)
    # the same gap and the same improvement in every seed: every resample gives 0.5
    assert (share.low, share.high) == pytest.approx((0.5, 0.5))
    assert share.gap.mean == pytest.approx(200.0) and share.gap.n == 5


def test_gap_share_interval_from_a_paired_bootstrap():
    g = {s: 400.0 + SPREAD[s] for s in SEEDS}
    a = {s: 250.0 + SPREAD[s] + NOISE[s] for s in SEEDS}
    h = {s: 200.0 + SPREAD[s] for s in SEEDS}
    share = gap_share(g, a, h, np.random.default_rng(1), resamples=4000)
    expected = (statistics.fmean(g.values()) - statistics.fmean(a.values())) / 200.0
    assert share.share == pytest.approx(expected) == pytest.approx(0.75)
    assert share.low < expected < share.high
    # seed noise of a few seconds on a 200 s gap: the interval is narrow
    assert share.low > 0.6 and share.high < 0.9


def test_gap_share_no_room():
    g = {s: 500.0 + SPREAD[s] + JITTER[s] for s in SEEDS}
    h = {s: 500.0 + SPREAD[s] for s in SEEDS}
    a = {s: 480.0 + SPREAD[s] for s in SEEDS}
    share = gap_share(g, a, h, np.random.default_rng(0))
    assert not share.room and math.isnan(share.share)
    assert share.gap.low <= 0.0 <= share.gap.high
    # a clear but sub-second gap: no room either
    tiny = gap_share({s: 200.5 for s in SEEDS}, a, {s: 200.0 for s in SEEDS}, np.random.default_rng(0))
    assert not tiny.room
