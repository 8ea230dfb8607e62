"""``marine episode``: run one episode of any environment behind any policy and estimator; RMS
errors and a figure. Its arguments (:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse

from . import common

#: The command's line in ``marine --help``.
HELP = "run one episode of any environment; print RMS errors, plot it"
#: The command's description in its help (argparse fills the lines anew).
DESCRIPTION = """\
Run one episode of an environment and print its return and the RMS error of every state the task
weighs (angles in degrees); with --plot, draw the true and measured states and the inputs against
time.
"""
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "seed": "episode seed (0)",
    "json": "also write the summary as JSON",
    "force": "replace existing outputs",
    "env_kwargs": 'environment arguments, SI units, e.g. \'{"zigzag": "20/20"}\'',
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine episode``'s own arguments."""
    from estimators import registry

    from ..episode import EPISODE_ESTIMATORS, EPISODE_POLICIES

    parser.add_argument("env", type=common.env_id,
                        help="environment id, e.g. marine_envs/ROV-v0 (or ROV-v0)")
    parser.add_argument("--policy", type=common.policy_name, choices=EPISODE_POLICIES,
                        default="lqr-state",
                        help="lqr-state (LQR on the true state, the default), lqr (on the raw "
                             "sensors), nominal (the nominal input; its old name zero still "
                             "works) or an excitation: sine, random, prbs")
    parser.add_argument("--estimator", choices=EPISODE_ESTIMATORS,
                        help="put an estimator between the sensors and the policy: "
                             f"{registry.describe()}; --policy lqr then acts on the full "
                             "estimated state")
    parser.add_argument("--seconds", type=common.positive_float,
                        help="episode length, s (the env's own)")
    parser.add_argument("--plot", metavar="PNG", help="write a figure of the episode")


def handle(args: argparse.Namespace) -> int:
    """Run ``marine episode`` as ``args`` ask; the exit code."""
    from ..episode import run

    seed = 0 if args.seed is None else args.seed  # --seed's default here
    plot = common.plot_path(args.plot, args.force)
    out = common.output_file(args.json, args.force, "--json")
    common.distinct(("--plot", plot), ("--json", out))
    common.check_estimator(args.estimator)
    env_kwargs = args.env_kwargs or {}
    common.check_env(args.env, env_kwargs)
    summary = run(args.env, policy=args.policy, seconds=args.seconds, seed=seed,
                  env_kwargs=env_kwargs, plot=plot, estimator=args.estimator)
    on = f" on {args.estimator}" if args.estimator else ""
    print(f"{args.env}, policy {args.policy}{on}, seed {seed}")
    for key, value in summary.items():
        print(f"  {key:<24}{value:>14.6g}")
    if plot is not None:
        print(f"plot written to {plot}")
    common.write_json_output(out, summary)
    return 0
