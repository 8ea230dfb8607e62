"""``marine reproduce``: re-run a source document's experiment and compare with its numbers. Its
parser (:func:`add_parser`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse
from typing import Any

from . import common


def add_parser(commands: Any) -> argparse.ArgumentParser:
    """Add ``marine reproduce`` to ``commands`` (the subparsers of ``marine``)."""
    from ..reproduce import REPRODUCTIONS

    reproduce = commands.add_parser(
        "reproduce", help="re-run a source document's experiment and compare with its numbers",
        description="Re-run an experiment of the source documents: the document's own settings "
                    "and a corrected setting where the document's are degenerate (the output "
                    "says which is which and why), averaged over seeds with their spread.\n\n"
                    "  usv-quantized-observer  the USV observer patent: PD observer vs "
                    "Luenberger on quantized\n"
                    "                          USV data\n"
                    "  hydrofoil-akf           the hydrofoil AKF paper: LQR fed by a KF vs the "
                    "adaptive KF,\n"
                    "                          time-varying sea\n"
                    "  rov-online-id           the morphing-robot patent: joint EKF of velocity "
                    "and 18 drag\n"
                    "                          coefficients through the morph, thrust "
                    "feed-forward\n"
                    "  dp-wave-frequency       the DP wave-frequency patent: FFT + Butterworth + "
                    "EKF estimate of\n"
                    "                          the wave frequencies, wave filter update\n"
                    "  hovercraft-zigzag       the hovercraft EKF paper: staged EKF identification "
                    "from 5/5, 15/15,\n"
                    "                          25/25 zig-zags vs least squares",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        parents=[common.DEBUG, common.JSON, common.FORCE, common.QUIET],
        option_help={"json": "write the results as JSON",
                     "force": "replace existing outputs"})
    reproduce.add_argument("name", choices=REPRODUCTIONS, help="the experiment")
    reproduce.add_argument("--quick", action="store_true",
                           help="fewer seeds and a shorter run (seconds, for a smoke test)")
    reproduce.add_argument("--plot", metavar="PNG", help="write the document-style figure")
    return reproduce


def handle(args: argparse.Namespace) -> int:
    from ..reproduce import run

    plot = common.plot_path(args.plot, args.force)
    out = common.output_file(args.json, args.force, "--json")
    common.distinct(("--plot", plot), ("--json", out))
    result = run(args.name, quick=args.quick, progress=not args.quiet)
    print(result.text)
    if plot is not None:
        result.plot(plot)
        print(f"plot written to {plot}")
    if out is not None:
        common.write_json_output(out, result.summary)
        print(f"results written to {out}")
    return 0
