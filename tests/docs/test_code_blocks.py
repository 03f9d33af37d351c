"""Documentation that runs: every fenced code block of README.md and of the site (docs/**/*.md, but
the research notes docs/NOTES.md and docs/changelog.md, records of what was run) runs here, is
checked here, or is marked in the page's source as not run, with the reason. One test per block,
named by its page and the line of its opening fence (``docs/guide/the-fleet.md:40``).

The marker is an HTML comment on the line right before the block's opening fence, out of sight on
the rendered page (GitHub and MyST keep HTML comments in the source)::

    <!-- docs-test: compose -->
    ```bash
    python scripts/train.py -m experiment=table seed=0,1,2,3,4 evs=200,300,400
    ```

``<!-- docs-test: KIND ARGS -->``, KIND one of:

``run``
    The block runs as written. The default of a ``python`` block (it needs no marker): it runs alone
    in a fresh process and folder (a reader copies one block, so a block imports what it uses), its
    traceback naming the page's lines. A shell block's commands run one after another in a fresh
    folder.
``small ARGS``
    The block runs on small settings. Python: every environment it makes
    (:class:`evcd.env.config.EnvConfig`, behind ``ChargingNavEnv``, ``FleetEnv``, ``gymnasium.make``
    and every ``evcd.experiments`` factory) is put on an 8 x 8 grid with five stations and a short,
    light day (:func:`small_env`); ``key=value`` (a Python literal) sets one more of its keywords.
    Shell: each ``python scripts/<x>.py`` command runs with the script's small settings appended
    (:func:`small_settings`: the grid of tests/conftest.py's ``script_overrides``, a tiny learner, two
    episodes), then the marker's Hydra overrides ``key=value`` (``train.py:key=value``: that script's
    commands only); later overrides win. A ``<...>`` placeholder (``outputs/train/<run>``) stands for
    the output folder of the block's previous command; ``after="python scripts/train.py ..."`` runs a
    command first, not shown on the page, for a block whose first command needs one. Both:
    ``"old=>new"`` replaces text of the block before it runs (it must occur; ``{osm}`` in ``new`` is a
    tiny OpenStreetMap extract). A chain of commands that another block runs too, with the same
    settings, runs once per test run (README.md's job and the guide's first run are one run).
``compose``
    For sweeps and runs of hours. Each ``python scripts/<x>.py`` command is composed exactly as
    written with the script's config (Hydra's compose API) and goes through the script's own checks
    (its ``main``, so a refusal exits with code 2 as on a console) up to where its simulation would
    start (:data:`STOP_AT`), without running it and without generating a day: the fleet's check that
    each day has EVs to guide, which writes the days' route files (~3 s a day on Jurong West, 29 days
    in the fleet table's sweep), is left to the run. A sweep (``-m``) is checked on a covering set of
    its jobs: every value of every swept key is in one checked job (as many jobs as the longest list,
    not the product). An argparse script's arguments are parsed by its own parser. A placeholder
    (``outputs/table/<time>``) is kept as a name; a check that needs its file fails (use ``small``).
``skip REASON``
    Not run, for REASON (an install, a server, the reader's own files). Reported as skipped.

In ``run``, ``small`` and ``compose`` shell blocks, the commands that set up a machine or start a
server (:data:`SHELL_ONLY`: pip, venv, tensorboard) are not run; any other command, a shell variable
or a pipe fails the test (mark the block ``skip``).

Blocks that are not code need no marker: no language, ``text``, ``toml``, ``yaml``, ``json`` and the
like (a tree, a table written as code, an output); ``toml`` and ``json`` blocks are parsed. MyST
directives other than ``{code-block}`` (``{toctree}``, ``{eval-rst}``) are not code blocks; a
directive's body is read as Markdown. A shell block without a marker, a block in another language
without one, a marker that does not parse or is not on the line right before a fence: the test of
that ``file:line`` fails and says what to write.

A block that runs or is composed is marked ``slow`` (it starts a process or builds environments:
~2 minutes of CPU for all of them, a minute on 2 workers); the collection and the markers are checked
in the quick tier too, so an unmarked block fails there.
"""

from __future__ import annotations

import argparse
import ast
import contextlib
import copy
import functools
import hashlib
import importlib.util
import inspect
import io
import json
import logging
import re
import shlex
import subprocess
import sys
import tomllib
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType
from typing import Any

import pytest

from tests.conftest import (
    FLEET_DEMAND,
    FLEET_WINDOW,
    PAPER_DAY_END,
    ROOT,
    build_once,
    compose_config,
    make_grid_scenario,
    shared_folder,
)

#: Pages whose blocks are records of what was run, not instructions.
NOT_COLLECTED = ("docs/NOTES.md", "docs/changelog.md")
KINDS = ("run", "small", "compose", "skip")
PYTHON = {"python", "py", "python3"}
SHELL = {"bash", "sh", "shell", "console", "zsh"}
#: Languages of blocks that are not code to run (``toml`` and ``json`` are parsed).
LITERAL = {"", "text", "txt", "none", "output", "toml", "yaml", "yml", "json", "ini", "csv", "xml"}
#: MyST directives that are code blocks; the body of any other directive is Markdown.
CODE_DIRECTIVES = {"code-block", "code", "sourcecode"}
#: Commands of a shell block that the tests never run, and why.
SHELL_ONLY = {
    "pip": "installs packages",
    "tensorboard": "starts a server",
    "venv": "makes a virtual environment",
    ".": "enters a virtual environment",
    "source": "enters a virtual environment",
}
#: Where each Hydra script's run starts once its checks have passed: ``compose`` stops there.
STOP_AT = {
    "train.py": "train_and_evaluate",
    "evaluate.py": "write_run_record",
    "train_sb3.py": "write_run_record",
    "forecast_errors.py": "write_run_record",
    "inspect_scenario.py": "network_summary",
}
#: A tiny learner and run (tests/scripts/test_train_script.py's); rules ignore the learner block.
TINY_TRAINING = [
    "learner.hidden=[16,16]", "learner.learning_starts=4", "learner.batch_size=4",
    "learner.target_update=5", "learner.exploration_steps=10", "train.episodes=2", "train.checkpoint_every=1",
    "train.validation.every=0", "eval.episodes=2", "eval.bootstrap_resamples=200",
]  # fmt: skip
PLACEHOLDER = re.compile(r"<([^<>\n]+)>")
#: A placeholder in a ``small`` block's command, before it is given the previous command's output.
RUN_SLOT = "@@run@@"
FENCE = re.compile(r"^(?P<indent> {0,3})(?P<fence>`{3,}|~{3,})\s*(?P<info>[^`]*?)\s*$")
MARKER = re.compile(r"^\s*<!--\s*docs-test:(?P<body>.*?)-->\s*$")
ANY_MARKER = re.compile(r"^\s*<!--\s*docs-test")
HOW = ("put <!-- docs-test: run | small ARGS | compose | skip REASON --> on the line right before its "
       "opening fence (tests/docs/test_code_blocks.py says what each does)")  # fmt: skip


# ---------------------------------------------------------------------------------------- collecting
@dataclass(frozen=True)
class Block:
    """A fenced code block of a page and what its marker asks for."""

    page: Path
    line: int  # of the opening fence, 1-based
    first: int  # the line of the code's first line
    lang: str
    code: str
    kind: str  # run, small, compose, skip, literal, or bad (``problem`` says what is wrong)
    args: tuple[str, ...] = ()
    problem: str = ""

    @property
    def where(self) -> str:
        page = self.page.relative_to(ROOT).as_posix() if self.page.is_relative_to(ROOT) else str(self.page)
        return f"{page}:{self.line}"


def pages() -> list[Path]:
    """README.md and the site's pages, but :data:`NOT_COLLECTED`."""
    found = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
    return [p for p in found if p.relative_to(ROOT).as_posix() not in NOT_COLLECTED]


def collect(page: Path) -> list[Block]:
    """The code blocks of ``page`` with their markers, and a ``bad`` block for a stray marker."""
    lines = page.read_text().splitlines()
    return list(_blocks(page, lines, 0, len(lines)))


def _blocks(page: Path, lines: list[str], start: int, end: int) -> Iterator[Block]:
    i = start
    while i < end:
        fence = FENCE.match(lines[i])
        if fence is None:
            if ANY_MARKER.match(lines[i]) and not (i + 1 < end and FENCE.match(lines[i + 1])):
                stray = Block(page, i + 1, i + 1, "", "", "bad")
                problem = (f"{stray.where}: a docs-test marker must be on the line right before a block's "
                           "opening fence, with no blank line between")  # fmt: skip
                yield Block(page, i + 1, i + 1, "", "", "bad", problem=problem)
            i += 1
            continue
        mark, info = fence["fence"], fence["info"]
        closing = re.compile(rf"^ {{0,3}}{re.escape(mark[0])}{{{len(mark)},}}\s*$")
        close = next((j for j in range(i + 1, end) if closing.match(lines[j])), end)
        directive = re.match(r"^\{([\w-]+)\}\s*(.*)$", info)
        if directive is not None and directive[1] not in CODE_DIRECTIVES:
            yield from _blocks(page, lines, i + 1, close)  # a directive's body is Markdown
        else:
            body = lines[i + 1 : close]
            if directive is not None:  # {code-block} python: its options first
                while body and re.match(r"^\s*:[\w-]+:", body[0]):
                    body = body[1:]
            lang = ((directive[2] if directive is not None else info).split() or [""])[0].lower()
            before = lines[i - 1] if i > start else ""
            marker = MARKER.match(before)
            text = marker["body"] if marker else before.strip() if ANY_MARKER.match(before) else None
            yield _block(page, i + 1, close - len(body) + 1, lang, "\n".join(body), text)
        i = close + 1


def _block(page: Path, line: int, first: int, lang: str, code: str, marker: str | None) -> Block:
    plain = Block(page, line, first, lang, code, "bad")

    def bad(problem: str) -> Block:
        return Block(page, line, first, lang, code, "bad", problem=f"{plain.where}: {problem}")

    if marker is None:
        if lang in PYTHON:
            return Block(page, line, first, lang, code, "run")
        if lang in LITERAL:
            return Block(page, line, first, lang, code, "literal")
        what = "a shell block runs nothing unless marked" if lang in SHELL else f"a {lang!r} block"
        return bad(f"{what}: {HOW}")
    if marker.startswith("<!--"):
        return bad(f"the marker {marker!r} does not parse: write <!-- docs-test: KIND ARGS --> on one line")
    kind, _, rest = marker.strip().partition(" ")
    if kind not in KINDS:
        return bad(f"unknown docs-test kind {kind!r}: {HOW}")
    if kind == "skip":
        if not rest.strip():
            return bad("docs-test: skip needs the reason the block is not run")
        return Block(page, line, first, lang, code, kind, (rest.strip(),))
    if lang not in PYTHON | SHELL:
        return bad(f"docs-test: {kind} on a {lang!r} block: only python and shell blocks run; use skip")
    if kind == "compose" and lang in PYTHON:
        return bad("docs-test: compose checks shell commands; a python block runs (run or small)")
    try:
        args = tuple(shlex.split(rest))
    except ValueError as exc:
        return bad(f"docs-test: {kind} {rest!r} does not parse: {exc}")
    if args and kind != "small":
        return bad(f"docs-test: {kind} takes no arguments (got {list(args)})")
    return Block(page, line, first, lang, code, kind, args)


# ---------------------------------------------------------------------------------------- shell commands
@dataclass(frozen=True)
class Command:
    """One command of a shell block: ``argv[0]`` a ``scripts/`` or ``examples/`` script, or a
    :data:`SHELL_ONLY` command (``shell_only`` says why it is not run)."""

    argv: tuple[str, ...]
    shell_only: str = ""

    @property
    def script(self) -> Path:
        return ROOT / self.argv[0]


def commands(block: Block, code: str, placeholder: str = "{}") -> list[Command]:
    """The commands of a shell block's ``code``, a ``<a name>`` placeholder written as
    ``placeholder.format("a_name")``. Raises ``pytest.fail`` naming a command the tests cannot run."""
    if block.lang == "console":  # commands after a prompt; the rest is output
        code = "\n".join(line[2:] for line in code.splitlines() if line.startswith("$ "))
    code = PLACEHOLDER.sub(lambda m: placeholder.format(re.sub(r"\W+", "_", m[1]).strip("_")), code)
    out: list[Command] = []
    for line in code.replace("\\\n", " ").splitlines():
        lexer = shlex.shlex(line, posix=True, punctuation_chars=True)
        lexer.whitespace_split, lexer.commenters = True, "#"
        words: list[str] = []
        for word in [*lexer, "&&"]:
            if word not in ("&&", ";"):
                if set(word) <= set("|&<>()"):
                    pytest.fail(f"{block.where}: {line.strip()!r}: the tests run no pipes or redirections; "
                                "mark the block skip with the reason", pytrace=False)  # fmt: skip
                words.append(word)
            elif words:
                out.append(_command(block, words))
                words = []
    return out


def _command(block: Block, words: list[str]) -> Command:
    text = " ".join(words)
    if any("$" in w for w in words):
        pytest.fail(f"{block.where}: {text!r} uses a shell variable: mark the block skip with the reason",
                    pytrace=False)  # fmt: skip
    python = words[0] in ("python", "python3")
    if python and len(words) > 1 and re.fullmatch(r"(scripts|examples)/[\w-]+\.py", words[1]):
        return Command(tuple(words[1:]))
    program = words[2] if python and words[1:2] == ["-m"] and len(words) > 2 else words[0]
    if program in ("pip", "pip3", "venv", ".", "source", "tensorboard"):
        return Command(tuple(words), SHELL_ONLY[program.rstrip("3")])
    pytest.fail(f"{block.where}: {text!r} is not a command the tests run (python scripts/<x>.py or "
                f"examples/<x>.py, or one of {sorted(SHELL_ONLY)}): mark the block skip with the reason",
                pytrace=False)  # fmt: skip


def replaced(block: Block, code: str, fixtures: dict[str, str]) -> str:
    """``code`` with the marker's ``"old=>new"`` replacements made (each must occur)."""
    for arg in block.args:
        if "=>" in arg:
            old, new = arg.split("=>", 1)
            if old not in code:
                pytest.fail(f"{block.where}: the marker replaces {old!r}, which the block no longer has",
                            pytrace=False)  # fmt: skip
            for name, path in fixtures.items():
                new = new.replace(f"{{{name}}}", path)
            code = code.replace(old, new)
    return code


# ---------------------------------------------------------------------------------------- small settings
def small_env(tmp_path_factory: pytest.TempPathFactory, env_cache: Path) -> dict[str, Any]:
    """What every environment of a ``small`` python block is made with: an 8 x 8 grid with five
    stations (as Jurong West: blocks that read ``obs[:5]`` keep their meaning) and the fleet tests'
    short, busy day (tests/conftest.py), one day for every split (built once for every block)."""
    grid = shared_folder(tmp_path_factory, "docs_grid5", lambda f: make_grid_scenario(f, k=5, spacing=500.0))
    return {"scenario": str(grid), "cache_dir": str(env_cache), "evs": None, "demand": FLEET_DEMAND,
            "departure_window": list(FLEET_WINDOW), "snapshot_every": 300.0, "day_end": PAPER_DAY_END,
            "demand_seeds": [0]}  # fmt: skip


def small_settings(script: str, grid: list[str]) -> list[str]:
    """The overrides a ``small`` block appends to ``python scripts/<script>`` (``grid``: the
    ``script_overrides`` fixture); none for an argparse script."""
    scenario = [o for o in grid if o.startswith(("scenario.", "evs="))]
    return {
        "train.py": [*grid, *TINY_TRAINING],
        "train_sb3.py": [*grid, "sb3.timesteps=64", "eval.episodes=2", "eval.bootstrap_resamples=200"],
        "evaluate.py": [*grid, "episodes=2", "bootstrap_resamples=200"],
        "forecast_errors.py": grid,
        "inspect_scenario.py": [*scenario, "begin=21600", "end=23400"],
    }.get(script, [])


def fixture_paths(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    """What ``{name}`` stands for in a marker's replacement."""
    from tests.scenario.test_network import OSM

    folder = shared_folder(tmp_path_factory, "docs_osm", lambda f: (f / "town.osm").write_text(OSM))
    return {"osm": str(folder / "town.osm")}


# ---------------------------------------------------------------------------------------- running
#: Runs a python block's file; with settings, every EnvConfig is made with them on top.
_PYTHON_DRIVER = """
import json, runpy, sys
settings = json.loads(sys.argv[1])
if settings is not None:
    from evcd.env import config
    made = config.EnvConfig.__init__
    def small(self, *args, **kwargs):
        made(self, *args, **{**kwargs, **settings})
    config.EnvConfig.__init__ = small
runpy.run_path(sys.argv[2], run_name="__main__")
"""


def run_python(block: Block, code: str, settings: dict[str, Any] | None, folder: Path) -> None:
    """Run ``code`` in a fresh process in ``folder``, its lines numbered as on the page."""
    file = folder / f"{block.page.name}.py"
    file.write_text("\n" * (block.first - 1) + code + "\n")
    proc = subprocess.run([sys.executable, "-c", _PYTHON_DRIVER, json.dumps(settings), str(file)], cwd=folder,
                          capture_output=True, text=True, timeout=600)  # fmt: skip
    if proc.returncode != 0:
        pytest.fail(f"{block.where}: the block failed:\n{(proc.stdout + proc.stderr)[-4000:]}", pytrace=False)


def run_commands(block: Block, cmds: list[Command], extra: dict[str, list[str]], runs: Path) -> None:
    """Run the script commands ``cmds`` one after another in one folder, each with ``extra[script]``
    appended; a placeholder (:data:`RUN_SLOT`) is the previous command's output folder. A chain that
    ran already in this test run (another block, the same commands and settings) is not run again."""
    key, cwd, previous = "", None, None
    for cmd in cmds:
        if cmd.shell_only:
            continue
        hydra = cmd.script.name in STOP_AT
        args = list(cmd.argv[1:])
        if any(RUN_SLOT in a for a in args):
            if previous is None:
                pytest.fail(f"{block.where}: {' '.join(cmd.argv)!r} reads the output of a command the block "
                            'does not run before it: give one with after="python scripts/..."',
                            pytrace=False)  # fmt: skip
            args = [re.sub(rf"[^=\s]*{RUN_SLOT}\S*", str(previous), a) for a in args]
        args += extra.get(cmd.script.name, []) if hydra else []
        key = hashlib.sha1(json.dumps([key, cmd.argv[0], args]).encode()).hexdigest()[:16]
        cwd = cwd or runs / key / "cwd"
        out = runs / key / "out"
        if hydra:
            args.append(f"hydra.{'sweep' if '-m' in args else 'run'}.dir={out}")
        build_once(runs, key, functools.partial(_run, cmd.script, args, cwd, runs / key / "result.json"))
        result = json.loads((runs / key / "result.json").read_text())
        if result["code"] != 0:
            pytest.fail(f"{block.where}: {cmd.argv[0]} {' '.join(args)}\nexited with code {result['code']}:\n"
                        f"{result['log']}", pytrace=False)  # fmt: skip
        previous = out if hydra else previous


def _run(script: Path, args: list[str], cwd: Path, result: Path) -> None:
    """``python script args`` in ``cwd``; its exit code and output's end into ``result``."""
    cwd.mkdir(parents=True, exist_ok=True)
    result.parent.mkdir(parents=True, exist_ok=True)
    proc = subprocess.run([sys.executable, str(script), *args], cwd=cwd, capture_output=True, text=True,
                          timeout=600)  # fmt: skip
    result.write_text(json.dumps({"code": proc.returncode, "log": (proc.stdout + proc.stderr)[-4000:]}))


# ---------------------------------------------------------------------------------------- composing
class Checked(BaseException):
    """Raised where a script's run would start: every check before it passed. A ``BaseException``,
    so that the script's ``except ValueError`` and Hydra's ``except Exception`` let it through."""


@functools.cache
def script_module(path: Path) -> ModuleType:
    spec = importlib.util.spec_from_file_location(f"docs_script_{path.stem}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def covering(overrides: list[str]) -> list[list[str]]:
    """Jobs of the sweep ``overrides`` (Hydra's override grammar) in which every value of every swept
    key appears: job ``i`` takes value ``i`` of each list, cycling the shorter ones."""
    from hydra.core.override_parser.overrides_parser import OverridesParser

    axes = []
    for o in OverridesParser.create().parse_overrides(overrides):
        if o.is_sweep_override():
            axes.append([f"{o.get_key_element()}={v}" for v in o.sweep_string_iterator()])
        else:
            axes.append([o.input_line])
    jobs = max((len(a) for a in axes), default=1)
    return [[a[i % len(a)] for a in axes] for i in range(jobs)]


@contextlib.contextmanager
def _patched(owner: Any, name: str, value: Any) -> Iterator[None]:
    old = getattr(owner, name)
    setattr(owner, name, value)
    try:
        yield
    finally:
        setattr(owner, name, old)


def _checked(*args: Any, **kwargs: Any) -> None:
    raise Checked


def _no_day(*args: Any) -> None:
    """In place of ``FleetEnv.check_days`` (which generates the days) in a compose check."""


def compose_problem(script: Path, args: tuple[str, ...], folder: Path) -> str | None:
    """Why ``python <script> args`` fails its ``compose`` check, or None (the module docstring);
    ``folder`` holds the run directories the script is told of (it makes none)."""
    log, err = io.StringIO(), io.StringIO()
    handler = logging.StreamHandler(log)
    handler.setLevel(logging.WARNING)
    logging.getLogger().addHandler(handler)
    problem = None
    try:
        with contextlib.redirect_stderr(err):
            if script.name in STOP_AT:
                _compose_hydra(script, list(args), folder)
            else:
                _parse_args(script, list(args))
    except SystemExit as exc:
        problem = f"refused (exit code {exc.code})"
    except Exception as exc:  # whatever the check raised is the finding
        problem = f"{type(exc).__name__}: {exc}"
    finally:
        logging.getLogger().removeHandler(handler)
    if problem is not None:
        problem += "\n" + (log.getvalue() + err.getvalue())[-3000:]
    return problem


def composed(script: Path, args: tuple[str, ...], runs: Path) -> str | None:
    """:func:`compose_problem`, once per test run for a command that several pages show."""
    key = hashlib.sha1(json.dumps([script.name, args]).encode()).hexdigest()[:16]
    result = runs / key / "problem.json"

    def check() -> None:
        result.parent.mkdir(parents=True, exist_ok=True)
        result.write_text(json.dumps(compose_problem(script, args, runs / key)))

    build_once(runs, key, check)
    return json.loads(result.read_text())


def _parse_args(script: Path, args: list[str]) -> None:
    """An argparse script's ``main`` up to its parsed arguments."""
    module = script_module(script)

    def then_stop(parse: Any) -> Any:
        def parse_then_stop(self: argparse.ArgumentParser, *a: Any, **k: Any) -> None:
            parse(self, *a, **k)
            raise Checked

        return parse_then_stop

    takes_argv = bool(inspect.signature(module.main).parameters)
    parser = argparse.ArgumentParser
    with _patched(parser, "parse_args", then_stop(parser.parse_args)), \
            _patched(parser, "parse_intermixed_args", then_stop(parser.parse_intermixed_args)), \
            _patched(sys, "argv", [str(script), *args]), contextlib.suppress(Checked):  # fmt: skip
        module.main(args) if takes_argv else module.main()
        raise AssertionError(f"{script.name} returned before parsing its arguments")


#: The networks read by compose checks in this process (Jurong West's takes ~0.7 s; a sweep's jobs
#: build two or three environments each).
_NETS: dict[Path, Any] = {}


def _compose_hydra(script: Path, args: list[str], folder: Path) -> None:
    """A Hydra script's config composed from ``args`` and its ``main`` run up to :data:`STOP_AT` (each
    job of a covering set with ``-m``), as ``python <script> args`` runs it."""
    import torch
    from hydra.core.hydra_config import HydraConfig
    from omegaconf import open_dict, read_write

    from evcd.env.fleet import FleetEnv
    from evcd.scenario import scenario

    module = script_module(script)
    source = script.read_text()
    config_name = re.search(r'config_name="(\w+)"', source)
    assert config_name is not None, script
    flags = [a for a in args if a.startswith("-")]
    if set(flags) - {"-m", "--multirun"}:
        raise AssertionError(f"flags {flags}: the check composes overrides only; mark the block skip")
    overrides = [a for a in args if not a.startswith("-")]
    if "refuse_removed_settings(sys.argv" in source:  # what its __main__ does before Hydra composes
        module.refuse_removed_settings(overrides, logging.getLogger(script.stem))
    threads, read = torch.get_num_threads(), scenario.read_net

    def read_net(net_file: str | Path) -> Any:  # once per process, not once per environment
        path = Path(net_file).resolve()
        if path not in _NETS:
            _NETS[path] = read(path)
        return _NETS[path]

    for n, job in enumerate(covering(overrides) if flags else [overrides]):
        try:
            cfg = compose_config(config_name[1], *job, return_hydra_config=True)
            with read_write(cfg.hydra), open_dict(cfg.hydra):
                cfg.hydra.runtime.output_dir = str(folder / f"job{n}")
                cfg.hydra.mode = "RUN"
            HydraConfig.instance().set_config(cfg)  # as Hydra's run_job
            task = copy.deepcopy(cfg)
            with read_write(task), open_dict(task):
                del task["hydra"]
            with _patched(module, STOP_AT[script.name], _checked), _patched(scenario, "read_net", read_net), \
                    _patched(FleetEnv, "check_days", _no_day), contextlib.suppress(Checked):  # fmt: skip
                module.main(task)
                raise AssertionError(f"{script.name} returned before {STOP_AT[script.name]}")
        except SystemExit as exc:
            raise RuntimeError(f"job {' '.join(job)}: refused (exit code {exc.code})") from None
        except Exception as exc:
            raise RuntimeError(f"job {' '.join(job)}: {type(exc).__name__}: {exc}") from exc
        finally:
            HydraConfig.instance().cfg = None
            torch.set_num_threads(threads)


# ---------------------------------------------------------------------------------------- the tests
def check_block(block: Block, request: pytest.FixtureRequest, folder: Path) -> None:
    """Run or check ``block`` as its marker says (the module docstring)."""
    if block.kind == "bad":
        pytest.fail(block.problem, pytrace=False)
    if block.kind == "skip":
        pytest.skip(f"not run: {block.args[0]}")
    if block.kind == "literal":
        if block.lang == "toml":
            tomllib.loads(block.code)
        elif block.lang == "json":
            json.loads(block.code)
        return
    factory = request.getfixturevalue("tmp_path_factory")
    fixtures = fixture_paths(factory) if block.kind == "small" else {}
    code = replaced(block, block.code, fixtures)
    if block.lang in PYTHON:
        settings = None
        if block.kind == "small":
            settings = small_env(factory, request.getfixturevalue("env_cache"))
            for arg in block.args:
                if "=>" not in arg:
                    key, _, value = arg.partition("=")
                    try:
                        settings[key] = ast.literal_eval(value)
                    except (SyntaxError, ValueError):
                        pytest.fail(f"{block.where}: docs-test: small {arg!r}: give key=<a Python literal>",
                                    pytrace=False)  # fmt: skip
        run_python(block, code, settings, folder)
        return
    if block.kind == "compose":
        runs = shared_folder(factory, "docs_composed")
        for cmd in commands(block, code):
            problem = None if cmd.shell_only else composed(cmd.script, cmd.argv[1:], runs)
            if problem:
                pytest.fail(f"{block.where}: {' '.join(cmd.argv)}\n{problem}", pytrace=False)
        return
    extra: dict[str, list[str]] = {}
    after: list[Command] = []
    if block.kind == "small":
        grid = request.getfixturevalue("script_overrides")
        for script in STOP_AT:
            mine = [a.split(":", 1)[1] for a in block.args if a.startswith(f"{script}:")]
            plain = [a for a in block.args if "=>" not in a and not re.match(r"^[\w-]+\.py:|^after=", a)]
            extra[script] = [*small_settings(script, grid), *plain, *mine]
        after = [c for a in block.args if a.startswith("after=") for c in commands(block, a[6:])]
    runs = shared_folder(factory, "docs_runs") if block.kind == "small" else folder
    run_commands(block, [*after, *commands(block, code, RUN_SLOT)], extra, runs)


BLOCKS = [block for page in pages() for block in collect(page)]


@pytest.mark.parametrize(
    "block",
    [pytest.param(b, id=b.where, marks=[pytest.mark.slow] if b.kind in ("run", "small", "compose") else [])
     for b in BLOCKS],
)  # fmt: skip
def test_code_block(block: Block, request: pytest.FixtureRequest, tmp_path: Path) -> None:
    check_block(block, request, tmp_path)


def test_the_pages_collected_are_readme_and_the_site_but_the_notes_and_changelog():
    names = {p.relative_to(ROOT).as_posix() for p in pages()}
    assert {"README.md", "docs/index.md", "docs/guide/getting-started.md", "docs/envs/fleet.md"} <= names
    assert not names & set(NOT_COLLECTED)
    assert {b.where.split(":")[0] for b in BLOCKS if b.kind != "literal"} >= {"README.md", "docs/FLEET.md"}


PLANTED = """# A page

```bash
python scripts/train.py agent=greedy
```

<!-- docs-test: skip starts a server -->
```bash
tensorboard --logdir outputs/
```

```python
print("runs by default")
```

```text
an output: no marker needed
```

<!-- docs-test: compose -->

```bash
python scripts/train.py
```

<!-- docs-test: sometimes -->
```bash
python scripts/train.py
```

<!-- docs-test: skip -->
```bash
python scripts/train.py
```

<!-- docs-test compose -->
```bash
python scripts/train.py
```

````{note}
<!-- docs-test: compose -->
```{code-block} bash
:caption: in a directive
python scripts/train.py agent=greedy
```
````

```c
int main(void) { return 0; }
```
"""


@pytest.fixture
def planted(tmp_path: Path) -> list[Block]:
    page = tmp_path / "page.md"
    page.write_text(PLANTED)
    return collect(page)


def test_a_block_without_a_marker_fails_with_its_place_and_what_to_write(planted, request, tmp_path):
    assert [(b.line, b.kind) for b in planted] == [
        (3, "bad"), (8, "skip"), (12, "run"), (16, "literal"), (20, "bad"), (22, "bad"), (27, "bad"),
        (32, "bad"), (37, "bad"), (43, "compose"), (49, "bad"),
    ]  # fmt: skip
    page = planted[0].page
    assert planted[0].problem.startswith(f"{page}:3: a shell block runs nothing unless marked")
    assert "docs-test: run | small ARGS | compose | skip REASON" in planted[0].problem
    assert "right before" in planted[4].problem and planted[4].line == 20  # the marker's line
    assert "unknown docs-test kind 'sometimes'" in planted[6].problem
    assert "needs the reason" in planted[7].problem
    assert "'<!-- docs-test compose -->' does not parse" in planted[8].problem
    assert planted[9].first == 45 and planted[9].code == "python scripts/train.py agent=greedy"
    assert "a 'c' block" in planted[10].problem
    for block in (planted[0], planted[4], planted[10]):
        with pytest.raises(pytest.fail.Exception, match=re.escape(f"{page}:{block.line}: ")):
            check_block(block, request, tmp_path)
    with pytest.raises(pytest.skip.Exception, match="not run: starts a server"):
        check_block(planted[1], request, tmp_path)


@pytest.mark.parametrize(
    "code,message",
    [
        ("W=1 python scripts/train.py $W", "uses a shell variable"),
        ("make all", "not a command the tests run"),
        ("python scripts/train.py | tee log", "no pipes or redirections"),
    ],
)
def test_a_command_the_tests_cannot_run_fails(code, message):
    block = Block(ROOT / "page.md", 3, 4, "bash", code, "compose")
    with pytest.raises(pytest.fail.Exception, match=re.escape(message)):
        commands(block, code)


def test_commands_split_chains_continuations_comments_and_placeholders():
    code = ("python -m pip install -e . && python scripts/train.py agent=dqn \\\n"
            "    'env.departure_window=[0,3600]'   # a comment\n"
            "python scripts/evaluate.py agent.checkpoint=outputs/train/<that run>\n")  # fmt: skip
    block = Block(ROOT / "page.md", 1, 2, "bash", code, "compose")
    found = commands(block, code)
    assert [c.argv for c in found] == [
        ("python", "-m", "pip", "install", "-e", "."),
        ("scripts/train.py", "agent=dqn", "env.departure_window=[0,3600]"),
        ("scripts/evaluate.py", "agent.checkpoint=outputs/train/that_run"),  # compose: a name
    ]
    assert found[0].shell_only == "installs packages" and not found[1].shell_only
    assert commands(block, code, RUN_SLOT)[2].argv[1] == f"agent.checkpoint=outputs/train/{RUN_SLOT}"


def test_a_sweep_is_checked_on_a_covering_set_of_its_jobs():
    jobs = covering(["agent=dqn,ppo", "seed=0,1,2", "evs=400", "env.observe=[],[route_time]"])
    assert jobs == [
        ["agent=dqn", "seed=0", "evs=400", "env.observe=[]"],
        ["agent=ppo", "seed=1", "evs=400", "env.observe=[route_time]"],
        ["agent=dqn", "seed=2", "evs=400", "env.observe=[]"],
    ]


@pytest.mark.slow
def test_compose_fails_on_what_hydra_or_the_script_refuses(tmp_path):
    train = ROOT / "scripts" / "train.py"
    assert "Could not find 'agent/nope'" in compose_problem(train, ("agent=nope",), tmp_path)
    assert "evs=-5" in compose_problem(train, ("agent=greedy", "evs=-5"), tmp_path)  # the script's check
    assert "refused (exit code 2)" in compose_problem(train, ("agent=greedy", "evs=-5"), tmp_path)
    assert compose_problem(ROOT / "scripts" / "make_table.py", ("--no-such-flag",), tmp_path)
    assert compose_problem(train, ("agent=greedy",), tmp_path) is None
