"""The DQN learners' policy: the Q-networks, what they read, the greedy stations, and the saved form.

    policy = QPolicy(n_stations=5, layout="DNZ", hidden=(512, 256), network="mlp", dueling=True,
                     points=2, normalized=False, seed=7)
    policy.greedy(obs)                              # argmax Q of each row of a batch (k, 3m)
    state = policy.state_dict(settings)             # networks, input scale, the learner's settings
    policy.load_state_dict(state, checked)          # refuses another network, size or format

What :class:`~evcd.agents.dqn.DQNAgent` learns and what ``scripts/evaluate.py`` loads: the online
network (which decides) and the target network (which the TD targets bootstrap from), built from one
seed inside ``torch.random.fork_rng`` so that no global random state is touched. The networks read
the observation in physical units (m, vehicles) times the input scale (:mod:`evcd.agents.inputs`):
km, tens of vehicles, multiples of the charging points. A checkpoint keeps the scale, so a loaded
policy sees what it was trained on in any environment.

A saved policy is checked before its networks are loaded: its format, its observation size and the
network settings (:data:`CHECKED_SETTINGS`); :func:`policy_settings` reads those settings back so that
a policy can be rebuilt to fit a checkpoint. A checkpoint of an earlier evcd that holds a setting
which has since left evcd (:mod:`evcd.utils.removed`) loads where that setting did nothing, and is
refused otherwise with the commit that still reads it.
"""

from __future__ import annotations

import copy
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import torch

from evcd.agents.inputs import InputScale
from evcd.agents.networks import make_q_network
from evcd.utils.checkpoint import CheckpointError, to_numpy
from evcd.utils.removed import drop_removed

#: The ``format`` of a DQN agent's state.
STATE_FORMAT = "evcd.agents.dqn/2"
#: The saved settings that decide how a policy is built, and how each is read back. A checkpoint made
#: before ``network`` existed holds the MLP.
POLICY_SETTINGS: dict[str, Any] = {"hidden": tuple, "network": str, "dueling": bool, "double": bool}
_BEFORE = {"network": "mlp"}
#: The settings a checkpoint's networks must share with the policy that loads them.
CHECKED_SETTINGS = tuple(POLICY_SETTINGS)


class QPolicy:
    """The online and target Q-networks of a DQN learner and the scale of their input.

    Args:
        n_stations: stations (actions).
        layout: the observation's blocks (``"DNZ"``, the fleet's ``"DNZH"``, with the observation
            options' letters after them).
        hidden, network, dueling: the network (:func:`~evcd.agents.networks.make_q_network`).
        points, normalized: the stations' charging points and whether the environment normalises
            its observations (:class:`~evcd.agents.inputs.InputScale`).
        seed: initialises the networks.
    """

    def __init__(
        self,
        n_stations: int,
        layout: str,
        hidden: Sequence[int],
        network: str,
        dueling: bool,
        points: int | Sequence[int] | None,
        normalized: bool,
        seed: int,
    ) -> None:
        self.n_stations = n_stations
        self.inputs = InputScale(points, n_stations, layout, normalized)
        with torch.random.fork_rng(devices=[]):
            torch.manual_seed(seed)
            self.online = make_q_network(self.inputs.size, n_stations, hidden, dueling, network)
        self.target = copy.deepcopy(self.online).requires_grad_(False)

    def q_values(self, obs: np.ndarray) -> np.ndarray:
        """The online network's Q-values for one observation ``(size,)`` or a batch ``(k, size)``."""
        with torch.no_grad():
            return self.online(self.inputs(obs)).numpy()

    def greedy(self, obs: np.ndarray) -> np.ndarray:
        """The station of highest Q-value of each row of a batch (ties to the lowest index)."""
        return self.q_values(obs).argmax(axis=-1)

    def update_target(self, tau: float) -> None:
        """``target <- tau * online + (1 - tau) * target`` (a copy when ``tau = 1``)."""
        with torch.no_grad():
            for t, o in zip(self.target.parameters(), self.online.parameters(), strict=True):
                t.copy_(o) if tau >= 1.0 else t.lerp_(o, tau)

    def state_dict(self, settings: Mapping[str, Any]) -> dict[str, Any]:
        """The networks and their input scale with the learner's ``settings`` (its hyperparameters and
        switches, :data:`POLICY_SETTINGS` among them), as a checkpoint keeps them. A snapshot: later
        training does not change it."""
        return {
            "format": STATE_FORMAT,
            "n_stations": self.n_stations,
            "config": dict(settings),
            "input_scale": torch.from_numpy(self.inputs.scale.copy()),
            "online": copy.deepcopy(self.online.state_dict()),
            "target": copy.deepcopy(self.target.state_dict()),
        }

    def load_state_dict(self, state: Any, settings: Mapping[str, Any]) -> bool:
        """Load a saved policy whose network settings are ``settings``' (:data:`CHECKED_SETTINGS`).
        The checkpoint's input scale replaces this policy's: the network keeps seeing what it was
        trained on, whatever this environment's observation units.

        Returns:
            Whether the checkpoint's input scale differs from this policy's own.

        Raises:
            CheckpointError: another format, observation size, network or setting (the message names
                it), or a removed setting the policy used.
        """
        saved = policy_settings(state)
        for key in CHECKED_SETTINGS:
            if list(np.atleast_1d(saved[key])) != list(np.atleast_1d(settings[key])):
                raise CheckpointError(f"the checkpoint's agent has {key}={saved[key]!r}; this one has "
                                      f"{key}={settings[key]!r} (use the same agent settings)")  # fmt: skip
        scale = np.asarray(to_numpy(state["input_scale"]), np.float32)
        if scale.shape != self.inputs.scale.shape:
            raise CheckpointError(
                f"the checkpoint was made for observations of size {scale.shape[0]}; this environment's "
                f"are {self.inputs.size} (layout {self.inputs.layout}: {len(self.inputs.layout)} x "
                f"{self.n_stations} stations; the observation options, env.observe, add blocks: evaluate "
                "with those it was trained with)"
            )
        other = not np.array_equal(scale, self.inputs.scale)
        try:
            self.online.load_state_dict(state["online"])
            self.target.load_state_dict(state["target"])
        except (RuntimeError, KeyError) as exc:
            raise CheckpointError(f"the checkpoint does not fit this agent: {exc}") from exc
        self.inputs.set(scale)
        return other


def policy_settings(state: Any) -> dict[str, Any]:
    """The network settings (:data:`POLICY_SETTINGS`) of a saved DQN policy, so that a policy can be
    rebuilt to load it.

    Raises:
        CheckpointError: ``state`` is not a DQN agent's state of this evcd, or its policy used a
            setting that has left evcd (one line naming it and the commit that still reads it).
    """
    found = state.get("format") if isinstance(state, Mapping) else type(state).__name__
    if found != STATE_FORMAT:
        earlier = isinstance(found, str) and found.startswith("evcd.agents.dqn/")
        why = " (an earlier evcd's: retrain with this version)" if earlier else ""
        raise CheckpointError(f"not a DQN agent state of this evcd (format {found!r}, expected "
                              f"{STATE_FORMAT!r}){why}")  # fmt: skip
    try:
        saved = {**_BEFORE, **drop_removed(state["config"], "learner.")}
    except ValueError as exc:
        raise CheckpointError(f"the checkpoint's policy: {exc}") from None
    return {key: read(saved[key]) for key, read in POLICY_SETTINGS.items()}
