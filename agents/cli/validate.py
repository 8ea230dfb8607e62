"""``marine validate``: check a diagnosis on other tests: predict records with its nominal and
corrected models. Its arguments (:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse
import contextlib
from typing import Any

from . import common

#: The command's line in ``marine --help``.
HELP = ("check a diagnosis on other tests: predict records with its nominal "
        "and corrected models")
#: The command's description in its help (argparse fills the lines anew).
DESCRIPTION = """\
Predict each recording with the nominal-calibrated model of a diagnosis (its calibrated values, no
findings) and its corrected model (with the findings): replayed (the recorded inputs, free
simulation from the first measured state) and, with --rerun, re-run as the manoeuvre the record
shows (a zig-zag with its rudder amplitude, heading check, first direction and rudder rate; a turn
at its steady rudder). Prints per record and model the RMS error of every angle channel (deg) and
the standard criteria of record and prediction (first and second overshoot, time to check yaw;
turning rate), and says when a finding is used outside the range it was fitted on.
"""
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "json": "write the table as JSON",
    "force": "replace existing outputs",
    "quiet": None,
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine validate``'s own arguments."""
    parser.add_argument("diagnosis", help="the diagnosis JSON written by 'marine diagnose "
                                          "--json'")
    parser.add_argument("recording", nargs="+",
                        help="recording file(s) of the diagnosis's model (.csv with its "
                             ".json sidecar, or .parquet), best tests it was not fitted on")
    parser.add_argument("--rerun", choices=("zigzag", "turn"),
                        help="also re-run each record as this manoeuvre, closed loop")
    parser.add_argument("--plot", metavar="PNG",
                        help="write a figure: the heading of each record and the predictions")


def handle(args: argparse.Namespace) -> int:
    """Run ``marine validate`` as ``args`` ask; the exit code."""
    from estimators.diagnosis.validation import validate

    out = common.output_file(args.json, args.force, "--json")
    plot = common.plot_path(args.plot, args.force)
    common.distinct(("--json", out), ("--plot", plot))
    with contextlib.ExitStack() as stack:
        bars: list[Any] = []

        def progress(done: int, total: int) -> None:  # the bar once the inputs are checked
            if not bars:
                bars.append(stack.enter_context(
                    common.progress_bar(total, "predicting", not args.quiet)))
            if bars[0] is not None:
                bars[0].update(done - bars[0].n)

        result = validate(args.diagnosis, args.recording, args.rerun, progress)
    print(result.table())
    if out is not None:
        common.write_json_output(out, result.to_dict())
        print(f"table written to {out}")
    if plot is not None:
        result.plot(plot)
        print(f"plot written to {plot}")
    return 0
