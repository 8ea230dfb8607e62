"""``marine demo``: a short USV episode, rudder fixed vs LQR: a table and a figure. Its parser
(:func:`add_parser`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse
from typing import Any

from .common import (
    DEBUG,
    FORCE,
    JSON,
    SEED,
    distinct,
    output_file,
    plot_path,
    positive_float,
    write_json_output,
)

DEMO_PLOT = "marine_demo.png"


def add_parser(commands: Any) -> argparse.ArgumentParser:
    """Add ``marine demo`` to ``commands`` (the subparsers of ``marine``)."""
    demo = commands.add_parser(
        "demo", help="a short USV episode: rudder fixed vs LQR; prints a table, writes a plot",
        description="Simulate the USV in a stern-quartering random sea with the rudder fixed and "
                    "with a discrete LQR autopilot acting on the noisy, quantized sensors; print "
                    "RMS heading, roll and rudder and the episode returns; write a plot.",
        parents=[DEBUG, SEED, JSON, FORCE],
        option_help={"seed": "episode seed (0)",
                     "json": "also write the summary as JSON",
                     "force": "replace existing outputs"})
    demo.add_argument("--seconds", type=positive_float, default=100.0,
                      help="episode length, s (100)")
    demo.add_argument("--hs", type=positive_float, default=2.0,
                      help="significant wave height, m (2.0)")
    demo.add_argument("--plot", help=f"figure path (default {DEMO_PLOT}, the demo's own: "
                                     "rewritten; another existing file needs --force)")
    demo.add_argument("--no-plot", action="store_true", help="do not write a figure")
    demo.set_defaults(run=handle)
    return demo


def handle(args: argparse.Namespace) -> int:
    from ..demo import format_table, roll_reduction, run_demo

    seed = 0 if args.seed is None else args.seed  # --seed's default here
    plot = None
    if not args.no_plot:  # the demo's own figure is rewritten; a path the user names is kept
        plot = plot_path(args.plot, args.force) if args.plot else plot_path(DEMO_PLOT, True)
    out = output_file(args.json, args.force, "--json")
    distinct(("--plot", plot), ("--json", out))
    summary = run_demo(seconds=args.seconds, seed=seed, hs=args.hs, plot=plot)
    print(f"USV-v0, Hs = {args.hs} m, stern-quartering sea, {args.seconds:g} s, seed {seed}")
    print(format_table(summary))
    print(f"LQR on the raw sensors reduces RMS roll by {roll_reduction(summary):.0%} "
          "(rudder-roll stabilisation) while holding the course.")
    if plot is not None:
        print(f"plot written to {plot}")
    write_json_output(out, summary)
    return 0
