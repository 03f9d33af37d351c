"""scripts/compare_runs.py on real runs of train.py on the grid: rows per world and dispatcher, and
pairs across runs on the same episodes."""

from __future__ import annotations

from tests.conftest import run_script


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
    proc = run_script("compare_runs.py", str(tmp_path / "plain"), "--reference", "peak/hindsight")
    assert proc.returncode == 2 and "not a row" in proc.stdout + proc.stderr
    proc = run_script("compare_runs.py", str(tmp_path / "plain"), "--out", str(out))
    assert proc.returncode == 2 and "exists" in proc.stdout + proc.stderr
