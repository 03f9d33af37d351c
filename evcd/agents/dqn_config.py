"""The hyperparameters of the DQN agent, declared once.

:class:`DQNConfig` is the one declaration: :class:`~evcd.agents.dqn.DQNAgent` takes it whole, and
Hydra's ``learner`` block is built from it as a structured config (``conf/learner/*.yaml`` extend it,
:mod:`evcd.experiments.schema`), so a key that is not a field, or a value of the wrong type, is refused when
the config is composed, and a value out of range when the agent is made.
"""

from __future__ import annotations

from dataclasses import dataclass, fields

from evcd.agents.networks import NETWORKS, check_hidden
from evcd.utils.validation import check_bool, check_choice, check_int, check_real

LOSSES = ("mse", "huber")
EXPLORATIONS = ("slot", "episode")


@dataclass(frozen=True)
class DQNConfig:
    """A DQN agent's hyperparameters; validated on creation (``ValueError`` naming the value).

    Attributes:
        hidden: hidden layer sizes of the MLP trunk.
        network: ``"mlp"`` (the paper's: one MLP reads the whole observation) or ``"station"`` (one
            trunk shared by the stations scores each from its own features and its index,
            :class:`~evcd.agents.networks.StationQNetwork`).
        lr: Adam learning rate (at the first gradient step) ...
        lr_end: ... moving linearly to this over ``lr_decay_steps`` gradient steps, then staying
            (``None``: ``lr`` throughout).
        lr_decay_steps: the length of that schedule, in gradient steps.
        batch_size: transitions per gradient step.
        buffer_size: replay capacity (transitions).
        gamma: discount per decision slot.
        n_step: rewards summed per stored transition (n-step returns; 1: one-step Q-learning).
        learning_starts: transitions stored before the first gradient step.
        train_freq: a round of learning every this many transitions.
        gradient_steps: gradient steps per round.
        target_update: gradient steps between target-network updates.
        tau: target update ``target <- tau * online + (1 - tau) * target``; 1 is a hard copy.
        epsilon_start: exploration rate at the first transition ...
        epsilon_end: ... moving linearly to this ...
        exploration_steps: ... over this many transitions.
        exploration: ``"slot"`` (an epsilon-greedy draw at every decision, the textbook form) or
            ``"episode"`` (one draw per episode: with probability epsilon the whole episode drives to
            one random station, like the Random baseline, instead of zig-zagging).
        alpha: priority exponent of the prioritized replay (0: uniform replay).
        beta_start: importance-sampling exponent at the first transition, annealed linearly to 1 ...
        beta_steps: ... over this many transitions.
        priority_eps: added to ``|TD error|`` so that no priority is zero.
        loss: ``"mse"`` (the paper's) or ``"huber"``; both weighted by the importance weights.
        max_grad_norm: clip the gradient's global norm to this (``None``: no clipping).
        reward_scale: rewards are multiplied by this before learning (the paper's reward reaches
            tens; a scale keeps the regression targets near 1).
        in_turn: the fleet only (``[D, N, Z, H]``): the EVs of one tick decide one after the other,
            in order of their best Q-value (the soonest expected charge first), each on its
            observation corrected for the stations chosen before it (:mod:`evcd.agents.in_turn`);
            ``False``: side by side on the tick's observations.
        rule_estimate: the network also reads, per station, the rule's estimated seconds to the start
            of charging computed from the observation (queue_aware's; reservation's on the fleet), one
            more block (:mod:`evcd.agents.rule_input`); needs the stations' points.
        rule_prior: the Q-value is that estimate turned into the discounted return of the ``"time"``
            reward plus the network's output, which starts at zero (:mod:`evcd.agents.rule_prior`):
            the untrained learner decides as the rule; needs the stations' points.
        rule_prior_bound_s: with ``rule_prior``, the network corrects the rule's estimate in seconds
            instead of adding to the Q-value: ``Q = prior(E + b tanh(c))`` with ``b`` this bound, so a
            station's estimate moves at most ``b`` seconds either way (the learner can reorder the
            stations the rule puts within ``2 b`` of each other, never send an EV to a queue the rule
            puts far longer). ``None``: the additive correction.
        rule_prior_relative: with ``rule_prior_bound_s``, each station's estimate moves by its
            correction less the stations' mean, without the floor at 0 s: a correction of every
            station alike (what a biased estimate teaches) is none (:mod:`evcd.agents.rule_prior`).
        switch_margin_s: an EV already sent to a station (or waiting in its car park) keeps it unless
            another station's Q-value, read as seconds to the start of charging under the ``"time"``
            reward (:func:`evcd.agents.switching.return_seconds`), is more than this many seconds
            sooner; 0 (default): the greedy station. The fleet rules' margin
            (:mod:`evcd.agents.switching`); a checkpoint keeps it as how its policy decides, and a
            policy loads with another margin (``+agent.switch_margin_s``). Needs the ``"time"`` reward.
    """

    hidden: tuple[int, ...] = (512, 256)
    network: str = "mlp"
    lr: float = 1e-3
    lr_end: float | None = None
    lr_decay_steps: int = 10_000
    batch_size: int = 32
    buffer_size: int = 10_000
    gamma: float = 0.99
    n_step: int = 1
    learning_starts: int = 100
    train_freq: int = 1
    gradient_steps: int = 1
    target_update: int = 8000
    tau: float = 1.0
    epsilon_start: float = 1.0
    epsilon_end: float = 0.1
    exploration_steps: int = 1000
    exploration: str = "slot"
    alpha: float = 0.6
    beta_start: float = 0.4
    beta_steps: int = 1000
    priority_eps: float = 1e-6
    loss: str = "mse"
    max_grad_norm: float | None = 10.0
    reward_scale: float = 1.0
    in_turn: bool = False
    rule_estimate: bool = False
    rule_prior: bool = False
    rule_prior_bound_s: float | None = None
    rule_prior_relative: bool = False
    switch_margin_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "hidden", check_hidden(self.hidden))
        for key in ("batch_size", "buffer_size", "train_freq", "gradient_steps", "target_update", "n_step"):
            check_int(key, getattr(self, key), minimum=1)
        for key in ("learning_starts", "exploration_steps", "beta_steps", "lr_decay_steps"):
            check_int(key, getattr(self, key), minimum=0)
        if self.buffer_size < self.batch_size:
            raise ValueError(f"buffer_size={self.buffer_size} < batch_size={self.batch_size}: the buffer "
                             "must hold at least one batch")  # fmt: skip
        for key in ("lr", "reward_scale", "priority_eps"):
            check_real(key, getattr(self, key), low=0.0, low_open=True)
        for key in ("gamma", "epsilon_start", "epsilon_end", "alpha", "beta_start"):
            check_real(key, getattr(self, key), low=0.0, high=1.0)
        check_real("tau", self.tau, low=0.0, high=1.0, low_open=True)
        check_choice("network", self.network, NETWORKS)
        check_choice("exploration", self.exploration, EXPLORATIONS)
        check_choice("loss", self.loss, LOSSES)
        check_bool("in_turn", self.in_turn)
        check_bool("rule_estimate", self.rule_estimate)
        check_bool("rule_prior", self.rule_prior)
        if self.rule_prior_bound_s is not None:
            check_real("rule_prior_bound_s", self.rule_prior_bound_s, low=0.0, low_open=True)
            if not self.rule_prior:
                raise ValueError(f"rule_prior_bound_s={self.rule_prior_bound_s!r} bounds the correction of "
                                 "rule_prior: set rule_prior=true, or leave it null")  # fmt: skip
        check_bool("rule_prior_relative", self.rule_prior_relative)
        if self.rule_prior_relative and self.rule_prior_bound_s is None:
            raise ValueError("rule_prior_relative=true centres the bounded correction of rule_prior: set "
                             "rule_prior_bound_s (seconds), or leave it false")  # fmt: skip
        check_real("switch_margin_s", self.switch_margin_s, low=0.0)
        if self.lr_end is not None:
            check_real("lr_end", self.lr_end, low=0.0, low_open=True)
        if self.max_grad_norm is not None:
            check_real("max_grad_norm", self.max_grad_norm, low=0.0, low_open=True)

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """The hyperparameters' names."""
        return tuple(f.name for f in fields(cls))


def linear_schedule(start: float, end: float, steps: int, t: int) -> float:
    """``start`` moving linearly to ``end`` over ``steps`` steps, then ``end`` (``steps = 0``: ``end``)."""
    if steps <= 0 or t >= steps:
        return float(end)
    return float(start + (end - start) * t / steps)
