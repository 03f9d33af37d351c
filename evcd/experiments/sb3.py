"""stable-baselines3 on the batched engine: the sweep vector environment behind SB3's ``VecEnv``.

    from evcd.experiments import make_sweep_env
    from evcd.experiments.sb3 import SB3VecEnv
    venv = SB3VecEnv(make_sweep_env(16, experiment="peak", split="train"))
    PPO("MlpPolicy", venv).learn(50_000)

Needs the optional extra ``pip install -e ".[sb3]"`` (this module is the only one that imports
stable-baselines3). SB3's conventions are the sweep's own (``SAME_STEP`` autoreset): a done
sub-environment's step returns the next episode's first observation, the last one in
``info["terminal_observation"]``; an episode cut by the window's end or truncated by the episode's
rules has ``info["TimeLimit.truncated"] = True`` (SB3 bootstraps it), and every ended episode's
``reason`` and ``travel_time`` are in its info.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from stable_baselines3.common.vec_env.base_vec_env import VecEnv

from evcd.env.sweep import SweepVectorEnv


class SB3VecEnv(VecEnv):
    """SB3's ``VecEnv`` over a :class:`~evcd.env.sweep.SweepVectorEnv` (module docstring).

    Args:
        venv: the sweep vector environment; closing this closes it.
    """

    def __init__(self, venv: SweepVectorEnv) -> None:
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None

    def reset(self) -> np.ndarray:
        """A new sweep (seeded by :meth:`seed`'s first seed, if one was given)."""
        seed = self._seeds[0] if self._seeds else None
        obs, _ = self.venv.reset(seed=seed)
        self._reset_seeds()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        """Keep the actions for :meth:`step_wait`."""
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        """One vector step: observations, rewards, dones and per-sub-environment infos."""
        if self._actions is None:
            raise RuntimeError("step_async must come before step_wait")
        obs, rewards, terminated, truncated, infos = self.venv.step(self._actions)
        self._actions = None
        dones = terminated | truncated
        out: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            final = infos["final_info"]
            out[i] = {"terminal_observation": infos["final_obs"][i],
                      "TimeLimit.truncated": bool(truncated[i]), "reason": final["reason"][i],
                      "travel_time": float(final["travel_time"][i])}  # fmt: skip
        return obs, rewards.astype(np.float32), dones, out

    def close(self) -> None:
        """Close the sweep's simulation."""
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """The sweep's attribute, once per sub-environment asked for."""
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        """Set an attribute of the sweep (shared by every sub-environment)."""
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args: Any, indices: Any = None, **method_kwargs: Any
    ) -> list[Any]:
        """Call a method of the sweep, once per sub-environment asked for."""
        method = getattr(self.venv, method_name)
        return [method(*method_args, **method_kwargs) for _ in self._get_indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        """No sub-environment is a wrapped Gymnasium env."""
        return [False] * len(self._get_indices(indices))

    def _get_indices(self, indices: Any) -> Sequence[int]:
        if indices is None:
            return range(self.num_envs)
        if isinstance(indices, int):
            return [indices]
        return list(indices)
