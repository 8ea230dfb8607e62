"""The source documents' experiments, re-run: every ``marine reproduce`` on one page.

Each reproduction runs a document's experiment in its own settings and, where those are
degenerate, in a corrected one, over several seeds; it prints a table that says which row is
the document's and which the correction, and draws its figure. This script runs them all (or
those named), writes each figure to ``docs/reproduce/NAME.png`` with its provenance and the
tables to the results page.

    python benchmarks/reproduce.py [NAME ...] [--quick] [--docs [PAGE]]
"""

from __future__ import annotations

import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))  # _common, also under pytest

import argparse  # noqa: E402
import time  # noqa: E402
from collections.abc import Sequence  # noqa: E402

from _common import REPO, add_docs_option, benchmark_run, check_page_path  # noqa: E402

from agents.reproduce import REPRODUCTIONS, run  # noqa: E402

TITLE = "The source documents' experiments"
ABOUT = """\
`marine reproduce NAME` re-runs one source document's experiment: the USV observer patent's
quantized-signal PD observer (`usv-quantized-observer`), the hydrofoil paper's adaptive Kalman
filter under LQR (`hydrofoil-akf`), the morphing robot's online identification by a joint
state/parameter EKF (`rov-online-id`), the DP patent's wave-frequency estimation
(`dp-wave-frequency`) and the hovercraft paper's EKF identification from zigzag tests
(`hovercraft-zigzag`). Each table says which setting is the document's and which is a
correction (where the document's own settings are degenerate) and why; numbers are means and
spreads over seeds. The documents' models and their sources are in [the models page](../models.md).
"""
FIGURES = REPO / "docs" / "reproduce"


def main(argv: Sequence[str] | None = None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("names", nargs="*", metavar="NAME",
                        help=f"reproductions to run (default: all): {', '.join(REPRODUCTIONS)}")
    parser.add_argument("--quick", action="store_true", help="fewer seeds and shorter runs")
    add_docs_option(parser, "reproduce")
    args = parser.parse_args(argv)
    unknown = sorted(set(args.names) - set(REPRODUCTIONS))
    if unknown:
        parser.error(f"unknown reproduction(s) {', '.join(unknown)}: one of "
                     f"{', '.join(REPRODUCTIONS)}")
    check_page_path(parser, args.docs)
    with benchmark_run("reproduce", argv) as bench:
        for name in args.names or REPRODUCTIONS:
            started = time.perf_counter()
            result = run(name, quick=args.quick, progress=True)
            seconds = time.perf_counter() - started
            bench.show(result.text, f"`{name}` ({seconds:.0f} s)", markdown=False)
            figure = FIGURES / f"{name}.png"
            result.plot(figure)  # saved with its provenance (marine_envs.provenance)
            bench.figures.append((figure.resolve(), f"marine reproduce {name}"))
    if args.docs:
        bench.write_page(args.docs, TITLE, ABOUT)


if __name__ == "__main__":
    main()
