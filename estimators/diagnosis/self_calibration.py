"""Calibrating by itself, when whole records are beyond the model (step 3 of
:mod:`.free_simulation`): whole records the model cannot follow from a fitted start (a craft
spinning for 30 s) are cut into the longest windows it follows, each from its own grown fit of
its start (multiple shooting), and the model's parameters the failing channels are most
sensitive to (among its ``calibration_candidates``) are calibrated there.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from numpy.typing import NDArray

from marine_envs.models import VehicleModel

from .comparison import MAX_CORRELATION
from .output_error import Fit, Run, Series, Structure, fit, jacobian

BoolArray = NDArray[np.bool_]
FloatArray = NDArray[np.float64]

#: Windows of the records that the model follows from a fitted start: the states-only fit's
#: in-sample error at most this share of the signal's variance. Measured on the shipped EPFL
#: hovercraft runs (10 Hz): whole runs (26-29 s) 1.4; by grown fits, 6.4-s windows within it,
#: 12.9-s ones not (by plain fits from rest: 2-s windows 0.001, 4-s 0.026).
FOLLOWED = 0.05
#: The first horizon (samples) of :func:`grown_fit`: four steps, over which a start's error
#: grows nearly linearly.
FIRST_HORIZON = 4
#: Shortest window, in samples per unknown initial state (the window must still hold them).
MIN_WINDOW_SAMPLES = 4
#: The tool calibrates at most this many parameters of its own choosing (a planar craft: an
#: input gain and a damping in each of surge, sway and yaw).
MAX_OWN_PARAMETERS = 6
#: A parameter is chosen when changing it by this share of its value moves the failing
#: channels by more than their sensor noise (RMS, in signal scales).
SENSITIVITY_STEP = 0.1
#: A parameter whose sensitivity, beyond the initial states' and the parameters chosen before
#: it, keeps less than this share of its own is told from them by no record (``MAX_CORRELATION``
#: as a share of the column: sqrt(1 - 0.98^2) = 0.2).
COLLINEAR = math.sqrt(1 - MAX_CORRELATION**2)


@dataclass
class SelfCalibration:
    """What the tool calibrates by itself when free simulation cannot follow whole records: the
    records cut into windows the model can follow (a start fitted per window: multiple
    shooting), and the model's parameters the failing channels are most sensitive to.

    :param series: the windows as a series.  :param names: the calibrated parameters (the
        user's, then the chosen).  :param start: start values by label (the windows' states).
    :param whole: the whole records' in-sample error share, per channel and in all.
    :param chosen: per chosen parameter, the RMS change of the failing channels (signal
        scales) when it changes by :data:`SENSITIVITY_STEP`.
    """

    series: Series
    names: tuple[str, ...]
    start: dict[str, float]
    whole: dict[str, float]
    chosen: dict[str, float]
    window: float

    def report(self, quality: dict[str, dict[str, Any]]) -> dict[str, Any]:
        """The JSON entry: why, the windows, the chosen parameters with ``quality`` (value, std
        and status per calibrated name)."""
        return {
            "why": ("free simulation cannot follow the whole records from a fitted start "
                    f"(in-sample error {self.whole['all']:.0%} of the signal); the model "
                    f"follows windows of {self.window:.3g} s, each from its own fitted start"),
            "whole_record_share": self.whole, "window_s": self.window,
            "windows": len(self.series.runs),
            "chosen_by_sensitivity": {n: {"sensitivity": g, **quality[n]}
                                      for n, g in self.chosen.items()}}


def nominal_fit(series: Series, calibrate: Sequence[str],
                start: dict[str, float] | None) -> Fit:
    """The initial states (and ``calibrate``) fitted to the whole records."""
    structure = Structure(series, tuple(calibrate))
    return fit(structure, _every_sample(series), structure.start(start))


def self_calibration(whole: Fit, say: Callable[[str], None]) -> SelfCalibration | None:
    """When free simulation cannot follow the whole records (``whole``: their
    :func:`nominal_fit`), the windows it follows and the parameters to calibrate there
    (:class:`SelfCalibration`); None when no window short enough is followed."""
    series, calibrate = whole.structure.series, whole.structure.names
    shares = _channel_shares(whole)
    say(f"free simulation cannot follow the whole records (in-sample error {whole.cost:.0%} "
        "of the signal): finding the windows it follows and the parameters to calibrate...")
    values = whole.values()
    windows, states = _followed_windows(series, calibrate, {n: values[n] for n in calibrate})
    if windows is None or states is None:
        return None
    failing = np.array([shares[c] > FOLLOWED for c in series.channels])
    chosen = sensitive_parameters(states, failing if failing.any() else ~failing)
    names = (*calibrate, *chosen)
    labels = Structure(windows, names).labels()
    return SelfCalibration(windows, names,
                           {k: v for k, v in states.values().items() if k in labels},
                           {**shares, "all": round(whole.cost, 4)}, chosen,
                           float(windows.runs[0].duration + windows.dt))


def _every_sample(series: Series) -> list[BoolArray | None]:
    return [np.ones(len(r.time), dtype=bool) for r in series.runs]


def _channel_shares(result: Fit) -> dict[str, float]:
    """Per channel, the fit's mean square error in signal scales (runs weighted alike)."""
    series = result.structure.series
    out = np.zeros(len(series.channels))
    for r, run in enumerate(series.runs):
        error = (result.structure.simulate(result.theta, r)[0] - run.y) / series.scale
        out += np.mean(error**2, axis=0) / len(series.runs)
    return {c: round(float(v), 4) for c, v in zip(series.channels, out, strict=True)}


def windowed(series: Series, samples: int) -> Series:
    """The series' runs cut into windows of ``samples`` (a shorter last piece joins the one
    before it when under half a window), each a run with its own start."""
    runs = []
    for record, run in enumerate(series.runs):
        edges = list(range(0, len(run.time), samples))
        if len(run.time) - edges[-1] < samples // 2 and len(edges) > 1:
            edges.pop()
        for a, b in zip(edges, [*edges[1:], len(run.time)], strict=True):
            runs.append(Run(f"{run.name}[{run.time[a]:.1f}-{run.time[b - 1]:.1f} s]",
                            run.time[a:b] - run.time[a], run.u[a:b], run.y[a:b], run.noise,
                            record))
    return dataclasses.replace(series, runs=runs)


def _followed_windows(series: Series, calibrate: Sequence[str],
                      start: dict[str, float] | None) -> tuple[Series | None, Fit | None]:
    """The longest windows (halving from half the shortest run) over which the fit of the
    initial states (and ``calibrate``) stays within :data:`FOLLOWED`, and that fit."""
    shortest = min(len(r.time) for r in series.runs)
    least = MIN_WINDOW_SAMPLES * int(series.excited().sum())
    samples = shortest // 2
    while samples >= least:
        windows = windowed(series, samples)
        structure = Structure(windows, tuple(calibrate))
        result = grown_fit(structure, structure.start(start))
        if result.cost <= FOLLOWED:
            return windows, result
        samples //= 2
    return None, None


def grown_fit(structure: Structure, theta: FloatArray) -> Fit:
    """:func:`.output_error.fit` over every sample, warm-started by fits over the first
    :data:`FIRST_HORIZON` samples of each run, then twice as many, and so on: a start far
    from a fast motion (a craft spinning at 10 rad/s from a start at rest) is found where the
    free simulation is still nearly linear in it, not in one of the far horizon's minima."""
    longest = max(len(r.time) for r in structure.series.runs)
    horizon = FIRST_HORIZON
    while horizon < longest:
        rows = [np.arange(len(r.time)) < horizon for r in structure.series.runs]
        theta = fit(structure, rows, theta).theta
        horizon *= 2
    return fit(structure, _every_sample(structure.series), theta)


def sensitive_parameters(result: Fit, channels: BoolArray) -> dict[str, float]:
    """The model's parameters the ``channels`` of the fit's residuals are sensitive to, most
    sensitive first (at most :data:`MAX_OWN_PARAMETERS`): each moves them, beyond the fit's
    unknowns and the parameters chosen before it, by more than the sensor noise when changed by
    :data:`SENSITIVITY_STEP` of its value, and is not collinear with them. Candidates: the
    model's :attr:`~VehicleModel.calibration_candidates` (else every parameter), nonzero and
    accepted 10 % either way. Returns ``{name: RMS change per SENSITIVITY_STEP}`` in signal
    scales."""
    structure = result.structure
    series, model = structure.series, structure.series.model
    declared = model.calibration_candidates or [f.name for f in dataclasses.fields(model.params)]
    candidates = [n for n in declared if n not in structure.names and _adjustable(model, n)]
    if not candidates:
        return {}
    wide = Structure(series, (*structure.names, *candidates))
    theta = wide.start({**result.values(), **{n: float(getattr(model.params, n))
                                               for n in candidates}})
    _, J = jacobian(wide, theta, _every_sample(series))
    J = J[_channel_rows(series, channels)]
    first, last = len(structure.names), len(structure.names) + len(candidates)
    own = J[:, first:last] * theta[first:last]  # per relative change
    vectors, values, _ = np.linalg.svd(np.delete(J, np.arange(first, last), axis=1),
                                       full_matrices=False)
    basis = vectors[:, values > 1e-10 * values[0]]
    columns = own - basis @ (basis.T @ own)
    original = np.linalg.norm(columns, axis=0)  # what each moves beyond the fit's unknowns
    noise = math.sqrt(np.mean([np.mean((r.noise[channels] / series.scale[channels]) ** 2)
                               for r in series.runs]))
    # residuals are weighted to a mean square: a column's norm is an RMS change
    chosen: dict[str, float] = {}
    for _ in range(MAX_OWN_PARAMETERS):
        norms = np.linalg.norm(columns, axis=0)
        usable = (norms > COLLINEAR * original) & (SENSITIVITY_STEP * norms > noise)
        usable[[candidates.index(n) for n in chosen]] = False
        if not usable.any():
            break
        k = int(np.argmax(np.where(usable, norms, 0.0)))
        chosen[candidates[k]] = round(float(SENSITIVITY_STEP * norms[k]), 6)
        q = columns[:, k] / norms[k]
        columns = columns - np.outer(q, q @ columns)
    return chosen


def _adjustable(model: VehicleModel, name: str) -> bool:
    value = getattr(model.params, name)
    if not isinstance(value, float) or value == 0 or not math.isfinite(value):
        return False
    try:
        model.with_params(**{name: value * 1.1})
        model.with_params(**{name: value * 0.9})
    except (ValueError, TypeError):
        return False
    return True


def _channel_rows(series: Series, channels: BoolArray) -> BoolArray:
    """The residual entries (:meth:`Structure.residuals`' order) of the selected channels."""
    return np.concatenate([np.tile(channels, len(run.time)) for run in series.runs])


# -- the answer -----------------------------------------------------------------------------------
