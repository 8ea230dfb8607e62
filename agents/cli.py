"""The ``marine`` command line: demo, simulate, episode, reproduce, diagnose, validate, train,
evaluate, bench, envs.

Every command checks what it is given (environment ids, numbers, input files, output paths and
the extras their formats need) before any work, and reports a mistake as one line
``marine CMD: error: ...`` with exit code 2, never a traceback (``marine --debug CMD ...``
shows it). An output that exists is refused unless ``--force``; forced, what the command wrote
there before (checkpoints, figures) is cleared first, so that two runs never mix; two outputs of
one command on the same path are refused.

Nothing is lost: every file is written whole or not at all (a temporary file beside it, renamed
over it at the end: :mod:`marine_envs.files`), so a full disk or an error leaves the earlier file
(or none), and a report folder is filled only once all of it is written. A file that cannot be
written or read is reported like a mistake, one line and exit code 2:
``marine CMD: error: cannot write PATH: No space left on device``.

Exit codes: 0 done; 2 a mistake in what was asked, or a file that cannot be read or written;
130 (128 + SIGINT) stopped by Ctrl-C, 143 (128 + SIGTERM) by SIGTERM, which every command takes
as Ctrl-C: ``marine train`` first saves the agent (``marine train --resume DIR`` continues it),
``marine simulate`` keeps the steps recorded so far; 141 (128 + SIGPIPE) when the reader of the
output went away (``marine envs | head -1``), silently.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import importlib.util
import json
import math
import os
import shutil
import signal
import sys
import threading
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

DESCRIPTION = """\
marine-envs: Gymnasium environments for marine vehicles in waves, seen through noisy, quantized
sensors; the literature's state estimators as wrappers; LQR and RL agents on the same cost.

Angles on the command line are in degrees; everything inside (and in recordings) is SI/radians.
"""

DIAGNOSE_DESCRIPTION = """\
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


BENCH_DESCRIPTION = """\
Run a grid of vehicles x estimators x sea states x sensor degradations x controllers x seeds.
Every controller is scored by the task's quadratic cost on the same seeded episodes; each cell
(all axes but the seed) runs its seeds as one batch. SB3 agents named in --controllers are
trained first, one per vehicle and estimator, on the moderate sea and default sensors, and
kept in DIR/agents. Finished cells are kept in DIR/rows.csv and not run again.

outputs (in --out):
  rows.csv, rows.parquet  a row per seed: vehicle, estimator, controller, sea, sensor, seed,
                          status (ok or n/a: why), cost, failed, seconds, rms_<state> and
                          rms_<input> (SI; _deg: degrees), saturated, estimation_rms_<state>
  summary.md              cost mean ± std per cell; the checks KF <= raw, true <= KF under LQR
  cost_by_estimator.png   cost by estimator per vehicle, a bar per controller
  degradation.png         cost against each degradation's level (if it has several levels)

on a Ray cluster: start it (ray start --head on one machine, ray start --address HEAD:6379 on
the others, each with marine-envs installed), then run on any of them:
  marine bench --backend ray --address auto --seeds 20 --sensors default noise=4 noise=16
(with --controllers ppo, --out must be on a filesystem all machines share: tasks save agents)
"""


# -- checks before any work ---------------------------------------------------------------------
#: Exit codes: a user mistake (argparse's own), and Ctrl-C (128 + SIGINT, the shell's convention).
EXIT_USAGE, EXIT_INTERRUPTED = 2, 130
#: A signal stopped the command: this plus the signal's number (the shell's convention).
EXIT_SIGNAL = 128
#: Exceptions that report a mistake in what was asked (a value, a file, a missing extra), not a
#: bug: one line, exit 2. Anything else keeps its traceback.
USER_ERRORS = (ValueError, OSError, ImportError)
#: Figure formats the commands write (matplotlib's raster and vector formats).
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff",
                 ".webp")
#: Estimators that need an optional dependency: name -> (module, extra).
ESTIMATOR_EXTRAS = {"pd": ("cvxpy", "estimators")}
#: What ``marine bench`` writes into its --out folder; --force clears exactly these.
BENCH_OWNED = ("rows.csv", "rows.parquet", "summary.md", "cost_by_estimator.png",
               "degradation.png", "grid.json", "agents")


def _argument_type(convert: Callable[[str], Any], check: Callable[[Any], bool], what: str
                   ) -> Callable[[str], Any]:
    """An argparse ``type``: ``convert`` the text, then require ``check``; else argparse's own
    one-line error naming the option and ``what`` it must be."""
    def parse(text: str) -> Any:
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is invalid: {what}") from None
        if not check(value):
            raise argparse.ArgumentTypeError(f"{text} is invalid: {what}")
        return value
    return parse


positive_int = _argument_type(int, lambda v: v >= 1, "an integer >= 1")
seed_int = _argument_type(int, lambda v: v >= 0, "an integer >= 0")
positive_float = _argument_type(float, lambda v: math.isfinite(v) and v > 0,
                                "a finite number > 0")
finite_float = _argument_type(float, math.isfinite, "a finite number")
fraction = _argument_type(float, lambda v: math.isfinite(v) and 0 < v <= 1,
                          "a fraction in (0, 1]")


def env_id(text: str) -> str:
    """An argparse ``type``: a registered marine environment id; ``USV-v0`` and ``usv`` name
    ``marine_envs/USV-v0``."""
    from marine_envs import ENVIRONMENTS

    aliases = {}
    for full in ENVIRONMENTS:
        short = full.split("/")[1]
        aliases.update({short.lower(): full, short.removesuffix("-v0").lower(): full})
    found = text if text in ENVIRONMENTS else aliases.get(text.lower().removeprefix(
        "marine_envs/"))
    if found is None:
        raise argparse.ArgumentTypeError(f"{text!r} is not a marine environment: one of "
                                         f"{', '.join(ENVIRONMENTS)}")
    return found


def json_object(text: str) -> dict[str, Any]:
    """An argparse ``type``: a JSON object."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"{text!r} is not valid JSON: {error}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: a JSON object, e.g. "
                                         '\'{"hs": 3.0}\'')
    return value


def _output_file(path: str | None, force: bool, option: str,
                 suffixes: Sequence[str] | None = None, companions: Sequence[Path] = (),
                 creates: Path | None = None) -> Path | None:
    """``path``, a file the command will write, checked before any work: a known suffix, an
    existing writable folder (or ``creates``, an output folder the command makes, or one in
    it), not a folder itself; an existing file (or one of its ``companions``, e.g. a CSV's
    sidecar) is refused unless ``force``.

    :raises ValueError: a bad suffix or folder.  :raises FileExistsError: it exists.
    """
    if path is None:
        return None
    out = Path(path)
    if out.exists() and not (out.is_file() or out.is_dir()):
        return out  # a device or a pipe (/dev/stdout): written through, never replaced
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise ValueError(f"{option} {path}: unknown format {out.suffix or '(no suffix)'!r}: "
                         f"one of {', '.join(suffixes)}")
    folder = out.parent
    made = creates is not None and Path(creates).resolve() in (folder.resolve(),
                                                               *folder.resolve().parents)
    if not folder.is_dir() and not made:
        raise ValueError(f"{option} {path}: the folder {folder} does not exist")
    if folder.is_dir() and not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {path}: the folder {folder} is not writable")
    if out.is_dir():
        raise ValueError(f"{option} {path} is a folder, not a file")
    existing = [str(p) for p in (out, *companions) if p.exists()]
    if existing == [str(out)] and not force:
        raise FileExistsError(f"{option} {path} exists: use --force to replace it")
    if existing and not force:
        raise FileExistsError(f"{option} {path}: {' and '.join(existing)} exist: use --force "
                              "to replace them")
    return out


def _output_dir(path: str, force: bool, option: str, owned: Callable[[Path], list[str]],
                hint: str = "") -> Path:
    """``path``, a folder the command will write into (created when work starts), checked
    before any work: not a file, under a writable folder; one that already holds what the
    command writes (``owned``) is refused unless ``force`` (which clears it when work
    starts), so that two runs never mix.

    :raises ValueError: not a folder, or not writable.  :raises FileExistsError: owned files.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{option} {path} is a file, not a folder")
    ancestor = next(p for p in (out, *out.parents) if p.exists())
    if not (ancestor.is_dir() and os.access(ancestor, os.W_OK | os.X_OK)):
        raise ValueError(f"{option} {path}: {ancestor} is not a writable folder")
    held = owned(out) if out.is_dir() else []
    if held and not force:
        raise FileExistsError(f"{option} {path} already holds {', '.join(held)}{hint}: use "
                              "--force to replace them")
    return out


def _check_estimator(name: str | None, option: str = "--estimator") -> None:
    """:raises ImportError: ``name`` needs an extra that is not installed (before any work)."""
    if name in ESTIMATOR_EXTRAS:
        module, extra = ESTIMATOR_EXTRAS[name]
        if importlib.util.find_spec(module) is None:
            raise ImportError(f"{option} {name} needs {module}: pip install "
                              f"\"marine-envs[{extra}]\"")


def _check_env(env: str, kwargs: Mapping[str, Any]) -> None:
    """Build ``env`` with ``kwargs`` once, so that an argument it refuses (or does not know)
    is reported before any work; its plausibility warnings come with the real run."""
    import gymnasium as gym

    import marine_envs  # noqa: F401  (registers the environments)
    from marine_envs.plausibility import PlausibilityWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlausibilityWarning)
        try:
            gym.make(env, **kwargs).close()
        except TypeError as error:  # an argument the environment does not take
            raise ValueError(f"--env-kwargs: {error}") from None


def _plot_path(path: str | None, force: bool, option: str = "--plot") -> Path | None:
    return _output_file(path, force, option, PLOT_SUFFIXES)


def _distinct(*outputs: tuple[str, Path | None]) -> None:
    """Refuse two outputs of one command on the same file (the second would overwrite the
    first): ``outputs`` are ``(option, path)``; devices and pipes are shared freely.

    :raises ValueError: naming both options.
    """
    seen: dict[str, str] = {}
    for option, path in outputs:
        if path is None or (path.exists() and not path.is_file()):
            continue
        key = os.path.realpath(path)
        if key in seen and seen[key] != option:
            raise ValueError(f"{seen[key]} and {option} name the same file {path}: give each "
                             "its own")
        seen.setdefault(key, option)


def _write_json(path: Path | None, document: Any) -> None:
    from marine_envs.files import write_json

    if path is not None:
        write_json(path, document, default=float)


@contextlib.contextmanager
def _bar(total: int, description: str, show: bool) -> Iterator[Any]:
    """A tqdm bar (None when not ``show``), closed whatever happens."""
    if not show:
        yield None
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=description, dynamic_ncols=True)
    try:
        yield bar
    finally:
        bar.close()


# -- the commands ---------------------------------------------------------------------------------
def _demo(args: argparse.Namespace) -> int:
    from .demo import format_table, roll_reduction, run_demo

    plot = None
    if not args.no_plot:  # the demo's own figure is rewritten; a path the user names is kept
        plot = _plot_path(args.plot, args.force) if args.plot else _plot_path(DEMO_PLOT, True)
    out = _output_file(args.json, args.force, "--json")
    _distinct(("--plot", plot), ("--json", out))
    summary = run_demo(seconds=args.seconds, seed=args.seed, hs=args.hs, plot=plot)
    print(f"USV-v0, Hs = {args.hs} m, stern-quartering sea, {args.seconds:g} s, seed {args.seed}")
    print(format_table(summary))
    print(f"LQR on the raw sensors reduces RMS roll by {roll_reduction(summary):.0%} "
          "(rudder-roll stabilisation) while holding the course.")
    if plot is not None:
        print(f"plot written to {plot}")
    _write_json(out, summary)
    return 0


def _simulate(args: argparse.Namespace) -> int:
    from marine_envs.recording import check_suffix, read_recording, sidecar

    from .simulate import record

    out = check_suffix(args.out)  # and Parquet's pyarrow
    _output_file(args.out, args.force, "--out",
                 companions=(sidecar(out),) if out.suffix.lower() == ".csv" else ())
    env_kwargs = args.env_kwargs or {}
    _check_env(args.env, env_kwargs)
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
    return 0 if done.signal is None else EXIT_SIGNAL + done.signal


def _actuator_sensors(text: str | None) -> bool | list[str]:
    """``--actuator-sensors``: absent, ``all`` (every input) or comma-separated inputs."""
    if text is None:
        return False
    names = [n.strip() for n in text.split(",") if n.strip()]
    return True if names == ["all"] else names


def _episode(args: argparse.Namespace) -> int:
    from .episode import run

    plot = _plot_path(args.plot, args.force)
    out = _output_file(args.json, args.force, "--json")
    _distinct(("--plot", plot), ("--json", out))
    _check_estimator(args.estimator)
    env_kwargs = args.env_kwargs or {}
    _check_env(args.env, env_kwargs)
    summary = run(args.env, policy=args.policy, seconds=args.seconds, seed=args.seed,
                  env_kwargs=env_kwargs, plot=plot, estimator=args.estimator)
    on = f" on {args.estimator}" if args.estimator else ""
    print(f"{args.env}, policy {args.policy}{on}, seed {args.seed}")
    for key, value in summary.items():
        print(f"  {key:<24}{value:>14.6g}")
    if plot is not None:
        print(f"plot written to {plot}")
    _write_json(out, summary)
    return 0


def _reproduce(args: argparse.Namespace) -> int:
    from .reproduce import run

    plot = _plot_path(args.plot, args.force)
    out = _output_file(args.json, args.force, "--json")
    _distinct(("--plot", plot), ("--json", out))
    result = run(args.name, quick=args.quick, progress=not args.quiet)
    print(result.text)
    if plot is not None:
        result.plot(plot)
        print(f"plot written to {plot}")
    if out is not None:
        _write_json(out, result.summary)
        print(f"results written to {out}")
    return 0


def _envs(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from marine_envs import ENVIRONMENTS

    for env_id in ENVIRONMENTS:
        env = gym.make(env_id)
        sim = env.unwrapped.sim
        print(f"{env_id}\n  model {sim.model.name}: states {', '.join(sim.model.state_names)}; "
              f"inputs {', '.join(sim.model.input_names)}\n  observation "
              f"{', '.join(sim.sensors.channels)} {env.observation_space}\n  action "
              f"{env.action_space}, dt {sim.dt} s")
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


def _diagnose(args: argparse.Namespace) -> int:
    from estimators.diagnosis import diagnose
    from estimators.diagnosis.api import expected_seconds, read_params
    from estimators.diagnosis.report import OWNED, owned_files

    out = _output_file(args.json, args.force, "--json")
    report = None if args.report is None else _output_dir(
        args.report, args.force, "--report", lambda d: [p.name for p in owned_files(d)],
        " (an earlier report)")
    if report is not None:
        _distinct(("--json", out), *(("--report", report / name) for name in OWNED
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
    with _bar(1, "diagnosing", not args.quiet) as bar:
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


def _validate(args: argparse.Namespace) -> int:
    from estimators.diagnosis.validation import validate

    out = _output_file(args.json, args.force, "--json")
    plot = _plot_path(args.plot, args.force)
    _distinct(("--json", out), ("--plot", plot))
    with contextlib.ExitStack() as stack:
        bars: list[Any] = []

        def progress(done: int, total: int) -> None:  # the bar once the inputs are checked
            if not bars:
                bars.append(stack.enter_context(_bar(total, "predicting", not args.quiet)))
            if bars[0] is not None:
                bars[0].update(done - bars[0].n)

        result = validate(args.diagnosis, args.recording, args.rerun, progress)
    print(result.table())
    if out is not None:
        _write_json(out, result.to_dict())
        print(f"table written to {out}")
    if plot is not None:
        result.plot(plot)
        print(f"plot written to {plot}")
    return 0


#: ``marine train`` options that --resume takes from the run's config.json instead.
RESUME_TAKES = ("env_id", "algo", "estimator", "n_envs", "backend", "seed", "out", "config")


def _train(args: argparse.Namespace, parser: argparse.ArgumentParser) -> int:
    from . import sb3

    if args.resume is not None:
        given = [name for name in RESUME_TAKES if getattr(args, name) is not None]
        if given:
            parser.error(f"--resume takes the run's settings from {args.resume}/config.json: "
                         f"drop {', '.join(_option(n) for n in given)}")
        # refuses a live run, then finds the last agent that loads, before any work
        result = sb3.resume(Path(args.resume), args.timesteps, progress_bar=not args.quiet)
    else:
        if args.env_id is None or args.out is None:
            parser.error("the environment id and --out DIR are required (or --resume DIR)")
        _check_estimator(args.estimator)
        config = Path(args.config) if args.config else sb3.HYPERPARAMS
        if not config.is_file():
            raise FileNotFoundError(f"--config {config}: no such file")
        sb3.settings(args.env_id, args.algo or "ppo", args.estimator, args.timesteps,
                     args.seed or 0, args.n_envs, args.backend or "native",
                     hyperparams_file=config)
        sb3.check_not_in_use(Path(args.out))  # a live run is named as such, --force or not
        out = _output_dir(args.out, args.force, "--out", sb3.existing_run,
                          " (a training run: --resume it)")
        result = sb3.train(args.env_id, args.algo or "ppo", args.estimator, args.timesteps,
                           out, args.seed or 0, args.n_envs, args.backend or "native",
                           progress_bar=not args.quiet, hyperparams_file=config,
                           force=args.force)
    if result.stop_signal is not None:
        print(f"marine train: interrupted at {result.timesteps} steps, saved to {result.out} "
              f"(continue: marine train --resume {result.out})", file=sys.stderr)
        return 128 + result.stop_signal  # the shell's convention: 130 SIGINT, 143 SIGTERM
    since = f" (from {result.resumed_from})" if result.resumed_from else ""
    print(f"trained {result.timesteps} steps{since} in {result.wall_seconds:.1f} s "
          f"({result.steps_per_second:.0f} steps/s); saved to {result.out}")
    if result.selected is not None:
        best = result.selected
        print(f"model.zip is the agent of {best['timesteps']} steps, the best on validation "
              f"({best['failed']} failed, mean cost {best['cost']:.4g}); the last is "
              "last_model.zip")
    return 0


def _option(dest: str) -> str:
    return "the environment id" if dest == "env_id" else "--" + dest.replace("_", "-")


def _evaluate(args: argparse.Namespace) -> int:
    import numpy as np

    from . import sb3
    from .evaluation import episode_steps

    out = _output_file(args.json, args.force, "--json")
    saved = sb3.find_agent(Path(args.dir))  # a run folder, a checkpoint or a model file
    config = sb3.read_config(saved.run)
    steps = episode_steps(config["env_id"], config.get("max_episode_steps"))
    print(f"{saved.model}" + (f" ({saved.timesteps} steps)" if saved.timesteps else "")
          + f": {config['env_id']} behind {config.get('estimator') or 'raw'}")
    with _bar(steps, "evaluating", not args.quiet) as bar:
        rows = sb3.evaluate(saved.model, args.episodes, args.seed,
                            progress=None if bar is None else bar.update)
        if bar is not None:
            bar.total = bar.n  # all boats done: the episodes may have ended early
    print(f"{args.episodes} episodes, seeds {args.seed}..{args.seed + args.episodes - 1} "
          "(mean ± std; angles in degrees):")
    for key in rows[0]:
        if key != "seed":
            values = [row[key] for row in rows]
            print(f"  {key:28s} {np.mean(values):12.5g} ± {np.std(values):.3g}")
    _write_json(out, {"rows": rows})
    return 0


def _bench_owned(out: Path) -> list[str]:
    return [name for name in BENCH_OWNED if (out / name).exists()]


def _bench(args: argparse.Namespace) -> int:
    from .benchmark import Grid, markdown_summary, run_grid, write_outputs, write_report
    from .benchmark.grid import cell_key
    from .benchmark.run import load_rows

    chosen = {k: tuple(v) if isinstance(v, list) else v for k, v in vars(args).items()
              if k in GRID_OPTIONS and v is not None}
    grid = dataclasses.replace(Grid.quick(), **chosen) if args.quick else Grid(**chosen)
    for name in grid.estimators:
        _check_estimator(name, "--estimators")
    if args.backend == "ray" and importlib.util.find_spec("ray") is None:
        raise ImportError("--backend ray needs Ray: pip install \"marine-envs[ray]\"")
    for controller in grid.controllers:
        if controller.startswith("sb3:"):
            from .sb3 import find_agent

            find_agent(Path(controller[4:]))
    out = Path(args.out)
    resuming = (out / "grid.json").is_file() and not args.force  # a rerun resumes (documented)
    if not resuming:
        _output_dir(args.out, args.force, "--out", _bench_owned, " (without its grid.json)")
    # resuming, the grid's own summaries inside --out (e.g. --report bench/report) are redone
    def own(path: str | None) -> bool:
        return resuming and path is not None and out.resolve() in Path(path).resolve().parents

    json_out = _output_file(args.json, args.force or own(args.json), "--json", creates=out)
    report = None if args.report is None else _output_dir(
        args.report, args.force or own(args.report), "--report",
        lambda d: ["index.html"] if (d / "index.html").exists() else [])
    _distinct(("--json", json_out), *(("--out", out / name) for name in BENCH_OWNED),
              ("--report", None if report is None else report / "index.html"))
    if resuming:
        before = json.loads((out / "grid.json").read_text())
        if before != json.loads(json.dumps(grid.settings())):
            raise ValueError(f"--out {out} holds a grid run with {before}, not "
                             f"{grid.settings()}: resume it with the same --seeds/--seconds/"
                             "--timesteps, use another --out, or --force to start afresh")
        done = {cell_key(r) for r in load_rows(out).to_dict("records")}
        cells = grid.cells()
        print(f"marine bench: resuming {out}: {sum(cell_key(c) in done for c in cells)} of "
              f"{len(cells)} cells done (--force starts afresh)", file=sys.stderr)
    elif args.force:
        for name in _bench_owned(out):
            if (out / name).is_dir():
                shutil.rmtree(out / name)
            else:
                (out / name).unlink()
    rows = run_grid(grid, out, args.backend, args.workers, args.address, not args.quiet)
    written = write_outputs(rows, out)
    print(markdown_summary(rows))
    if report is not None:
        written.append(write_report(rows, out, report, grid))
    if json_out is not None:
        from marine_envs.files import write_json

        records = json.loads(rows.to_json(orient="records"))
        json_out.parent.mkdir(parents=True, exist_ok=True)  # inside --out: made with it
        write_json(json_out, {"rows": records}, indent=1)
        written.append(json_out)
    print("wrote " + ", ".join(map(str, written)))
    return 0


#: ``marine train``'s algorithms and backends: agents.sb3's ALGOS and BACKENDS, named here so
#: that the parser (``--help``, ``--version``, any command) does not import torch.
TRAIN_ALGOS = ("ppo", "sac", "td3", "a2c", "ppo_lstm")
TRAIN_BACKENDS = ("native", "dummy")
GRID_OPTIONS = ("vehicles", "estimators", "controllers", "seas", "sensors", "seeds", "seconds",
                "timesteps")
DEMO_PLOT = "marine_demo.png"


class Parser(argparse.ArgumentParser):
    """argparse, with a mistake reported on one line, ``marine CMD: error: ...`` (exit 2)."""

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="marine", description=DESCRIPTION,
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--debug", action="store_true",
                        help="show the traceback of an error (for a bug report)")
    from marine_envs import __version__

    parser.add_argument("--version", action="version", version=f"marine-envs {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")

    demo = commands.add_parser(
        "demo", help="a short USV episode: rudder fixed vs LQR; prints a table, writes a plot",
        description="Simulate the USV in a stern-quartering random sea with the rudder fixed and "
                    "with a discrete LQR autopilot acting on the noisy, quantized sensors; print "
                    "RMS heading, roll and rudder and the episode returns; write a plot.")
    demo.add_argument("--seconds", type=positive_float, default=100.0,
                      help="episode length, s (100)")
    demo.add_argument("--seed", type=seed_int, default=0, help="episode seed (0)")
    demo.add_argument("--hs", type=positive_float, default=2.0,
                      help="significant wave height, m (2.0)")
    demo.add_argument("--plot", help=f"figure path (default {DEMO_PLOT}, the demo's own: "
                                     "rewritten; another existing file needs --force)")
    demo.add_argument("--no-plot", action="store_true", help="do not write a figure")
    demo.add_argument("--json", metavar="PATH", help="also write the summary as JSON")
    demo.add_argument("--force", action="store_true", help="replace existing outputs")
    demo.set_defaults(run=_demo)

    from .simulate import POLICIES

    sim = commands.add_parser(
        "simulate", help="record an episode (CSV or Parquet) in the recording format",
        description="Run an environment under an excitation signal or LQR and record time, "
                    "commanded inputs and sensor outputs (SI units) with the model name and "
                    "parameters as metadata (an actuator effect of effects= acts after the "
                    "command: --actuator-sensors records what the actuators applied too). The "
                    "format follows the file suffix: .csv (with a .csv.json sidecar) or "
                    ".parquet (needs pyarrow).")
    sim.add_argument("--env", type=env_id, default="marine_envs/USV-v0",
                     help="environment id (marine_envs/USV-v0, or USV-v0)")
    sim.add_argument("--steps", type=_argument_type(int, lambda v: v >= 2, "an integer >= 2"),
                     help="number of samples (1000; with --replay the record's)")
    sim.add_argument("--seed", type=seed_int, default=None,
                     help="episode seed (random if omitted)")
    sim.add_argument("--out", required=True,
                     help="output file, .csv (with a .csv.json sidecar) or .parquet (needs "
                          "pyarrow: pip install \"marine-envs[parquet]\")")
    sim.add_argument("--force", action="store_true", help="replace an existing --out")
    sim.add_argument("--policy", choices=POLICIES, default="prbs",
                     help="excitation: zero, sine, random (held uniform levels), prbs (held "
                          "+-amplitude levels), or lqr (closed loop on the sensors; with "
                          "--amplitude, plus a random-step dither held --hold s: a closed-loop "
                          "identification experiment); default prbs")
    sim.add_argument("--amplitude", type=fraction, help="excitation amplitude, fraction of "
                                                        "the actuator range (0.3; lqr: none)")
    sim.add_argument("--period", type=positive_float, help="sine period, s (20)")
    sim.add_argument("--hold", type=positive_float,
                     help="random/prbs hold time, s (5; lqr's dither 2)")
    sim.add_argument("--env-kwargs", metavar="JSON", type=json_object,
                     help='environment arguments, SI units, e.g. \'{"hs": 3.0, "tp": 9}\'')
    sim.add_argument("--disturbances", default="", metavar="NAMES",
                     help="comma-separated disturbance channels to record too (the model's "
                          "names, e.g. the ROV's morph command s_cmd or the hovercraft's "
                          "wind_north,wind_east): a diagnosis then takes them as known inputs")
    sim.add_argument("--actuator-sensors", nargs="?", const="all", metavar="NAMES",
                     help="record what the actuators applied too, as a position sensor on "
                          "each (column <input>_applied, e.g. delta_applied): 'all' (the "
                          "default when given alone) or comma-separated inputs; the input "
                          "columns always hold the command")
    sim.add_argument("--actuator-noise", type=_argument_type(
        float, lambda v: math.isfinite(v) and v >= 0, "a finite number >= 0"), metavar="STD",
                     help="white noise of the actuator position sensors, standard deviation "
                          "in the inputs' SI units (rad, N); default 0")
    sim.add_argument("--replay", metavar="RECORD",
                     help="instead of --policy, the commands of RECORD (a recording of the "
                          "environment's model) from its first sample, at its sample period: "
                          "e.g. through a diagnosed vessel, --env-kwargs '{\"effects\": "
                          "\"diagnosis.json\", \"waves\": false}'")
    sim.add_argument("--quiet", action="store_true", help="no progress bar")
    sim.set_defaults(run=_simulate)

    from estimators import registry

    from .episode import EPISODE_ESTIMATORS, EPISODE_POLICIES

    episode = commands.add_parser(
        "episode", help="run one episode of any environment; print RMS errors, plot it",
        description="Run one episode of an environment and print its return and the RMS error "
                    "of every state the task weighs (angles in degrees); with --plot, draw the "
                    "true and measured states and the inputs against time.")
    episode.add_argument("env", type=env_id, help="environment id, e.g. marine_envs/ROV-v0 "
                                                  "(or ROV-v0)")
    episode.add_argument("--policy", choices=EPISODE_POLICIES, default="lqr-state",
                         help="lqr-state (LQR on the true state, the default), lqr (on the raw "
                              "sensors), or an excitation: zero, sine, random, prbs")
    episode.add_argument("--estimator", choices=EPISODE_ESTIMATORS,
                         help="put an estimator between the sensors and the policy: "
                              f"{registry.describe()}; --policy lqr then acts on the full "
                              "estimated state")
    episode.add_argument("--seconds", type=positive_float,
                         help="episode length, s (the env's own)")
    episode.add_argument("--seed", type=seed_int, default=0, help="episode seed (0)")
    episode.add_argument("--plot", metavar="PNG", help="write a figure of the episode")
    episode.add_argument("--env-kwargs", metavar="JSON", type=json_object,
                         help='environment arguments, SI units, e.g. \'{"zigzag": "20/20"}\'')
    episode.add_argument("--json", metavar="PATH", help="also write the summary as JSON")
    episode.add_argument("--force", action="store_true", help="replace existing outputs")
    episode.set_defaults(run=_episode)

    from .reproduce import REPRODUCTIONS

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
        formatter_class=argparse.RawDescriptionHelpFormatter)
    reproduce.add_argument("name", choices=REPRODUCTIONS, help="the experiment")
    reproduce.add_argument("--quick", action="store_true",
                           help="fewer seeds and a shorter run (seconds, for a smoke test)")
    reproduce.add_argument("--json", metavar="PATH", help="write the results as JSON")
    reproduce.add_argument("--plot", metavar="PNG", help="write the document-style figure")
    reproduce.add_argument("--quiet", action="store_true", help="no progress bar")
    reproduce.add_argument("--force", action="store_true", help="replace existing outputs")
    reproduce.set_defaults(run=_reproduce)

    diagnose = commands.add_parser(
        "diagnose", help="find why a model and a recording disagree: which physics it lacks",
        description=DIAGNOSE_DESCRIPTION, formatter_class=argparse.RawDescriptionHelpFormatter)
    diagnose.add_argument("recording", nargs="+",
                          help="recording file(s) (.csv with its .json sidecar, or .parquet), "
                               "as written by 'marine simulate'; several: one series")
    diagnose.add_argument("--model", help="model name (default: the recording's metadata)")
    diagnose.add_argument("--params", metavar="FILE",
                          help='JSON object of nominal parameter overrides (names as in '
                               'docs/models.md, SI units), e.g. {"wn": 0.6}; applied on top of the '
                               "recording's metadata")
    diagnose.add_argument("--calibrate", metavar="P1,P2,...",
                          help="nominal parameters to fit first (comma-separated), so that "
                               "only what the model's structure leaves out remains")
    diagnose.add_argument("--method", choices=("auto", "free", "innovations"), default="auto",
                          help="free simulation (model tests) or filter innovations (seaway "
                               "records); default: auto (see above)")
    diagnose.add_argument("--json", metavar="OUT", help="write the diagnosis as JSON")
    diagnose.add_argument("--report", metavar="DIR",
                          help="write report.md, its PNG figures and diagnosis.json into DIR")
    diagnose.add_argument("--force", action="store_true",
                          help="replace an existing --json, or the report (and every figure) "
                               "in --report")
    cut = diagnose.add_argument_group(
        "long records (the expected run time is printed first; a seaway record takes about "
        "1 ms per sample)")
    cut.add_argument("--start", type=finite_float, metavar="SECONDS",
                     help="diagnose from this time on (the record's own clock, s)")
    cut.add_argument("--stop", type=finite_float, metavar="SECONDS",
                     help="diagnose up to this time (s)")
    cut.add_argument("--decimate", type=positive_int, default=1, metavar="K",
                     help="keep every K-th sample (no filtering: keep the new rate well above "
                          "the vehicle's bandwidth); default 1")
    diagnose.add_argument("--quiet", action="store_true", help="no progress bar")
    diagnose.set_defaults(run=_diagnose)

    validate = commands.add_parser(
        "validate", help="check a diagnosis on other tests: predict records with its nominal "
                         "and corrected models",
        description="Predict each recording with the nominal-calibrated model of a diagnosis "
                    "(its calibrated values, no findings) and its corrected model (with the "
                    "findings): replayed (the recorded inputs, free simulation from the first "
                    "measured state) and, with --rerun, re-run as the manoeuvre the record shows "
                    "(a zig-zag with its rudder amplitude, heading check, first direction and "
                    "rudder rate; a turn at its steady rudder). Prints per record and model the "
                    "RMS error of every angle channel (deg) and the standard criteria of record "
                    "and prediction (first and second overshoot, time to check yaw; turning "
                    "rate), and says when a finding is used outside the range it was fitted on.")
    validate.add_argument("diagnosis", help="the diagnosis JSON written by 'marine diagnose "
                                            "--json'")
    validate.add_argument("recording", nargs="+",
                          help="recording file(s) of the diagnosis's model (.csv with its "
                               ".json sidecar, or .parquet), best tests it was not fitted on")
    validate.add_argument("--rerun", choices=("zigzag", "turn"),
                          help="also re-run each record as this manoeuvre, closed loop")
    validate.add_argument("--json", metavar="OUT", help="write the table as JSON")
    validate.add_argument("--plot", metavar="PNG",
                          help="write a figure: the heading of each record and the predictions")
    validate.add_argument("--force", action="store_true", help="replace existing outputs")
    validate.add_argument("--quiet", action="store_true", help="no progress bar")
    validate.set_defaults(run=_validate)

    train = commands.add_parser(
        "train", help="train a Stable-Baselines3 agent (PPO, SAC, TD3, A2C) on an environment",
        description="Train an SB3 agent on the native batched environment, optionally behind "
                    "a state estimator. Hyperparameters per vehicle and algorithm come from "
                    "agents/hyperparams.yaml (RL-Zoo style; --config another file); writes "
                    "config.json (at once, then final), model.zip, vecnormalize.pkl (if "
                    "normalised) and checkpoints/ into --out. Where the settings give "
                    "validation_episodes, model.zip is the checkpoint that did best on them "
                    "(fewest failures, then least cost) and last_model.zip the last. Ctrl-C "
                    "stops at the next step, saves as at the end and exits with code 130; "
                    "--resume DIR continues from the last saved agent with its step count.")
    train.add_argument("env_id", nargs="?", type=env_id,
                       help="environment id, e.g. marine_envs/USV-v0 (or USV-v0)")
    train.add_argument("--algo", choices=TRAIN_ALGOS,
                       help="ppo, sac, td3, a2c or ppo_lstm (sb3-contrib's RecurrentPPO: the "
                            "recurrent extra); default ppo")
    train.add_argument("--estimator", choices=registry.names(), metavar="ESTIMATOR",
                       help="what the agent sees: raw (the sensors, the default), true (the "
                            f"true state) or an estimator: {registry.describe()}")
    train.add_argument("--timesteps", type=positive_int,
                       help="environment steps (default: the YAML's n_timesteps; with "
                            "--resume: the total to reach, default the run's own)")
    train.add_argument("--n-envs", type=positive_int,
                       help="boats stepped together (default: the YAML's)")
    train.add_argument("--backend", choices=TRAIN_BACKENDS,
                       help="native (our batched env, the default) or dummy (SB3's "
                            "DummyVecEnv)")
    train.add_argument("--seed", type=seed_int, help="seed (default 0)")
    train.add_argument("--out", metavar="DIR", help="output directory")
    train.add_argument("--force", action="store_true",
                       help="replace a run already in --out (its model, checkpoints, logs)")
    train.add_argument("--resume", metavar="DIR",
                       help="continue the run in DIR (a 'marine train --out' folder) from its "
                            "last saved agent, with its config.json's settings")
    train.add_argument("--config", metavar="YAML",
                       help="hyperparameters file in agents/hyperparams.yaml's format")
    train.add_argument("--quiet", action="store_true", help="no progress bar")
    train.set_defaults(run=lambda args: _train(args, train))

    evaluate = commands.add_parser(
        "evaluate", help="evaluate an agent 'marine train' saved: cost and errors over seeded "
                         "episodes",
        description="Run the agent over seeded episodes behind its training estimator and print "
                    "the task's quadratic cost, failures, RMS errors of the weighted states and "
                    "inputs (angles in degrees), the fraction of saturated steps and the "
                    "estimator's RMS errors, as mean ± std over the episodes.")
    evaluate.add_argument("dir", help="the directory 'marine train --out' wrote (its model.zip, "
                                      "else its latest checkpoint), or a model file in it "
                                      "(e.g. checkpoints/model_8192_steps.zip)")
    evaluate.add_argument("--episodes", type=positive_int, default=5,
                          help="episodes (default 5)")
    evaluate.add_argument("--seed", type=seed_int, default=0,
                          help="first episode's seed; the others follow (default 0)")
    evaluate.add_argument("--json", metavar="PATH", help="also write {\"rows\": [...]} as JSON")
    evaluate.add_argument("--force", action="store_true", help="replace an existing --json")
    evaluate.add_argument("--quiet", action="store_true", help="no progress bar")
    evaluate.set_defaults(run=_evaluate)

    bench = commands.add_parser(
        "bench", help="estimator x controller benchmark grid over vehicles, seas and sensors",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=BENCH_DESCRIPTION)
    axes = bench.add_argument_group("the grid (each a space-separated list)")
    axes.add_argument("--vehicles", nargs="+", type=str,
                      help="usv hydrofoil rov dp hovercraft (default: all)")
    axes.add_argument("--estimators", nargs="+",
                      help=f"{' '.join(registry.names())}, or one registered with "
                           "estimators.registry.register (default: true raw kf akf ekf)")
    axes.add_argument("--controllers", nargs="+",
                      help="lqr, nominal, ppo/sac/td3/a2c (trained here per vehicle and "
                           "estimator) or sb3:DIR (a 'marine train' output) (default: lqr)")
    axes.add_argument("--seas", nargs="+", help="calm moderate rough (default: moderate)")
    axes.add_argument("--sensors", nargs="+",
                      help="default, or degradations kind=level joined by +: noise=K (K x the "
                           "default noise), quant=K (a step of K default stds), dropout=P, "
                           "delay=N (control periods); e.g. default noise=4 dropout=0.2")
    axes.add_argument("--seeds", type=positive_int,
                      help="episodes per cell, seeds 0..N-1 (default 5)")
    axes.add_argument("--seconds", type=positive_float,
                      help="episode length, s (default: the env's)")
    axes.add_argument("--timesteps", type=positive_int,
                      help="training steps of each agent the grid trains (default 100000)")
    bench.add_argument("--quick", action="store_true",
                       help="a small grid over all five vehicles: true raw kf akf, lqr and ppo, "
                            "default and noise=32 sensors, 3 seeds of 60 s, 20000-step PPO "
                            "(other options override its settings)")
    bench.add_argument("--out", default="bench", metavar="DIR",
                       help="rows.csv, summary.md, figures, trained agents; a rerun of the "
                            "same grid resumes (default: bench)")
    bench.add_argument("--force", action="store_true",
                       help="start afresh: clear what an earlier run wrote into --out, and "
                            "replace --json and --report")
    bench.add_argument("--backend", choices=("local", "ray"), default="local",
                       help="local processes (default) or Ray tasks")
    bench.add_argument("--address", help="Ray cluster address (auto, or HOST:PORT); without it "
                                         "--backend ray starts a local Ray")
    bench.add_argument("--workers", type=positive_int, default=os.cpu_count() or 1,
                       help="processes (local) or CPUs of the local Ray (default: all cores)")
    bench.add_argument("--json", metavar="PATH", help='also write {"rows": [...]} as JSON')
    bench.add_argument("--report", metavar="DIR",
                       help="also write DIR/index.html: the tables and figures in one page")
    bench.add_argument("--quiet", action="store_true", help="no progress bars")
    bench.set_defaults(run=_bench)

    envs = commands.add_parser("envs", help="list the environments with their spaces")
    envs.set_defaults(run=_envs)
    return parser


@contextlib.contextmanager
def _warnings_as_lines(command: str) -> Iterator[None]:
    """The project's own warnings (implausible values, solver troubles) as one line each,
    ``marine CMD: warning: ...``; others as Python shows them."""
    show = warnings.showwarning

    def line(message: Warning | str, category: type[Warning], filename: str, lineno: int,
             file: Any = None, text: str | None = None) -> None:
        if category.__module__.split(".")[0] in ("marine_envs", "estimators", "agents"):
            print(f"{command}: warning: {message}", file=sys.stderr)
        else:
            show(message, category, filename, lineno, file, text)

    warnings.showwarning = line
    try:
        yield
    finally:
        warnings.showwarning = show


#: Hints in the library's messages that name a Python argument, and what a command-line user
#: does instead.
COMMAND_LINE_HINTS = {
    "pass require_uniform=False to accept non-uniform sampling":
        "resample the record to a uniform time step (its median step, say) first",
    "pass model=... to read the file as SI units with nominal parameters":
        "give --model to read the file as SI units with nominal parameters",
    "pass model=...": "give --model",
    "use method='free' (or 'auto')": "use --method free (or auto)",
}


def _one_line(error: BaseException) -> str:
    text = "; ".join(part.strip() for part in str(error).splitlines() if part.strip()) \
        or type(error).__name__
    for python, command_line in COMMAND_LINE_HINTS.items():
        text = text.replace(python, command_line)
    return text


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a batch system's time limit), raised where the program is, as Ctrl-C
    raises :class:`KeyboardInterrupt`: every command stops (and saves) the same way for both."""


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (signals are caught only in the
    main thread: elsewhere nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(number: int, frame: Any) -> NoReturn:
        raise Terminated

    before = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``marine`` with ``argv`` (default: the command line); the exit code (see the module's
    docstring): 0, 2 for a mistake in what was asked (one line on stderr), 128 + the signal's
    number when a signal stopped it."""
    try:
        try:
            return _main(argv)
        finally:
            sys.stdout.flush()  # a reader that went away shows here, not at the exit
    except BrokenPipeError:
        # Python's recipe (the signal module's docs): what is left goes nowhere, no message
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_SIGNAL + signal.SIGPIPE


def _main(argv: Sequence[str] | None) -> int:
    args = build_parser().parse_args(argv)
    command = f"marine {args.command}"
    try:
        with _warnings_as_lines(command), _sigterm_as_interrupt():
            return args.run(args)
    except KeyboardInterrupt as error:
        terminated = isinstance(error, Terminated)
        print(f"{command}: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
        return EXIT_SIGNAL + (signal.SIGTERM if terminated else signal.SIGINT)
    except BrokenPipeError:
        raise
    except USER_ERRORS as error:
        if args.debug:
            raise
        print(f"{command}: error: {_one_line(error)}", file=sys.stderr)
        return EXIT_USAGE


if __name__ == "__main__":
    sys.exit(main())
