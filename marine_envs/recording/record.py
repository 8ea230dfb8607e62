"""The :class:`Recording`: a validated table of a vehicle's logged run in SI units, with its
views (time, inputs, measured channels, units), missing samples filled and windows cut."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import InitVar, dataclass, field
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

from .. import plausibility
from ..models import VehicleModel, get_model
from .format import (
    APPLIED,
    TIME,
    _canonical,
    _check_columns,
    _check_finite,
    _check_meta,
    _check_time,
    _numeric,
    _si_units,
    _vehicle,
)


@dataclass(eq=False, repr=False)  # eq on DataFrames is elementwise, so compare explicitly
class Recording:
    """A validated recording in SI units (the format: :mod:`marine_envs.recording`).

    :param data: columns ``time`` (s), the model's inputs, then the measured channels, in model
        order and SI units; any column order is accepted and normalised.
    :param model: model name, see :func:`marine_envs.models.model_names`.
    :param params: parameter overrides by docs/models.md symbol (SI units).
    :param meta: free-form extra metadata (env id, seed, dt, policy, ...); JSON-serialisable.
    :param require_uniform: reject a non-uniform time step (not stored).
    :param declared_units: the units the file declared per column, before conversion to SI
        (not stored): they name the likely unit mistake in :attr:`warnings`.
    :raises ValueError: the recording breaks the format; the message names the column or row.
    """

    data: pd.DataFrame
    model: str
    params: dict[str, float] = field(default_factory=dict)
    meta: dict[str, Any] = field(default_factory=dict)
    require_uniform: InitVar[bool] = True
    declared_units: InitVar[Mapping[str, str] | None] = None
    #: After :meth:`filled`: which samples of :attr:`measurements` were missing, ``(n, m)``
    #: (None: none were), so that a filter can still skip them.
    gaps = None

    def __post_init__(self, require_uniform: bool,
                      declared_units: Mapping[str, str] | None) -> None:
        self.validate(require_uniform)
        self.params = dict(self.params)
        self.meta = dict(self.meta)
        # A float64 copy in canonical column order, so callers' frames are never aliased.
        self.data = self.data[list(self.units)].astype(float).reset_index(drop=True)
        #: Why some columns look implausible for the model (unit mistakes?), one line each.
        self.warnings: list[str] = self._plausibility(declared_units or {})

    @classmethod
    def from_arrays(
        cls,
        model: str,
        time: ArrayLike,
        inputs: ArrayLike,
        measurements: Mapping[str, ArrayLike],
        params: Mapping[str, float] | None = None,
        meta: Mapping[str, Any] | None = None,
        *,
        disturbances: Mapping[str, ArrayLike] | None = None,
        applied: Mapping[str, ArrayLike] | None = None,
        require_uniform: bool = True,
    ) -> Recording:
        """Build and validate a recording from arrays in SI units.

        :param model: model name.
        :param time: sample times, s, shape ``(n,)``.
        :param inputs: model inputs in the model's SI units, shape ``(n, n_u)``; ``(n,)`` is
            accepted for a single-input model.
        :param measurements: measured channels by state name, each shape ``(n,)``, SI units.
        :param params: parameter overrides by docs/models.md symbol.
        :param meta: free-form extra metadata.
        :param disturbances: measured disturbances by the model's disturbance names, each
            shape ``(n,)``, SI units.
        :param applied: actuator position sensors by input name (``inputs`` being the
            commands), each shape ``(n,)``, SI units: the columns ``<input>_applied``.
        :param require_uniform: reject a non-uniform time step.
        """
        vehicle = _vehicle(model, params or {})
        time = np.asarray(time)
        inputs = np.asarray(inputs)
        if inputs.ndim == 1 and len(vehicle.input_names) == 1:
            inputs = inputs[:, None]
        if inputs.ndim != 2 or inputs.shape[1] != len(vehicle.input_names):
            raise ValueError(f"inputs must have shape (n, {len(vehicle.input_names)}) for columns "
                             f"{', '.join(vehicle.input_names)}; got shape {inputs.shape}")
        unknown = [name for name in measurements if name not in vehicle.output_names]
        if unknown:
            raise ValueError(f"unknown measured channel(s) {unknown} for model {model!r}; "
                             f"allowed: {', '.join(vehicle.output_names)}")
        columns = {TIME: time, **dict(zip(vehicle.input_names, inputs.T, strict=True))}
        unknown = [name for name in disturbances or {} if name not in vehicle.disturbance_names]
        if unknown:
            raise ValueError(f"unknown disturbance(s) {unknown} for model {model!r}; allowed: "
                             f"{', '.join(vehicle.disturbance_names)}")
        unknown = [name for name in applied or {} if name not in vehicle.input_names]
        if unknown:
            raise ValueError(f"unknown actuator(s) {unknown} for model {model!r}; allowed: "
                             f"{', '.join(vehicle.input_names)}")
        columns.update({name + APPLIED: np.asarray(values)
                        for name, values in (applied or {}).items()})
        for given in (disturbances or {}, measurements):
            columns.update({name: np.asarray(values) for name, values in given.items()})
        for name, values in columns.items():
            if values.shape != (len(time),):
                raise ValueError(f"column {name!r} must have shape ({len(time)},) like time; "
                                 f"got {values.shape}")
        return cls(pd.DataFrame(columns), model, dict(params or {}), dict(meta or {}),
                   require_uniform=require_uniform)

    def validate(self, require_uniform: bool = True) -> None:
        """Check the recording against the format.

        :param require_uniform: also require a uniform time step (relative tolerance
            :data:`~marine_envs.recording.format.UNIFORM_RTOL` of the median step).
        :raises ValueError: naming the offending column, row, parameter or metadata key.
        """
        vehicle = _vehicle(self.model, self.params)
        _check_meta(self.meta)
        if not isinstance(self.data, pd.DataFrame):
            raise ValueError(f"data must be a pandas DataFrame, got {type(self.data).__name__}")
        _check_columns(self.data, vehicle)
        if len(self.data) < 2:
            raise ValueError(f"recording has {len(self.data)} row(s); at least 2 rows are needed")
        values = {name: _numeric(self.data[name], name) for name in _canonical(self.data, vehicle)}
        _check_finite(values, vehicle.output_names)
        _check_time(values[TIME], require_uniform)

    def _plausibility(self, declared: Mapping[str, str]) -> list[str]:
        """One line per column whose values look like a unit mistake
        (:mod:`marine_envs.plausibility`): inputs beyond twice the model's bounds, angles
        beyond 2 pi, rates beyond half a turn a second, an angle that turns faster or slower
        than its rate says."""
        vehicle = _vehicle(self.model, self.params)
        low, high = vehicle.u_bounds
        bounds = dict(zip(vehicle.input_names, np.maximum(np.abs(low), np.abs(high)).tolist(),
                          strict=True))
        bounds.update({name + APPLIED: bound for name, bound in bounds.items()})
        lines = [plausibility.recorded_values(name, self.data[name].to_numpy(), unit,
                                              declared.get(name), bounds.get(name))
                 for name, unit in self.units.items() if name != TIME]
        lines += [plausibility.angle_rate(angle, self.data[angle].to_numpy(), rate,
                                          self.data[rate].to_numpy(), self.time)
                  for angle, rate in plausibility.rate_pairs(vehicle)
                  if angle in self.data.columns and rate in self.data.columns]
        return [line for line in lines if line]

    # -- missing samples and cuts ----------------------------------------------------------------
    @property
    def missing(self) -> np.ndarray:
        """Which measurements are missing (NaN: a sample the logger dropped), shape
        ``(n, len(measured_names))``."""
        return np.isnan(self.measurements)

    def filled(self) -> Recording:
        """This recording with every missing measurement replaced by linear interpolation in
        time between its channel's neighbouring samples (the nearest one at the ends; angles
        through their unwrapped values), and :attr:`gaps` marking them, for code that needs
        complete columns but should still skip these samples."""
        missing = self.missing
        data, time = self.data.copy(), self.time
        for j, name in enumerate(self.measured_names):
            gap = missing[:, j]
            if not gap.any():
                continue
            known = data[name].to_numpy()[~gap]
            angle = self.units[name] == "rad"
            values = np.interp(time[gap], time[~gap], np.unwrap(known) if angle else known)
            if angle and np.all(np.abs(known) <= math.pi):  # a wrapped channel stays wrapped
                values = np.angle(np.exp(1j * values))
            data.loc[gap, name] = values
        out = Recording(data, self.model, self.params, self.meta, require_uniform=False)
        out.gaps = missing if missing.any() else None
        out.warnings = list(self.warnings)  # read with the file's declared units
        return out

    def window(self, start: float | None = None, stop: float | None = None,
               decimate: int = 1) -> Recording:
        """The samples with ``start <= time <= stop`` (s, on the record's own clock; None:
        from the first, to the last), every ``decimate``-th of them. Decimation keeps samples
        and filters nothing: the sensor noise stays white, content above the new Nyquist
        frequency folds down (keep ``decimate`` below the sample rate over the vehicle's
        bandwidth).

        :raises ValueError: ``decimate`` not an integer >= 1, ``start >= stop``, or fewer than 2
            samples left (naming the numbers).
        """
        if isinstance(decimate, bool) or not isinstance(decimate, int | np.integer) \
                or decimate < 1:
            raise ValueError(f"decimate={decimate!r} is invalid: an integer >= 1")
        time = self.time
        low = time[0] if start is None else float(start)
        high = time[-1] if stop is None else float(stop)
        if not (math.isfinite(low) and math.isfinite(high) and low < high):
            raise ValueError(f"start={start!r}, stop={stop!r} are invalid: start < stop, in s "
                             f"(the record runs from {time[0]:.6g} s to {time[-1]:.6g} s)")
        rows = np.flatnonzero((time >= low) & (time <= high))[::decimate]
        if rows.size < 2:
            raise ValueError(f"start={start!r}, stop={stop!r}, decimate={decimate} leave "
                             f"{rows.size} sample(s) of a record from {time[0]:.6g} s to "
                             f"{time[-1]:.6g} s; at least 2 are needed")
        meta = dict(self.meta)
        if rows.size < len(time):
            meta["window"] = {"start": float(time[rows[0]]), "stop": float(time[rows[-1]]),
                              "decimate": int(decimate)}
        out = Recording(self.data.iloc[rows], self.model, self.params, meta,
                        require_uniform=False)
        out.gaps = None if self.gaps is None else self.gaps[rows]
        out.warnings = list(self.warnings)  # read with the file's declared units
        return out

    # -- views ---------------------------------------------------------------------------------
    @property
    def time(self) -> np.ndarray:
        """Sample times, s, shape ``(n,)``."""
        return self.data[TIME].to_numpy(dtype=float)

    @property
    def dt(self) -> float:
        """Sampling period, s: the median time step (the step itself when sampling is uniform)."""
        return float(np.median(np.diff(self.time)))

    @property
    def input_names(self) -> tuple[str, ...]:
        """Input columns, in model order."""
        return get_model(self.model).input_names

    @property
    def actuator_names(self) -> tuple[str, ...]:
        """The inputs with an actuator position sensor's column (``<input>_applied``), in
        model order."""
        return tuple(n for n in get_model(self.model).input_names
                     if n + APPLIED in self.data.columns)

    def applied(self, name: str) -> np.ndarray:
        """Input ``name``'s actuator position sensor, SI units, shape ``(n,)``."""
        return self.data[name + APPLIED].to_numpy(dtype=float)

    @property
    def disturbance_names(self) -> tuple[str, ...]:
        """Measured disturbance columns present in the recording, in model order."""
        return tuple(n for n in get_model(self.model).disturbance_names if n in self.data.columns)

    @property
    def measured_names(self) -> tuple[str, ...]:
        """Measured channels present in the recording, in model (state) order."""
        return tuple(n for n in get_model(self.model).output_names if n in self.data.columns)

    @property
    def inputs(self) -> np.ndarray:
        """Inputs in SI units, shape ``(n, len(input_names))``."""
        return self.data[list(self.input_names)].to_numpy(dtype=float)

    def inputs_for(self, model: VehicleModel) -> np.ndarray:
        """The columns ``model`` takes as inputs, SI units, shape ``(n, len(model.input_names))``:
        its actuators, and the recorded disturbances of a
        :class:`~marine_envs.models.MeasuredDisturbances`."""
        return self.data[list(model.input_names)].to_numpy(dtype=float)

    @property
    def measurements(self) -> np.ndarray:
        """Measured channels in SI units, shape ``(n, len(measured_names))``."""
        return self.data[list(self.measured_names)].to_numpy(dtype=float)

    @property
    def units(self) -> dict[str, str]:
        """SI unit of every column, in column order (time, inputs, actuator position
        sensors, measured disturbances, measured channels)."""
        vehicle = get_model(self.model)
        si = _si_units(vehicle)
        return {name: si[name] for name in _canonical(self.data, vehicle)}

    def __repr__(self) -> str:
        return (f"Recording(model={self.model!r}, params={self.params!r}, n={len(self.data)}, "
                f"measured={self.measured_names!r}, meta={self.meta!r})")
