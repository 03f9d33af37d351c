"""The rule as a learner's starting point: a Q-value that is the rule's estimate turned into a return,
plus a learned correction that starts at zero (``DQNConfig.rule_prior``).

    q = RulePriorQ(correction, n_stations=5, reads_estimate=True, slot_s=60.0, gamma=0.9, reward_scale=10.0)
    q(x)      # x: the network input with the estimate block last -> prior(estimate) + correction(x)

Under the ``"time"`` reward (minus the slot's hours, :func:`evcd.env.reward.time_reward`) an EV that
starts charging ``E`` seconds from now collects ``r = -slot_s / 3600 x reward_scale`` in each of the
``E / slot_s`` slots before, so the discounted return of driving to a station the rule estimates at
``E`` seconds is

    prior(E) = r x (1 - gamma ** (E / slot_s)) / (1 - gamma)        (r x E / slot_s when gamma = 1)

(:func:`time_return`; ``E / slot_s`` is read as a real number). Its argmax is the rule's argmin: an
untrained learner with ``rule_prior`` decides as the rule whose estimate it reads (queue_aware on the
single target, reservation counting ``Z + G`` on the fleet: :mod:`evcd.agents.rule_input`), and in turn
on the fleet it assigns a tick's EVs one after the other on that estimate, as central does. The
correction network's output layers start at zero, so learning moves the Q-values away from the rule's
only where the returns say so (a residual on a fixed baseline, as in residual policy learning, Silver
et al. 2018, here on the value).

The prior's constants (``slot_s``, ``gamma``, ``reward_scale``) are buffers of the module: a checkpoint
keeps them, so a loaded policy adds the prior it was trained with.

With a bound ``b`` (``DQNConfig.rule_prior_bound_s``) the network corrects the estimate instead of the
value: ``Q(s, a) = prior(max(0, E_a + b tanh(c(s)[a])))``, the rule's seconds moved at most ``b``
either way. An additive correction of a few tenths reorders stations the discount has squeezed
together (at ``gamma`` 0.9 a station 20 minutes from charging and one 40 minutes away differ by 0.18);
in seconds, a correction cannot send an EV to a queue the rule puts more than ``2 b`` longer.

The bounded correction can also learn one shift for every station: where the rule's estimate is
biased (every station reached sooner than it says), bootstrapped targets push all corrections to
``-b`` together (measured: docs/PERTURBED.md "Corrections that saturate"). The shift alone keeps the
rule's order, but with the floor at 0 every station the rule puts within ``b`` seconds ties at 0 and
the lowest index wins. With ``relative`` (``DQNConfig.rule_prior_relative``) the network moves each
station by its correction less their mean, ``Q(s, a) = prior(E_a + b tanh(c_a - mean(c)))``, without
the floor (``prior`` of negative seconds is a return above 0, still in order): a correction of every
station alike is none, so the bound is spent on the stations' order.
"""

from __future__ import annotations

from typing import Any

import torch
from torch import nn

from evcd.agents.rule_input import ESTIMATE_UNIT_S

#: the reward shape whose return the prior is (:data:`evcd.env.reward.REWARDS`)
PRIOR_REWARD = "time"


def time_return(seconds: torch.Tensor, slot_s: float, gamma: float, reward_scale: float) -> torch.Tensor:
    """The discounted return of ``seconds`` to the start of charging under the ``"time"`` reward scaled
    by ``reward_scale``, with one reward per slot of ``slot_s`` seconds discounted by ``gamma``."""
    per_slot = -slot_s / 3600.0 * reward_scale
    slots = seconds / slot_s
    if gamma >= 1.0:
        return per_slot * slots
    return per_slot * (1.0 - torch.pow(torch.as_tensor(gamma, dtype=seconds.dtype), slots)) / (1.0 - gamma)


def zero_output_layers(net: nn.Module) -> None:
    """Zero the weights and biases of ``net``'s output layers (its direct ``Linear`` children: the
    Q head, or the value and advantage heads), so that it outputs 0 for every input until trained."""
    with torch.no_grad():
        for child in net.children():
            if isinstance(child, nn.Linear):
                child.weight.zero_()
                child.bias.zero_()


class RulePriorQ(nn.Module):
    """``Q(x, a) = prior(E_a) + correction(x)[a]``: the rule's estimate as a return plus a network.

    Args:
        correction: the Q-network whose output is added to the prior (its output layers are zeroed
            here). It reads the whole input if ``reads_estimate``, else the input without the estimate.
        n_stations: stations (the estimate block's length, the input's last ``n_stations`` values, in
            :data:`~evcd.agents.rule_input.ESTIMATE_UNIT_S`).
        reads_estimate: whether the correction also reads the estimate block (``rule_estimate``).
        slot_s: the decision interval (s): one reward per slot.
        gamma: the learner's discount.
        reward_scale: the learner's reward scale.
        bound_s: ``None`` (the network's output is added to the prior) or the most seconds the
            network's correction moves the estimate either way (``prior(E + bound_s tanh(c))``).
        relative: with ``bound_s``, each station's correction less the stations' mean, without the
            floor at 0 (module docstring).

    Raises:
        ValueError: ``slot_s`` or ``bound_s`` not above 0, or ``gamma`` outside (0, 1].
    """

    def __init__(
        self,
        correction: nn.Module,
        n_stations: int,
        reads_estimate: bool,
        slot_s: float,
        gamma: float,
        reward_scale: float,
        bound_s: float | None = None,
        relative: bool = False,
    ) -> None:
        super().__init__()
        if not slot_s > 0:
            raise ValueError(f"rule_prior: decision_interval={slot_s!r} must be > 0 (seconds per slot)")
        if bound_s is not None and not bound_s > 0:
            raise ValueError(f"rule_prior_bound_s={bound_s!r} must be > 0 (seconds) or None")
        if relative and bound_s is None:
            raise ValueError("rule_prior_relative=True centres the bounded correction: give bound_s")
        if not 0.0 < gamma <= 1.0:
            raise ValueError(f"rule_prior: gamma={gamma!r} must be in (0, 1]")
        zero_output_layers(correction)
        self.correction = correction
        self.n_stations = int(n_stations)
        self.reads_estimate = bool(reads_estimate)
        self.register_buffer("slot_s", torch.tensor(float(slot_s)))
        self.register_buffer("gamma", torch.tensor(float(gamma)))
        self.register_buffer("reward_scale", torch.tensor(float(reward_scale)))
        #: the correction's bound in estimate units (the checkpoint's config holds it: not saved here)
        self.bound = None if bound_s is None else float(bound_s) / ESTIMATE_UNIT_S
        self.relative = bool(relative)

    def prior(self, estimate: torch.Tensor) -> torch.Tensor:
        """The prior Q-values ``(..., m)`` of the estimate block (in ``ESTIMATE_UNIT_S``)."""
        return time_return(estimate * ESTIMATE_UNIT_S, float(self.slot_s), float(self.gamma),
                           float(self.reward_scale))  # fmt: skip

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        """Q-values ``(batch, m)`` of inputs ``x`` whose last ``m`` values are the estimate block."""
        estimate = x[..., -self.n_stations :]
        seen = x if self.reads_estimate else x[..., : -self.n_stations]
        if self.bound is None:
            return self.prior(estimate) + self.correction(seen)
        c = self.correction(seen)
        if self.relative:
            return self.prior(estimate + self.bound * torch.tanh(c - c.mean(dim=-1, keepdim=True)))
        return self.prior(torch.clamp(estimate + self.bound * torch.tanh(c), min=0.0))


def prior_network(
    net: nn.Module, n_stations: int, config: Any, decision_interval: float | None, reward: object
) -> RulePriorQ:
    """``net`` as the correction of a :class:`RulePriorQ` for a learner of ``config`` (a
    :class:`~evcd.agents.dqn_config.DQNConfig`: its ``rule_estimate``, ``gamma``, ``reward_scale``,
    ``rule_prior_bound_s``, ``rule_prior_relative``) in an environment of ``decision_interval`` seconds
    per slot and reward ``reward``.

    Raises:
        ValueError: ``reward`` is not :data:`PRIOR_REWARD` (the prior is that reward's return), or no
            ``decision_interval`` is known.
    """
    if reward != PRIOR_REWARD:
        raise ValueError(f"rule_prior=True with reward={reward!r}: the prior is the return of the "
                         f"{PRIOR_REWARD!r} reward (env.reward={PRIOR_REWARD}, as in experiment=peak and "
                         "the fleet); build the agent for its environment (make_agent_for_env) or pass "
                         f"reward={PRIOR_REWARD!r} and decision_interval")  # fmt: skip
    if decision_interval is None:
        raise ValueError("rule_prior=True needs the environment's decision_interval (seconds per slot): "
                         "build the agent for its environment (make_agent_for_env) or pass it")  # fmt: skip
    return RulePriorQ(net, n_stations, config.rule_estimate, float(decision_interval), config.gamma,
                      config.reward_scale, config.rule_prior_bound_s, config.rule_prior_relative)  # fmt: skip
