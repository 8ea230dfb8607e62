"""A record sized for the seaway method: its step checked, its rate and length bounded.

The seaway method (:mod:`.seaway`) holds, per sample, the filter's and smoother's matrices and
every candidate term's response: its memory grows with the record (a USV: 90 kB a sample;
100k samples peaked at 7.6 GB). So before any work:

* :func:`step_problem` - a sample step too coarse for the model (the prediction horizon or the
  model's fastest oscillation not resolved: time in milliseconds read as seconds, or a
  ``--decimate`` too large) is refused, naming the step;
* :func:`plan` / :func:`sized` - a record sampled faster than the step the method was tuned
  at (:data:`SEAWAY_STEP`, the environments' own) is decimated to it, anti-aliased; a record
  still longer than the method's sample budget (:data:`SEAWAY_BYTES_PER_SAMPLE`,
  :data:`MEMORY_BUDGET`) is cut to its most excited part. Both are said (``log``, and the
  Diagnosis' ``record``), never silent.

Records of the usual length at the environments' step (300 s at 10 Hz) are judged whole and
unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import pandas as pd
from scipy import signal

from marine_envs.models import VehicleModel
from marine_envs.recording import TIME, Recording

from .seaway import MIN_DURATION

#: The sample step (s) every constant of the seaway method was tuned at: the environments'
#: own (``env.unwrapped.system.dt``); a record sampled faster is decimated to it.
SEAWAY_STEP = {"usv": 0.1, "rov": 0.1, "dp_vessel": 0.5, "hovercraft": 0.1, "hydrofoil": 0.05}
DEFAULT_STEP = 0.1
#: Peak memory of the seaway method per sample, bytes: the slope of the peak RSS of ``marine
#: diagnose`` between records of 3000 and 6000 samples (1500 and 3000 for the ROV; made by
#: ``marine simulate`` under LQR, seed 2; the DP vessel and hydrofoil by ``synthesize``). What
#: grows: the candidate terms' regressors, ``(T, n, k)`` each (``hypotheses._in_equation``,
#: 69 MB of the USV's 3000 samples), and the filter's matrices, ``(T, n, n)`` each.
SEAWAY_BYTES_PER_SAMPLE = {"usv": 9.0e4, "rov": 1.31e6, "dp_vessel": 1.7e5, "hovercraft": 3.4e4,
                           "hydrofoil": 4.8e4}
DEFAULT_BYTES_PER_SAMPLE = 2.0e5
#: Memory the seaway method may take, bytes: with the interpreter and its libraries (0.25 GB)
#: and a 2M-row record's own storage, a diagnosis stays within 2 GB.
MEMORY_BUDGET = 1.0e9
#: An ordinary record (300 s at the method's step, the acceptance set's) is never cut, whatever
#: the budget says (the ROV's 3001 samples take 4.2 GB: bounded, not within the budget).
ORDINARY_SECONDS = 300.0
#: The prediction horizon (s, :class:`.selection.DiagnosisConfig`) must span this many steps.
STEPS_PER_HORIZON = 2


@dataclass(frozen=True)
class Plan:
    """How a record is sized for the seaway method.

    :param factor: decimation factor (1: the record's own rate).  :param step: the step after
        it, s.  :param samples: the samples after it.  :param budget: the samples the method
        may take; a longer record is cut to its most excited ``budget`` samples.
    """

    factor: int
    step: float
    samples: int
    budget: int

    @property
    def cut(self) -> bool:
        return self.samples > self.budget

    @property
    def judged(self) -> int:
        """The samples the method will judge."""
        return min(self.samples, self.budget)


def coarsest_step(vehicle: VehicleModel, horizon: float) -> float:
    """The coarsest sample step (s) a record of ``vehicle`` can be judged on: the prediction
    ``horizon`` spans :data:`STEPS_PER_HORIZON` steps, and the Nyquist frequency is above the
    linearised model's fastest oscillation (a ROV's 5.7 rad/s heave-pitch, the USV's 0.63 rad/s
    roll)."""
    eigenvalues = np.linalg.eigvals(vehicle.linearize()[0])
    oscillation = float(np.max(np.abs(eigenvalues[np.abs(eigenvalues.imag) > 0]), initial=0.0))
    step = horizon / STEPS_PER_HORIZON
    return min(step, math.pi / oscillation) if oscillation > 0 else step


def step_problem(recording: Recording, vehicle: VehicleModel, horizon: float) -> str:
    """Why ``recording``'s sample step is too coarse to judge against ``vehicle`` (naming a
    likely slip: time in milliseconds, a decimation too large), or absurdly fine for a record
    too short to judge (time in seconds declared as ms), or ``""``."""
    step, coarsest = recording.dt, coarsest_step(vehicle, horizon)
    name = recording.meta.get("name", "the recording")
    duration = float(recording.time[-1] - recording.time[0])
    if step < SEAWAY_STEP.get(vehicle.name, DEFAULT_STEP) / 100 and duration < MIN_DURATION \
            <= 1000 * duration and 1000 * step <= coarsest:
        return (f"{name}: {len(recording.time)} samples over {duration:.3g} s "
                f"({1 / step:.3g} Hz) is an absurd rate for the {vehicle.name} model: is the "
                "time in seconds, declared as ms? (leave \"time\" out of \"units\")")
    if step <= coarsest:
        return ""
    decimate = recording.meta.get("window", {}).get("decimate", 1)
    if decimate > 1 and step / decimate <= coarsest:
        why = (f"keeping every {decimate}-th sample leaves a step of {step:.3g} s: decimate by "
               f"{max(1, int(coarsest / (step / decimate)))} at most (a long record is sized "
               "by the diagnosis itself)")
    elif step / 1000 <= coarsest:
        why = "is the time in milliseconds? (declare \"units\": {\"time\": \"ms\"})"
    else:
        why = "record the vehicle faster"
    return (f"{name}: sample step {step:.3g} s ({1 / step:.3g} Hz) is too coarse for the "
            f"{vehicle.name} model: at most {coarsest:.3g} s (the {horizon:g}-s prediction "
            f"horizon and the model's fastest oscillation must be resolved); {why}")


def plan(recording: Recording, vehicle: VehicleModel) -> Plan:
    """How ``recording`` is sized for the seaway method (the module doc)."""
    target = SEAWAY_STEP.get(vehicle.name, DEFAULT_STEP)
    step = recording.dt
    factor = max(1, int(target / step * (1 + 1e-6)))
    samples = len(recording.data) // factor
    per_sample = SEAWAY_BYTES_PER_SAMPLE.get(vehicle.name, DEFAULT_BYTES_PER_SAMPLE)
    ordinary = int(round(ORDINARY_SECONDS / (step * factor))) + 1
    return Plan(factor, step * factor, samples, max(int(MEMORY_BUDGET / per_sample), ordinary))


def sized(recording: Recording, vehicle: VehicleModel,
          log: Callable[[str], None] | None = None) -> tuple[Recording, dict[str, Any]]:
    """``recording`` decimated and cut as :func:`plan` says, and what was done (empty: the
    record as it was), said on ``log``."""
    how = plan(recording, vehicle)
    done: dict[str, Any] = {}
    if how.factor > 1:
        recording = decimated(recording, how.factor)
        done["decimated"] = {"factor": how.factor, "step": round(recording.dt, 6),
                             "reason": "sampled faster than the seaway method's step for the "
                                       f"{vehicle.name} model (anti-aliased)"}
    if how.cut:
        recording, (start, stop) = most_excited(recording, how.budget)
        done["cut"] = {"start": round(start, 6), "stop": round(stop, 6), "samples": how.budget,
                       "reason": f"{how.samples} samples are more than the seaway method's "
                                 f"budget of {how.budget} (its memory grows with the record): "
                                 "judged on the most excited part"}
    for line in described(done) if log is not None else ():
        log(line)
    return recording, done


def described(done: dict[str, Any]) -> list[str]:
    """What :func:`sized` did, one line each (a Diagnosis' ``record``)."""
    return [f"{what} before the diagnosis: {how['reason']}" + (
        f" ({how['start']:.0f}-{how['stop']:.0f} s, {how['samples']} samples)" if what == "cut"
        else f" (by {how['factor']}, to a step of {how['step']:g} s)")
        for what, how in done.items()]


def decimated(recording: Recording, factor: int) -> Recording:
    """``recording`` at ``factor`` times its step: the measured channels low-passed and
    decimated (scipy's polyphase filter, zero phase; angles through their unwrapped values),
    the inputs and disturbances averaged over each new step (a held input's mean), as
    :mod:`estimators.diagnosis.output_error` resamples a model test."""
    n = len(recording.data) // factor * factor
    data = recording.data.iloc[:n]
    columns: dict[str, np.ndarray] = {TIME: data[TIME].to_numpy()[::factor]}
    measured = set(recording.measured_names)
    for name in data.columns[1:]:
        values = data[name].to_numpy()
        if name not in measured:
            columns[name] = values.reshape(-1, factor).mean(axis=1)
            continue
        angle = recording.units[name] == "rad"
        low = signal.resample_poly(np.unwrap(values) if angle else values, 1, factor,
                                   padtype="line")
        if angle and np.all(np.abs(values) <= math.pi):  # a wrapped channel stays wrapped
            low = np.angle(np.exp(1j * low))
        columns[name] = low
    meta = {**recording.meta, "resampled": {"decimate": factor, "anti_aliased": True}}
    out = Recording(pd.DataFrame(columns), recording.model, recording.params, meta,
                    require_uniform=False)
    if recording.gaps is not None:  # a new sample is missing when its whole step was
        out.gaps = recording.gaps[:n].reshape(-1, factor, recording.gaps.shape[1]).all(axis=1)
    out.warnings = list(recording.warnings)
    return out


def most_excited(recording: Recording, samples: int) -> tuple[Recording, tuple[float, float]]:
    """The ``samples`` consecutive samples of ``recording`` where its channels and inputs
    move most (the sum of their squared steps, each in units of its own RMS step), and their
    first and last time, s."""
    moves = np.zeros(len(recording.data) - 1)
    for name in recording.data.columns[1:]:
        step = np.diff(recording.data[name].to_numpy())
        scale = float(np.mean(step**2))
        if scale > 0:
            moves += step**2 / scale
    total = np.concatenate([[0.0], np.cumsum(moves)])
    first = int(np.argmax(total[samples - 1:] - total[:len(total) - samples + 1]))
    time = recording.time
    start, stop = float(time[first]), float(time[first + samples - 1])
    return recording.window(start, stop), (start, stop)
