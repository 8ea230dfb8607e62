"""``diagnose(recording, model) -> Diagnosis``: locate, name, model and validate a mismatch.

Checks the input first, a ``ValueError`` naming the problem before any work: parameter overrides
and the names to calibrate, the same recording given twice, the recordings' model, disturbance
columns and sample step (:func:`.sizing.step_problem`: time in milliseconds, a decimation too
large), and an angle and its rate a degree factor apart (:func:`_degree_slips`). A record in a
seaway is then sized to the method's step and sample budget (:mod:`.sizing`). Then chooses the way
the record is judged: model tests (a series, a free decay) go to :mod:`.free_simulation`, judged in
free simulation; a record in a seaway to :mod:`.seaway`, judged by the nominal filter's
innovations; either way, a record with actuator position sensors gets the actuators' effects
read off them (:mod:`.actuators`) and its hull judged on the positions. A recording the tool
cannot judge gets ``mismatch=None`` and the reason, never a confident wrong answer.
"""

from __future__ import annotations

import json
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from marine_envs import plausibility
from marine_envs.models import MeasuredDisturbances, VehicleModel, get_model
from marine_envs.recording import Recording, read_recording

from . import actuators, sizing
from .free_simulation import diagnose_series
from .result import Diagnosis
from .seaway import SEAWAY_STAGES, Stage, check, diagnose_seaway, other_model
from .selection import DiagnosisConfig

__all__ = ["METHODS", "SEAWAY_STAGES", "check", "diagnose", "expected_seconds", "read_params"]

#: How a recording is judged (see :func:`diagnose`).
METHODS = ("auto", "free", "innovations")
#: Run time of a record in a seaway per model: (seconds, seconds per sample), measured on 2
#: cores (3000 and 6000 samples, no calibration); the ROV's re-measured as CPU time on one
#: core with the compiled smoother (benchmarks/diagnosis_speed.py: 18.2 and 18.4 s for two
#: 3000-sample environment records, 28.3 and 32.6 s before); other models: the default.
SEAWAY_SECONDS = {"usv": (0.5, 7e-4), "rov": (8.8, 3.2e-3), "dp_vessel": (0.8, 9e-4),
                  "hovercraft": (2.4, 8e-4), "hydrofoil": (2.5, 4.5e-4)}
DEFAULT_SECONDS = (1.0, 1e-3)


def diagnose(recording: Recording | str | Path | Sequence[Recording | str | Path],
             model: str | VehicleModel | None = None, *,
             params: Mapping[str, float] | str | Path | None = None,
             calibrate: Sequence[str] | str = (), config: DiagnosisConfig | None = None,
             method: str = "auto", log: Callable[[str], None] | None = None,
             stage: Stage | None = None) -> Diagnosis:
    """Diagnose why ``model`` and a recording (or a series of recordings) disagree.

    :param recording: a :class:`~marine_envs.recording.Recording` or a path to one, or a
        sequence of them: a series of tests of one vehicle (one parameter set for all).
    :param model: model name or object; default: the (first) recording's metadata.
    :param params: nominal parameter overrides (names as in docs/models.md, SI units), on top
        of the recording's metadata: a mapping, or the path of a JSON object of them.
    :param calibrate: nominal parameters to fit first, so that only what the model's
        *structure* leaves out remains; names, or one comma-separated string.
    :param config: the sea-record search's configuration (one default for every case).
    :param method: ``"free"``: judge in free simulation (model tests: decays, zigzags, lab
        runs; :mod:`.free_simulation`); ``"innovations"``: the smoother and filter innovations of
        a record in a seaway; ``"auto"``: free simulation for a series or a free decay (inputs
        held), the innovations otherwise.
    :param log: called with a line on what the (seconds-long) search is doing.
    :param stage: called at the start of each stage with its name, index and the number of
        stages (:data:`SEAWAY_STAGES`, or :data:`.free_simulation.FREE_STAGES`): for a progress bar.

    A sample a logger dropped (NaN in a measured channel) is a missing measurement: the
    filters predict through it, and the free simulation compares with the record's value
    interpolated from its neighbours (``missing_samples`` counts them per channel). Values
    that look like unit mistakes (:attr:`~marine_envs.recording.Recording.warnings`) are
    listed in ``warnings``.

    A record in a seaway sampled faster than the method's step, or longer than its sample
    budget, is decimated (anti-aliased) and cut to its most excited part (:mod:`.sizing`),
    said on ``log`` and in the Diagnosis' ``record``: memory does not grow with the record.

    :raises ValueError: invalid ``params``, ``calibrate`` or ``method`` (naming the entry), a
        recording given twice (naming both), a recording that is not valid for the model
        (naming the column), a sample step too coarse for the model, or an angle and its rate
        a degree factor apart (naming them); all before any work.
    """
    if method not in METHODS:
        raise ValueError(f"method={method!r}: must be one of {', '.join(METHODS)}")
    config = config or DiagnosisConfig()
    overrides = read_params(params) if isinstance(params, str | Path) else _numbers(params)
    # an unknown model name fails here, naming the known ones, before the recording is read
    vehicle = get_model(model) if isinstance(model, str) else model
    sources = [recording] if isinstance(recording, Recording | str | Path) else list(recording)
    if not sources:
        raise ValueError("no recording given")
    recordings = [r if isinstance(r, Recording) else _named(read_recording(
        r, model=None if vehicle is None else vehicle.name), r) for r in sources]
    _refuse_duplicates(recordings)
    notes = {"warnings": [w for rec in recordings for w in rec.warnings],
             "missing_samples": _missing(recordings)}
    if notes["missing_samples"] and log is not None:
        log("missing samples taken as dropped measurements: " + ", ".join(
            f"{c} {n}" for c, n in notes["missing_samples"].items()))
    recordings = [rec.filled() if rec.missing.any() else rec for rec in recordings]
    diagnosis = _diagnose(recordings, vehicle, overrides, calibrate, config, method, log, stage)
    diagnosis.warnings, diagnosis.missing_samples = notes["warnings"], notes["missing_samples"]
    return diagnosis


def expected_seconds(recordings: Sequence[Recording], method: str = "auto",
                     calibrate: bool = False) -> float | None:
    """A rough run time of :func:`diagnose`, s, from the records' length (as
    :func:`.sizing.plan` sizes them) and the model's measured rate (:data:`SEAWAY_SECONDS`; a
    calibration smooths twice more); None for free simulation (model tests), which resamples
    to the model's bandwidth: seconds on the model's compiled equations, minutes where a
    recorded disturbance is one of its inputs (simulated by numpy)."""
    if method == "free" or (method == "auto" and _model_test(recordings)):
        return None
    fixed, per_sample = SEAWAY_SECONDS.get(recordings[0].model, DEFAULT_SECONDS)
    samples = sum(sizing.plan(rec, get_model(rec.model)).judged for rec in recordings)
    return (fixed + per_sample * samples) * (2.0 if calibrate else 1.0)


def _missing(recordings: Sequence[Recording]) -> dict[str, int]:
    """Missing samples per measured channel over ``recordings`` (channels with some)."""
    counts: dict[str, int] = {}
    for rec in recordings:
        for name, n in zip(rec.measured_names, rec.missing.sum(axis=0).tolist(), strict=True):
            if n:
                counts[name] = counts.get(name, 0) + int(n)
    return counts


def _diagnose(recordings: list[Recording], vehicle: VehicleModel | None,
              overrides: dict[str, float], calibrate: Sequence[str] | str,
              config: DiagnosisConfig, method: str, log: Callable[[str], None] | None,
              stage: Stage | None) -> Diagnosis:
    """:func:`diagnose` of recordings read and complete (gaps filled and marked)."""
    vehicle = get_model(recordings[0].model) if vehicle is None else vehicle
    overrides = {**recordings[0].params, **overrides}
    vehicle = vehicle.with_params(**overrides) if overrides else vehicle
    calibrate = _parameter_names(calibrate, vehicle)
    for rec in recordings:
        if rec.model != vehicle.name:
            return Diagnosis(vehicle.name, None, other_model(rec, vehicle))
    for problem in (sizing.step_problem(rec, vehicle, config.horizon) for rec in recordings):
        if problem:
            raise ValueError(problem)
    slips = [line for rec in recordings for line in _degree_slips(rec, vehicle)]
    if slips:
        raise ValueError("; ".join(slips))
    vehicle = _with_measured_disturbances(vehicle, recordings)
    # an actuator position sensor shows its actuator's effects directly; the hull is judged on
    # the position they give the command (residuals.model_inputs)
    found, recordings = actuators.judge(recordings, vehicle, config)
    if method == "free" or (method == "auto" and _model_test(recordings)):
        diagnosis = diagnose_series(recordings, vehicle, calibrate, log=log, stage=stage)
    elif len(recordings) > 1:
        diagnosis = diagnose_seaway(recordings, vehicle, calibrate, config, log, stage)
    else:
        record, resized = sizing.sized(recordings[0], vehicle, log)
        diagnosis = diagnose_seaway([record], vehicle, calibrate, config, log, stage)
        diagnosis.record = resized
    if isinstance(vehicle, MeasuredDisturbances):
        diagnosis.measured_disturbances = vehicle.measured_disturbances
    diagnosis.params = overrides
    return actuators.merged(diagnosis, found)


def _refuse_duplicates(recordings: Sequence[Recording]) -> None:
    """:raises ValueError: two of ``recordings`` hold the same data (one file given twice, or
    a copy of it), naming them: one test twice is not a series of two (judged as one, it
    reports a false input delay)."""
    for k, rec in enumerate(recordings):
        for first in range(k):
            other = recordings[first]
            if other.model == rec.model and other.data.shape == rec.data.shape \
                    and other.data.equals(rec.data):
                raise ValueError(f"the same recording is given twice: "
                                 f"{_label(recordings, first)} and {_label(recordings, k)} "
                                 "hold identical data; give each test once")


def _label(recordings: Sequence[Recording], k: int) -> str:
    return f"recording {k + 1} ({recordings[k].meta.get('name', 'unnamed')})"


def _degree_slips(recording: Recording, vehicle: VehicleModel) -> list[str]:
    """An angle and its rate 180 / pi apart (:func:`~marine_envs.plausibility.degree_slip`):
    one of them is in degrees, declared in radians. Judged, the record would give a confident
    wrong answer (a yaw rate in deg/s: "no mismatch"), so it is refused, naming the fix."""
    out = []
    name = recording.meta.get("name", "the recording")
    for angle, rate in plausibility.rate_pairs(vehicle):
        if angle not in recording.data.columns or rate not in recording.data.columns:
            continue
        ratio = plausibility.angle_rate_ratio(recording.data[angle].to_numpy(),
                                              recording.data[rate].to_numpy(), recording.time)
        if not plausibility.degree_slip(ratio):
            continue
        assert ratio is not None
        if ratio < 1:
            column, unit = rate, "deg/s"
            told = f"{rate} is {1 / ratio:.1f}x the rate at which {angle} changes"
        else:
            column, unit = angle, "deg"
            told = f"{angle} changes {ratio:.1f}x more than its rate {rate} says"
        out.append(f"{name}: {told}: {column} is in {unit}, not in SI units; declare it "
                   f"(\"units\": {{\"{column}\": \"{unit}\"}} in the metadata) or convert it")
    return out


def _named(recording: Recording, path: str | Path) -> Recording:
    recording.meta.setdefault("name", Path(path).name)
    return recording


def _with_measured_disturbances(vehicle: VehicleModel, recordings: Sequence[Recording]
                                ) -> VehicleModel:
    """``vehicle`` taking the recorded disturbance columns (a logged wind, current or command)
    as inputs, or itself when there are none.

    :raises ValueError: the recordings of a series record different disturbances."""
    names = {rec.disturbance_names for rec in recordings}
    if len(names) > 1:
        raise ValueError(f"the recordings record different disturbances {sorted(names)}: a "
                         "series needs the same columns in every recording")
    measured = names.pop()
    return MeasuredDisturbances(vehicle, measured) if measured else vehicle


def _model_test(recordings: Sequence[Recording]) -> bool:
    """A series or a free decay (every input held): judged in free simulation."""
    rec = recordings[0]
    return len(recordings) > 1 or not rec.inputs.size \
        or bool(np.all(np.ptp(rec.inputs, axis=0) == 0))


def read_params(path: str | Path) -> dict[str, float]:
    """Nominal parameter overrides from a JSON file: one object of parameter names to numbers
    (SI units), e.g. ``{"wn": 0.6}``.

    :raises ValueError: an unreadable file, invalid JSON, or not an object of numbers.
    """
    try:
        value: Any = json.loads(Path(path).read_text())
    except OSError as error:
        raise ValueError(f"params {path}: cannot read it: {error.strerror or error}") from None
    except json.JSONDecodeError as error:
        raise ValueError(f"params {path}: not valid JSON: {error}") from None
    if not isinstance(value, dict):
        raise ValueError(f"params {path}: must be a JSON object of parameter names to "
                         f"numbers, e.g. {{\"wn\": 0.6}}; got {type(value).__name__}")
    return _numbers(value, f"params {path}")


def _numbers(params: Mapping[str, Any] | None, where: str = "params") -> dict[str, float]:
    bad = {k: v for k, v in (params or {}).items()
           if isinstance(v, bool) or not isinstance(v, int | float | np.floating | np.integer)}
    if bad:
        raise ValueError(f"{where}: parameter values must be numbers; got {bad}")
    return {k: float(v) for k, v in (params or {}).items()}


def _parameter_names(names: Sequence[str] | str, vehicle: VehicleModel) -> tuple[str, ...]:
    """``calibrate`` as parameter names of ``vehicle``; :raises ValueError: an unknown one."""
    if isinstance(names, str):
        names = names.split(",")
    try:
        return vehicle.check_parameter_names(n.strip() for n in names if n.strip())
    except ValueError as error:
        raise ValueError(f"calibrate: {error}") from None
