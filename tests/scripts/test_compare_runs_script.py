"""scripts/compare_runs.py on real runs of train.py on the grid (single target and fleet): rows per
world and dispatcher, and pairs across runs on the same episodes."""

from __future__ import annotations

import json
import shutil

import pytest

from evcd.report.compare import Runs, compare_markdown
from tests.conftest import run_script


@pytest.mark.slow
def test_runs_of_a_seed_pair_across_worlds(script_overrides, tmp_path):
    """A calm run and one whose agents see the points in service (all in service on a calm day):
    queue_aware decides the same in both, so its paired difference across the worlds is exactly 0
    on every episode; greedy differs from it."""
    for name, extra in (("plain", []), ("sees", ["env.observe=[points_in_service]"])):
        run = f"hydra.run.dir={tmp_path / name}"
        proc = run_script("train.py", *script_overrides, "agent=greedy", "eval.episodes=4",
                          "eval.baselines=[queue_aware]", *extra, run)  # fmt: skip
        assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    out = tmp_path / "compare.md"
    proc = run_script("compare_runs.py", str(tmp_path / "plain"), str(tmp_path / "sees"),
                      "--reference", "peak/queue_aware", "--out", str(out))  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    rows = {
        tuple(c.strip() for c in line.strip("|").split("|")[:2]): line
        for line in out.read_text().splitlines()[2:]
    }
    assert set(rows) == {("peak", "greedy"), ("peak", "queue_aware"), ("peak sees P", "greedy"),
                         ("peak sees P", "queue_aware")}  # fmt: skip
    assert "+0.0 n=1; 0 / 0 of 4" in rows["peak sees P", "queue_aware"]
    # only some worlds' rows (a page's render), still paired with a reference outside them
    runs = Runs.read([tmp_path / "plain", tmp_path / "sees"])
    lines = compare_markdown(runs, [("peak", "queue_aware")], worlds=["peak sees P"]).splitlines()[2:]
    assert [line.split("|")[1:3] for line in lines] == [
        [" peak sees P ", " greedy "],
        [" peak sees P ", " queue_aware "],
    ]
    assert lines[1].endswith("| +0.0 n=1; 0 / 0 of 4 |")
    proc = run_script("compare_runs.py", str(tmp_path / "plain"), "--reference", "peak/hindsight")
    assert proc.returncode == 2 and "not a row" in proc.stdout + proc.stderr
    proc = run_script("compare_runs.py", str(tmp_path / "plain"), "--out", str(out))
    assert proc.returncode == 2 and "exists" in proc.stdout + proc.stderr


@pytest.mark.slow
def test_fleet_runs_pair_by_fleet_episode_on_the_guided_evs(script_overrides, tmp_path):
    """The same for fleet runs: rows per world on the guided EVs' mean travel time of each fleet
    episode (the value in the run's fleet_episodes.csv), queue_aware exactly 0 across the worlds."""
    from tests.scripts.test_train_fleet_script import FLEET

    for name, extra in (("plain", []), ("sees", ["env.observe=[points_in_service]"])):
        run = f"hydra.run.dir={tmp_path / name}"
        proc = run_script("train.py", *script_overrides, *FLEET, "agent=greedy", "eval.episodes=1",
                          "eval.baselines=[queue_aware]", *extra, run)  # fmt: skip
        assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    runs = Runs.read([tmp_path])
    greedy = json.loads((tmp_path / "plain" / "results.json").read_text())["summary"]["guided_travel"]
    assert runs.travel["fleet", "greedy"] == {0: {0: pytest.approx(greedy)}}
    assert runs.task["fleet", "queue_aware"] == "fleet"
    same = runs.paired(("fleet sees P", "queue_aware"), ("fleet", "queue_aware"))
    assert same is not None and same.stat.mean == 0.0 and same.pairs == 1
    censored = Runs.read([tmp_path], "guided_travel_censored")
    assert set(censored.travel) == set(runs.travel)
    with pytest.raises(ValueError, match="fleet_measure='speed': choose among guided_travel"):
        Runs.read([tmp_path], "speed")


@pytest.mark.slow
def test_a_run_read_twice_is_kept_once_and_other_numbers_for_it_are_named(script_overrides, tmp_path, caplog):
    from tests.scripts.test_train_fleet_script import FLEET

    run = tmp_path / "a"
    proc = run_script("train.py", *script_overrides, *FLEET, "agent=greedy", "eval.episodes=1",
                      "eval.baselines=[]", f"hydra.run.dir={run}")  # fmt: skip
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    shutil.copytree(run, tmp_path / "b")  # the same run again (a re-run that reproduced): silent
    with caplog.at_level("WARNING", logger="evcd.report.compare"):
        first = Runs.read([tmp_path])
    assert not caplog.records
    csv_path = tmp_path / "b" / "fleet_episodes.csv"
    header, row = csv_path.read_text().splitlines()[:2]
    cells = row.split(",")
    at = header.split(",").index("guided_travel")
    cells[at] = str(float(cells[at]) + 1.0)
    csv_path.write_text("\n".join([header, ",".join(cells)]) + "\n")
    with caplog.at_level("WARNING", logger="evcd.report.compare"):
        again = Runs.read([tmp_path])
    assert again.travel == first.travel  # the first read (a) is kept
    assert any("seed 0 again" in r.getMessage() and "other numbers" in r.getMessage() for r in caplog.records)


def test_a_fleet_row_is_never_paired_with_a_single_targets():
    runs = Runs({("fleet", "greedy"): {0: {0: 300.0}}, ("peak", "greedy"): {0: {0: 200.0}}},
                {("fleet", "greedy"): "fleet", ("peak", "greedy"): "single"})  # fmt: skip
    assert runs.paired(("fleet", "greedy"), ("peak", "greedy")) is None
    assert runs.paired(("fleet", "greedy"), ("fleet", "greedy")) is not None


@pytest.mark.slow
def test_against_calm_pairs_each_perturbed_row_with_its_dispatcher_calm(script_overrides, tmp_path):
    """``--against-calm``: a perturbed row minus the same dispatcher in the calm run of its regime and
    observation; the per-seed difference is the two runs' mean travel times apart (no episode
    truncated, the same episodes); a perturbed world without a calm run of its observation, and the
    calm rows, get none."""
    outages = ["perturbations=outages", "perturbations.outages.per_day=20",
               "perturbations.outages.start_window=[18000,23400]"]  # fmt: skip
    worlds = {"calm": [], "outages": outages, "outages_sees": [*outages, "env.observe=[points_in_service]"]}
    for name, extra in worlds.items():
        proc = run_script("train.py", *script_overrides, "agent=queue_aware", "eval.episodes=4",
                          "eval.baselines=[greedy]", *extra, f"hydra.run.dir={tmp_path / name}")  # fmt: skip
        assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    runs = Runs.read([tmp_path])
    assert runs.calm_world["peak +outages sees P"] == "peak sees P"
    summary = {
        n: json.loads((tmp_path / n / "results.json").read_text())["summary"] for n in ("calm", "outages")
    }
    assert summary["calm"]["truncated"] == summary["outages"]["truncated"] == 0
    p = runs.against_calm(("peak +outages", "queue_aware"))
    assert p is not None and p.pairs == 4
    assert p.per_seed[0] == pytest.approx(
        summary["outages"]["mean_travel_time"] - summary["calm"]["mean_travel_time"]
    )
    assert runs.against_calm(("peak", "queue_aware")) is None
    assert runs.against_calm(("peak +outages sees P", "queue_aware")) is None
    proc = run_script("compare_runs.py", str(tmp_path), "--against-calm")
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-3000:]
    lines = {tuple(c.strip() for c in line.strip("|").split("|")[:2]): line.strip("|").split("|")[-1].strip()
             for line in proc.stdout.splitlines()[2:] if line.startswith("|")}  # fmt: skip
    assert proc.stdout.splitlines()[0].endswith("- the same dispatcher calm (per seed) |")
    assert lines["peak +outages", "queue_aware"].endswith(f"(0: {p.per_seed[0]:+.1f})")
    assert lines["peak +outages", "greedy"].startswith(
        f"{runs.against_calm(('peak +outages', 'greedy')).stat.mean:+.1f}"
    )
    assert lines["peak", "greedy"] == lines["peak +outages sees P", "queue_aware"] == ""
