"""Identification data: :class:`Segment` (one run of inputs and measurements on a uniform time
grid), the checks of segments and parameter names against a model, and per-parameter values.

Data convention (as :meth:`~estimators.ekf.ExtendedKalmanFilter.filter`): ``inputs[k]`` is held
from ``time[k]`` to ``time[k + 1]``; ``measurements[k]`` is taken at ``time[k]``. SI units,
radians; NaN is not allowed (drop or interpolate missing samples first).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.models import VehicleModel

FloatArray = NDArray[np.float64]
#: Fewest samples a segment may have.
MIN_SAMPLES = 10


@dataclasses.dataclass(frozen=True)
class Segment:
    """One run of a vehicle: inputs and measurements on a uniform time grid.

    :param time: sample times ``(T,)``, s, strictly increasing with a uniform step.
    :param inputs: model inputs ``(T, n_u)`` in the model's units; row ``k`` is held until
        ``time[k + 1]``.
    :param measurements: measured channels ``(T, m)``, named by ``measured``.
    :param measured: the channels, names of ``model.output_names``.
    :param disturbance: model disturbance, ``(n_d,)`` constant or ``(T, n_d)``; None = zero.
    :param x0: initial state guess ``(n_x,)``; None = the model's nominal state with the measured
        states replaced by their first sample.
    :param angular: measured channels that are angles (possibly wrapped), rad.
    :param name: a label for reports (e.g. ``"5/5"``).
    """

    time: FloatArray
    inputs: FloatArray
    measurements: FloatArray
    measured: tuple[str, ...]
    disturbance: FloatArray | None = None
    x0: FloatArray | None = None
    angular: tuple[str, ...] = ()
    name: str = ""

    def __post_init__(self) -> None:
        label = f"segment {self.name!r}" if self.name else "segment"
        set_ = lambda k, v: object.__setattr__(self, k, v)  # noqa: E731 - frozen dataclass
        time = _finite_array(f"{label} time", self.time, 1)
        T = time.shape[0]
        if T < MIN_SAMPLES:
            raise ValueError(f"{label} has {T} samples; at least {MIN_SAMPLES} are needed")
        step = np.diff(time)
        if not (step > 0).all():
            raise ValueError(f"{label} time must be strictly increasing (row "
                             f"{int(np.argmax(step <= 0)) + 1})")
        if np.abs(step - step.mean()).max() > 1e-6 * step.mean():
            raise ValueError(f"{label} time step is not uniform ({step.min():g} to "
                             f"{step.max():g} s); resample first")
        set_("time", time)
        set_("measured", (self.measured,) if isinstance(self.measured, str)
             else tuple(self.measured))
        set_("angular", tuple(self.angular))
        for key, width in (("inputs", None), ("measurements", len(self.measured))):
            a = _finite_array(f"{label} {key}", getattr(self, key), 2)
            if a.shape[0] != T:
                raise ValueError(f"{label} {key} has {a.shape[0]} rows but time has {T}")
            if width is not None and a.shape[1] != width:
                raise ValueError(f"{label} measurements have {a.shape[1]} columns but "
                                 f"{width} channels are named ({', '.join(self.measured)})")
            set_(key, a)
        if self.disturbance is not None:
            d = _finite_array(f"{label} disturbance", self.disturbance, None)
            if d.ndim == 2 and d.shape[0] != T:
                raise ValueError(f"{label} disturbance has {d.shape[0]} rows but time has {T}")
            set_("disturbance", d)
        if self.x0 is not None:
            set_("x0", _finite_array(f"{label} x0", self.x0, 1))
        unknown = sorted(set(self.angular) - set(self.measured))
        if unknown:
            raise ValueError(f"{label} angular channel(s) {unknown} are not measured")

    @property
    def dt(self) -> float:
        """Sampling period, s."""
        return float(self.time[1] - self.time[0])

    @property
    def label(self) -> str:
        return f"segment {self.name!r}" if self.name else "segment"

    @classmethod
    def from_recording(cls, recording: Any, name: str = "",
                       angular: Sequence[str] = ()) -> Segment:
        """A segment from a :class:`~marine_envs.recording.Recording` (SI units)."""
        return cls(recording.time, recording.inputs, recording.measurements,
                   recording.measured_names, angular=tuple(angular), name=name)

    def unwrapped(self) -> FloatArray:
        """The measurements with the angular channels unwrapped, ``(T, m)``."""
        y = self.measurements.copy()
        for c in self.angular:
            j = self.measured.index(c)
            y[:, j] = np.unwrap(y[:, j])
        return y


def _finite_array(name: str, value: ArrayLike, ndim: int | None) -> FloatArray:
    a = np.asarray(value, dtype=float)
    if ndim is not None and a.ndim != ndim:
        raise ValueError(f"{name} must be {ndim}-D, got shape {a.shape}")
    bad = ~np.isfinite(a)
    if bad.any():
        where = np.argwhere(bad)[0]
        raise ValueError(f"{name} has {int(bad.sum())} non-finite value(s) (NaN or inf), first "
                         f"at index {tuple(int(i) for i in where)}; drop or interpolate them")
    return a


def as_segments(data: Segment | Sequence[Segment]) -> list[Segment]:
    """``data`` as a non-empty list of segments."""
    segments = [data] if isinstance(data, Segment) else list(data)
    if not segments or not all(isinstance(s, Segment) for s in segments):
        raise TypeError("data must be a Segment or a non-empty sequence of Segments")
    return segments


def noise_std(segment: Segment) -> FloatArray:
    """Measurement noise standard deviation of each channel ``(m,)``, estimated from the data:
    the spread of the second differences, which for white noise have variance ``6 sigma^2``
    while those of a smooth signal sampled fast are ~0; samples beyond 4 robust (MAD) standard
    deviations (input steps, outliers) are left out."""
    d2 = np.diff(segment.unwrapped(), 2, axis=0)
    centred = d2 - np.median(d2, axis=0)
    mad = np.median(np.abs(centred), axis=0) / 0.6745
    kept = np.where(np.abs(centred) <= 4 * mad, centred, np.nan)
    return np.sqrt(np.nanmean(kept**2, axis=0) / 6.0)


def _check_data(model: VehicleModel, segments: list[Segment]) -> None:
    """Segment contents against the model: channels, input and disturbance widths, one dt."""
    n_u, n_d = len(model.input_names), len(model.disturbance_names)
    for s in segments:
        unknown = sorted(set(s.measured) - set(model.output_names))
        if unknown:
            raise ValueError(f"{s.label}: measured channel(s) {unknown} are not outputs of model "
                             f"{model.name!r}: {', '.join(model.output_names)}")
        if s.inputs.shape[1] != n_u:
            raise ValueError(f"{s.label} inputs have {s.inputs.shape[1]} columns; model "
                             f"{model.name!r} has {n_u} ({', '.join(model.input_names)})")
        if s.disturbance is not None and s.disturbance.shape[-1] != n_d:
            raise ValueError(f"{s.label} disturbance has width {s.disturbance.shape[-1]}; "
                             f"model {model.name!r} has {n_d}")
        if s.x0 is not None and s.x0.shape != (len(model.state_names),):
            raise ValueError(f"{s.label} x0 has shape {s.x0.shape}; expected "
                             f"({len(model.state_names)},)")
    first = segments[0]
    for s in segments[1:]:
        if s.measured != first.measured:
            raise ValueError(f"{s.label} measures {s.measured} but {first.label} measures "
                             f"{first.measured}; identify from segments with the same channels")
        if not math.isclose(s.dt, first.dt, rel_tol=1e-6):
            raise ValueError(f"{s.label} has dt={s.dt:g} s but {first.label} has {first.dt:g} s")


def check_parameters(model: VehicleModel, parameters: Sequence[str]) -> tuple[str, ...]:
    """The parameter names, validated: known scalar fields of ``model.params``, no repeats.

    :raises ValueError: naming the unknown parameters and listing the known ones.
    """
    if isinstance(parameters, str):
        parameters = (parameters,)
    names = tuple(parameters)
    if not names:
        raise ValueError("no parameters to identify: give at least one name")
    scalars = [f.name for f in dataclasses.fields(model.params)
               if isinstance(getattr(model.params, f.name), int | float)
               and not isinstance(getattr(model.params, f.name), bool)]
    unknown = [n for n in names if n not in scalars]
    if unknown:
        raise ValueError(f"unknown parameter(s) {unknown} for model {model.name!r}; known: "
                         f"{', '.join(scalars)}")
    repeated = sorted({n for n in names if names.count(n) > 1})
    if repeated:
        raise ValueError(f"parameter(s) {repeated} listed more than once")
    return names


def _values(model: VehicleModel, names: tuple[str, ...], given: Mapping[str, float] | None,
            what: str) -> FloatArray:
    """Per-parameter values from ``given`` (a mapping by name), default the model's own."""
    given = dict(given or {})
    extra = sorted(set(given) - set(names))
    if extra:
        raise ValueError(f"{what} names parameter(s) {extra} that are not identified here "
                         f"({', '.join(names)})")
    out = np.array([float(given.get(n, getattr(model.params, n))) for n in names])
    if not np.isfinite(out).all():
        raise ValueError(f"{what} has non-finite values: {dict(zip(names, out, strict=True))}")
    return out


def _scales(names: tuple[str, ...], initial: FloatArray, given: Mapping[str, float] | None,
            what: str = "prior_std") -> FloatArray:
    """Per-parameter scale (prior std): ``given`` by name, default ``|initial|``."""
    given = dict(given or {})
    extra = sorted(set(given) - set(names))
    if extra:
        raise ValueError(f"{what} names parameter(s) {extra} that are not identified here")
    out = np.array([float(given.get(n, abs(v))) for n, v in zip(names, initial, strict=True)])
    bad = [n for n, s in zip(names, out, strict=True) if not (math.isfinite(s) and s > 0)]
    if bad:
        raise ValueError(f"{what} of {bad} must be finite and > 0 (their initial value is 0: "
                         f"give {what}={{name: value}})")
    return out


def _initial_state(model: VehicleModel, s: Segment) -> FloatArray:
    if s.x0 is not None:
        return s.x0.copy()
    x0 = np.array(model.x0, dtype=float)
    for j, c in enumerate(s.measured):
        if c in model.state_names:
            x0[model.state_names.index(c)] = s.measurements[0, j]
    return x0
