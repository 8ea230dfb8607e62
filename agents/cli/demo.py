"""``marine demo``: a short USV episode, rudder fixed vs LQR: a table and a figure. Its arguments
(:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse

from . import common

DEMO_PLOT = "marine_demo.png"


#: The command's line in ``marine --help``.
HELP = "a short USV episode: rudder fixed vs LQR; prints a table, writes a plot"
#: The command's description in its help (argparse fills the lines anew).
DESCRIPTION = """\
Simulate the USV in a stern-quartering random sea with the rudder fixed and with a discrete LQR
autopilot acting on the noisy, quantized sensors; print RMS heading, roll and rudder and the
episode returns; write a plot.
"""
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "seed": "episode seed (0)",
    "json": "also write the summary as JSON",
    "force": "replace existing outputs",
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine demo``'s own arguments."""
    parser.add_argument("--seconds", type=common.positive_float, default=100.0,
                        help="episode length, s (100)")
    parser.add_argument("--hs", type=common.positive_float, default=2.0,
                        help="significant wave height, m (2.0)")
    parser.add_argument("--plot", help=f"figure path (default {DEMO_PLOT}, the demo's own: "
                                       "rewritten; another existing file needs --force)")
    parser.add_argument("--no-plot", action="store_true", help="do not write a figure")


def handle(args: argparse.Namespace) -> int:
    """Run ``marine demo`` as ``args`` ask; the exit code."""
    from ..demo import format_table, roll_reduction, run_demo

    seed = 0 if args.seed is None else args.seed  # --seed's default here
    plot = None
    if not args.no_plot:  # the demo's own figure is rewritten; a path the user names is kept
        plot = common.plot_path(args.plot, args.force) if args.plot else \
            common.plot_path(DEMO_PLOT, True)
    out = common.output_file(args.json, args.force, "--json")
    common.distinct(("--plot", plot), ("--json", out))
    summary = run_demo(seconds=args.seconds, seed=seed, hs=args.hs, plot=plot)
    print(f"USV-v0, Hs = {args.hs} m, stern-quartering sea, {args.seconds:g} s, seed {seed}")
    print(format_table(summary))
    print(f"LQR on the raw sensors reduces RMS roll by {roll_reduction(summary):.0%} "
          "(rudder-roll stabilisation) while holding the course.")
    if plot is not None:
        print(f"plot written to {plot}")
    common.write_json_output(out, summary)
    return 0
