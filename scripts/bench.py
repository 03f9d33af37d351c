"""Benchmark the environment: fast vs paper episodes, overhead over raw SUMO, snapshot build.

    python scripts/bench.py                 # Jurong West, 400 EVs: ~25 min on 2 cores
    python scripts/bench.py --quick         # ends within about a minute (numbers are indicative)
    python scripts/bench.py --equivalence 50 --out equivalence.json   # fast vs paper |dT| only
    python scripts/bench.py --suite replay   # replay buffer only: sample + priority update (seconds)
    python scripts/bench.py --suite throughput   # batched engine vs single env, learning, 2 processes
    python scripts/bench.py --suite engines --episodes 200 --batch-sizes 25 100   # engine equivalence
    python scripts/bench.py --suite fleet --episodes 3   # a fleet episode vs its day alone (400 EVs, peak)
    python scripts/bench.py --suite determinism [train.py overrides ...]   # same seed, same result?
    python scripts/bench.py --suite vector --num-envs 16 --steps 200   # the sweep vector env vs single
    python scripts/bench.py --suite perturbed --episodes 2   # a day built calm vs perturbed (mixed, peak)
    python scripts/bench.py --suite planner --episodes 3 --time-limits 1 10   # the fleet's bound (.[bound])
    python scripts/bench.py --suite days                 # days built one after the other vs side by side
    python scripts/bench.py --suite reproduce --page readme hydra/launcher=joblib hydra.launcher.n_jobs=2

``--suite determinism`` trains the same short run twice (the README job cut to 200 training and 20
evaluation episodes, on ``--scenario`` with ``--evs``; train.py overrides given after the options
are applied last), each in a fresh process with its own heap layout (another working directory,
hash seed and an unrelated allocation first; the first run builds the days it lacks, the second
loads them), then compares every episode row and the SHA-256 of the final agent state
(:mod:`evcd.bench.determinism`): it prints ``identical`` or the first difference and exits 0 or 1.

``--suite reproduce`` runs a page's reproduce command (``scripts/reproduce.py``) on the page's small
version, each sweep cut to its first job, cold (an empty day cache) and then warm, and extrapolates the
whole page from them; ``--full DIR`` (a finished reproduction of the whole page) adds its measured wall
time and its ratio to the small version (:mod:`evcd.report.reproduce.cost`). Overrides after the options
go to every job (Hydra's, such as the launcher, to every sweep).

Every run also times the prioritized replay buffer: ``per_sample_update_us`` (sample a batch of 32
from 10,000 transitions and update its priorities; also as ``replay_batch_us``) and
``per_transition_us`` (the same per transition).

``--equivalence N`` runs N greedy episodes (departures 05:00-07:00) under both protocols and reports
``|T_fast - T_paper|``; the paper runs stop at charge start (``day_end=0``: what happens after the
target starts charging cannot change its travel time), which keeps 50 episodes under an hour.

Writes ``bench.json`` (``--out``) with the measured figures and every timed episode. Every figure
is measured in the same run, side by side. The ratios carry across machines; the absolute ones
(``per_sample_update_us``, the reproduce suite's minutes) and their goals hold for the machine that
measured them (the README's: 2 shared cores, no GPU).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import logging
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from evcd.bench import engines as engine_bench
from evcd.bench.equivalence import compare_protocols
from evcd.bench.protocols import run_bench
from evcd.bench.replay import time_replay
from evcd.cli.params import learner_config
from evcd.experiments.compose import compose_experiment
from evcd.scenario.demand import DemandConfig
from evcd.scenario.scenario import JURONG_WEST
from evcd.utils.atomic import atomic_write_text

log = logging.getLogger("bench")

CONF = Path(__file__).resolve().parents[1] / "conf"
SCRIPTS = Path(__file__).resolve().parent


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--scenario", type=Path, default=JURONG_WEST, help="scenario folder (default Jurong West)")
    p.add_argument("--evs", type=int, default=400, help="background EVs (default 400)")
    p.add_argument("--fast-episodes", type=int, default=20, help="fast episodes (default 20)")
    p.add_argument("--paper-episodes", type=int, default=3, help="paper episodes, first seeds (default 3)")
    p.add_argument("--cache-dir", type=Path, default=None, help="snapshot cache (default: a fresh temp dir)")
    p.add_argument("--out", type=Path, default=Path("bench.json"), help="result file (default bench.json)")
    p.add_argument("--force", action="store_true", help="overwrite an existing --out file")
    p.add_argument("--quick", action="store_true", help="small demand, short window, paper cut at +1 h")
    p.add_argument("--equivalence", type=int, default=0, metavar="N", help="only measure fast vs paper |dT|")
    p.add_argument("--suite", choices=("env", "replay", "throughput", "engines", "fleet", "determinism",
                                       "vector", "perturbed", "planner", "days", "reproduce"),
                   default="env",
                   help="env (default): episodes, SUMO, replay; replay: the replay buffer alone; "
                        "throughput: the batched engine's speed; engines: batched vs single; "
                        "fleet: a fleet episode against its day alone; determinism: the same "
                        "training twice in fresh processes, compared; vector: the sweep vector "
                        "environment against the single one, in the README job's world; perturbed: "
                        "the README job's day built calm and with every kind of perturbation; "
                        "planner: the fleet's clairvoyant bound read and solved on the fleet table's "
                        "episodes; days: the fleet table's held-out days of seed 0 built one after the "
                        "other and side by side; reproduce: a page's reproduce command on its small "
                        "version, cold and warm")  # fmt: skip
    p.add_argument("--episodes", type=int, default=200,
                   help="engines suite: episode seeds (default 200); fleet: episodes (~3); "
                        "perturbed: builds of each day (~2); planner: fleet episodes (~3)")  # fmt: skip
    p.add_argument("--guided-share", type=float, default=1.0,
                   help="fleet and planner suites: guided share (default 1)")  # fmt: skip
    p.add_argument(
        "--time-limits",
        type=float,
        nargs="+",
        default=[1.0, 10.0],
        help="planner suite: the solver's limits to compare (deterministic s; default 1 10)",
    )
    p.add_argument("--batch-sizes", type=int, nargs="+", default=[25],
                   help="engines suite: batch_episodes values to compare (default 25)")  # fmt: skip
    p.add_argument("--num-envs", type=int, default=16, help="vector suite: sub-environments (default 16)")
    p.add_argument("--steps", type=int, default=200, help="vector suite: vector steps (default 200)")
    p.add_argument("--sb3-timesteps", type=int, default=4096,
                   help="vector suite: SB3 PPO's timesteps via the sweep (0: none; .[sb3])")  # fmt: skip
    p.add_argument("--page", default="readme", help="reproduce suite: the page (docs/reproduce/<page>.yaml)")
    p.add_argument(
        "--full",
        type=Path,
        default=None,
        metavar="DIR",
        help="reproduce suite: a finished reproduce.py --out of the whole page, to compare with",
    )
    p.add_argument(
        "--work",
        type=Path,
        default=None,
        metavar="DIR",
        help="reproduce suite: a new folder for its runs (default outputs/bench/reproduce/<time>)",
    )
    p.add_argument(
        "overrides",
        nargs="*",
        help="determinism and reproduce suites: overrides for the jobs (e.g. agent=dqn)",
    )
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(levelname)s %(name)s: %(message)s")
    if args.evs < 0 or args.fast_episodes < 1 or args.paper_episodes < 0:
        log.error("need evs >= 0, fast-episodes >= 1, paper-episodes >= 0 (got %s, %s, %s)",
                  args.evs, args.fast_episodes, args.paper_episodes)  # fmt: skip
        return 2
    if args.out.exists() and not args.force:
        log.error("%s exists; pass --force to replace it", args.out)
        return 2
    if args.overrides and args.suite not in ("determinism", "reproduce"):
        log.error("overrides %s are for --suite determinism or reproduce only", args.overrides)
        return 2
    if args.suite == "determinism":
        return run_determinism(args)
    if args.suite == "reproduce":
        return run_reproduce(args)
    replay = time_replay()
    log.info("replay buffer: %.1f us per batch of 32 (sample + priority update), %.2f us per transition",
             replay["per_sample_update_us"], replay["per_transition_us"])  # fmt: skip
    replay_summary = {**replay, "goals": {"per_sample_update_us": "<= 100"}}
    if args.suite == "replay":
        atomic_write_text(args.out, json.dumps({"summary": replay_summary}, indent=1))
        log.info("wrote %s", args.out)
        return 0
    env_kwargs: dict = {"scenario": args.scenario, "evs": args.evs}
    if args.suite == "vector":
        return run_vector(args)
    if args.suite == "fleet":
        from evcd.bench.fleet import fleet_learning_rate, fleet_overhead

        fleet_kwargs = {**env_kwargs, "guided_share": args.guided_share, "cache_dir": args.cache_dir}
        learner = learner_config(compose_experiment("peak", conf_dir=CONF).learner)  # the default regime's
        try:
            report = fleet_overhead(fleet_kwargs, episodes=args.episodes)
            report["learning"] = fleet_learning_rate({**fleet_kwargs, "reward": "time"}, learner)
        except ValueError as exc:
            log.error("%s", exc)
            return 2
        report["fleet_transitions_per_second"] = report["learning"]["fleet_transitions_per_second"]
        atomic_write_text(args.out, json.dumps(report, indent=1))
        log.info("fleet_overhead %.2f (goal %s), fleet_transitions_per_second %.1f; wrote %s",
                 report["fleet_overhead"], report["goals"]["fleet_overhead"],
                 report["fleet_transitions_per_second"], args.out)  # fmt: skip
        return 0
    if args.suite == "planner":
        return run_planner(args)
    if args.suite == "days":
        return run_days(args)
    if args.suite == "perturbed":
        from evcd.bench.perturbed import perturbed_build_cost

        window = list(compose_experiment("peak", conf_dir=CONF).env.departure_window)
        report = perturbed_build_cost({**env_kwargs, "departure_window": window}, repeats=args.episodes)
        atomic_write_text(args.out, json.dumps(report, indent=1))
        log.info("perturbed_build_ratio %.2f (calm %.1f s, perturbed %.1f s, events %s); wrote %s",
                 report["perturbed_build_ratio"], report["calm_build_s"], report["perturbed_build_s"],
                 report["events"], args.out)  # fmt: skip
        return 0
    if args.suite in ("throughput", "engines"):
        report = run_engine_suite(args, env_kwargs, replay)
        atomic_write_text(args.out, json.dumps(report, indent=1))
        for key, value in report["summary"].items():
            log.info("%-30s %s", key, value)
        log.info("wrote %s", args.out)
        return 0
    if args.equivalence:
        window = (5 * 3600.0, 7 * 3600.0)
        diff = compare_protocols(
            args.equivalence, policy="greedy", departure_window=window, day_end=0.0,
            cache_dir=args.cache_dir, **env_kwargs,
        )  # fmt: skip
        report = {"equivalence": diff.summary(), "window": window, "seeds": diff.seeds,
                  "fast": diff.fast, "paper": diff.paper,
                  "fast_reasons": diff.fast_reasons, "paper_reasons": diff.paper_reasons}  # fmt: skip
        atomic_write_text(args.out, json.dumps(report, indent=1))
        log.info("fast vs paper: %s; wrote %s", diff.summary(), args.out)
        return 0
    paper_day_end = None
    if args.quick:
        # a night window: a short day build, light traffic; the paper protocol is cut 1 h after it
        env_kwargs |= {"departure_window": (3600.0, 4200.0), "demand": DemandConfig(evs=args.evs)}
        args.fast_episodes, args.paper_episodes = min(args.fast_episodes, 5), min(args.paper_episodes, 1)
        paper_day_end = 4200.0 + 3600.0
    else:
        env_kwargs |= {"departure_window": (6 * 3600.0, 22 * 3600.0)}
    try:
        result = run_bench(env_kwargs, args.fast_episodes, args.paper_episodes, args.cache_dir, paper_day_end)
    except (ValueError, FileNotFoundError) as exc:
        log.error("%s", exc)
        return 2
    summary = {**result.summary(), **replay}
    summary["goals"] = {**summary["goals"], **replay_summary["goals"]}
    report = {
        "summary": summary,
        "quick": args.quick,
        "config": {k: str(v) for k, v in result.config.items()},
        "fast": [dataclasses.asdict(e) for e in result.fast],
        "paper": [dataclasses.asdict(e) for e in result.paper],
        "raw_sumo_s": result.raw_sumo_s,
    }
    atomic_write_text(args.out, json.dumps(report, indent=1))
    for key, value in summary.items():
        log.info("%-45s %s", key, value)
    log.info("wrote %s", args.out)
    return 0


def run_vector(args: argparse.Namespace) -> int:
    """The sweep vector environment against the single environment in the README job's world
    (``experiment=peak``, its training days, queue_aware), both measured in this run."""
    from evcd.bench.vector import sweep_benchmark
    from evcd.experiments.worlds import split_kwargs

    overrides = [f"evs={args.evs}", f"scenario.path={args.scenario}"]
    if args.cache_dir is not None:
        overrides.append(f"env.cache_dir={args.cache_dir}")
    try:
        world = split_kwargs(compose_experiment("peak", overrides, conf_dir=CONF), "train", 0)
        report = sweep_benchmark(world, args.num_envs, args.steps, args.fast_episodes)
    except ValueError as exc:
        log.error("%s", exc)
        return 2
    report["world"] = {k: str(v) for k, v in world.items() if k != "demand"}
    if args.sb3_timesteps > 0:
        report["sb3_ppo"] = sb3_rate(world, args.num_envs, args.sb3_timesteps)
        sb3 = report["sb3_ppo"]
        log.info("SB3 PPO learning through the sweep (%d envs): %.1f decisions/s over %d",
                 args.num_envs, sb3["decisions_per_s"], sb3["decisions"])  # fmt: skip
    atomic_write_text(args.out, json.dumps(report, indent=1))
    s, one, eq = report["sweep"], report["single"], report["equivalence"]
    two = report["make_vector_env_2"]
    log.info("sweep (%d envs): %.1f decisions/s over %d decisions; single environment: %.1f decisions/s "
             "(%.1fx); make_vector_env(2): %.1f decisions/s (%.1fx)", args.num_envs, s["decisions_per_s"],
             s["decisions"], one["decisions_per_s"], report["speedup"], two["decisions_per_s"],
             report["speedup_vs_make_vector_env_2"])  # fmt: skip
    log.info("its %d episodes replayed alone (%d pairs): mean difference %+.1f s, mean |difference| %.1f s, "
             "%d identical; wrote %s", eq["replayed"], eq["pairs"], eq["mean_difference_s"],
             eq["mean_abs_difference_s"], eq["identical"], args.out)  # fmt: skip
    return 0


def sb3_rate(world: dict, num_envs: int, timesteps: int) -> dict:
    """stable-baselines3's PPO learning through the sweep (its default MLP, 128 steps per rollout,
    normalised observations): decisions per second, its first sweep's start (a snapshot load)
    included."""
    from stable_baselines3 import PPO

    from evcd.env import ChargingNavEnv
    from evcd.env.sweep import SweepVectorEnv
    from evcd.experiments.sb3 import SB3VecEnv

    venv = SB3VecEnv(SweepVectorEnv(ChargingNavEnv(**{**world, "normalize_obs": True}), num_envs))
    try:
        venv.seed(0)
        model = PPO("MlpPolicy", venv, n_steps=128, batch_size=256, seed=0, verbose=0)
        t0 = time.perf_counter()
        model.learn(total_timesteps=timesteps)
        wall = time.perf_counter() - t0
    finally:
        venv.close()
    return {"decisions": int(model.num_timesteps), "wall_s": wall,
            "decisions_per_s": model.num_timesteps / wall}  # fmt: skip


#: The determinism suite's run: the README job, shorter.
DETERMINISM_RUN = ("agent=dueling_ddqn", "train.episodes=200", "train.checkpoint_every=100",
                   "train.validation.every=0", "eval.episodes=20", "progress=false")  # fmt: skip


def run_determinism(args: argparse.Namespace) -> int:
    """Train the same run twice in fresh processes and compare them (module docstring)."""
    from evcd.bench.determinism import ALLOCATE_FIRST, compare_runs

    script = str(SCRIPTS / "train.py")
    work = Path(tempfile.mkdtemp(prefix="evcd-determinism-"))
    common = [*DETERMINISM_RUN, f"scenario.path={args.scenario}", f"evs={args.evs}"]
    if args.cache_dir is not None:
        common.append(f"env.cache_dir={args.cache_dir}")
    processes = [  # (hash seed, working directory, command)
        ("0", SCRIPTS.parent, [sys.executable, script]),
        ("1", work, [sys.executable, "-c", ALLOCATE_FIRST.format(script=script)]),
    ]
    runs = []
    for i, (hash_seed, cwd, cmd) in enumerate(processes, start=1):
        run = work / f"run{i}"
        log.info("run %d of 2 (fresh process, PYTHONHASHSEED=%s, in %s) -> %s", i, hash_seed, cwd, run)
        with open(work / f"run{i}.log", "w") as out:
            proc = subprocess.run([*cmd, *common, *args.overrides, f"hydra.run.dir={run}"], cwd=cwd,
                                  env={**os.environ, "PYTHONHASHSEED": hash_seed}, stdout=out,
                                  stderr=subprocess.STDOUT)  # fmt: skip
        if proc.returncode != 0:
            log.error("run %d failed (exit %d); its log: %s", i, proc.returncode, work / f"run{i}.log")
            return 2
        runs.append(run)
    report = compare_runs(*runs)
    report["overrides"] = [*common, *args.overrides]
    atomic_write_text(args.out, json.dumps(report, indent=1))
    if report["identical"]:
        log.info("identical: %s rows, %s transitions, policy sha256 %s; wrote %s", report["rows"],
                 report["transitions"][0], report["policy_sha256"][0], args.out)  # fmt: skip
        shutil.rmtree(work)
        return 0
    log.error("NOT identical: %s (runs kept in %s); wrote %s", report["first_difference"], work, args.out)
    return 1


def run_reproduce(args: argparse.Namespace) -> int:
    """The reproduce suite: a page's small version through scripts/reproduce.py, cold then warm."""
    from datetime import datetime

    from evcd.report.reproduce.cost import reproduce_cost
    from evcd.report.reproduce.spec import PageError, load_page, split_overrides

    work = args.work or Path("outputs") / "bench" / "reproduce" / datetime.now().strftime("%Y-%m-%d_%H-%M-%S")
    try:
        page = load_page(args.page, CONF.parent / "docs" / "reproduce")
        extra, hydra = split_overrides(args.overrides)
        report = reproduce_cost(page, work.resolve(), SCRIPTS, extra, hydra, full=args.full)
    except PageError as exc:
        log.error("%s", exc)
        return 2
    atomic_write_text(args.out, json.dumps(report, indent=1))
    log.info("page %s: small version (%d of %d jobs) %.1f s cold, %.1f s warm (day builds %.1f s); the whole "
             "page ~%.0f min extrapolated at %d job(s) at once", page.name, report["small_jobs"],
             report["full_jobs"], report["small_cold_s"], report["small_warm_s"], report["day_builds_s"],
             report["full_minutes_extrapolated"], report["parallel_jobs"])  # fmt: skip
    if "full_minutes_measured" in report:
        log.info("the whole page measured: %.0f min, %.1f times the small version cold",
                 report["full_minutes_measured"], report["full_over_small"])  # fmt: skip
    log.info("wrote %s", args.out)
    return 0


def run_planner(args: argparse.Namespace) -> int:
    """The planner suite on the fleet table's world (``experiment=fleet``, evaluation split of seed 0)."""
    from evcd.bench.planner import planner_cost
    from evcd.experiments.worlds import split_kwargs
    from evcd.planner.solver import MissingSolverError

    cfg = compose_experiment("fleet", [f"fleet.guided_share={args.guided_share}"], conf_dir=CONF)
    kwargs = {**split_kwargs(cfg, "eval", 0), "cache_dir": args.cache_dir}
    try:
        report = planner_cost(kwargs, episodes=args.episodes, time_limits=args.time_limits)
    except (ValueError, MissingSolverError) as exc:
        log.error("%s", exc)
        return 2
    atomic_write_text(args.out, json.dumps(report, indent=1))
    for limit, row in report["limits"].items():
        log.info("limit %s: solve %.1f s median (max %.1f), proven gap %.1f %% median (max %.1f %%), "
                 "%d of %d optimal; the fleet table's bound column ~%.0f min on %d cores", limit,
                 row["solve_s_median"], row["solve_s_max"], 100 * row["gap_median"], 100 * row["gap_max"],
                 row["optimal"], row["episodes"], row["bound_column_minutes"], report["jobs"])  # fmt: skip
    log.info("reading an episode %.1f s (median); wrote %s", report["read_s_median"], args.out)
    return 0


def run_days(args: argparse.Namespace) -> int:
    """The days suite: the fleet table's held-out days of seed 0 (its world, 600 EVs, the morning peak)
    built one after the other and two at a time, each from an empty cache."""
    from evcd.bench.day_builds import day_build_speedup
    from evcd.experiments.worlds import split_kwargs

    cfg = compose_experiment("fleet", [], conf_dir=CONF)
    kwargs = split_kwargs(cfg, "eval", 0)
    world = {k: v for k, v in kwargs.items() if k not in ("guided_share", "cache_dir")}
    report = day_build_speedup(world, workers=2)
    atomic_write_text(args.out, json.dumps(report, indent=1))
    log.info("%d days: one after the other %.1f s, two at a time %.1f s: day_build_speedup %.2f; wrote %s",
             report["days"], report["one_by_one_s"], report["side_by_side_s"], report["day_build_speedup"],
             args.out)  # fmt: skip
    return 0


def run_engine_suite(args: argparse.Namespace, env_kwargs: dict, replay: dict) -> dict:
    """The batched engine's suites (Jurong West, the morning peak, the default training regime)."""
    peak = {**env_kwargs, "departure_window": engine_bench.PEAK, "cache_dir": args.cache_dir}
    if args.suite == "engines":
        out = engine_bench.compare_engines(peak, args.episodes, args.batch_sizes)
        return {"summary": out.pop("summary"), **out}
    from evcd.agents.dqn import DQNAgent  # noqa: F401  (torch imported before timing)

    regime = compose_experiment("peak", conf_dir=CONF)  # the default regime, as train.py composes it
    peak_rates = engine_bench.engine_rates({**peak, "reward": "time"}, 20, 400, 25)
    peak_100 = engine_bench.engine_rates({**peak, "reward": "time"}, 20, 400, 100)  # the faster setting
    eval_run = engine_bench.engine_rates({**peak, "reward": "time"}, 1, 100, 25)["batched"]
    day = {**peak, "departure_window": engine_bench.WHOLE_DAY}
    day_rates = engine_bench.engine_rates(day, 10, 400, 25)
    learner = learner_config(regime.learner)
    learning = engine_bench.learning_rate({**peak, "reward": "time"}, learner, 1000, 25)
    scaling = engine_bench.parallel_scaling(peak, 200, 25)
    routes = engine_bench.kept_routes({**peak, "reward": "time"}, 400, 25)

    def speedup(r: dict) -> float:
        return r["batched"]["episodes_per_s"] / r["single"]["episodes_per_s"]

    summary = {
        "batched_speedup": speedup(peak_rates),
        "batched_speedup_batch100": speedup(peak_100),
        "batched_speedup_whole_day": speedup(day_rates),
        "transitions_per_second": learning["transitions_per_s"],
        "parallel_scaling_2": scaling["scaling"],
        "per_sample_update_us": replay["per_sample_update_us"],
        "eval_run_100_s": eval_run["wall_s"],
        "train_episodes_per_second": learning["episodes_per_s"],
        "going_back_share": learning["going_back_share"],
        "kept_routes_speedup": routes["speedup"],
        "kept_routes_same_rows": routes["same_rows"],
        "goals": {"batched_speedup": ">= 10 (aim 30)", "parallel_scaling_2": ">= 1.7",
                  "per_sample_update_us": "<= 100"},
    }  # fmt: skip
    return {"summary": summary, "peak": peak_rates, "peak_batch100": peak_100, "whole_day": day_rates,
            "learning": learning, "scaling": scaling, "routes": routes, "replay": replay}  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
