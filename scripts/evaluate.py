"""Evaluate an agent: run it for a number of episodes and report its travel times.

    python scripts/evaluate.py agent=greedy evs=400 episodes=50 seed=0
    python scripts/evaluate.py -m agent=random,greedy,queue_aware evs=200,300,400 seed=0,1,2
    python scripts/evaluate.py agent=random env.departure_window=[25200,32400]   # morning only
    python scripts/evaluate.py agent=dueling_ddqn agent.checkpoint=outputs/train/<run>   # a trained policy
    python scripts/evaluate.py task=fleet agent=central evs=400 fleet.guided_share=0.5 episodes=5  # fleet
    python scripts/evaluate.py task=fleet agent=dqn agent.checkpoint=outputs/train/<fleet run> episodes=5
    python scripts/evaluate.py task=fleet agent=fleet_bound evs=600 episodes=5   # the clairvoyant bound

Writes ``episodes.csv`` (one row per episode) and ``results.json`` (summary, rows, config) into the
Hydra run directory and logs the summary: mean, median and 95% bootstrap interval of the mean
travel time over the episodes that ended charging, and how many were truncated. With ``task=fleet``
(docs/FLEET.md) every episode guides many EVs at once: ``fleet_episodes.csv`` (the measures of each
episode), ``results.json`` and ``fleet_trace.png`` (the first episode's queues and guided EVs heading to
each station).
"""

from __future__ import annotations

import dataclasses
import logging
import sys
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import hydra
from hydra.core.hydra_config import HydraConfig
from hydra.utils import to_absolute_path
from omegaconf import DictConfig, OmegaConf

from evcd.agents import agent_class, agent_defaults
from evcd.agents.saved_policy import saved_run
from evcd.cli.errors import refuse_removed_settings, stop_on_bad_setting
from evcd.cli.params import agent_params
from evcd.cli.run_record import write_run_record
from evcd.cli.trained_world import run_config, trained_world, warnings
from evcd.env import ChargingNavEnv
from evcd.env.fleet import FleetEnv
from evcd.env.runners import check_engine, make_runner
from evcd.env.runners.fleet import FleetRunner
from evcd.experiments.schema import register_configs
from evcd.experiments.worlds import env_kwargs, fleet_kwargs
from evcd.loops.evaluate import evaluate
from evcd.loops.fleet_bound import fleet_learns, make_fleet_dispatcher
from evcd.loops.hindsight import dispatcher_learns, make_dispatcher
from evcd.loops.run_files import FLEET_PNG, RESULTS_JSON, write_episodes_csv, write_results_json
from evcd.loops.seeds import agent_rng
from evcd.loops.tasks import TASKS
from evcd.planner import MissingSolverError
from evcd.report.scenario import format_table
from evcd.utils.checkpoint import CheckpointError
from evcd.utils.validation import check_int

log = logging.getLogger("evaluate")


def trained_policy(
    name: str, params: dict[str, Any], learns: bool
) -> tuple[dict[str, Any], Mapping[str, Any] | None, Mapping[str, Any] | None]:
    """The agent's arguments and, for a learner, its trained policy (``agent.checkpoint``), whose
    network settings replace the agent block's (:meth:`~evcd.agents.Agent.checkpoint_options`: the
    policy is rebuilt as it was trained), and the config of the run that trained it (where the
    checkpoint holds one); load the policy into the agent once it is made.

    Raises:
        ValueError: a learner without ``agent.checkpoint``.
        CheckpointError: the checkpoint is unreadable, does not hold an agent of this kind, or holds
            a policy another name stands for (``agent=dqn`` with a Dueling DDQN policy).
    """
    path = params.pop("checkpoint", None)
    if not learns:
        return params, None, None
    if path is None:
        raise ValueError(f"agent {name!r} learns: give the trained policy with agent.checkpoint=PATH "
                         "(a run directory of scripts/train.py or a checkpoint file)")  # fmt: skip
    path = to_absolute_path(str(path))
    policy, trained_config = saved_run(path)
    trained_config = run_config(path, trained_config)  # a run's best/: its run's
    try:
        options = agent_class(name).checkpoint_options(policy)
    except CheckpointError as exc:
        raise CheckpointError(f"checkpoint {path!r}: {exc}") from exc
    implied = agent_defaults(name)
    clash = {k: v for k, v in options.items() if k in implied and implied[k] != v}
    if clash:
        raise CheckpointError(f"checkpoint {path!r} holds a policy with {clash}, but agent={name} means "
                              f"{ {k: implied[k] for k in clash} }: evaluate it under the name it was "
                              "trained as")  # fmt: skip
    log.info("%s: the trained policy of %s", name, path)
    return {**params, **options}, policy, trained_config


def run(cfg: DictConfig, out_dir: Path) -> dict[str, Any]:
    """Evaluate the agent described by ``cfg`` (either task); write its files into ``out_dir``; return
    the summary with its headline as ``mean_travel_time`` (with ``task=fleet``: the guided EVs')."""
    # every check before SUMO starts
    episodes = check_int("episodes", cfg.episodes, minimum=1)
    seed = check_int("seed", cfg.seed, minimum=0)
    resamples = check_int("bootstrap_resamples", cfg.bootstrap_resamples, minimum=1)
    task = TASKS["fleet" if cfg.task == "fleet" else "single"]
    dispatcher = _fleet_dispatcher if task.name == "fleet" else _dispatcher
    name, agent, runner, trained_config = dispatcher(cfg, seed)
    config = OmegaConf.to_container(cfg, resolve=True)
    world = trained_world(trained_config, config)
    files = [out_dir / task.eval_csv, out_dir / RESULTS_JSON]
    if task.name == "fleet":
        files.append(out_dir / FLEET_PNG)
    for path in files:
        if path.exists():
            raise FileExistsError(f"{path} exists: evaluate into a fresh run directory")
    write_run_record(out_dir, cfg)  # every check passed
    log.info("%s%s on %s, evs=%s, %d episodes, seed %d", "fleet: " if task.name == "fleet" else "", agent,
             runner.env.scenario.root, cfg.evs, episodes, seed)  # fmt: skip
    for line in warnings(world):
        log.warning(line)
    try:
        runner.prepare()  # build the day snapshots now, so that no episode's wall time includes them
        result = evaluate(runner, agent, episodes, seed, progress=bool(cfg.progress), resamples=resamples)
    finally:
        runner.close()
    if world is not None:
        result = dataclasses.replace(result, extra={**result.extra, "trained_world": world})
    write_episodes_csv(result, files[0])
    write_results_json(result, files[1], config=config)
    task.figures(out_dir, result, {}, runner)
    s = result.summary
    if task.name == "fleet":
        log.info("episodes:\n%s", format_table([r.row() for r in result.rows], "{:.1f}"))
        log.info(
            "fleet %s, evs=%s, guided_share %s, seed %d: guided EVs %.1f s (95%% CI %.1f-%.1f), all EVs "
            "%.1f s, herding %.2f, %d of %d guided EVs truncated; %.1f s per episode",
            name, cfg.evs, runner.env.guided_share, seed, s.guided_travel, *s.guided_travel_ci, s.all_travel,
            s.herding, s.truncated, s.guided, s.mean_wall_s,
        )  # fmt: skip
    else:
        log.info("episodes:\n%s", format_table([_brief(r) for r in result.rows], "{:.0f}"))
        log.info(
            "%s, evs=%s, seed=%d: mean travel time %.1f s (95%% CI %.1f-%.1f), median %.1f s, over %d of %d "
            "episodes (%d truncated); %.2f s per episode",
            name, cfg.evs, seed, s.mean_travel_time, s.ci_low, s.ci_high, s.median_travel_time,
            s.completed, s.episodes, s.truncated, s.mean_wall_s,
        )  # fmt: skip
    log.info("wrote %s", ", ".join(map(str, files)))
    return {**dataclasses.asdict(s), "mean_travel_time": task.score(s)}


def _dispatcher(cfg: DictConfig, seed: int) -> tuple[str, Any, Any, Mapping[str, Any] | None]:
    """The single target's dispatcher (with its trained policy), runner and the trained policy's run
    config; no SUMO yet."""
    name, params = agent_params(cfg)  # unknown agent -> ValueError listing the known ones
    params, policy, trained_config = trained_policy(name, params, dispatcher_learns(name))
    engine, batch = check_engine(cfg.engine, cfg.batch_episodes)
    env = ChargingNavEnv(**env_kwargs(cfg))  # validates every env value; loads the scenario, no SUMO
    agent = make_dispatcher(name, env, agent_rng(seed), **params)
    if policy is not None:
        agent.load_state_dict(policy, policy_only=True)
    return name, agent, make_runner(env, engine, batch), trained_config


def _fleet_dispatcher(cfg: DictConfig, seed: int) -> tuple[str, Any, FleetRunner, Mapping[str, Any] | None]:
    """``task=fleet``: one dispatcher for every guided EV (with its trained policy), the fleet's
    runner and the trained policy's run config; no SUMO yet."""
    params: dict[str, Any] = OmegaConf.to_container(cfg.agent, resolve=True)
    name = str(params.pop("name"))
    params, policy, trained_config = trained_policy(name, params, fleet_learns(name))
    env = FleetEnv(**fleet_kwargs(cfg))  # validates every value; loads the scenario, no SUMO
    env.check_days()  # every day has EVs to guide (its routes, no SUMO)
    agent = make_fleet_dispatcher(name, env, agent_rng(seed), **params)  # or the clairvoyant bound
    if policy is not None:
        agent.load_state_dict(policy, policy_only=True)
    return name, agent, FleetRunner(env), trained_config


def _brief(row: Any) -> dict[str, Any]:
    keys = ("episode", "departure", "choices", "station_id", "travel_time", "queue_wait", "reason")
    return {k: getattr(row, k) for k in keys}


register_configs(Path(__file__).resolve().parents[1] / "conf")


@hydra.main(version_base="1.3", config_path="../conf", config_name="evaluate")
def main(cfg: DictConfig) -> float:
    """Hydra entry point; returns the mean travel time (for sweepers). A bad setting exits with code 2,
    or in a multirun fails only its own job (:func:`~evcd.cli.errors.stop_on_bad_setting`)."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    try:
        return run(cfg, out_dir)["mean_travel_time"]
    except (ValueError, FileNotFoundError, FileExistsError, CheckpointError, MissingSolverError) as exc:
        stop_on_bad_setting(exc, log, out_dir, cfg)


if __name__ == "__main__":
    refuse_removed_settings(sys.argv[1:], log)
    main()
