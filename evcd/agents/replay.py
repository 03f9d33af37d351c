"""Prioritized experience replay (Schaul et al. 2016, proportional variant), numpy only.

    buffer = PrioritizedReplayBuffer(capacity=10_000, obs_dim=15, alpha=0.6)
    slot = buffer.add(obs, action, reward, next_obs, terminated, truncated, discount=0.99)
    batch = buffer.sample(32, rng, beta=0.4)          # batch.weights scale each TD loss term
    buffer.update_priorities(batch.indices, td_errors)

A transition ``i`` is drawn with probability ``P(i) = p_i / sum_k p_k`` where ``p_i = (|td_i| + eps) **
alpha``; ``alpha = 0`` is uniform replay. The priorities live in a :class:`SumTree` whose descent and
updates are vectorised over the batch: a sample + update round costs a few numpy calls per tree level
(14 levels for 10,000 slots) whatever the batch size, instead of a Python loop per transition.

The module does not import torch: :meth:`PrioritizedReplayBuffer.state_dict` holds only numpy arrays and
Python scalars, which a caller can turn into tensors and save with ``torch.save`` and read back with
``torch.load(weights_only=True)``.
"""

from __future__ import annotations

import math
import operator
from typing import Any, NamedTuple

import numpy as np

from evcd.utils.validation import check_int, check_real, require


class SumTree:
    """Prefix-sum search over non-negative weights in O(log n), for sampling proportionally to them.

    The tree is one flat float64 array of ``2 * P`` nodes (``P`` the power of two >= ``capacity``): the
    root at 1, the children of node ``k`` at ``2k`` and ``2k + 1``, the leaves at ``[P, 2P)``; the padding
    leaves stay 0 and are therefore never found. Every inner node is recomputed as exactly
    ``left + right`` (never updated by a difference), so rounding errors cannot accumulate over millions
    of updates and the tree is a pure function of its leaves (a restored tree finds the same leaves).
    """

    def __init__(self, capacity: int) -> None:
        check_int("capacity", capacity, minimum=1)
        self.capacity = int(capacity)
        self._leaf0 = 1 << (self.capacity - 1).bit_length()  # P
        self._depth = self._leaf0.bit_length() - 1  # log2(P) levels below the root
        self._tree = np.zeros(2 * self._leaf0, dtype=np.float64)
        # Node k's children (2k, 2k + 1) are adjacent, so one complex128 read fetches both at once.
        self._pairs = self._tree.view(np.complex128)
        self._shifts = np.arange(1, self._depth + 1, dtype=np.int64)[:, None]
        # The largest leaf for which even P of them sum without overflowing to inf.
        self._max_value = float(np.finfo(np.float64).max) / (2 * self._leaf0)

    def total(self) -> float:
        """Sum of all leaves (the root)."""
        return float(self._tree[1])

    def max(self) -> float:
        """Largest leaf (O(capacity): meant for checks, not for the hot path)."""
        return float(self._tree[self._leaf0 : self._leaf0 + self.capacity].max())

    def get(self, indices: np.ndarray) -> np.ndarray:
        """Leaf values at ``indices`` (float64).

        Raises:
            ValueError: an index outside ``[0, capacity)``.
        """
        idx = self._check_indices(indices, self.capacity)
        return self._tree[idx + self._leaf0]

    def set(self, indices: np.ndarray, values: np.ndarray) -> None:
        """Set leaves and repair their ancestors; for a repeated index the last value wins.

        Raises:
            ValueError: an index outside ``[0, capacity)``, or a value that is NaN, infinite, negative or
                so large that the total could overflow (the message names it).
        """
        idx = self._check_indices(indices, self.capacity)
        vals = np.broadcast_to(np.asarray(values, dtype=np.float64), idx.shape)
        self._check_values(vals)
        self._write(idx, vals)

    def set_all(self, values: np.ndarray) -> None:
        """Replace every leaf at once and rebuild the tree bottom-up (O(capacity), for restoring)."""
        vals = np.asarray(values, dtype=np.float64)
        require(vals.shape == (self.capacity,), f"values of shape {vals.shape}: expected ({self.capacity},)")
        self._check_values(vals)
        tree, p = self._tree, self._leaf0
        tree[p : p + self.capacity] = vals
        tree[p + self.capacity :] = 0.0
        while p > 1:
            half = p // 2
            tree[half:p] = tree[p : 2 * p : 2] + tree[p + 1 : 2 * p : 2]
            p = half

    def find(self, targets: np.ndarray) -> np.ndarray:
        """For each target prefix sum ``t``, the leaf ``i`` with ``cumsum[i - 1] <= t < cumsum[i]``.

        The result is always a leaf with a positive value below ``capacity``: a target at or (by rounding)
        just above the total goes to the last positive leaf.

        Raises:
            ValueError: the tree is empty (total 0), or a target is NaN, negative or above the total.
        """
        t = np.asarray(targets, dtype=np.float64).reshape(-1)
        total = self.total()
        require(total > 0.0, "cannot search a sum tree whose total is 0")
        if t.size and not (t.min() >= 0.0 and t.max() <= total * (1.0 + 1e-9)):
            bad = t[~((t >= 0.0) & (t <= total * (1.0 + 1e-9)))][0]
            raise ValueError(f"target {bad!r} outside [0, total = {total!r})")
        return self._find(t).reshape(np.shape(targets))

    # -- unchecked internals (the replay buffer validates once, then calls these) --------------------

    def _write(self, idx: np.ndarray, vals: np.ndarray) -> None:
        if idx.size > 1 and not (idx[1:] > idx[:-1]).all():  # keep the last of each repeated index
            order = np.argsort(idx, kind="stable")
            ordered = idx[order]
            last = np.ones(idx.size, dtype=bool)
            np.not_equal(ordered[1:], ordered[:-1], out=last[:-1])
            idx, vals = ordered[last], vals[order][last]
        node = idx + self._leaf0
        tree, pairs = self._tree, self._pairs
        tree[node] = vals
        for parents in node >> self._shifts:  # one row per level, leaves' parents first
            # A parent listed twice is harmless: each copy writes the same exact sum.
            children = pairs[parents]
            tree[parents] = children.real + children.imag

    def _find(self, t: np.ndarray) -> np.ndarray:
        """Descend with ``go right iff t >= left sum``; a rounding slip that ends on a 0 leaf is redone."""
        tree = self._tree
        x = t.copy()
        node = np.ones(x.size, dtype=np.int64)
        for _ in range(self._depth):
            np.add(node, node, out=node)
            left = tree[node]
            right = x >= left
            x -= left * right
            node += right
        slipped = tree[node] <= 0.0
        if slipped.any():
            node[slipped] = self._find_guarded(t[slipped])
        return node - self._leaf0

    def _find_guarded(self, t: np.ndarray) -> np.ndarray:
        """Slow path: never step into a subtree of sum 0, so the leaf reached is always positive."""
        x = t.copy()
        node = np.ones(x.size, dtype=np.int64)
        for _ in range(self._depth):
            children = self._pairs[node]
            right = (x >= children.real) & (children.imag > 0.0)
            x -= children.real * right
            node = 2 * node + right
        return node

    @staticmethod
    def _check_indices(indices: np.ndarray, limit: int) -> np.ndarray:
        idx = np.asarray(indices)
        require(idx.dtype.kind in "iu", f"indices of dtype {idx.dtype}: must be integers")
        idx = idx.astype(np.int64, copy=False).reshape(-1)
        if idx.size and not idx.view(np.uint64).max() < limit:  # a negative index wraps to a huge one
            bad = idx[(idx < 0) | (idx >= limit)][0]
            raise ValueError(f"index {int(bad)} outside [0, {limit})")
        return idx

    def _check_values(self, vals: np.ndarray) -> None:
        if vals.size and not (vals.min() >= 0.0 and vals.max() <= self._max_value):
            bad = vals[~((vals >= 0.0) & (vals <= self._max_value))][0]
            raise ValueError(f"priority {float(bad)!r}: must be finite, >= 0 and <= {self._max_value:.3g}")


class Batch(NamedTuple):
    """A sampled minibatch; ``terminated`` and ``truncated`` stay apart because a truncation bootstraps."""

    obs: np.ndarray  # (B, obs_dim) float32
    actions: np.ndarray  # (B,) int64
    rewards: np.ndarray  # (B,) float32
    next_obs: np.ndarray  # (B, obs_dim) float32
    terminated: np.ndarray  # (B,) bool: charge start, no bootstrap
    truncated: np.ndarray  # (B,) bool: time-limit end, still bootstraps
    discounts: np.ndarray  # (B,) float32 what the value of next_obs is worth (gamma ** steps)
    weights: np.ndarray  # (B,) float32 importance-sampling weights, max 1
    indices: np.ndarray  # (B,) int64 buffer slots, for update_priorities
    probabilities: np.ndarray  # (B,) float64 P(i) each transition was drawn with


def importance_weights(probabilities: np.ndarray, size: int, beta: float) -> np.ndarray:
    """``w_i = (size * P(i)) ** -beta / max_j w_j``: undoes the bias of non-uniform replay (fully at
    ``beta = 1``) while the max normalisation only ever scales the loss down, keeping steps stable.

    Computed as ``(min_j P(j) / P(i)) ** beta`` (``size`` cancels), which cannot overflow.

    Raises:
        ValueError: a probability not in ``(0, 1]``, ``size < 1`` or ``beta`` outside ``[0, 1]``.
    """
    p = np.asarray(probabilities, dtype=np.float64)
    check_int("size", size, minimum=1)
    check_real("beta", beta, low=0.0, high=1.0)
    if p.size and not (p.min() > 0.0 and p.max() <= 1.0):
        bad = p[~((p > 0.0) & (p <= 1.0))][0]
        raise ValueError(f"probability {float(bad)!r} outside (0, 1]")
    return _weights(p, beta)


def _weights(p: np.ndarray, beta: float) -> np.ndarray:
    return ((p.min() / p) ** beta).astype(np.float32)


#: What :meth:`PrioritizedReplayBuffer.state_dict` holds.
_STATE_KEYS = ("obs", "next_obs", "actions", "rewards", "terminated", "truncated", "discounts",
               "priorities", "position", "size", "max_priority", "alpha", "eps", "capacity",
               "obs_dim")  # fmt: skip


class PrioritizedReplayBuffer:
    """Ring buffer of transitions sampled in proportion to their last TD error (proportional PER).

    New transitions enter at the running maximum priority (starting at 1.0), so each is replayed at
    least about as often as the most surprising one until its own TD error is known.
    """

    def __init__(self, capacity: int, obs_dim: int, alpha: float = 0.6, eps: float = 1e-6) -> None:
        check_int("capacity", capacity, minimum=1)
        check_int("obs_dim", obs_dim, minimum=1)
        check_real("alpha", alpha, low=0.0, high=1.0)
        check_real("eps", eps, low=0.0, low_open=True)
        self.capacity, self.obs_dim = int(capacity), int(obs_dim)
        self.alpha, self.eps = float(alpha), float(eps)
        self._obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self._next_obs = np.zeros((capacity, obs_dim), dtype=np.float32)
        self._actions = np.zeros(capacity, dtype=np.int64)
        self._rewards = np.zeros(capacity, dtype=np.float32)
        self._terminated = np.zeros(capacity, dtype=bool)
        self._truncated = np.zeros(capacity, dtype=bool)
        self._discounts = np.zeros(capacity, dtype=np.float32)
        self._tree = SumTree(capacity)
        self._position = 0  # the slot the next transition goes to
        self._size = 0
        self._max_priority = 1.0

    def __len__(self) -> int:
        return self._size

    def add(
        self,
        obs: Any,
        action: int,
        reward: float,
        next_obs: Any,
        terminated: bool,
        truncated: bool,
        discount: float = 1.0,
    ) -> int:
        """Store a transition over the oldest one once full; returns its slot.

        ``discount`` is what the value of ``next_obs`` is worth to this transition (``gamma`` for a
        one-step transition, ``gamma ** k`` for one that sums ``k`` rewards); ``terminated`` still
        cuts the bootstrap whatever it is.

        Raises:
            ValueError: an observation not of shape ``(obs_dim,)``, a negative action, a non-finite
                reward or a discount outside ``[0, 1]``.
        """
        o, o2 = self._check_obs("obs", obs), self._check_obs("next_obs", next_obs)
        a, r = operator.index(action), float(reward)
        require(a >= 0, f"action {a}: must be >= 0")
        require(math.isfinite(r), f"reward {r!r}: must be finite")
        check_real("discount", discount, low=0.0, high=1.0)
        slot = self._position
        self._obs[slot], self._next_obs[slot] = o, o2
        self._actions[slot], self._rewards[slot] = a, r
        self._terminated[slot], self._truncated[slot] = bool(terminated), bool(truncated)
        self._discounts[slot] = discount
        self._tree._write(np.array([slot], dtype=np.int64), np.array([self._max_priority]))
        self._position = (slot + 1) % self.capacity
        self._size = min(self._size + 1, self.capacity)
        return slot

    def sample(self, batch_size: int, rng: np.random.Generator, beta: float) -> Batch:
        """Stratified draw: ``[0, total)`` cut into ``batch_size`` equal segments, one draw in each, which
        spreads a batch over the priority mass and lowers the variance of its gradient.

        Raises:
            ValueError: an empty buffer, ``batch_size < 1`` or ``beta`` outside ``[0, 1]``.
        """
        check_int("batch_size", batch_size, minimum=1)
        check_real("beta", beta, low=0.0, high=1.0)
        require(self._size > 0, "cannot sample from an empty replay buffer")
        tree = self._tree
        total = tree.total()
        require(total > 0.0, "cannot sample: every stored priority is 0")
        targets = (np.arange(batch_size) + rng.random(batch_size)) * (total / batch_size)
        idx = tree._find(targets)
        probs = tree._tree[idx + tree._leaf0] / total
        return Batch(
            self._obs[idx], self._actions[idx], self._rewards[idx], self._next_obs[idx],
            self._terminated[idx], self._truncated[idx], self._discounts[idx], _weights(probs, beta), idx,
            probs,
        )  # fmt: skip

    def update_priorities(self, indices: np.ndarray, td_errors: np.ndarray) -> None:
        """Set ``p = (|td| + eps) ** alpha`` for the given slots (a repeated slot: its last error wins).

        Raises:
            ValueError: an index outside ``[0, len(self))``, a NaN or infinite TD error, or shapes
                that differ (each message names the value).
        """
        idx = SumTree._check_indices(indices, self._size)
        td = np.asarray(td_errors, dtype=np.float64).reshape(-1)
        require(td.shape == idx.shape, f"{td.size} TD errors for {idx.size} indices")
        if not td.size:
            return
        priorities = (np.abs(td) + self.eps) ** self.alpha
        top = float(priorities.max())  # NaN if any is NaN
        if not top <= self._tree._max_value:
            bad = td[~(np.abs(td) < math.inf)]
            if bad.size:
                raise ValueError(f"TD error {float(bad[0])!r}: must be finite")
            raise ValueError(f"TD error {float(td[np.argmax(priorities)])!r}: too large to sum priorities")
        self._max_priority = max(self._max_priority, top)
        self._tree._write(idx, priorities)

    def priorities(self, indices: np.ndarray) -> np.ndarray:
        """Stored priorities ``p`` (after ``alpha``) of the given slots; 0 for a slot never filled."""
        return self._tree.get(indices)

    @property
    def max_priority(self) -> float:
        """The priority the next added transition gets."""
        return self._max_priority

    def state_dict(self) -> dict[str, Any]:
        """Copies of the storage and priorities plus scalars: only numpy arrays and Python scalars."""
        return {
            "obs": self._obs.copy(), "next_obs": self._next_obs.copy(), "actions": self._actions.copy(),
            "rewards": self._rewards.copy(), "terminated": self._terminated.copy(),
            "truncated": self._truncated.copy(), "discounts": self._discounts.copy(),
            "priorities": self._tree.get(np.arange(self.capacity)),
            "position": self._position, "size": self._size, "max_priority": self._max_priority,
            "alpha": self.alpha, "eps": self.eps, "capacity": self.capacity, "obs_dim": self.obs_dim,
        }  # fmt: skip

    def load_state_dict(self, state: dict[str, Any]) -> None:
        """Restore a :meth:`state_dict` exactly (alpha and eps included); nothing changes on error.

        Raises:
            ValueError: a missing key, another capacity or obs_dim, an array of the wrong shape, or an
                inconsistent position / size / priority (the message names it).
        """
        missing = sorted(set(_STATE_KEYS) - set(state))
        require(not missing, f"replay state lacks {missing}")
        for key in ("capacity", "obs_dim"):
            mine, theirs = getattr(self, key), int(state[key])
            require(theirs == mine, f"replay state has {key} {theirs}, this buffer {mine}")
        cap, dim = self.capacity, self.obs_dim
        arrays = {}
        for key, dtype, shape in (
            ("obs", np.float32, (cap, dim)), ("next_obs", np.float32, (cap, dim)),
            ("actions", np.int64, (cap,)), ("rewards", np.float32, (cap,)), ("terminated", bool, (cap,)),
            ("truncated", bool, (cap,)), ("discounts", np.float32, (cap,)),
            ("priorities", np.float64, (cap,)),
        ):  # fmt: skip
            arr = np.asarray(state[key]).astype(dtype)
            require(arr.shape == shape, f"replay state {key!r} has shape {arr.shape}, expected {shape}")
            arrays[key] = arr
        size, position = int(state["size"]), int(state["position"])
        alpha, eps, max_priority = float(state["alpha"]), float(state["eps"]), float(state["max_priority"])
        require(0 <= size <= cap, f"replay state size {size} outside [0, {cap}]")
        require(position == size or (size == cap and 0 <= position < cap),
                 f"replay state position {position} inconsistent with size {size}")  # fmt: skip
        check_real("alpha", alpha, low=0.0, high=1.0)
        require(0.0 < eps < math.inf, f"replay state eps {eps!r}: must be finite and > 0")
        require(0.0 < max_priority < math.inf, f"replay state max_priority {max_priority!r}: must be > 0")
        require(not arrays["priorities"][size:].any(), "replay state has priorities on slots never filled")
        self._tree.set_all(arrays["priorities"])  # validates the priorities before anything else changes
        for key in ("obs", "next_obs", "actions", "rewards", "terminated", "truncated", "discounts"):
            getattr(self, f"_{key}")[...] = arrays[key]
        self._size, self._position, self._max_priority = size, position, max_priority
        self.alpha, self.eps = alpha, eps

    def _check_obs(self, name: str, obs: Any) -> np.ndarray:
        arr = np.asarray(obs, dtype=np.float32)
        require(arr.shape == (self.obs_dim,), f"{name} of shape {arr.shape}: expected ({self.obs_dim},)")
        return arr
