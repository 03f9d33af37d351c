"""TorchRL's multi-agent PPO on evcd's fleet: one policy shared by every guided EV (parameter
sharing), trained in the fleet table's world (``experiment=fleet``: 600 EVs, morning peak, every
charging EV guided) through TorchRL's own PettingZoo wrapper, data collector, GAE and clipped PPO loss.

    pip install -e ".[marl]"
    python examples/torchrl_fleet.py --batches 20                    # ~20 fleet episodes
    python examples/torchrl_fleet.py --batches 2 --frames 32 --override evs=300   # a quick look

TorchRL's wrapper reads every possible agent's observation at reset, while the fleet's agents join
mid-episode; so the fleet goes through its fixed-slot view (:class:`evcd.env.fleet.slots.FleetSlots`:
K slots that EVs occupy while on their way, inactive ones all zeros). The loss sees only the steps of
occupied slots (``info.active``), and an EV's last step (``info.ended``) ends its return, so GAE never
runs from one EV into the next of its slot. Observations come normalised (the fleet's ``[D, N, Z, H]``:
km, tens of vehicles, vehicles per charging point). The mean travel time of the EVs whose trips ended
in each batch is printed: the learning curve.
"""

from __future__ import annotations

import argparse

import torch
from tensordict.nn import TensorDictModule
from torch import nn
from torchrl.collectors import Collector
from torchrl.envs.libs.pettingzoo import PettingZooWrapper
from torchrl.modules import MLP, ProbabilisticActor
from torchrl.objectives import ClipPPOLoss, ValueEstimators

from evcd.env.fleet.slots import FleetSlots
from evcd.experiments import parallel_env

GROUP = "slot"  # TorchRL groups the agents slot_0 .. slot_{K-1} by their name


def make_env(split: str, overrides: list[str], slots: int, seed: int) -> PettingZooWrapper:
    """The fleet table's world for ``split`` in K slots, as a TorchRL environment."""
    fleet = FleetSlots(parallel_env(experiment="fleet", split=split, overrides=overrides), slots=slots)
    return PettingZooWrapper(fleet, use_mask=True, categorical_actions=True, done_on_any=False, seed=seed)


def make_modules(env: PettingZooWrapper) -> tuple[ProbabilisticActor, TensorDictModule]:
    """The shared policy and value networks: one MLP applied to every slot's observation."""
    obs_size = env.observation_spec[GROUP, "observation"].shape[-1]
    stations = int(env.full_action_spec[GROUP, "action"].space.n)
    logits = TensorDictModule(
        MLP(in_features=obs_size, out_features=stations, num_cells=[64, 64], activation_class=nn.Tanh),
        in_keys=[(GROUP, "observation")],
        out_keys=[(GROUP, "logits")],
    )
    actor = ProbabilisticActor(
        logits,
        in_keys={"logits": (GROUP, "logits")},
        out_keys=[(GROUP, "action")],
        distribution_class=torch.distributions.Categorical,
        return_log_prob=True,
        log_prob_key=(GROUP, "sample_log_prob"),
    )
    critic = TensorDictModule(
        MLP(in_features=obs_size, out_features=1, num_cells=[64, 64], activation_class=nn.Tanh),
        in_keys=[(GROUP, "observation")],
        out_keys=[(GROUP, "state_value")],
    )
    return actor, critic


def mark_ev_ends(data) -> None:
    """An EV's last step ends its return: the slot's done (for GAE) is the episode's end or its EV's."""
    ended = data.get(("next", GROUP, "info", "ended")).bool().unsqueeze(-1)
    for key in ("done", "terminated"):
        over = data.get(("next", key)).unsqueeze(-1).expand_as(ended)
        data.set(("next", GROUP, key), over | ended)


def main() -> None:
    parser = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    parser.add_argument("--batches", type=int, default=20, help="collect-and-learn rounds")
    parser.add_argument("--frames", type=int, default=180, help="fleet steps (60 s ticks) per batch")
    parser.add_argument(
        "--slots", type=int, default=64, help="fixed agent slots (>= EVs on their way at once)"
    )
    parser.add_argument("--epochs", type=int, default=4)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--override", action="append", default=[], help="a Hydra override (repeatable)")
    args = parser.parse_args()
    torch.manual_seed(args.seed)

    env = make_env("train", args.override, args.slots, args.seed)
    actor, critic = make_modules(env)
    loss = ClipPPOLoss(
        actor_network=actor,
        critic_network=critic,
        clip_epsilon=0.2,
        entropy_coeff=0.01,
        normalize_advantage=True,
    )
    loss.set_keys(
        reward=(GROUP, "reward"),
        action=(GROUP, "action"),
        value=(GROUP, "state_value"),
        sample_log_prob=(GROUP, "sample_log_prob"),
        done=(GROUP, "done"),
        terminated=(GROUP, "terminated"),
        advantage=(GROUP, "advantage"),
        value_target=(GROUP, "value_target"),
    )
    loss.make_value_estimator(ValueEstimators.GAE, gamma=0.99, lmbda=0.95)
    optim = torch.optim.Adam(loss.parameters(), lr=3e-4)
    initial = torch.nn.utils.parameters_to_vector(actor.parameters()).detach().clone()
    collector = Collector(
        env,
        actor,
        frames_per_batch=args.frames,
        total_frames=args.frames * args.batches,
        auto_register_policy_transforms=False,
    )
    for batch, data in enumerate(collector):
        mark_ev_ends(data)
        with torch.no_grad():
            loss.value_estimator(
                data, params=loss.critic_network_params, target_params=loss.target_critic_network_params
            )
        # the steps of occupied slots only: one sample per EV decision
        steps = data.get(GROUP)[data.get((GROUP, "info", "active")).bool()]
        for _ in range(args.epochs):
            parts = loss(_nested(steps))
            total = parts["loss_objective"] + parts["loss_critic"] + parts["loss_entropy"]
            optim.zero_grad()
            total.backward()
            nn.utils.clip_grad_norm_(loss.parameters(), 1.0)
            optim.step()
        collector.update_policy_weights_()
        ended = data.get(("next", GROUP, "info", "ended")).bool()
        travel = data.get(("next", GROUP, "info", "travel_time"))[ended]
        mean = f"{travel.nanmean().item():.1f} s" if travel.numel() else "-"
        print(
            f"batch {batch}: {steps.shape[0]} EV decisions, {int(ended.sum())} trips ended, "
            f"mean travel time {mean}",
            flush=True,
        )
    collector.shutdown()
    env.close()
    change = (torch.nn.utils.parameters_to_vector(actor.parameters()) - initial).norm().item()
    print(f"policy weights changed by {change:.3g} (L2)")


def _nested(steps):
    """The occupied slots' steps under the group key, as the loss reads them."""
    from tensordict import TensorDict

    return TensorDict({GROUP: steps}, batch_size=steps.batch_size)


if __name__ == "__main__":
    main()
