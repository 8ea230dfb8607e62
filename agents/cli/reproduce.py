"""``marine reproduce``: re-run a source document's experiment and compare with its numbers. Its
arguments (:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse

from . import common

#: The command's line in ``marine --help``.
HELP = "re-run a source document's experiment and compare with its numbers"
DESCRIPTION = ("Re-run an experiment of the source documents: the document's own settings "
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
               "                          25/25 zig-zags vs least squares")
#: The description is laid out by hand.
FORMATTER = argparse.RawDescriptionHelpFormatter
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "json": "write the results as JSON",
    "force": "replace existing outputs",
    "quiet": None,
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine reproduce``'s own arguments."""
    from ..reproduce import REPRODUCTIONS

    parser.add_argument("name", choices=REPRODUCTIONS, help="the experiment")
    parser.add_argument("--quick", action="store_true",
                        help="fewer seeds and a shorter run (seconds, for a smoke test)")
    parser.add_argument("--plot", metavar="PNG", help="write the document-style figure")


def handle(args: argparse.Namespace) -> int:
    """Run ``marine reproduce`` as ``args`` ask; the exit code."""
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
