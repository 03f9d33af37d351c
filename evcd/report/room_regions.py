"""The room the fleet's best rule leaves, on the documentation pages: rendered from the room's tables
(``docs/fleet_room/<world>/fleet_results.csv``, made by ``scripts/reproduce.py room``: the clairvoyant
bound, :mod:`evcd.loops.fleet_bound`, beside the rules on the fleet table's episodes) and, for the shares
of the greedy -> bound gap, the fleet table's learners (:mod:`evcd.report.fleet_regions`).

Each function takes the repository root and returns a generated region's Markdown
(:mod:`evcd.report.pages`): the README's room line, the fleet page's line per world and its table of the
shares of the gap each dispatcher closes.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from evcd.report.fleet_regions import paired, read_jobs, seed_mean, share_label
from evcd.report.markdown import markdown_table, signed
from evcd.report.markdown import signed_interval as _signed
from evcd.report.seed_stats import GapShare, gap_share

#: The room's tables (``scripts/reproduce.py room``): the clairvoyant bound beside the rules, by world.
ROOM = {world: Path("docs") / "fleet_room" / world / "fleet_results.csv" for world in ("calm", "perturbed")}


def room(root: Path) -> str:
    """The README's line on the room ``central`` leaves: ``central`` minus the played plan (the
    clairvoyant dispatcher, :mod:`evcd.loops.fleet_bound`) per guided EV, calm and perturbed, at the
    highest and the lowest guided share."""
    worlds = {world: read_jobs(root, table) for world, table in ROOM.items()}
    top, low = max(worlds["calm"]), min(worlds["calm"])
    at_top = []
    for world, shares in worlds.items():
        room_ = paired(shares[top], "central", "fleet_bound")
        part = room_.mean / seed_mean(shares[top]["central"], "guided_travel")
        at_top.append(f"{_signed(room_)} {world} ({part:.0%} of central's time)")
    lows = [f"{signed(paired(worlds[w][low], 'central', 'fleet_bound').mean)} {w}" for w in worlds]
    seeds = len(worlds["calm"][top]["central"])
    return (f"- How much room central leaves on the fleet, per guided EV: central minus a dispatcher that "
            "knows the future, played in SUMO on the same episodes (600 EVs, guided share "
            f"{share_label(top)}, {seeds} seeds; s, mean over seeds [95% t]): {' and '.join(at_top)}; at "
            f"guided share {share_label(low)}, {' and '.join(lows)} "
            "([`docs/FLEET.md`](docs/FLEET.md)).")  # fmt: skip


def room_worlds(root: Path) -> str:
    """The fleet page's line per world: ``central`` minus the played plan and minus the proven bound,
    per guided EV, at each guided share (the mean over seeds of the seeds' differences)."""
    lines = []
    for world, table in ROOM.items():
        shares = read_jobs(root, table)
        order = sorted(shares, reverse=True)
        plan = " / ".join(signed(paired(shares[s], "central", "fleet_bound").mean) for s in order)
        bound = []
        for s in order:
            central, bounds = shares[s]["central"], shares[s]["fleet_bound"]
            seeds = sorted(set(central) & set(bounds))
            bound.append(signed(float(np.mean([central[k].guided_travel - bounds[k].bound for k in seeds]))))
        lines.append(f"- {world}: {plan} to the played plan; {' / '.join(bound)} to the bound (guided shares "
                     f"{' / '.join(map(share_label, order))}).")  # fmt: skip
    return "\n".join(lines)


def _gap_text(gap: GapShare) -> str:
    """A share of the gap with its interval (none for one seed), or ``no room``."""
    if not gap.room:
        return "no room"
    return f"{gap.share:.2f}" + (f" [{gap.low:.2f}, {gap.high:.2f}]" if math.isfinite(gap.low) else "")


def room_shares(root: Path) -> str:
    """The fleet page's table of the share of the greedy -> proven bound gap each dispatcher closes, per
    guided share, calm: ``central`` and the played plan from the room's table, the fleet table's
    learners and ``queue_aware`` on the same episodes (the seed means; a paired bootstrap over seeds
    drawn from one generator of seed 0, in the table's order)."""
    room, table = read_jobs(root, ROOM["calm"]), read_jobs(root)
    shares = sorted(room, reverse=True)
    rows = {"central": (room, "central"), "played plan": (room, "fleet_bound"),
            **{a: (table, a) for a in ("dqn", "dueling_ddqn", "queue_aware")}}  # fmt: skip
    rng = np.random.default_rng(0)
    cells: dict[str, list[str]] = {name: [] for name in rows}
    for share in shares:
        greedy = {s: j.guided_travel for s, j in room[share]["greedy"].items()}
        bound = {s: j.bound for s, j in room[share]["fleet_bound"].items()}
        for name, (jobs, agent) in rows.items():
            mine = {s: j.guided_travel for s, j in jobs[share][agent].items()}
            cells[name].append(_gap_text(gap_share(greedy, mine, bound, rng)))
    header = ["share of the gap closed", *(f"guided share {share_label(s)}" for s in shares)]
    return "\n".join([*markdown_table(header, [[n, *c] for n, c in cells.items()]), "",
                      "(G - A) / (G - B) of the seed means, G greedy, B the proven bound, A the dispatcher "
                      "[95% paired bootstrap interval over seeds]; `central` and the played plan from the "
                      "room's table, the learners and `queue_aware` from the fleet table, on the same "
                      "episodes."])  # fmt: skip
