"""The rules of a learner's run, played beside its training in a process of their own.

A learner's run plays rules twice: the validation's rules once on the validation episodes, and the
evaluation's baselines on the evaluation episodes. Neither depends on the training, and an episode
depends only on its seed and its dispatcher, in any process (same seed, same result). So on a machine
with a core to spare the trainer hands them to a second process when training starts
(:class:`RulesBeside`) and takes their rows where it would have played them: the same rows, and the
rules' time is gone from the run's wall time. libsumo runs one simulation per process: hence a
process (``python -m evcd.loops.beside``, as a day build's: it works under any launcher, Hydra's
joblib workers included), which makes its own runners from a picklable factory
(:class:`RunnerRecipe`) and hands each result back as a file. A trainer killed before it closes the
process leaves nothing behind: the process ends within a second and removes its files.

    beside = RulesBeside(RunnerRecipe(kwargs_by_phase, "batched", 25), settings, rules, baselines)
    ...
    record.rules.update(beside.validation_rules())   # at the first validation
    bases = beside.baselines()                        # at the evaluation
    beside.close()
"""

from __future__ import annotations

import os
import pickle
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import traceback
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from evcd.env import ChargingNavEnv
from evcd.env.day_builds import child_env, output_tail
from evcd.env.runners import EpisodeRunner, make_runner
from evcd.loops.evaluate import Dispatcher, evaluate
from evcd.loops.seeds import VALIDATION_STREAM
from evcd.loops.stats import EvalResult
from evcd.loops.tasks import task_of
from evcd.loops.validation import travel_times
from evcd.utils.atomic import atomic_write_bytes

#: Fewest rule episodes worth a second process (starting one costs a few seconds of imports).
MIN_EPISODES = 20


@dataclass(frozen=True)
class RunnerRecipe:
    """A picklable ``runners(phase)``: each phase's :class:`~evcd.env.ChargingNavEnv` arguments, and the
    engine that plays them (:func:`~evcd.env.runners.make_runner`)."""

    kwargs: Mapping[str, Mapping[str, Any]]
    engine: str
    batch_episodes: int

    def __call__(self, phase: str) -> EpisodeRunner:
        return make_runner(ChargingNavEnv(**self.kwargs[phase]), self.engine, self.batch_episodes)


def rule_episodes(settings: Any, rules: Mapping[str, Any], baselines: Mapping[str, Any]) -> int:
    """How many episodes the rules of a run play: what :class:`RulesBeside` would take off the training's
    process (``settings``: the run's :class:`~evcd.loops.train.TrainSettings`)."""
    validated = len(rules) * settings.validation.episodes if settings.validation.every else 0
    return validated + len(baselines) * settings.eval_episodes


def _play(recipe: Callable[[str], EpisodeRunner], settings: Any, rules: Mapping[str, Dispatcher],
          baselines: Mapping[str, Dispatcher], out: Path) -> None:  # fmt: skip
    """The second process: the validation's rules, then the baselines, each written as it is done."""
    times: dict[str, list[float]] = {}
    if rules:
        runner = recipe("validation")
        try:
            runner.prepare()
            specs = task_of(runner).specs(settings.seed, settings.validation.episodes, runner,
                                          VALIDATION_STREAM)  # fmt: skip
            for name, rule in rules.items():
                times[name] = travel_times(runner.run(specs, rule))
        finally:
            runner.close()
    atomic_write_bytes(out / "validation.pickle", pickle.dumps(times))
    bases: dict[str, EvalResult] = {}
    if baselines:
        runner = recipe("eval")
        try:
            runner.prepare()
            for name, baseline in baselines.items():
                bases[name] = evaluate(runner, baseline, settings.eval_episodes, settings.seed,
                                       progress=False, resamples=settings.resamples)  # fmt: skip
        finally:
            runner.close()
    atomic_write_bytes(out / "baselines.pickle", pickle.dumps(bases))


class RulesBeside:
    """Plays the validation's ``rules`` and the evaluation's ``baselines`` of a run in a second process,
    from now on (module docstring).

    Args:
        recipe: a picklable ``runners(phase)`` (``"validation"``, ``"eval"``), e.g. a :class:`RunnerRecipe`.
        settings: the run's :class:`~evcd.loops.train.TrainSettings` (seed, episodes, validation).
        rules: the rules validated beside the learner, by name (none: no validation rules).
        baselines: the evaluation's rules, by name.
    """

    def __init__(self, recipe: Callable[[str], EpisodeRunner], settings: Any, rules: Mapping[str, Dispatcher],
                 baselines: Mapping[str, Dispatcher]) -> None:  # fmt: skip
        self._dir = tempfile.TemporaryDirectory(prefix="evcd_rules_beside_")
        self.out = Path(self._dir.name)
        job = self.out / "job.pickle"
        job.write_bytes(pickle.dumps((recipe, settings, dict(rules), dict(baselines))))
        self._log = open(self.out / "output.log", "w+b")  # noqa: SIM115  (closed by close())
        command = [sys.executable, "-m", "evcd.loops.beside", str(job), str(self.out), str(os.getpid())]
        self._process = subprocess.Popen(command, stdout=self._log, stderr=subprocess.STDOUT, env=child_env())
        self._got: dict[str, Any] = {}

    def _wait(self, what: str) -> Any:
        path = self.out / f"{what}.pickle"
        while what not in self._got:
            if path.is_file():
                self._got[what] = pickle.loads(path.read_bytes())
            elif self._process.poll() is not None and not path.is_file():
                tail = output_tail(self._log)
                code = self._process.returncode
                raise RuntimeError(f"the process playing the rules beside the training failed (exit {code}) "
                                   f"before its {what}:\n" + "\n".join(tail))  # fmt: skip
            else:
                time.sleep(0.1)
        return self._got[what]

    def validation_rules(self) -> dict[str, list[float]]:
        """Each validation rule's travel times on the validation episodes (NaN where truncated)."""
        return self._wait("validation")

    def baselines(self) -> dict[str, EvalResult]:
        """Each baseline's evaluation on the run's evaluation episodes."""
        return self._wait("baselines")

    def close(self) -> None:
        """Stop the second process (at once if it is still playing) and remove its files."""
        if self._process.poll() is None:
            self._process.kill()
        self._process.wait()
        self._log.close()
        self._dir.cleanup()


def _orphaned(parent: int, out: Path) -> bool:
    """Whether the trainer that started this process is gone (then its folder ``out`` is removed)."""
    if os.getppid() == parent:
        return False
    shutil.rmtree(out, ignore_errors=True)
    return True


def _watch(parent: int, out: Path) -> None:
    """End this process (and remove ``out``) soon after its trainer ends without closing it: killed."""
    while not _orphaned(parent, out):
        time.sleep(1.0)
    os._exit(1)


def main(argv: Sequence[str]) -> int:
    """``python -m evcd.loops.beside JOB_PICKLE OUT_DIR TRAINER_PID``: what :class:`RulesBeside` runs."""
    job, out, parent = Path(argv[0]), Path(argv[1]), int(argv[2])
    threading.Thread(target=_watch, args=(parent, out), daemon=True).start()
    try:
        recipe, settings, rules, baselines = pickle.loads(job.read_bytes())
        _play(recipe, settings, rules, baselines, out)
    except BaseException:  # anything: the trainer reports the end of this output
        traceback.print_exc()
        return 1
    finally:
        _orphaned(parent, out)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
