"""Train an agent and evaluate it beside greedy on held-out episodes.

    python scripts/train.py agent=dueling_ddqn evs=400
    python scripts/train.py -m agent=dqn,dueling_ddqn evs=200,300,400          # one run directory per job
    python scripts/train.py agent=dqn experiment=paper                          # the paper's protocol
    python scripts/train.py agent=greedy                                        # rules: evaluation only
    python scripts/train.py agent=hindsight                                     # best station in hindsight
    python scripts/train.py -m experiment=table agent=random,greedy,queue_aware,hindsight,dqn,dueling_ddqn \
        seed=0,1,2,3,4 evs=200,300,400                                          # the results table (joblib)
    python scripts/train.py resume=true hydra.run.dir=outputs/train/<run>       # continue a run
    python scripts/train.py experiment=fleet agent=dueling_ddqn                 # the fleet (docs/FLEET.md)
    python scripts/train.py experiment=fleet agent=fleet_bound                  # its clairvoyant bound
    tensorboard --logdir outputs/

Everything is in ``conf/train.yaml`` (and ``conf/experiment/``); see :mod:`evcd.loops.train` for what a
run does and writes; ``scripts/make_table.py`` turns a sweep into the results table. Bad settings
stop the run with exit code 2 and a message naming the value, before SUMO starts (in a multirun
only that job fails; the others run, then the sweep exits with code 1).
"""

from __future__ import annotations

import logging
import sys
from pathlib import Path
from typing import Any

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from evcd.agents import agent_class, make_agent_for_env
from evcd.cli.errors import refuse_removed_settings, stop_on_bad_setting
from evcd.cli.params import agent_params, check_learner_overrides, learner_config
from evcd.cli.run_record import write_run_record
from evcd.env import ChargingNavEnv
from evcd.env.day_builds import available_cores
from evcd.env.fleet import FleetEnv
from evcd.env.runners import FleetRunner, check_engine, make_runner
from evcd.experiments.schema import register_configs
from evcd.experiments.worlds import check_forecaster, split_days, split_kwargs
from evcd.loops.beside import MIN_EPISODES, RunnerRecipe, rule_episodes
from evcd.loops.fleet import fleet_dispatcher_learns
from evcd.loops.fleet_bound import fleet_learns, make_fleet_dispatcher
from evcd.loops.hindsight import check_rule, dispatcher_learns, make_dispatcher
from evcd.loops.seeds import agent_rng, baseline_rng
from evcd.loops.tasks import TASKS
from evcd.loops.train import TrainSettings, train_and_evaluate
from evcd.loops.validation import ValidationSettings
from evcd.planner import MissingSolverError
from evcd.utils.checkpoint import CheckpointError
from evcd.utils.validation import check_int

log = logging.getLogger("train")


def check_task(cfg: DictConfig) -> str:
    """The run's task, if its regime is made for it: ``task=fleet`` trains in a fleet regime
    (``experiment=fleet``: episodes, checkpoints and validation sized for fleet episodes, which last
    ~100 single-target episodes each), and a fleet regime trains the fleet.

    Raises:
        ValueError: the task and the regime do not go together (the message says what to pass).
    """
    task, regime = str(cfg.task), str(cfg.regime)
    if task not in ("single", "fleet"):
        raise ValueError(f"task={task!r}: must be single or fleet")
    if task == "fleet" and not regime.startswith("fleet"):
        raise ValueError(f"task=fleet with experiment regime {regime!r}: train the fleet with "
                         "experiment=fleet (its episodes, checkpoints and validation are sized for fleet "
                         "episodes)")  # fmt: skip
    if task == "single" and regime.startswith("fleet"):
        raise ValueError(f"regime {regime!r} is the fleet's: it needs task=fleet")
    return task


def _train_days(cfg: DictConfig, seed: int) -> tuple[int, ...]:
    """The training days, checked with the evaluation days (:func:`~evcd.experiments.worlds.split_days`:
    with ``eval.day_per_seed`` each seed has its own held-out days)."""
    train_days, eval_days = split_days(cfg, "train", seed), split_days(cfg, "eval", seed)
    if tuple(cfg.env.demand_seeds) != train_days:
        raise ValueError(f"env.demand_seeds={list(cfg.env.demand_seeds)}: train.py sets it from "
                         f"train.days (and eval.days); set those instead")  # fmt: skip
    if set(train_days) & set(eval_days):
        log.warning("train.days and eval.days share %s: the evaluation is not on unseen traffic",
                    sorted(set(train_days) & set(eval_days)))  # fmt: skip
    return train_days


def _settings(cfg: DictConfig, seed: int, min_episodes: int) -> dict[str, Any]:
    """The :class:`TrainSettings` of both tasks, checked (a fleet run has ``min_episodes`` 1: it is
    made for a learner)."""
    return {
        "episodes": check_int("train.episodes", cfg.train.episodes, minimum=min_episodes),
        "eval_episodes": check_int("eval.episodes", cfg.eval.episodes, minimum=1),
        "seed": seed,
        "checkpoint_every": check_int("train.checkpoint_every", cfg.train.checkpoint_every, minimum=0),
        "progress": bool(cfg.progress),
        "log_window": check_int("train.log_window", cfg.train.log_window, minimum=1),
        "resamples": check_int("eval.bootstrap_resamples", cfg.eval.bootstrap_resamples, minimum=1),
        "validation": ValidationSettings(
            cfg.train.validation.every,
            cfg.train.validation.episodes,
            cfg.train.validation.select_best,
        ),
    }


def build(cfg: DictConfig) -> dict[str, Any]:
    """Everything the run needs, checked before any simulation starts."""
    seed = check_int("seed", cfg.seed, minimum=0)
    train_days = _train_days(cfg, seed)
    settings = TrainSettings(
        **_settings(cfg, seed, min_episodes=0),
        rotate_days=len(train_days) if bool(cfg.train.rotate_days) else 0,
    )
    check_int("torch_threads", cfg.torch_threads, minimum=1)
    engine, batch = check_engine(cfg.engine, cfg.batch_episodes)
    name, params = agent_params(cfg)
    if dispatcher_learns(name) and settings.episodes < 1:
        raise ValueError(f"train.episodes={settings.episodes}: agent {name!r} learns, so it needs >= 1")
    if params.get("checkpoint") is not None:
        raise ValueError("agent.checkpoint is for scripts/evaluate.py; to continue a training run use "
                         "resume=true with its hydra.run.dir")  # fmt: skip
    params.pop("checkpoint", None)
    kwargs = {phase: split_kwargs(cfg, phase, seed) for phase in ("train", "eval")}
    envs = {phase: ChargingNavEnv(**kwargs[phase]) for phase in ("train", "eval")}
    # validates every environment value; loads the scenario; no SUMO yet
    rules: dict[str, Any] = {}
    if settings.validation.every and dispatcher_learns(name):
        kwargs["validation"] = split_kwargs(cfg, "tuning", seed)
        envs["validation"] = ChargingNavEnv(**kwargs["validation"])
        rules = {str(r): make_dispatcher(str(check_rule(r, "train.validation.rules")), envs["validation"],
                                         baseline_rng(seed)) for r in cfg.train.validation.rules}  # fmt: skip
    agent = make_dispatcher(name, envs["train"], agent_rng(settings.seed), **params)
    check_learning_starts(agent, settings.episodes, envs["train"].config)
    baselines = {}
    for rule in cfg.eval.baselines:
        check_rule(rule, "eval.baselines")
        baselines[str(rule)] = make_dispatcher(str(rule), envs["eval"], baseline_rng(settings.seed))
    return {"settings": settings, "agent": agent, "baselines": baselines, "envs": envs, "rules": rules,
            "runner": lambda phase: make_runner(envs[phase], engine, batch),
            "recipe": RunnerRecipe(kwargs, engine, batch)}  # fmt: skip


def check_learning_starts(agent: Any, episodes: int, env_config: Any) -> None:
    """Refuse a learner that cannot take one gradient step: ``learning_starts`` above the transitions
    ``episodes`` training episodes can hold at most (an episode decides at most once per
    ``decision_interval`` until ``max_travel_time``). The twin of DQNConfig's ``batch_size`` check;
    :func:`evcd.loops.best_policy.check_learned` refuses to report a learner that took none."""
    starts = getattr(getattr(agent, "config", None), "learning_starts", None)
    if starts is None or not getattr(agent, "learns", False):
        return
    per_episode = int(env_config.max_travel_time // env_config.decision_interval) + 1
    if starts > episodes * per_episode:
        raise ValueError(f"learner.learning_starts={starts}: the {episodes} training episodes hold at most "
                         f"{episodes * per_episode} transitions ({per_episode} each: max_travel_time / "
                         "decision_interval), so the network would never learn; lower learning_starts or "
                         "raise train.episodes")  # fmt: skip


def _fleet_rule(name: Any, env: FleetEnv, seed: int, key: str) -> Any:
    if fleet_dispatcher_learns(name):
        raise ValueError(f"{key}: {name!r} is not a rule (the fleet's rules: random, greedy, queue_aware, "
                         "reservation, central)")  # fmt: skip
    return make_agent_for_env(str(name), env, baseline_rng(seed))


def build_fleet(cfg: DictConfig) -> dict[str, Any]:
    """``task=fleet``: everything the fleet run needs, checked before any simulation starts."""
    seed = check_int("seed", cfg.seed, minimum=0)
    _train_days(cfg, seed)
    settings = TrainSettings(**_settings(cfg, seed, min_episodes=1))
    check_int("torch_threads", cfg.torch_threads, minimum=1)
    params: dict[str, Any] = OmegaConf.to_container(cfg.agent, resolve=True)
    name = str(params.pop("name"))
    learns = fleet_learns(name)  # unknown or single-only -> ValueError listing the fleet's
    if params.pop("checkpoint", None) is not None:
        raise ValueError("agent.checkpoint is for scripts/evaluate.py; to continue a training run use "
                         "resume=true with its hydra.run.dir")  # fmt: skip
    if learns and agent_class(name).learner_block:
        params["config"] = learner_config(cfg.learner)
    # refuses the single target's options; validates every value (guided_share in (0, 1]); no SUMO yet
    envs = {split: FleetEnv(**split_kwargs(cfg, split, seed)) for split in ("train", "eval")}
    rules: dict[str, Any] = {}
    if settings.validation.every and learns:
        envs["validation"] = FleetEnv(**split_kwargs(cfg, "tuning", seed))
        rules = {str(r): _fleet_rule(r, envs["validation"], seed, "train.validation.rules")
                 for r in cfg.train.validation.rules}  # fmt: skip
    for env in envs.values():
        env.check_days()  # every day has EVs to guide (its route file; no SUMO)
    # the agent, or the clairvoyant bound (agent=fleet_bound: planned, then played, per episode)
    agent = make_fleet_dispatcher(name, envs["train"], agent_rng(seed), **params)
    baselines = {str(r): _fleet_rule(r, envs["eval"], seed, "eval.baselines") for r in cfg.eval.baselines}
    return {"settings": settings, "agent": agent, "baselines": baselines, "envs": envs, "rules": rules,
            "runner": lambda phase: FleetRunner(envs[phase])}  # fmt: skip


def fleet_report_lines(result: Any, evs: int) -> list[str]:
    """A fleet run's outcome: training, the guided EVs' and everybody's travel times, the pairs."""
    s, t, seed = result.evaluation.summary, result.training, result.evaluation.seed
    lines = []
    if t["episodes"]:
        lines.append(
            f"trained {t['episodes']} fleet episodes, {t['transitions']} agent steps, {t['gradient_steps']} "
            f"gradient steps in {t['wall_s']:.0f} s ({t['transitions_per_second']:.1f} agent steps/s; day "
            f"builds {t['day_build_s']:.0f} s, validation {t['validation_s']:.0f} s)"
        )
    lines.append(
        f"{result.evaluation.agent}, evs={evs}, seed={seed}: guided EVs {s.guided_travel:.1f} s (95% CI "
        f"{s.guided_travel_ci[0]:.1f}-{s.guided_travel_ci[1]:.1f}), all EVs {s.all_travel:.1f} s, "
        f"herding {s.herding:.2f}, {s.truncated} of {s.guided} guided EVs truncated, over "
        f"{s.episodes} fleet episodes"
    )
    for name, measures in result.paired.items():
        for key, p in measures.items():
            lines.append(
                f"vs {name}, {key} on the same {p['pairs']} episodes: {p['agent_mean']:.1f} s vs "
                f"{p['baseline_mean']:.1f} s, difference {p['mean_difference']:+.1f} s (95% CI "
                f"{p['ci_low']:+.1f} to {p['ci_high']:+.1f}); lower in {p['agent_faster']}, higher in "
                f"{p['agent_slower']}"
            )
    return lines


def train(cfg: DictConfig) -> float:
    """Run the training described by ``cfg`` in Hydra's run directory; return the evaluation mean
    travel time (what a sweeper minimises; with ``task=fleet`` the guided EVs')."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    check_learner_overrides(str(cfg.agent.name), HydraConfig.get().overrides.task)
    check_forecaster(cfg)
    fleet = check_task(cfg) == "fleet"
    parts = build_fleet(cfg) if fleet else build(cfg)
    torch.set_num_threads(int(cfg.torch_threads))
    envs, agent, settings = parts["envs"], parts["agent"], parts["settings"]
    share = f", guided_share {envs['train'].guided_share}" if fleet else ""
    log.info("%s%r on %s, evs=%s%s, train days %s, eval days %s, seed %d -> %s", "fleet: " if fleet else "",
             agent, envs["train"].scenario.root, cfg.evs, share, list(envs["train"].config.demand_seeds),
             list(envs["eval"].config.demand_seeds), settings.seed, out_dir)  # fmt: skip
    result = train_and_evaluate(
        agent,
        parts["runner"],
        settings,
        out_dir,
        baselines=parts["baselines"],
        resume=bool(cfg.resume),
        config=OmegaConf.to_container(cfg, resolve=True),
        validation_rules=parts["rules"],
        on_start=lambda: write_run_record(out_dir, cfg),  # once the run directory passed its checks
        beside=_beside(parts),
    )
    for line in (fleet_report_lines if fleet else report_lines)(result, cfg.evs):
        log.info("%s", line)
    return TASKS[result.evaluation.task].score(result.evaluation.summary)


def _beside(parts: dict[str, Any]) -> RunnerRecipe | None:
    """The runners of a second process that plays a learner's rules while it trains (evcd.loops.beside),
    where a core is free and the rules play enough episodes to pay for starting it."""
    recipe = parts.get("recipe")
    if recipe is None or available_cores() < 2:
        return None
    enough = rule_episodes(parts["settings"], parts["rules"], parts["baselines"]) >= MIN_EPISODES
    return recipe if enough else None


def report_lines(result: Any, evs: int) -> list[str]:
    """The run's outcome in a few sentences: training, evaluation, the paired comparisons, per day."""
    s, t = result.evaluation.summary, result.training
    lines = []
    if t["episodes"]:
        targets = f", {t['target_updates']} target updates" if t["target_updates"] else ""
        lines.append(
            f"trained {t['episodes']} episodes, {t['transitions']} transitions, {t['gradient_steps']} "
            f"gradient steps{targets} in {t['wall_s']:.0f} s "
            f"({t['transitions_per_second']:.1f} transitions/s; day builds {t['day_build_s']:.0f} s)"
        )
    lines.append(
        f"{result.evaluation.agent}, evs={evs}, seed={result.evaluation.seed}: mean travel time "
        f"{s.mean_travel_time:.1f} s (95% CI {s.ci_low:.1f}-{s.ci_high:.1f}) over {s.completed} of "
        f"{s.episodes} evaluation episodes ({s.truncated} truncated)"
    )
    for name, p in result.paired.items():
        lines.append(
            f"vs {name} on the same {p['pairs']} episodes: {p['agent_mean']:.1f} s vs "
            f"{p['baseline_mean']:.1f} s, difference {p['mean_difference']:+.1f} s (95% CI "
            f"{p['ci_low']:+.1f} to {p['ci_high']:+.1f}); faster in {p['agent_faster']}, equal in "
            f"{p['equal']}, slower in {p['agent_slower']}"
        )
    runs = {result.evaluation.agent: result.evaluation.rows}
    runs.update({name: base.rows for name, base in result.baselines.items()})
    days = sorted({r.day for r in result.evaluation.rows})
    if len(days) > 1:
        for day in days:
            means = ", ".join(f"{name} {_day_mean(rows, day):.1f} s" for name, rows in runs.items())
            count = sum(r.day == day for r in result.evaluation.rows)
            lines.append(f"evaluation day {day} ({count} episodes): {means}")
    return lines


def _day_mean(rows: Any, day: int) -> float:
    charged = [r.travel_time for r in rows if r.day == day and not r.truncated]
    return sum(charged) / len(charged) if charged else float("nan")


register_configs(Path(__file__).resolve().parents[1] / "conf")


@hydra.main(version_base="1.3", config_path="../conf", config_name="train")
def main(cfg: DictConfig) -> float:
    """Hydra entry point; a bad setting exits with code 2, or in a multirun fails only its own job
    (:func:`~evcd.cli.errors.stop_on_bad_setting`)."""
    try:
        return train(cfg)
    except (ValueError, FileNotFoundError, FileExistsError, CheckpointError, MissingSolverError) as exc:
        stop_on_bad_setting(exc, log, Path(HydraConfig.get().runtime.output_dir), cfg)


if __name__ == "__main__":
    refuse_removed_settings(sys.argv[1:], log)
    main()
