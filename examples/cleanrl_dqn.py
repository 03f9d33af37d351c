"""A single-file DQN in the style of CleanRL's ``dqn.py``, trained on evcd's batched engine.

    python examples/cleanrl_dqn.py                                   # the README job's world, 16 targets
    python examples/cleanrl_dqn.py --decisions 2000 --episodes 5     # a quick look
    tensorboard --logdir outputs/cleanrl_dqn

It trains on ``make_sweep_env``: ``--envs`` targets co-simulated in one SUMO run of their day (the
README job's world, ``experiment=peak``, its training days), many times the decisions per second of one
``gymnasium.make`` environment. Three things differ from CleanRL's script, which is written for
Gymnasium 0.29 and one environment:

1. **Autoreset.** Gymnasium 1.x vector environments default to next-step autoreset; evcd's is
   ``SAME_STEP`` (SB3's convention): the step in which an episode ends already returns the next
   episode's first observation, and the ended episode's last one is in ``infos["final_obs"]`` (its
   ``reason`` and ``travel_time`` in ``infos["final_info"]``). So the transition of a slot that ended
   is stored with ``final_obs``, not with the returned observation, and no bogus transition from one
   episode into the next is ever stored.
2. **Schedules count decisions.** One vector step is ``--envs`` decisions; epsilon, learning starts,
   the training frequency and target updates are counted in decisions, so that a setting means the
   same with 1 or 64 targets.
3. **Evaluation beside a rule.** The greedy policy then plays the held-out episodes that
   ``scripts/train.py experiment=peak`` evaluates its learners on, in the single environment, beside
   evcd's queue_aware rule on the very same episodes.

Observations come normalised (``D`` km, ``N`` tens of vehicles, ``Z`` per charging point).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F  # noqa: N812
from torch.utils.tensorboard import SummaryWriter

from evcd.experiments import evaluate_policy, make_sweep_env


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--envs", type=int, default=16, help="targets co-simulated per SUMO run")
    p.add_argument("--decisions", type=int, default=12_000, help="decisions to train on (all targets)")
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--buffer-size", type=int, default=10_000)
    p.add_argument("--gamma", type=float, default=0.9)
    p.add_argument("--batch-size", type=int, default=32)
    p.add_argument("--target-update", type=int, default=500, help="decisions between target-network copies")
    p.add_argument("--start-e", type=float, default=1.0)
    p.add_argument("--end-e", type=float, default=0.05)
    p.add_argument("--exploration-fraction", type=float, default=0.5, help="of the decisions")
    p.add_argument("--learning-starts", type=int, default=500, help="decisions before learning")
    p.add_argument("--train-frequency", type=int, default=4, help="decisions per gradient step")
    p.add_argument("--episodes", type=int, default=50, help="held-out evaluation episodes")
    p.add_argument("--logdir", default="outputs/cleanrl_dqn", help="TensorBoard runs go below it")
    p.add_argument("--override", action="append", default=[], help="a Hydra override (repeatable)")
    return p.parse_args()


class QNetwork(nn.Module):
    def __init__(self, obs_dim: int, n_actions: int) -> None:
        super().__init__()
        self.network = nn.Sequential(nn.Linear(obs_dim, 120), nn.ReLU(), nn.Linear(120, 84), nn.ReLU(),
                                     nn.Linear(84, n_actions))  # fmt: skip

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.network(x)


class ReplayBuffer:
    """A numpy ring of transitions: observation, action, reward, next observation, terminated."""

    def __init__(self, size: int, obs_dim: int) -> None:
        self.obs, self.next_obs = np.zeros((size, obs_dim), np.float32), np.zeros((size, obs_dim), np.float32)
        self.actions, self.rewards = np.zeros(size, np.int64), np.zeros(size, np.float32)
        self.terminated = np.zeros(size, np.float32)
        self.size, self.pos, self.full = size, 0, False

    def add(self, obs: np.ndarray, action: int, reward: float, next_obs: np.ndarray, done: bool) -> None:
        i = self.pos
        self.obs[i], self.actions[i], self.rewards[i] = obs, action, reward
        self.next_obs[i], self.terminated[i] = next_obs, done
        self.pos = (i + 1) % self.size
        self.full = self.full or self.pos == 0

    def sample(self, n: int, rng: np.random.Generator) -> tuple[torch.Tensor, ...]:
        idx = rng.integers(0, self.size if self.full else self.pos, n)
        return tuple(torch.from_numpy(a[idx]) for a in (self.obs, self.actions, self.rewards, self.next_obs,
                                                          self.terminated))  # fmt: skip


def linear_schedule(start_e: float, end_e: float, duration: int, t: int) -> float:
    return max(end_e, start_e + (end_e - start_e) * t / max(duration, 1))


def evaluate(q: QNetwork, overrides: list[str], episodes: int, seed: int) -> tuple[float, float]:
    """Mean travel time (s) of the greedy policy and of queue_aware on the same held-out episodes
    (evcd's own evaluation: :func:`evcd.experiments.evaluate_policy`)."""

    @torch.no_grad()
    def greedy(obs: np.ndarray) -> int:
        return int(q(torch.from_numpy(obs)).argmax())

    report = evaluate_policy(greedy, "peak", episodes, seed, rules=("queue_aware",), overrides=overrides)
    return report.summary["policy"].mean_travel_time, report.summary["queue_aware"].mean_travel_time


def main() -> None:
    args = parse_args()
    run = Path(args.logdir) / f"seed{args.seed}_{int(time.time())}"
    writer = SummaryWriter(str(run))
    table = "\n".join(f"|{key}|{value}|" for key, value in vars(args).items())
    writer.add_text("hyperparameters", f"|param|value|\n|-|-|\n{table}")
    rng = np.random.default_rng(args.seed)
    torch.manual_seed(args.seed)

    envs = make_sweep_env(args.envs, experiment="peak", split="train", overrides=args.override)
    obs_dim, n_actions = envs.single_observation_space.shape[0], int(envs.single_action_space.n)
    q, target = QNetwork(obs_dim, n_actions), QNetwork(obs_dim, n_actions)
    target.load_state_dict(q.state_dict())
    optimizer = torch.optim.Adam(q.parameters(), lr=args.lr)
    rb = ReplayBuffer(args.buffer_size, obs_dim)

    obs, _ = envs.reset(seed=args.seed)
    decisions, start = 0, time.time()
    while decisions < args.decisions:
        epsilon = linear_schedule(args.start_e, args.end_e, int(args.exploration_fraction * args.decisions),
                                  decisions)  # fmt: skip
        with torch.no_grad():
            greedy = q(torch.from_numpy(obs)).argmax(dim=1).numpy()
        explore = rng.random(args.envs) < epsilon
        actions = np.where(explore, rng.integers(0, n_actions, args.envs), greedy)
        # a truncated episode (stuck, time cap, the sweep's end) still bootstraps: only termination cuts it
        next_obs, rewards, terminated, _truncated, infos = envs.step(actions)

        # SAME_STEP autoreset: an ended slot's real last observation is in infos["final_obs"]
        real_next = next_obs.copy()
        if "final_obs" in infos:
            ended = infos["_final_obs"]
            real_next[ended] = infos["final_obs"][ended]
            for slot in np.flatnonzero(ended):
                writer.add_scalar("charts/travel_time", infos["final_info"]["travel_time"][slot], decisions)
                writer.add_scalar("charts/charged", float(terminated[slot]), decisions)
        for i in range(args.envs):
            rb.add(obs[i], actions[i], rewards[i], real_next[i], terminated[i])
        obs = next_obs

        for _ in range(args.envs):  # one vector step is --envs decisions
            decisions += 1
            if decisions > args.learning_starts and decisions % args.train_frequency == 0:
                b_obs, b_actions, b_rewards, b_next, b_terminated = rb.sample(args.batch_size, rng)
                with torch.no_grad():
                    best_next = target(b_next).max(dim=1).values
                    td_target = b_rewards + args.gamma * best_next * (1 - b_terminated)
                old = q(b_obs).gather(1, b_actions[:, None]).squeeze(1)
                loss = F.mse_loss(td_target, old)
                optimizer.zero_grad()
                loss.backward()
                optimizer.step()
                if decisions % 100 == 0:
                    writer.add_scalar("losses/td_loss", loss.item(), decisions)
                    writer.add_scalar("losses/q_values", old.mean().item(), decisions)
                    writer.add_scalar("charts/epsilon", epsilon, decisions)
                    rate = decisions / (time.time() - start)
                    writer.add_scalar("charts/decisions_per_second", rate, decisions)
            if decisions % args.target_update == 0:
                target.load_state_dict(q.state_dict())
    envs.close()
    writer.close()

    dqn, rule = evaluate(q, args.override, args.episodes, args.seed)
    print(f"trained {decisions} decisions in {time.time() - start:.0f} s; logs in {run}")
    print(f"held-out: DQN {dqn:.1f} s, queue_aware {rule:.1f} s on the same {args.episodes} episodes")


if __name__ == "__main__":
    main()
