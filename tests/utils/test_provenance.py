"""Which code made a number (evcd.utils.provenance): the commit of a real git checkout, whether it has
uncommitted changes, and "not a git checkout" anywhere else."""

from __future__ import annotations

import shutil
import subprocess
from importlib.metadata import version
from pathlib import Path

import pytest

from evcd.utils.provenance import NOT_A_CHECKOUT, code_record, git_commit
from tests.conftest import ROOT

pytestmark = pytest.mark.skipif(shutil.which("git") is None, reason="git is not installed")


def git(root: Path, *args: str) -> str:
    env = {"GIT_AUTHOR_NAME": "t", "GIT_AUTHOR_EMAIL": "t@t", "GIT_COMMITTER_NAME": "t",
           "GIT_COMMITTER_EMAIL": "t@t", "PATH": "/usr/bin:/bin"}  # fmt: skip
    out = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, env=env, check=True)
    return out.stdout.strip()


def test_a_checkout_names_its_commit_and_whether_tracked_files_changed(tmp_path):
    repo = tmp_path / "repo"
    repo.mkdir()
    git(repo, "init", "-q")
    (repo / "a.txt").write_text("one\n")
    git(repo, "add", "a.txt")
    git(repo, "commit", "-q", "-m", "first")
    head = git(repo, "rev-parse", "HEAD")
    assert git_commit(repo) == (head, False)
    (repo / "untracked.txt").write_text("new\n")
    assert git_commit(repo) == (head, False)  # untracked files are not the code that ran
    (repo / "a.txt").write_text("two\n")
    assert git_commit(repo) == (head, True)
    # a folder inside the checkout is not the top of a checkout of its own (an installed package
    # inside someone else's repository must not take that repository's commit)
    (repo / "site").mkdir()
    assert git_commit(repo / "site") == (NOT_A_CHECKOUT, None)


def test_elsewhere_it_is_not_a_git_checkout(tmp_path):
    assert git_commit(tmp_path) == (NOT_A_CHECKOUT, None)
    assert git_commit(tmp_path / "missing") == (NOT_A_CHECKOUT, None)


def test_the_record_names_this_evcd():
    record = code_record()
    assert record["evcd"] == version("evcd")
    if (ROOT / ".git").exists():
        assert record["commit"] == git(ROOT, "rev-parse", "HEAD") and isinstance(record["dirty"], bool)
    else:
        assert record == {"evcd": version("evcd"), "commit": NOT_A_CHECKOUT, "dirty": None}
