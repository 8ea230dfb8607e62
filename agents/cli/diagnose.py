"""``marine diagnose``: find why a model and its recordings disagree: which physics the model lacks.
Its arguments (:func:`arguments`) beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

from . import common

#: The command's line in ``marine --help``.
HELP = "find why a model and a recording disagree: which physics it lacks"
DESCRIPTION = """\
Diagnose why a vehicle model and recordings of the vehicle disagree. Prints a summary and the
channel ranking; exit code 0 whether or not a mismatch is found (or the record is too short or
unexcited to judge: the reason is printed), 2 on invalid input.

two ways to judge (--method; auto picks free simulation for a series or a free decay, the
innovations otherwise):
  free          model tests (decays, zigzags, lab runs): the model is simulated freely over
                each whole record. --calibrate fits the named parameters by output error (from
                the record's own natural frequency and damping when it is a decay), with
                standard errors and an identifiability verdict; nested models (each candidate
                refitted with the calibrated parameters and the linear term it extends) are
                compared on held-out data: the last 30 % of one record, or each record of a
                series predicted by the model fitted on the others. Several recordings are one
                series: one parameter set, each its own initial state.
  innovations   records in a seaway: the nominal model's Kalman smoother estimates every
                state; its multi-step prediction errors locate the mismatch (channels, time
                windows, frequency band); every catalogue term is fitted to what the model
                cannot explain and kept only if it improves the predictions of the held-out
                last 30 % of the record significantly. Disturbance columns in the record (a
                logged wind, current or command: 'marine simulate --disturbances') are taken
                as known inputs; the filter estimates only the others.

catalogue (what a model may leave out):
  state terms   current, linear_damping, quadratic_damping, nonlinear_damping, coupling,
                nonlinear_restoring, parameter_change (a step at an unknown time),
                wave_frequency (a narrow-band oscillation), unlisted (a product of states or
                inputs no entry names)
  actuators     input_gain, input_delay, input_saturation, input_deadzone, input_rate_limit
  sensors       sensor_bias

the JSON (--json, or diagnosis.json in --report):
  model, mismatch (true / false / null = cannot judge), reason (when it cannot judge),
  channels [{name, score}] ranked by share of the excess prediction error,
  windows [{start, end, channel}] (s), band {low, high} (rad/s) or null,
  findings [{effect, target, parameters, std, confidence, improvement, explanation}],
  fit {method, before: {rmse}, after: {rmse}, improvement, validation, terms} (held-out, SI
  units), calibration (with --calibrate); free simulation adds calibration_quality {converged,
  parameters {name: {value, std, status}}, correlations}, model_check (the record's natural
  frequency and damping against the model's modes), unexplained {channel: {rmse,
  share_of_signal}}, alternatives (terms the data cannot tell apart, and the test that would),
  and each finding's standard_form (B1 B2 B3 damping, C1 C3 restoring, per unit inertia);
  warnings (values that look like unit mistakes, e.g. a rudder 57x its bound: degrees
  declared as rad?) and missing_samples {channel: n} (empty or NaN cells of a measured channel:
  samples the logger dropped, taken as missing measurements) when there are any
"""


#: The description is laid out by hand.
FORMATTER = argparse.RawDescriptionHelpFormatter
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {
    "json": "write the diagnosis as JSON",
    "force": "replace an existing --json, or the report (and every figure) "
             "in --report",
    "quiet": None,
}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine diagnose``'s own arguments."""
    parser.add_argument("recording", nargs="+",
                        help="recording file(s) (.csv with its .json sidecar, or .parquet), "
                             "as written by 'marine simulate'; several: one series")
    parser.add_argument("--model", help="model name (default: the recording's metadata)")
    parser.add_argument("--params", metavar="FILE",
                        help='JSON object of nominal parameter overrides (names as in '
                             'docs/models.md, SI units), e.g. {"wn": 0.6}; applied on top of the '
                             "recording's metadata")
    parser.add_argument("--calibrate", metavar="P1,P2,...",
                        help="nominal parameters to fit first (comma-separated), so that "
                             "only what the model's structure leaves out remains")
    parser.add_argument("--method", choices=("auto", "free", "innovations"), default="auto",
                        help="free simulation (model tests) or filter innovations (seaway "
                             "records); default: auto (see above)")
    parser.add_argument("--report", metavar="DIR",
                        help="write report.md, its PNG figures and diagnosis.json into DIR")
    cut = parser.add_argument_group(
        "long records (the expected run time is printed first; a seaway record takes about "
        "1 ms per sample)")
    cut.add_argument("--start", type=common.finite_float, metavar="SECONDS",
                     help="diagnose from this time on (the record's own clock, s)")
    cut.add_argument("--stop", type=common.finite_float, metavar="SECONDS",
                     help="diagnose up to this time (s)")
    cut.add_argument("--decimate", type=common.positive_int, default=1, metavar="K",
                     help="keep every K-th sample (no filtering: keep the new rate well above "
                          "the vehicle's bandwidth); default 1")


def handle(args: argparse.Namespace) -> int:
    """Run ``marine diagnose`` as ``args`` ask; the exit code."""
    from estimators.diagnosis import diagnose
    from estimators.diagnosis.api import expected_seconds, read_params
    from estimators.diagnosis.report import OWNED, owned_files

    out = common.output_file(args.json, args.force, "--json")
    report = None if args.report is None else common.output_dir(
        args.report, args.force, "--report", lambda d: [p.name for p in owned_files(d)],
        " (an earlier report)")
    if report is not None:
        common.distinct(("--json", out), *(("--report", report / name) for name in OWNED
                                           if "*" not in name))
    params = read_params(args.params) if args.params else None
    recordings = _read_recordings(args)  # warnings of implausible units are printed here
    if args.calibrate:
        from marine_envs.models import get_model

        try:
            get_model(args.model or recordings[0].model).check_parameter_names(
                n.strip() for n in args.calibrate.split(",") if n.strip())
        except ValueError as error:
            raise ValueError(f"--calibrate: {error}") from None
    say = _diagnose_log(not args.quiet)
    samples = sum(len(rec.time) for rec in recordings)
    spans = ", ".join(f"{rec.time[-1] - rec.time[0]:.0f} s" for rec in recordings)
    seconds = expected_seconds(recordings, args.method, bool(args.calibrate))
    say(f"{samples} samples ({spans}) of model {args.model or recordings[0].model}: " + (
            "free simulation (seconds; minutes where a recorded disturbance is an input)"
            if seconds is None else  # the rate varies with what the search finds
            f"expected run time {_duration(seconds)} to {_duration(3 * seconds)}")
        + ("" if seconds is None or seconds < 20 else
           "; --decimate K or --start/--stop SECONDS cut it"))
    with common.progress_bar(1, "diagnosing", not args.quiet) as bar:
        def stage(name: str, index: int, total: int) -> None:
            if bar is not None:
                bar.total = total
                bar.set_description(name)
                bar.update(index - bar.n)

        diagnosis = diagnose(recordings if len(recordings) > 1 else recordings[0], args.model,
                             params=params, calibrate=args.calibrate or (),
                             method=args.method, log=say, stage=stage)
        if bar is not None:
            bar.set_description("done")
            bar.update(bar.total - bar.n)
    _print_diagnosis(diagnosis)
    if out is not None:
        diagnosis.to_json(out)
        print(f"diagnosis written to {out}")
    if report is not None:
        from estimators.diagnosis.report import write_report

        # replaces the earlier report (--force) as a whole once the new one is written
        path = write_report(diagnosis, report, ", ".join(Path(r).name for r in args.recording))
        print(f"report written to {path}")
    return 0


def _duration(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.0f} min"


def _read_recordings(args: argparse.Namespace) -> list[Any]:
    """The recordings of ``marine diagnose``, read, checked and cut (--start, --stop,
    --decimate) before any work."""
    from marine_envs.models import get_model
    from marine_envs.recording import read_recording

    model = None if args.model is None else get_model(args.model).name
    recordings = []
    for path in args.recording:
        rec = read_recording(path, model=model)
        rec.meta.setdefault("name", Path(path).name)
        if args.start is not None or args.stop is not None or args.decimate > 1:
            rec = rec.window(args.start, args.stop, args.decimate)
        recordings.append(rec)
    return recordings


def _diagnose_log(show: bool) -> Callable[[str], None]:
    """``marine diagnose``'s status lines on stderr, above a progress bar."""
    def say(line: str) -> None:
        if not show:
            return
        from tqdm import tqdm

        tqdm.write(f"marine diagnose: {line}", file=sys.stderr)
    return say


def _print_diagnosis(diagnosis: Any) -> None:
    from estimators.diagnosis.sizing import described

    for line in diagnosis.warnings:
        print(f"  warning: {line}")
    if diagnosis.missing_samples:
        print("  missing samples (taken as dropped measurements): " + ", ".join(
            f"{c} {n}" for c, n in diagnosis.missing_samples.items()))
    for line in described(diagnosis.record):
        print(f"  {line}")
    print(diagnosis.summary())
    if diagnosis.mismatch is False and diagnosis.reason:
        print(f"  reason: {diagnosis.reason}")
    if diagnosis.channels:
        if "score" in diagnosis.channels[0]:
            print("channels (share of the prediction error beyond sensor noise):")
            for channel in diagnosis.channels:
                print(f"  {channel['name']:<12}{channel['score']:>8.1%}")
        else:
            print("channels (held-out free-simulation RMS error of the nominal model, SI):")
            for channel in diagnosis.channels:
                print(f"  {channel['name']:<12}{channel['rmse']:>12.4g}")
