"""Parallel environments: one spawned process (one libsumo) each."""

from __future__ import annotations

import numpy as np
import pytest

from evcd.env import make_vector_env
from evcd.sim.driver import SumoDriver
from tests.conftest import GRID_ENV


@pytest.mark.slow
def test_two_workers_step_independently(grid_env_dir, env_cache):
    envs = make_vector_env(2, scenario=grid_env_dir, cache_dir=env_cache, **GRID_ENV)
    try:
        obs, infos = envs.reset(seed=10)
        assert obs.shape == (2, 9) and obs.dtype == np.float32
        assert infos["departure"][0] != infos["departure"][1]  # seeds 10 and 11
        for _ in range(3):
            obs, _, _, truncated, infos = envs.step(np.array([0, 1]))
        assert obs.shape == (2, 9) and not truncated.any()
    finally:
        envs.close()
    assert SumoDriver.active() is None  # the workers held the simulations, not this process


def test_bad_arguments_fail_before_workers_start(grid_env_dir, env_cache):
    with pytest.raises(ValueError, match="protocol"):
        make_vector_env(2, scenario=grid_env_dir, cache_dir=env_cache, protocol="nope")
    with pytest.raises(ValueError, match="num_envs"):
        make_vector_env(0, scenario=grid_env_dir)
