"""Train stable-baselines3's PPO or DQN in an evcd experiment's world, then evaluate it with evcd's own
evaluation on the episodes ``scripts/train.py`` evaluates its agents on, beside the rules.

    pip install -e ".[sb3]"
    python scripts/train_sb3.py sb3=ppo evs=400                       # the README job's world
    python scripts/train_sb3.py -m sb3=ppo,dqn seed=0,1,2,3,4         # five seeds of each
    python scripts/train_sb3.py sb3=dqn sb3.params.learning_rate=0.001 sb3.timesteps=20000

Training: SB3's own ``learn`` on the experiment's training days and window, through the batched
engine as a vector environment (``sb3.envs`` targets on one decision clock per SUMO run;
:mod:`evcd.experiments.sb3_train`), for ``sb3.timesteps`` decisions. Evaluation: the trained policy
(deterministic) as an evcd dispatcher, through :func:`evcd.loops.train.train_and_evaluate` with the
same runner, episodes, baselines, paired intervals and files as any ``train.py`` run; its
``results.json`` names the agent ``sb3_ppo`` / ``sb3_dqn`` (so ``scripts/make_table.py`` reads these
runs beside ``train.py``'s) and holds SB3's training in ``training``. Also written: ``sb3_model.zip``
(SB3's own format, ``PPO.load``) and ``tensorboard/``. Settings: ``conf/train_sb3.yaml``, the
algorithm's in ``conf/sb3/``. Bad settings stop the run with exit code 2 before SUMO starts.
"""

from __future__ import annotations

import json
import logging
from pathlib import Path
from typing import Any

import hydra
import torch
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from evcd.cli.errors import stop_on_bad_setting
from evcd.cli.run_record import write_run_record
from evcd.env import ChargingNavEnv
from evcd.env.runners import check_engine, make_runner
from evcd.experiments.schema import register_configs
from evcd.experiments.worlds import check_forecaster, split_days, split_kwargs
from evcd.loops.hindsight import check_rule, make_dispatcher
from evcd.loops.run_files import RESULTS_JSON
from evcd.loops.seeds import baseline_rng
from evcd.loops.train import TrainSettings, train_and_evaluate
from evcd.loops.train_state import check_run_dir
from evcd.utils.atomic import atomic_write_json
from evcd.utils.validation import check_int

log = logging.getLogger("train_sb3")

MODEL_ZIP = "sb3_model.zip"


def build(cfg: DictConfig) -> dict[str, Any]:
    """Everything the run needs, checked before any simulation starts (SB3 is imported here: the
    optional extra)."""
    from evcd.experiments.sb3_train import SB3Settings

    if str(cfg.task) != "single" or str(cfg.regime).startswith("fleet"):
        raise ValueError(
            f"task={cfg.task}, regime {cfg.regime!r}: train_sb3.py trains the single target "
            "(the fleet's multi-agent form is evcd.experiments.parallel_env)"
        )
    check_forecaster(cfg)
    seed = check_int("seed", cfg.seed, minimum=0)
    train_days, eval_days = split_days(cfg, "train", seed), split_days(cfg, "eval", seed)
    if set(train_days) & set(eval_days):
        raise ValueError(f"train days {list(train_days)} and evaluation days {list(eval_days)} overlap")
    sb3 = OmegaConf.to_container(cfg.sb3, resolve=True)
    settings = SB3Settings(
        str(sb3["algo"]),
        sb3["envs"],
        sb3["timesteps"],
        dict(sb3.get("params") or {}),
        bool(sb3.get("normalize_reward", False)),
    )
    eval_settings = TrainSettings(
        episodes=0,
        eval_episodes=check_int("eval.episodes", cfg.eval.episodes, minimum=1),
        seed=seed,
        progress=bool(cfg.progress),
        resamples=check_int("eval.bootstrap_resamples", cfg.eval.bootstrap_resamples, minimum=1),
    )
    check_int("torch_threads", cfg.torch_threads, minimum=1)
    engine, batch = check_engine(cfg.engine, cfg.batch_episodes)
    train_env = ChargingNavEnv(**{**split_kwargs(cfg, "train", seed), "normalize_obs": True})
    eval_env = ChargingNavEnv(**split_kwargs(cfg, "eval", seed))
    baselines = {str(rule): make_dispatcher(check_rule(rule, "eval.baselines"), eval_env, baseline_rng(seed))
                 for rule in cfg.eval.baselines}  # fmt: skip
    return {
        "sb3": settings,
        "eval_settings": eval_settings,
        "train_env": train_env,
        "eval_env": eval_env,
        "baselines": baselines,
        "runner": lambda phase: make_runner(eval_env, engine, batch),
    }


def run_config(cfg: DictConfig, label: str) -> dict[str, Any]:
    """The run's resolved settings as ``results.json`` stores them: ``agent`` is the SB3 block (named
    ``label``), and the DQN ``learner`` block, which SB3 does not read, is left out."""
    config = OmegaConf.to_container(cfg, resolve=True)
    config.pop("learner", None)
    config["agent"] = {"name": label, **config.pop("sb3")}
    return config


def train(cfg: DictConfig) -> float:
    """Train and evaluate the run of ``cfg`` in Hydra's run directory; return the evaluation mean travel
    time (what a sweeper minimises)."""
    from evcd.experiments.sb3_train import SB3Policy, save_model, train_sb3

    out_dir = Path(HydraConfig.get().runtime.output_dir)
    parts = build(cfg)
    check_run_dir(out_dir, resume=False)
    if (out_dir / MODEL_ZIP).exists():
        raise FileExistsError(
            f"{out_dir / MODEL_ZIP} exists: use a new run directory (nothing is overwritten)"
        )
    torch.set_num_threads(int(cfg.torch_threads))
    settings, train_env = parts["sb3"], parts["train_env"]
    write_run_record(out_dir, cfg)
    log.info(
        "%s on %s, evs=%s, train days %s, eval days %s, seed %d, %d decisions -> %s",
        settings.label,
        train_env.scenario.root,
        cfg.evs,
        list(train_env.config.demand_seeds),
        list(parts["eval_env"].config.demand_seeds),
        int(cfg.seed),
        settings.timesteps,
        out_dir,
    )
    model, report = train_sb3(settings, train_env, int(cfg.seed), out_dir / "tensorboard", bool(cfg.progress))
    save_model(model, out_dir / MODEL_ZIP)
    log.info(
        "trained %d decisions (%d episodes, %d cut or truncated) in %.0f s (%.1f decisions/s), %d "
        "gradient steps",
        report.timesteps,
        report.episodes,
        report.truncated,
        report.wall_s,
        report.timesteps / max(report.wall_s, 1e-9),
        report.gradient_steps,
    )
    policy = SB3Policy.for_env(parts["eval_env"], model, settings.label)
    result = train_and_evaluate(
        policy,
        parts["runner"],
        parts["eval_settings"],
        out_dir,
        baselines=parts["baselines"],
        config=run_config(cfg, settings.label),
    )
    record_training(out_dir / RESULTS_JSON, report.to_dict())
    s = result.evaluation.summary
    log.info(
        "%s, evs=%s, seed=%d: mean travel time %.1f s (95%% CI %.1f-%.1f) over %d of %d evaluation episodes",
        settings.label,
        cfg.evs,
        int(cfg.seed),
        s.mean_travel_time,
        s.ci_low,
        s.ci_high,
        s.completed,
        s.episodes,
    )
    for name, p in result.paired.items():
        log.info(
            "vs %s on the same %d episodes: %.1f s vs %.1f s, difference %+.1f s (95%% CI %+.1f to %+.1f)",
            name,
            p["pairs"],
            p["agent_mean"],
            p["baseline_mean"],
            p["mean_difference"],
            p["ci_low"],
            p["ci_high"],
        )
    return float(s.mean_travel_time)


def record_training(path: Path, training: dict[str, Any]) -> None:
    """Put SB3's training (``training``) into the run's ``results.json`` (rewritten atomically): the
    evaluation wrote the counters of evcd's trainer, which did not train this policy."""
    data = json.loads(path.read_text())
    data["training"] = {**data.get("training", {}), **training, "episodes_done": training["episodes"]}
    atomic_write_json(path, data)


register_configs(Path(__file__).resolve().parents[1] / "conf")


@hydra.main(version_base="1.3", config_path="../conf", config_name="train_sb3")
def main(cfg: DictConfig) -> float:
    """Hydra entry point; a bad setting exits with code 2 (in a multirun only its job fails)."""
    try:
        return train(cfg)
    except (ValueError, FileNotFoundError, FileExistsError) as exc:
        stop_on_bad_setting(exc, log, Path(HydraConfig.get().runtime.output_dir), cfg)


if __name__ == "__main__":
    main()
