"""The hyperparameters of the PPO learner (:class:`PPOConfig`), declared once: the agent's Hydra block
(``agent=ppo``, ``agent.<field>=...``) is made from these defaults (:mod:`evcd.experiments.schema`).

The defaults were chosen for the default regime (``experiment=peak``: the ``time`` reward, minus
hours per slot) on its tuning seed 100 and tuning days 2 and 5 only, among seven candidates, and
checked on tuning seed 101 (docs/guide/reproduce-the-paper.md, "PPO"; the tuning table is in
docs/NOTES.md): the station network, lr 1e-3, rollouts of 128 transitions, 10 epochs of minibatches
of 32.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from evcd.agents.networks import NETWORKS, check_hidden
from evcd.utils.validation import check_bool, check_choice, check_int, check_real


@dataclass(frozen=True)
class PPOConfig:
    """PPO's settings (Schulman et al. 2017, the clipped objective; GAE of Schulman et al. 2016).

    Attributes:
        hidden: layer sizes of the policy's and the value's networks (one each).
        network: the policy's network, ``"mlp"`` or ``"station"`` (one trunk scoring every station
            from its own features: :class:`~evcd.agents.networks.StationQNetwork`); the value's is an MLP.
        lr: Adam's learning rate (both networks).
        rollout_steps: transitions of whole episodes gathered before an update (an update follows the
            episode that brings the rollout to at least this many).
        epochs: passes over the rollout per update.
        minibatch_size: transitions per gradient step.
        gamma: discount per decision.
        gae_lambda: the GAE parameter (1: Monte Carlo returns; 0: one-step TD).
        clip: the ratio's clipping range ``[1 - clip, 1 + clip]``.
        value_coef: weight of the value loss ``0.5 (V - R)^2``.
        entropy_coef: weight of the entropy bonus.
        max_grad_norm: gradient-norm clipping.
        normalize_advantages: standardise the advantages of each minibatch.
        reward_scale: rewards are multiplied by this before learning (60 with the ``time`` reward: the
            returns in minutes, so the value loss is not negligible beside the policy's).
    """

    hidden: tuple[int, ...] = (64, 64)
    network: str = "station"
    lr: float = 1e-3
    rollout_steps: int = 128
    epochs: int = 10
    minibatch_size: int = 32
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip: float = 0.2
    value_coef: float = 0.5
    entropy_coef: float = 0.01
    max_grad_norm: float = 0.5
    normalize_advantages: bool = True
    reward_scale: float = 60.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", check_hidden(self.hidden))
        check_choice("network", self.network, NETWORKS)
        for key in ("rollout_steps", "epochs", "minibatch_size"):
            check_int(key, getattr(self, key), minimum=1)
        for key in ("lr", "clip", "max_grad_norm", "reward_scale"):
            check_real(key, getattr(self, key), low=0.0, low_open=True)
        for key in ("gamma", "gae_lambda"):
            check_real(key, getattr(self, key), low=0.0, high=1.0)
        for key in ("value_coef", "entropy_coef"):
            check_real(key, getattr(self, key), low=0.0)
        check_bool("normalize_advantages", self.normalize_advantages)

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """The hyperparameters' names."""
        return tuple(f.name for f in fields(cls))
