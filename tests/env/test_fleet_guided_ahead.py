"""The fleet's ``G`` (``observe=[..., guided_ahead]``): per station, the other guided EVs driving there
that are due before this one, on a hand-built day and along whole episodes against the definition
(the rows' own ``T``); the single target refuses it before SUMO starts."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from evcd.agents import make_agent_for_env
from evcd.env import ChargingNavEnv
from evcd.env.fleet.events import guided_ahead
from evcd.env.observation import check_layout
from tests.env.handmade import ev

FAR = "A0A1 A1B1 B1C1 C1D1"  # plans cs1 (index 0), far from cs2
NEAR = "D2C2 C2B2"  # plans cs2 (index 1), a few seconds from it


def _blocks(row: np.ndarray, m: int, letters: str = "DNZHTG") -> dict[str, np.ndarray]:
    return {c: row[i * m : (i + 1) * m] for i, c in enumerate(letters)}


def test_g_counts_the_guided_evs_due_before_this_one(make_small_fleet):
    """Two guided EVs: one far from both stations, one about to reach cs2. While each heads to its
    own station, each is due at its station before the other would be (``G`` = ``H``); once both
    are sent to cs2, the near one is ahead of the far one and not the reverse (``G`` < ``H``)."""
    env = make_small_fleet([ev("far", 5, FAR, "pa_cs1"), ev("near", 6, NEAR, "pa_cs2")],
                           observe=["route_time", "guided_ahead"])  # fmt: skip
    assert env.layout == "DNZHTG" and env.observation_space("far").shape == (12,)
    obs, _ = env.reset(seed=0)
    assert env.agents == ["far", "near"]
    far, near = _blocks(obs["far"], 2), _blocks(obs["near"], 2)
    assert far["H"].tolist() == far["G"].tolist() == [0.0, 1.0]
    assert near["H"].tolist() == near["G"].tolist() == [1.0, 0.0]
    assert near["T"][1] < far["T"][1] and far["T"][0] < near["T"][0]  # why: each is nearer its own
    obs, *_ = env.step({"far": 1, "near": 1})  # both to cs2 (1 point)
    assert env.agents == ["far", "near"] and env.simulation.controller.status("near") is None
    far, near = _blocks(obs["far"], 2), _blocks(obs["near"], 2)
    assert far["H"].tolist() == [0.0, 1.0] and far["G"].tolist() == [0.0, 1.0]
    assert near["H"].tolist() == [0.0, 1.0] and near["G"].tolist() == [0.0, 0.0]
    np.testing.assert_array_equal(env.guided["far"].obs.extra["G"], [0, 1])
    # normalised: G in multiples of the station's points, like H (cs1 has 2 points, cs2 one)
    scaled = make_small_fleet([ev("far", 5, FAR, "pa_cs1"), ev("near", 6, NEAR, "pa_cs2")],
                              observe=["guided_ahead"], normalize_obs=True)  # fmt: skip
    assert scaled.layout == "DNZHG"
    obs, _ = scaled.reset(seed=0)
    assert obs["near"][8:].tolist() == [0.5, 0.0] and obs["far"][8:].tolist() == [0.0, 1.0]


@pytest.mark.slow
def test_g_is_the_part_of_h_due_first_along_whole_episodes(make_fleet):
    """On the 8 x 8 grid's fleet, every agent's ``G`` at every tick is, per station, the other agents
    driving there whose ``T`` to it is below this one's ``T`` there; never above ``H``, below it at
    some ticks; a learner (exploring) reads the layout."""
    env = make_fleet(guided_share=1.0, observe=["route_time", "guided_ahead"], decision_interval=30.0)
    m = len(env.stations)
    learner = make_agent_for_env("dqn", env, np.random.default_rng(0))
    assert learner.layout == "DNZHTG"
    obs, _ = env.reset(seed=2)
    states: dict[str, object] = {}
    checked, below = 0, 0
    while env.agents:
        rows = {a: _blocks(obs[a], m) for a in env.agents}
        ctrl = env.simulation.controller
        driving = {a for a in env.agents if ctrl.status(a) is None}
        for a, blocks in rows.items():
            expected = np.zeros(m)
            for b in driving - {a}:
                s = env.guided[b].station
                expected[s] += rows[b]["T"][s] < blocks["T"][s]
            np.testing.assert_array_equal(blocks["G"], expected)
            assert (blocks["G"] <= blocks["H"]).all()
            below += int((blocks["G"] < blocks["H"]).any())
            checked += 1
        episodes = [states.setdefault(a, learner.new_episode(np.random.default_rng(len(states))))
                    for a in env.agents]  # fmt: skip
        stations = learner.decide(np.stack([obs[a] for a in env.agents]), episodes, explore=True)
        obs, *_ = env.step(dict(zip(env.agents, stations.tolist(), strict=True)))
    assert checked >= 50 and below >= 5, (checked, below)


def test_an_ev_not_observed_counts_as_ahead_and_none_is_ahead_of_itself():
    """:func:`guided_ahead` on its own: ``b`` (not observed at this tick) is due everywhere first;
    ``a`` is not ahead of itself; a waiting EV counts nowhere."""
    guided = {v: SimpleNamespace(station=s) for v, s in (("a", 0), ("b", 1), ("c", 0))}
    times = {"a": np.array([100.0, 50.0]), "c": np.array([0.0, 80.0])}
    out = guided_ahead(guided, {"a": True, "b": True, "c": False}, times, 2)  # type: ignore[arg-type]
    assert out["a"].tolist() == [0, 1] and out["c"].tolist() == [0, 1]


def test_the_single_target_refuses_guided_ahead_before_sumo_starts(small_scenario):
    with pytest.raises(ValueError, match=r"guided_ahead.*fleet"):
        ChargingNavEnv(scenario=small_scenario.root, observe=["guided_ahead"])
    assert check_layout("DNZHPTFG") == "DNZHPTFG"
    with pytest.raises(ValueError, match="layout 'DNZHGT'"):
        check_layout("DNZHGT")
