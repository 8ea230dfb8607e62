"""Write ``docs/results/index.md``: a table of every results page the benchmarks wrote (what it
measures, the command that made it, how long that took, when and at what load), read from the
pages themselves, and the benchmarks that have no page yet.

    python benchmarks/results_index.py [--out docs/results/index.md]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import re  # noqa: E402
from collections.abc import Sequence  # noqa: E402
from pathlib import Path  # noqa: E402

from _common import RESULTS  # noqa: E402

from marine_envs.files import write_text  # noqa: E402

BENCHMARKS = Path(__file__).resolve().parent
INTRO = """\
Every table and figure on these pages was printed or drawn by a benchmark script in
`benchmarks/`, run with `--docs`, which writes the page with the command, the commit, the date,
the machine, its load and the BLAS threads of that run (BLAS is pinned to one thread in every
benchmark). Speeds are given as ratios to a reference measured in the same run: the machine
that ran them was shared with other jobs, so absolute rates and seconds are slower than on an
idle machine. This index is written by `python benchmarks/results_index.py`."""


def page_summary(page: Path) -> dict[str, str]:
    """The title, the first sentence of the description and the record of a results page."""
    text = page.read_text(encoding="utf-8")
    title = text.splitlines()[0].removeprefix("# ").strip()
    about = text.split("\n\n")[1].replace("\n", " ")
    record = dict(re.findall(r"^- (command|date|wall time|load average): (.*)$", text, re.M))
    return {"page": page.stem, "title": title, "what": _first_sentence(about),
            "command": record.get("command", "?"), "seconds": record.get("wall time", "?"),
            "date": record.get("date", "?")[:10],
            "load": record.get("load average", "?").split(" at the start")[0]}


def _first_sentence(text: str) -> str:
    match = re.match(r"(.+?)\.(\s|$)", text)
    return (match.group(1) if match else text.rstrip(".")) + "."


def index(folder: Path) -> str:
    """The index page of the results pages in ``folder``."""
    pages = sorted(p for p in folder.glob("*.md") if p.name != "index.md")
    rows = [page_summary(p) for p in pages]
    lines = ["# Results", "", INTRO, "",
             "| page | what it measures | command | wall time | date | load at start |",
             "|---|---|---|---:|---|---:|"]
    lines += [f"| [{r['title']}]({r['page']}.md) | {r['what']} | {r['command']} | "
              f"{r['seconds']} | {r['date']} | {r['load']} |" for r in rows]
    missing = sorted({p.stem for p in BENCHMARKS.glob("*.py") if not p.stem.startswith("_")
                      and p.stem != "results_index"} - {p.stem for p in pages})
    if missing:
        lines += ["", "No page yet (not run on the machine that wrote these): "
                  + ", ".join(f"`python benchmarks/{name}.py --docs`" for name in missing) + "."]
    lines += ["", "```{toctree}", ":hidden:", "", *(p.stem for p in pages), "```", ""]
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--out", type=Path, default=RESULTS / "index.md",
                        help="the index page (default docs/results/index.md)")
    args = parser.parse_args(argv)
    write_text(args.out, index(args.out.parent))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
