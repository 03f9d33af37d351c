"""Prioritized replay: the sum tree against a naive cumsum, sampling statistics, weights, ring buffer,
validation and a state round trip through ``torch.save`` / ``torch.load(weights_only=True)``."""

from __future__ import annotations

import io
import math
import re
import subprocess
import sys

import numpy as np
import pytest
import torch

from evcd.agents.replay import Batch, PrioritizedReplayBuffer, SumTree, importance_weights

OBS_DIM = 3
# chi-square critical value, 9 degrees of freedom, p = 1e-4 (scipy.stats.chi2.ppf(1 - 1e-4, 9))
CHI2_9DOF = 33.72


def _obs(i: float) -> np.ndarray:
    return np.full(OBS_DIM, i, dtype=np.float32)


def _filled(n: int, capacity: int | None = None, **kwargs) -> PrioritizedReplayBuffer:
    """Transition ``i`` has obs ``i``, action ``i % 4``, reward ``i``, next obs ``i + 1``, discount
    ``1 / (i + 1)``."""
    buf = PrioritizedReplayBuffer(capacity or n, OBS_DIM, **kwargs)
    for i in range(n):
        buf.add(_obs(i), i % 4, float(i), _obs(i + 1), terminated=i % 3 == 0, truncated=i % 3 == 1,
                discount=1 / (i + 1))  # fmt: skip
    return buf


def _assert_consistent(tree: SumTree) -> None:
    """Every inner node is exactly the sum of its two children; padding leaves are 0."""
    t, p = tree._tree, tree._leaf0
    while p > 1:
        half = p // 2
        np.testing.assert_array_equal(t[half:p], t[p : 2 * p : 2] + t[p + 1 : 2 * p : 2])
        p = half
    assert not t[tree._leaf0 + tree.capacity :].any()


def _chi2(counts: np.ndarray, probs: np.ndarray) -> float:
    expected = counts.sum() * probs
    return float(((counts - expected) ** 2 / expected).sum())


# -- SumTree --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("capacity", [1, 3, 7, 100, 1000])
def test_sum_tree_matches_naive_cumsum(capacity):
    """Random sets (with repeated indices, last wins), gets and finds; integer values keep sums exact."""
    for seed in range(50):
        rng = np.random.default_rng(seed)
        tree, naive = SumTree(capacity), np.zeros(capacity)
        for _ in range(200):
            op = rng.integers(3)
            if op == 0:
                k = int(rng.integers(1, 2 * min(capacity, 8) + 1))
                idx = rng.integers(0, capacity, k)
                vals = rng.integers(0, 10, k).astype(np.float64)  # zeros included
                tree.set(idx, vals)
                for i, v in zip(idx, vals, strict=True):
                    naive[i] = v
            elif op == 1:
                idx = rng.integers(0, capacity, 5)
                np.testing.assert_array_equal(tree.get(idx), naive[idx])
            elif naive.sum() > 0:
                total = naive.sum()
                targets = np.concatenate([
                    rng.integers(0, int(total) * 4, 10) / 4.0,  # on and between the boundaries
                    [0.0, total - 0.25, np.nextafter(total, 0.0)], np.cumsum(naive)[:-1],
                ])  # fmt: skip
                targets = targets[targets < total]  # a boundary before trailing zeros is the total itself
                expected = np.searchsorted(np.cumsum(naive), targets, side="right")
                np.testing.assert_array_equal(tree.find(targets), expected)
            assert tree.total() == naive.sum()
        _assert_consistent(tree)


def test_sum_tree_random_floats_find_within_round_off():
    rng = np.random.default_rng(0)
    tree = SumTree(1000)
    vals = rng.random(1000) * (rng.random(1000) < 0.7)  # 30 % zeros
    tree.set(np.arange(1000), vals)
    cum = np.cumsum(vals)
    targets = rng.random(10_000) * tree.total()
    found = tree.find(targets)
    lower = np.where(found > 0, cum[found - 1], 0.0)
    assert (vals[found] > 0).all()
    assert (lower - 1e-9 <= targets).all() and (targets < cum[found] + 1e-9).all()
    assert math.isclose(tree.total(), vals.sum(), rel_tol=1e-12)
    assert tree.max() == vals.max()


def test_find_never_returns_zero_leaf_or_padding(monkeypatch):
    guarded_calls = []
    real = SumTree._find_guarded
    monkeypatch.setattr(SumTree, "_find_guarded", lambda self, t: guarded_calls.append(t) or real(self, t))
    rng = np.random.default_rng(3)
    for capacity in (3, 5, 7, 100, 1000):
        for _ in range(20):
            vals = rng.choice([0.0, 1e-300, 1e-7, 0.1, 0.3, 1.0, 1e16], size=capacity)
            vals[rng.integers(capacity)] = 0.7  # never all zero
            vals[-1] = 0.0  # the last leaf empty: overshoots land on padding or on it
            tree = SumTree(capacity)
            tree.set(np.arange(capacity), vals)
            total = tree.total()
            bounds = np.cumsum(vals)
            targets = np.concatenate([[0.0, total, np.nextafter(total, 0.0), total * (1 + 1e-12)], bounds,
                                      np.nextafter(bounds, 0.0), np.nextafter(bounds, np.inf)])  # fmt: skip
            targets = targets[targets <= total * (1 + 1e-12)]
            found = tree.find(targets)
            assert (found < capacity).all() and (vals[found] > 0).all(), (vals, targets, found)
    assert guarded_calls, "the adversarial targets never exercised the guarded descent"
    # the last target at the very total goes to the last positive leaf
    tree = SumTree(3)
    tree.set(np.arange(3), [0.1, 0.2, 0.3])
    assert tree.find(np.array([tree.total()]))[0] == 2


def test_set_all_builds_the_same_tree_as_incremental_sets():
    rng = np.random.default_rng(1)
    vals = rng.random(100)
    a, b = SumTree(100), SumTree(100)
    for i in rng.permutation(100):
        a.set(np.array([i]), vals[i : i + 1])
    b.set_all(vals)
    np.testing.assert_array_equal(a._tree, b._tree)
    _assert_consistent(b)


def test_set_with_repeated_indices_keeps_the_last_value():
    tree = SumTree(8)
    tree.set(np.array([5, 2, 5, 5, 2]), np.array([1.0, 2.0, 3.0, 4.0, 6.0]))
    np.testing.assert_array_equal(tree.get(np.array([2, 5])), [6.0, 4.0])
    assert tree.total() == 10.0
    _assert_consistent(tree)


@pytest.mark.parametrize("value", [np.nan, np.inf, -1.5, 1e308])
def test_sum_tree_rejects_bad_values(value):
    tree = SumTree(4)
    tree.set(np.arange(4), np.ones(4))
    with pytest.raises(ValueError, match=f"priority {re.escape(repr(value))}"):
        tree.set(np.array([0, 1]), np.array([1.0, value]))
    np.testing.assert_array_equal(tree.get(np.arange(4)), np.ones(4))  # nothing written
    assert tree.total() == 4.0


def test_sum_tree_rejects_bad_indices_and_targets():
    tree = SumTree(4)
    with pytest.raises(ValueError, match="total is 0"):
        tree.find(np.array([0.0]))
    tree.set(np.arange(4), np.ones(4))
    for idx, shown in ((4, "index 4"), (-1, "index -1")):
        with pytest.raises(ValueError, match=shown):
            tree.set(np.array([0, idx]), np.ones(2))
        with pytest.raises(ValueError, match=shown):
            tree.get(np.array([idx]))
    with pytest.raises(ValueError, match="integers"):
        tree.get(np.array([1.0]))
    for target in (-0.5, np.nan, 4.5):
        with pytest.raises(ValueError, match="target"):
            tree.find(np.array([1.0, target]))
    with pytest.raises(ValueError, match="capacity=0"):
        SumTree(0)


# -- sampling -------------------------------------------------------------------------------------------


def test_sampling_frequencies_match_priorities():
    buf = _filled(10, alpha=0.6)
    td = np.array([0.5, 1.0, 2.0, 3.0, 0.1, 5.0, 6.0, 8.0, 0.2, 4.0])
    buf.update_priorities(np.arange(10), td)
    probs = (np.abs(td) + buf.eps) ** 0.6
    probs /= probs.sum()
    rng = np.random.default_rng(0)
    counts = np.zeros(10)
    for _ in range(1000):
        batch = buf.sample(32, rng, beta=0.4)
        np.add.at(counts, batch.indices, 1)
        np.testing.assert_allclose(batch.probabilities, probs[batch.indices], rtol=1e-12)
    assert _chi2(counts, probs) < CHI2_9DOF
    # the same counts would reject a uniform sampler and a sampler shifted by one leaf
    assert _chi2(counts, np.full(10, 0.1)) > 10 * CHI2_9DOF
    assert _chi2(counts, np.roll(probs, 1)) > 10 * CHI2_9DOF


def test_alpha_zero_is_uniform_replay():
    buf = _filled(10, alpha=0.0)
    buf.update_priorities(np.arange(10), np.array([0.1, 1, 2, 3, 40, 5, 6, 8, 0.2, 4]))
    np.testing.assert_array_equal(buf.priorities(np.arange(10)), np.ones(10))
    rng = np.random.default_rng(1)
    counts = np.zeros(10)
    for _ in range(1000):
        np.add.at(counts, buf.sample(31, rng, beta=1.0).indices, 1)
    assert _chi2(counts, np.full(10, 0.1)) < CHI2_9DOF
    skewed = (np.array([0.1, 1, 2, 3, 40, 5, 6, 8, 0.2, 4]) + 1e-6) ** 0.6
    assert _chi2(counts, skewed / skewed.sum()) > 10 * CHI2_9DOF


def test_sampling_is_stratified():
    buf = _filled(1000, alpha=1.0)
    rng = np.random.default_rng(2)
    buf.update_priorities(np.arange(1000), rng.exponential(size=1000))
    cum = np.cumsum(buf.priorities(np.arange(1000)))
    seed_rng, twin_rng = np.random.default_rng(5), np.random.default_rng(5)
    for _ in range(20):
        batch = buf.sample(64, seed_rng, beta=0.5)
        seg = cum[-1] / 64
        k = np.arange(64)
        lower = np.where(batch.indices > 0, cum[batch.indices - 1], 0.0)
        # leaf k's interval [lower, upper) meets segment k
        assert (lower <= (k + 1) * seg + 1e-9).all() and (cum[batch.indices] >= k * seg - 1e-9).all()
        # and it is exactly the leaf under the one uniform draw of that segment
        targets = (k + twin_rng.random(64)) * seg
        np.testing.assert_array_equal(batch.indices, np.searchsorted(cum, targets, side="right"))
        buf.update_priorities(batch.indices, rng.exponential(size=64))
        cum = np.cumsum(buf.priorities(np.arange(1000)))


def test_importance_weights_by_hand():
    # P = [.1, .2, .3, .4], N = 4, beta = .5: w = (4 P)^-.5 = [.4, .8, 1.2, 1.6]^-.5, max at P = .1
    w = importance_weights(np.array([0.1, 0.2, 0.3, 0.4]), 4, 0.5)
    np.testing.assert_allclose(w, [1.0, math.sqrt(0.5), math.sqrt(1 / 3), 0.5], rtol=1e-6)
    assert w.dtype == np.float32 and w.max() == 1.0
    np.testing.assert_array_equal(importance_weights(np.array([0.1, 0.2, 0.7]), 3, 0.0), np.ones(3))
    # through the buffer: priorities [1, 2, 3, 4] with alpha = 1
    buf = _filled(4, alpha=1.0, eps=1e-6)
    buf.update_priorities(np.arange(4), np.array([1.0, 2.0, 3.0, 4.0]) - 1e-6)
    batch = buf.sample(4, np.random.default_rng(0), beta=0.5)
    p = np.array([0.1, 0.2, 0.3, 0.4])[batch.indices]
    expected = (4 * p) ** -0.5 / ((4 * p) ** -0.5).max()
    np.testing.assert_allclose(batch.weights, expected, rtol=1e-6)
    assert batch.weights.max() == 1.0 and 3 in batch.indices  # the last segment holds only leaf 3
    with pytest.raises(ValueError, match=r"probability 0\.0"):
        importance_weights(np.array([0.5, 0.0]), 2, 0.5)
    with pytest.raises(ValueError, match="beta=2"):
        importance_weights(np.array([0.5]), 2, 2)


def test_batch_fields_and_dtypes():
    buf = _filled(20)
    batch = buf.sample(8, np.random.default_rng(0), beta=0.4)
    assert isinstance(batch, Batch)
    assert Batch._fields[:9] == ("obs", "actions", "rewards", "next_obs", "terminated", "truncated",
                                 "discounts", "weights", "indices")  # fmt: skip
    assert batch.obs.shape == batch.next_obs.shape == (8, OBS_DIM)
    assert batch.obs.dtype == batch.next_obs.dtype == batch.rewards.dtype == batch.weights.dtype == np.float32
    assert batch.discounts.dtype == np.float32
    assert batch.actions.dtype == batch.indices.dtype == np.int64
    assert batch.terminated.dtype == batch.truncated.dtype == bool
    ids = batch.obs[:, 0].astype(int)
    np.testing.assert_array_equal(ids, batch.indices)
    np.testing.assert_array_equal(batch.next_obs[:, 0], ids + 1)
    np.testing.assert_array_equal(batch.actions, ids % 4)
    np.testing.assert_array_equal(batch.rewards, ids)
    np.testing.assert_array_equal(batch.discounts, (1 / (ids + 1)).astype(np.float32))


def test_terminated_and_truncated_kept_apart():
    buf = PrioritizedReplayBuffer(4, OBS_DIM)
    flags = [(True, False), (False, True), (False, False), (True, True)]
    for i, (term, trunc) in enumerate(flags):
        buf.add(_obs(i), 0, 0.0, _obs(i), term, trunc)
    rng = np.random.default_rng(0)
    seen = set()
    for _ in range(20):
        batch = buf.sample(4, rng, beta=0.4)
        for i, term, trunc in zip(batch.indices, batch.terminated, batch.truncated, strict=True):
            assert (bool(term), bool(trunc)) == flags[i]
            seen.add(int(i))
    assert seen == {0, 1, 2, 3}


def test_same_seed_same_samples():
    a, b = _filled(50), _filled(50)
    for buf in (a, b):
        buf.update_priorities(np.arange(50), np.random.default_rng(9).standard_normal(50))
    ra, rb = np.random.default_rng(4), np.random.default_rng(4)
    for _ in range(5):
        _assert_batches_equal(a.sample(16, ra, 0.4), b.sample(16, rb, 0.4))
    other = a.sample(16, np.random.default_rng(5), 0.4)
    assert not np.array_equal(other.indices, b.sample(16, np.random.default_rng(4), 0.4).indices)


def _assert_batches_equal(x: Batch, y: Batch) -> None:
    for name, u, v in zip(Batch._fields, x, y, strict=True):
        np.testing.assert_array_equal(u, v, err_msg=name)
        assert u.dtype == v.dtype, name


# -- priorities and the ring buffer ---------------------------------------------------------------------


def test_new_transitions_enter_at_the_running_max_priority():
    buf = PrioritizedReplayBuffer(10, OBS_DIM, alpha=0.5)
    slot = buf.add(_obs(0), 0, 0.0, _obs(1), False, False)
    assert buf.priorities(np.array([slot]))[0] == 1.0 == buf.max_priority
    buf.update_priorities(np.array([slot]), np.array([-8.0]))  # |td| counts
    big = (8.0 + buf.eps) ** 0.5
    slot = buf.add(_obs(1), 0, 0.0, _obs(2), False, False)
    assert buf.priorities(np.array([slot]))[0] == big == buf.max_priority
    buf.update_priorities(np.array([0, 1]), np.array([0.1, 0.2]))  # smaller errors: the max stays
    slot = buf.add(_obs(2), 0, 0.0, _obs(3), False, False)
    assert buf.priorities(np.array([slot]))[0] == big
    buf.update_priorities(np.array([2, 2]), np.array([1.0, 3.0]))  # a repeated slot: the last error wins
    assert buf.priorities(np.array([2]))[0] == (3.0 + buf.eps) ** 0.5


def test_ring_buffer_overwrites_the_oldest():
    buf = _filled(5, alpha=1.0)
    buf.update_priorities(np.arange(5), np.zeros(5))  # every priority eps
    buf.update_priorities(np.array([4]), np.array([7.0]))
    for i in range(5, 8):
        assert buf.add(_obs(i), i % 4, float(i), _obs(i + 1), False, False) == i - 5
    assert len(buf) == 5
    state = buf.state_dict()
    assert sorted(state["obs"][:, 0].astype(int)) == [3, 4, 5, 6, 7]
    np.testing.assert_allclose(buf.priorities(np.arange(5)), [7 + 1e-6] * 3 + [1e-6, 7 + 1e-6])
    rng = np.random.default_rng(0)
    for _ in range(50):
        assert (buf.sample(5, rng, 0.4).obs[:, 0] >= 3).all()


def test_priorities_of_unfilled_slots_are_never_sampled():
    buf = _filled(3, capacity=100)
    rng = np.random.default_rng(0)
    for _ in range(200):
        assert (buf.sample(16, rng, 0.4).indices < 3).all()


# -- validation -----------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("kwargs", "shown"),
    [
        ({"capacity": 0}, "capacity=0"), ({"capacity": 2.5}, r"capacity=2\.5"),
        ({"capacity": True}, "capacity=True"), ({"obs_dim": 0}, "obs_dim=0"),
        ({"alpha": -0.1}, r"alpha=-0\.1"),
        ({"alpha": 1.5}, r"alpha=1\.5: must be a finite number in \[0, 1\]"),
        ({"alpha": math.nan}, "alpha=nan"),
        ({"eps": 0.0}, r"eps=0\.0"), ({"eps": -1e-6}, "eps=-1e-06"), ({"eps": math.inf}, "eps=inf"),
    ],
)  # fmt: skip
def test_constructor_rejects_bad_arguments(kwargs, shown):
    with pytest.raises(ValueError, match=shown):
        PrioritizedReplayBuffer(**{"capacity": 10, "obs_dim": OBS_DIM, **kwargs})


def test_sample_rejects_bad_arguments_and_empty_buffer():
    buf = PrioritizedReplayBuffer(10, OBS_DIM)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="empty"):
        buf.sample(4, rng, 0.4)
    buf.add(_obs(0), 0, 0.0, _obs(1), False, False)
    for batch_size, beta, shown in ((0, 0.4, "batch_size=0"), (4, -0.1, "beta=-0.1"), (4, 1.1, "beta=1.1")):
        with pytest.raises(ValueError, match=shown):
            buf.sample(batch_size, rng, beta)


def test_add_rejects_bad_transitions():
    buf = PrioritizedReplayBuffer(10, OBS_DIM)
    with pytest.raises(ValueError, match=r"obs of shape \(4,\)"):
        buf.add(np.zeros(4), 0, 0.0, _obs(0), False, False)
    with pytest.raises(ValueError, match=r"next_obs of shape \(1, 3\)"):
        buf.add(_obs(0), 0, 0.0, np.zeros((1, 3)), False, False)
    with pytest.raises(ValueError, match="reward nan"):
        buf.add(_obs(0), 0, math.nan, _obs(0), False, False)
    with pytest.raises(ValueError, match="action -1"):
        buf.add(_obs(0), -1, 0.0, _obs(0), False, False)
    for discount in (-0.1, 1.5, math.nan):
        with pytest.raises(ValueError, match="discount="):
            buf.add(_obs(0), 0, 0.0, _obs(0), False, False, discount=discount)
    assert len(buf) == 0


@pytest.mark.parametrize(("td", "shown"), [(math.nan, "nan"), (math.inf, "inf"), (-math.inf, "-inf")])
def test_update_priorities_rejects_non_finite_errors(td, shown):
    buf = _filled(4)
    before = buf.priorities(np.arange(4))
    with pytest.raises(ValueError, match=f"TD error {shown}"):
        buf.update_priorities(np.array([0, 1]), np.array([0.5, td]))
    np.testing.assert_array_equal(buf.priorities(np.arange(4)), before)
    assert buf.max_priority == 1.0


def test_update_priorities_rejects_bad_indices():
    buf = _filled(4, capacity=10)
    with pytest.raises(ValueError, match=r"index 4 outside \[0, 4\)"):  # a slot never filled
        buf.update_priorities(np.array([4]), np.array([1.0]))
    with pytest.raises(ValueError, match="index -1"):
        buf.update_priorities(np.array([-1]), np.array([1.0]))
    with pytest.raises(ValueError, match="2 TD errors for 1 indices"):
        buf.update_priorities(np.array([0]), np.array([1.0, 2.0]))


# -- state ----------------------------------------------------------------------------------------------


def _used_buffer() -> PrioritizedReplayBuffer:
    buf = _filled(73, capacity=50, alpha=0.7, eps=1e-3)
    rng = np.random.default_rng(11)
    for _ in range(10):
        batch = buf.sample(8, rng, 0.5)
        buf.update_priorities(batch.indices, rng.standard_normal(8) * 3)
    return buf


def _assert_same_state(a: PrioritizedReplayBuffer, b: PrioritizedReplayBuffer) -> None:
    sa, sb = a.state_dict(), b.state_dict()
    assert sa.keys() == sb.keys()
    for key in sa:
        np.testing.assert_array_equal(sa[key], sb[key], err_msg=key)
    np.testing.assert_array_equal(a._tree._tree, b._tree._tree)


def test_state_round_trip_restores_exactly():
    buf = _used_buffer()
    state = buf.state_dict()
    for key, value in state.items():
        assert isinstance(value, np.ndarray) or type(value) in (int, float, bool), key
    restored = PrioritizedReplayBuffer(50, OBS_DIM)  # default alpha / eps: taken from the state
    restored.load_state_dict(state)
    assert (restored.alpha, restored.eps, len(restored)) == (0.7, 1e-3, 50)
    _assert_same_state(buf, restored)
    buf.add(_obs(-1), 1, 1.0, _obs(-1), False, True)  # the state is a copy, not a view
    assert not (state["obs"] == -1).any()
    restored.add(_obs(-1), 1, 1.0, _obs(-1), False, True)
    ra, rb = np.random.default_rng(3), np.random.default_rng(3)
    for _ in range(10):
        x, y = buf.sample(8, ra, 0.5), restored.sample(8, rb, 0.5)
        _assert_batches_equal(x, y)
        td = ra.standard_normal(8)
        rb.standard_normal(8)
        buf.update_priorities(x.indices, td)
        restored.update_priorities(y.indices, td)
    _assert_same_state(buf, restored)


def test_state_round_trip_through_torch_weights_only():
    buf = _used_buffer()
    state = buf.state_dict()
    as_tensors = {k: torch.from_numpy(v) if isinstance(v, np.ndarray) else v for k, v in state.items()}
    blob = io.BytesIO()
    torch.save(as_tensors, blob)
    blob.seek(0)
    loaded = torch.load(blob, weights_only=True)
    restored = PrioritizedReplayBuffer(50, OBS_DIM)
    restored.load_state_dict({k: v.numpy() if isinstance(v, torch.Tensor) else v for k, v in loaded.items()})
    _assert_same_state(buf, restored)
    _assert_batches_equal(buf.sample(16, np.random.default_rng(8), 0.6),
                          restored.sample(16, np.random.default_rng(8), 0.6))  # fmt: skip


def test_load_state_rejects_mismatches_and_changes_nothing():
    state = _used_buffer().state_dict()
    with pytest.raises(ValueError, match="capacity 50, this buffer 51"):
        PrioritizedReplayBuffer(51, OBS_DIM).load_state_dict(state)
    with pytest.raises(ValueError, match="obs_dim 3, this buffer 4"):
        PrioritizedReplayBuffer(50, 4).load_state_dict(state)
    target = _filled(50, alpha=0.3)
    before = target.state_dict()
    bad_states = [
        ({k: v for k, v in state.items() if k != "priorities"}, "lacks"),
        ({**state, "obs": state["obs"][:, :2]}, "'obs' has shape"),
        ({**state, "priorities": np.where(np.arange(50) == 7, np.nan, state["priorities"])}, "priority nan"),
        ({**state, "priorities": -state["priorities"]}, "priority -"),
        ({**state, "size": 51}, "size 51"),
        ({**state, "alpha": 2.0}, "alpha=2.0"),
    ]
    for bad, shown in bad_states:
        with pytest.raises(ValueError, match=shown):
            target.load_state_dict(bad)
        _assert_same_state(target, _filled(50, alpha=0.3))
    after = target.state_dict()
    for key, value in before.items():  # every array and counter as it was before the refused loads
        np.testing.assert_array_equal(after[key], value, err_msg=key)


def test_module_does_not_import_torch():
    code = "import sys, evcd.agents.replay, evcd.bench.replay; assert 'torch' not in sys.modules"
    subprocess.run([sys.executable, "-c", code], check=True)
