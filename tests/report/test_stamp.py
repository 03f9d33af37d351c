"""Every table says what made its numbers (evcd.report.stamp): the environment's versioned id, evcd's
version and commit, the machine; jobs of older code read "not recorded" and the page warns first."""

from __future__ import annotations

from evcd.report.stamp import NOT_RECORDED, JobStamp, job_stamp, stamp_markdown, stamp_sentence

TODAY = "evcd/ChargingNav-v1"
MACHINE = {"cpu": "AMD EPYC 7B13", "cpu_capability": "AVX2", "packages": {"torch": "2.13.0"}}


def record(commit: str = "a" * 40, dirty: bool | None = False, env: str = TODAY) -> dict:
    return {
        "environment": env,
        "code": {"evcd": "0.1.0", "commit": commit, "dirty": dirty},
        "machine": MACHINE,
    }


def test_a_job_stamp_reads_the_records_of_results_json():
    stamp = job_stamp(record(dirty=True))
    assert stamp == JobStamp(
        TODAY, "0.1.0", "a" * 40 + " + uncommitted changes", "AMD EPYC 7B13 (AVX2), torch 2.13.0"
    )
    assert job_stamp({"agent": "greedy"}) == JobStamp(NOT_RECORDED, NOT_RECORDED, NOT_RECORDED, NOT_RECORDED)
    assert job_stamp(record(commit="not a git checkout", dirty=None)).commit == "not a git checkout"


def test_a_page_of_todays_jobs_names_them_once_without_a_warning():
    lines = stamp_markdown([job_stamp(record()), job_stamp(record())], TODAY)
    assert lines[0] == f"- Environment: `{TODAY}`"
    assert f"commit `{'a' * 40}`" in lines[1] and "jobs" not in "\n".join(lines)


def test_older_or_unrecorded_jobs_are_said_first_with_their_counts():
    stamps = [
        job_stamp(record()),
        job_stamp(record(env="evcd/ChargingNav-v0", commit="b" * 40)),
        job_stamp({}),
    ]
    lines = stamp_markdown(stamps, TODAY)
    assert lines[0].startswith(f"**Made with another environment than today's `{TODAY}`** (2 of 3 jobs")
    text = "\n".join(lines)
    assert f"`{NOT_RECORDED}` (1 of 3 jobs)" in text and "`evcd/ChargingNav-v0` (1 of 3 jobs)" in text
    assert f"`{'b' * 40}` (1 of 3 jobs)" in text


def test_a_headline_stamp_counts_the_commits_most_jobs_first_and_shortens_them():
    stamps = [job_stamp(record(commit="b" * 40))] + [job_stamp(record())] * 2 + [job_stamp({})]
    sentence = stamp_sentence(stamps)
    assert sentence.startswith(f"Made with `{TODAY}` (3 of 4 jobs) and `{NOT_RECORDED}` (1), evcd ")
    assert sentence.endswith(f"by commits `aaaaaaa` (2 of 4 jobs), `bbbbbbb` (1) and `{NOT_RECORDED}` (1).")
    one = stamp_sentence([job_stamp(record(dirty=True))])
    assert one == (f"Made with `{TODAY}`, evcd `0.1.0`, on `AMD EPYC 7B13 (AVX2), torch 2.13.0`, "
                   "by commit `aaaaaaa + uncommitted changes`.")  # fmt: skip
