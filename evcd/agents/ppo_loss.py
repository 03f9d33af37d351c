"""PPO's arithmetic, apart from any network: generalised advantage estimation and the clipped loss.

    advantages, returns = gae(rewards, values, bootstrap, gamma=0.99, lam=0.95)
    terms = ppo_loss(new_logp, old_logp, advantages, new_values, returns, entropy, clip=0.2)

Both are pure functions of arrays (numpy for :func:`gae`, torch for :func:`ppo_loss`), so the tests
check them against values computed by hand.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch


def gae(
    rewards: np.ndarray, values: np.ndarray, bootstrap: float, gamma: float, lam: float
) -> tuple[np.ndarray, np.ndarray]:
    """The advantages and returns of one episode's ``T`` steps (GAE, Schulman et al. 2016).

    ``delta_t = r_t + gamma * V_{t+1} - V_t`` with ``V_T = bootstrap`` (0 after a termination; the
    value of the last true observation after a truncation), ``A_t = delta_t + gamma * lam * A_{t+1}``
    and the return ``R_t = A_t + V_t`` (the value loss's target).

    Args:
        rewards: ``r_0 .. r_{T-1}``.
        values: ``V(s_0) .. V(s_{T-1})``, as estimated when each action was taken.
        bootstrap: ``V_T``.
        gamma: discount per step.
        lam: the GAE parameter.

    Returns:
        ``(advantages, returns)``, float64 arrays of length ``T``.

    Raises:
        ValueError: ``rewards`` and ``values`` differ in length.
    """
    r = np.asarray(rewards, dtype=np.float64)
    v = np.asarray(values, dtype=np.float64)
    if r.shape != v.shape or r.ndim != 1:
        raise ValueError(f"rewards {r.shape} and values {v.shape}: one of each per step")
    advantages = np.zeros_like(r)
    next_value, running = float(bootstrap), 0.0
    for t in range(len(r) - 1, -1, -1):
        delta = r[t] + gamma * next_value - v[t]
        running = delta + gamma * lam * running
        advantages[t] = running
        next_value = v[t]
    return advantages, advantages + v


@dataclass(frozen=True)
class LossTerms:
    """One minibatch's loss and what it is made of (the scalars are plain floats but ``total``)."""

    total: torch.Tensor
    policy: float
    value: float
    entropy: float
    approx_kl: float
    clip_fraction: float


def ppo_loss(
    new_logp: torch.Tensor,
    old_logp: torch.Tensor,
    advantages: torch.Tensor,
    new_values: torch.Tensor,
    returns: torch.Tensor,
    entropy: torch.Tensor,
    *,
    clip: float,
    value_coef: float = 0.5,
    entropy_coef: float = 0.0,
) -> LossTerms:
    """The clipped surrogate objective with its value and entropy terms, to minimise:

    ``-mean(min(rho A, clip(rho, 1 - clip, 1 + clip) A)) + value_coef * 0.5 * mean((V - R)^2)
    - entropy_coef * mean(H)``, ``rho = exp(new_logp - old_logp)``.

    ``approx_kl`` is ``mean((rho - 1) - log rho)`` (an unbiased, non-negative estimate of
    ``KL(old || new)``); ``clip_fraction`` the share of ratios outside the clipping range.
    """
    log_ratio = new_logp - old_logp
    ratio = torch.exp(log_ratio)
    surrogate = torch.minimum(ratio * advantages, torch.clamp(ratio, 1.0 - clip, 1.0 + clip) * advantages)
    policy = -surrogate.mean()
    value = 0.5 * torch.mean((new_values - returns) ** 2)
    mean_entropy = entropy.mean()
    total = policy + value_coef * value - entropy_coef * mean_entropy
    with torch.no_grad():
        kl = float(((ratio - 1.0) - log_ratio).mean())
        clipped = float(((ratio - 1.0).abs() > clip).float().mean())
    return LossTerms(total, float(policy.detach()), float(value.detach()), float(mean_entropy.detach()), kl,
                     clipped)  # fmt: skip
