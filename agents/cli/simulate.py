"""``marine simulate``: record an episode of any environment (CSV or Parquet) in the recording
format. Its arguments (:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse
import math
import sys

from . import common

#: The command's line in ``marine --help``.
HELP = "record an episode (CSV or Parquet) in the recording format"
#: The command's description in its help (argparse fills the lines anew).
DESCRIPTION = """\
Run an environment under an excitation signal or LQR and record time, commanded inputs and sensor
outputs (SI units) with the model name and parameters as metadata (an actuator effect of effects=
acts after the command: --actuator-sensors records what the actuators applied too). The format
follows the file suffix: .csv (with a .csv.json sidecar) or .parquet (needs pyarrow).
"""
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "seed": "episode seed (random if omitted)",
    "force": "replace an existing --out",
    "env_kwargs": "environment arguments, SI units, e.g. "
                  '\'{"hs": 3.0, "tp": 9}\'',
    "quiet": None,
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine simulate``'s own arguments."""
    from ..simulate import POLICIES

    parser.add_argument("--env", type=common.env_id, default="marine_envs/USV-v0",
                        help="environment id (marine_envs/USV-v0, or USV-v0)")
    parser.add_argument("--steps", help="number of samples (1000; with --replay the record's)",
                        type=common.argument_type(int, lambda v: v >= 2, "an integer >= 2"))
    parser.add_argument("--out", required=True,
                        help="output file, .csv (with a .csv.json sidecar) or .parquet (needs "
                             "pyarrow: pip install \"marine-envs[parquet]\")")
    parser.add_argument("--policy", type=common.policy_name, choices=POLICIES, default="prbs",
                        help="nominal (the nominal input; its old name zero still works), an "
                             "excitation: sine, random (held uniform levels), prbs (held "
                             "+-amplitude levels), or lqr (closed loop on the sensors; with "
                             "--amplitude, plus a random-step dither held --hold s: a closed-loop "
                             "identification experiment); default prbs")
    parser.add_argument("--amplitude", type=common.fraction,
                        help="excitation amplitude, fraction of the actuator range (0.3; lqr: "
                             "none)")
    parser.add_argument("--period", type=common.positive_float, help="sine period, s (20)")
    parser.add_argument("--hold", type=common.positive_float,
                        help="random/prbs hold time, s (5; lqr's dither 2)")
    parser.add_argument("--disturbances", default="", metavar="NAMES",
                        help="comma-separated disturbance channels to record too (the model's "
                             "names, e.g. the ROV's morph command s_cmd or the hovercraft's "
                             "wind_north,wind_east): a diagnosis then takes them as known inputs")
    parser.add_argument("--actuator-sensors", nargs="?", const="all", metavar="NAMES",
                        help="record what the actuators applied too, as a position sensor on "
                             "each (column <input>_applied, e.g. delta_applied): 'all' (the "
                             "default when given alone) or comma-separated inputs; the input "
                             "columns always hold the command")
    parser.add_argument("--actuator-noise", type=common.argument_type(
        float, lambda v: math.isfinite(v) and v >= 0, "a finite number >= 0"), metavar="STD",
                     help="white noise of the actuator position sensors, standard deviation "
                          "in the inputs' SI units (rad, N); default 0")
    parser.add_argument("--replay", metavar="RECORD",
                        help="instead of --policy, the commands of RECORD (a recording of the "
                             "environment's model) from its first sample, at its sample period: "
                             "e.g. through a diagnosed vessel, --env-kwargs '{\"effects\": "
                             "\"diagnosis.json\", \"waves\": false}'")


def handle(args: argparse.Namespace) -> int:
    """Run ``marine simulate`` as ``args`` ask; the exit code."""
    from marine_envs.recording import check_suffix, read_recording, sidecar

    from ..simulate import record

    out = check_suffix(args.out)  # and Parquet's pyarrow
    common.output_file(args.out, args.force, "--out",
                       companions=(sidecar(out),) if out.suffix.lower() == ".csv" else ())
    env_kwargs = args.env_kwargs or {}
    common.check_env(args.env, env_kwargs)
    options = {k: v for k, v in (("amplitude", args.amplitude), ("period", args.period),
                                 ("hold", args.hold)) if v is not None}
    disturbances = [n.strip() for n in args.disturbances.split(",") if n.strip()]
    if args.actuator_noise is not None and args.actuator_sensors is None:
        raise ValueError("--actuator-noise goes with --actuator-sensors")
    actuators = _actuator_sensors(args.actuator_sensors)
    replay = None if args.replay is None else read_recording(args.replay)
    steps = args.steps if args.steps is not None or replay is not None else 1000
    done = record(out, args.env, steps, seed=args.seed, policy=args.policy,
                  env_kwargs=env_kwargs, progress=not args.quiet, disturbances=disturbances,
                  actuator_sensors=actuators, actuator_noise=args.actuator_noise or 0.0,
                  replay=replay, **options)
    kept = f": kept {done.steps} steps in {done.path}" if done.signal is not None else ""
    print(f"marine simulate: {done.stopped}{kept}", file=sys.stderr)
    print(f"wrote {done.steps} samples ({done.seconds:.1f} s) of model {done.model!r}: inputs "
          f"{', '.join(done.input_names)}; channels {', '.join(done.measured_names)}"
          + (f"; disturbances {', '.join(done.disturbance_names)}"
             if done.disturbance_names else "")
          + (f"; actuator positions {', '.join(n + '_applied' for n in done.actuator_names)}"
             if done.actuator_names else "") + f" -> {done.path}")
    return 0 if done.signal is None else common.EXIT_SIGNAL + done.signal


def _actuator_sensors(text: str | None) -> bool | list[str]:
    """``--actuator-sensors``: absent, ``all`` (every input) or comma-separated inputs."""
    if text is None:
        return False
    names = [n.strip() for n in text.split(",") if n.strip()]
    return True if names == ["all"] else names
