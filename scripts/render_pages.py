"""Render the documentation's generated regions from the committed data (evcd.report.pages).

    python scripts/render_pages.py            # rewrite the generated regions of README.md (and the pages
                                              # of evcd.report.pages.PAGES) from docs/results.csv, ...
    python scripts/render_pages.py --check    # change nothing; list where a page differs, cell by cell

Exit codes: 0 done (with ``--check``: every page is as its data renders it); 1 ``--check`` found a
difference (each is listed); 2 a page's regions are malformed or a data file is missing.
"""

from __future__ import annotations

import argparse
import logging
import sys
from pathlib import Path

from evcd.report.pages import PAGES, PageError, differences, render_page
from evcd.utils.atomic import atomic_write_text

log = logging.getLogger("render_pages")
ROOT = Path(__file__).resolve().parents[1]


def main(argv: list[str] | None = None) -> int:
    """Command-line entry point; returns the exit code."""
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--check", action="store_true", help="change nothing; list the differences")
    p.add_argument("--root", type=Path, default=ROOT, help="the repository root (default: this checkout)")
    args = p.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    found = []
    for page in PAGES:
        path = args.root / page
        text = path.read_text()
        try:
            rendered = render_page(text, args.root)
        except (PageError, OSError, KeyError, ValueError) as exc:
            log.error("%s: %s", page, exc)
            return 2
        if args.check:
            found += differences(text, rendered, page)
        elif rendered != text:
            atomic_write_text(path, rendered)
            log.info("rewrote the generated regions of %s", page)
    for line in found:
        print(line)
    if args.check:
        log.info("%s", f"{len(found)} difference(s)" if found else "every page is as its data renders it")
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
