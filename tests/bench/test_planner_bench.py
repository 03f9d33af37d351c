"""The planner benchmark on the grid: each limit's solve times and proven gaps come from real solves
of episodes read in SUMO, and a bad limit is refused before SUMO starts."""

from __future__ import annotations

import math

import pytest

from evcd.bench.planner import TABLE_EPISODES, planner_cost
from tests.conftest import FLEET_DEMAND, FLEET_WINDOW


@pytest.mark.slow
def test_planner_cost_on_the_grid(grid_env_dir, env_cache) -> None:
    kwargs = {"scenario": grid_env_dir, "cache_dir": env_cache, "demand": FLEET_DEMAND,
              "departure_window": FLEET_WINDOW, "guided_share": 1.0}  # fmt: skip
    out = planner_cost(kwargs, episodes=1, time_limits=(0.01, 5.0))
    rows = out["episodes"]
    assert [r["time_limit_s"] for r in rows] == [0.01, 5.0] and rows[0]["guided"] >= 10
    assert rows[0]["read_s"] == rows[1]["read_s"] > 0  # one reading, both limits solve its problem
    short, long = out["limits"]["0.01"], out["limits"]["5.0"]
    assert long["no_plan"] == 0  # the long search finds a plan: a proven bound lies below it
    assert rows[1]["bound"] <= rows[1]["model"] + 1e-6
    assert rows[1]["gap"] == pytest.approx((rows[1]["model"] - rows[1]["bound"]) / rows[1]["model"])
    if short["no_plan"] == 0:  # more search never proves less
        assert long["gap_max"] <= short["gap_max"] + 1e-9
    else:  # a search too short to find a plan is counted, not averaged in
        assert math.isnan(rows[0]["gap"]) and math.isnan(short["gap_median"])
    per_episode = 2 * out["read_s_median"] + long["solve_s_median"]
    assert long["bound_column_minutes"] == pytest.approx(per_episode * TABLE_EPISODES / 2 / 60)


def test_a_bad_limit_is_refused_before_sumo(tmp_path) -> None:
    with pytest.raises(ValueError, match="time_limit_s"):
        planner_cost({"scenario": tmp_path / "no-such-scenario"}, time_limits=(0.0,))
