"""Recordings: logged runs of a vehicle, real or simulated, in one documented file format.

A recording is a table, stored as CSV or Parquet, plus a little JSON metadata. Rows are samples;
rows are counted from 0 (the CSV header is not a row).

Columns
    ``time``
        Sample time in seconds, strictly increasing. The step must be uniform (every step within a
        relative 1e-3 of the median step) unless the reader is called with
        ``require_uniform=False``.
    one column per model input
        Named as in the model's ``input_names`` (for ``usv``: ``delta``). All are required. The
        input *commanded* (by a controller, a pilot, an excitation signal), as a trial's log
        holds it; what the actuator delivered may differ (a rate limit, a saturation, a delay):
        that goes in an actuator position sensor's column.
    one column per measured channel
        Named as in the model's ``output_names`` (its states, plus derived outputs such as the DP
        vessel's measured position; for ``usv``: ``v, r, psi, p, phi``). Channels that
        were not measured are simply absent, but at least one must be present.
    optional: actuator position sensors
        Named after a model input plus ``_applied`` (for ``usv``: ``delta_applied``), in the
        input's unit: what the actuator delivered, read by a sensor on it (a rudder angle
        indicator), beside the command in the input's own column. Complete, like the inputs.
        A diagnosis judges the map from command to position directly and takes the position
        as the input to the hull (:mod:`estimators.diagnosis.actuators`).
    optional: measured disturbances
        Named as in the model's ``disturbance_names`` (the hovercraft's ``wind_north``, the
        ROV's ``current_n`` or morph command ``s_cmd``): a wind, current or command that was
        logged. A diagnosis takes them as known inputs
        (:class:`~marine_envs.models.MeasuredDisturbances`) instead of estimating them.

    No other columns are allowed and there must be at least two rows. Every value must be a
    finite number, except in the measured channels: there an empty cell or NaN marks a sample
    the logger dropped, a missing measurement (:attr:`Recording.missing`; the filters skip it,
    as they skip a dropped sensor sample). Time, inputs and disturbances must be complete.

Metadata, a JSON object
    ``model`` (required)
        Name of the vehicle model, one of :func:`marine_envs.models.model_names`.
    ``params`` (optional)
        Parameter overrides by docs/models.md symbol, e.g. ``{"wn": 0.7}``; validated by the model.
    ``units`` (optional)
        Unit of each column, e.g. ``{"time": "s", "phi": "deg"}``. Columns not listed are in the
        model's SI units. A unit in :data:`UNIT_CONVERSIONS` (degrees, knots, milliseconds, ...)
        is converted to SI once, when the file is read; any other unit must equal the SI unit.
        Files written by :func:`write_recording` are always in SI units and say so.
    any other key
        Free-form information (environment id, seed, dt, policy, ...) that is kept in
        :attr:`Recording.meta` and written back unchanged.

    Parquet stores the metadata in the file's schema metadata under the key ``marine_envs``. CSV
    stores it in a sidecar file named after the data file plus ``.json`` (``run.csv`` ->
    ``run.csv.json``); a sidecar that replaces the suffix (``run.json``) is also read. A CSV without
    sidecar can be read only by naming the model: ``read_recording("run.csv", model="usv")``.

Example, ``run.csv``::

    time,delta,psi,phi
    0.0,0.0,0.0,0.0
    0.1,0.05,0.001,-0.002
    ...

and ``run.csv.json``::

    {"model": "usv", "params": {"wn": 0.7}, "units": {"time": "s", "delta": "deg", "psi": "deg",
     "phi": "deg"}, "seed": 3, "policy": "lqr"}

Reading checks all of the above and raises ``ValueError`` naming the offending column or row.
Values that are legal but implausible for the model (an input beyond twice its bound, an angle
beyond 2 pi: most often a unit mistake) are kept, and listed in :attr:`Recording.warnings` with
the likely mistake; :func:`read_recording` also issues them as
:class:`~marine_envs.plausibility.PlausibilityWarning`.
Parquet support needs pyarrow: ``pip install "marine-envs[parquet]"``.

Writing (:func:`write_recording`, or :func:`stream_recording` for a recording made row by row,
in bounded memory) is whole or nothing: a full disk or an error leaves the earlier file and its
sidecar as they were, never a truncated table or a sidecar that does not match it.
"""

from __future__ import annotations

import contextlib
import importlib.util
import json
import math
import os
import re
from collections.abc import Callable, Iterator, Mapping, Sequence
from dataclasses import InitVar, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

from . import plausibility
from .files import atomic_path
from .models import VehicleModel, get_model

#: Key of the metadata in the Parquet schema metadata.
METADATA_KEY = "marine_envs"
#: Metadata keys with a meaning of their own; every other key goes to :attr:`Recording.meta`.
RESERVED_KEYS = ("model", "params", "units")
TIME = "time"
#: An actuator position sensor's column: the input's name plus this (``delta_applied``).
APPLIED = "_applied"
#: A time step may differ from the median step by this fraction before it counts as non-uniform.
UNIFORM_RTOL = 1e-3
#: Non-SI units accepted in the metadata: unit -> (SI unit, factor to multiply by).
UNIT_CONVERSIONS: dict[str, tuple[str, float]] = {
    "ms": ("s", 1e-3),
    "min": ("s", 60.0),
    "deg": ("rad", math.pi / 180),
    "deg/s": ("rad/s", math.pi / 180),
    "deg/s^2": ("rad/s^2", math.pi / 180),
    "kn": ("m/s", 1852 / 3600),
    "knot": ("m/s", 1852 / 3600),
    "knots": ("m/s", 1852 / 3600),
    "km/h": ("m/s", 1 / 3.6),
    "mm": ("m", 1e-3),
    "cm": ("m", 1e-2),
    "km": ("m", 1e3),
}
_PARQUET_HINT = 'Parquet recordings need pyarrow: pip install "marine-envs[parquet]"'
# pandas < 3 parses floats with a fast but not always exact converter; 3.x is exact by default.
_CSV_READ_OPTIONS: dict[str, Any] = (
    {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
)


@dataclass(eq=False, repr=False)  # eq on DataFrames is elementwise, so compare explicitly
class Recording:
    """A validated recording in SI units (see the module docstring for the format).

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
            :data:`UNIFORM_RTOL` of the median step).
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


# -- writing ---------------------------------------------------------------------------------
#: Rows a :class:`RecordingStream` holds in memory before it writes them to the file.
CHUNK_ROWS = 8192


def write_recording(recording: Recording, path: str | Path) -> Path:
    """Write ``recording`` in SI units, choosing the format from the suffix of ``path``.

    ``.csv`` writes the table and a JSON sidecar ``<path>.json``; ``.parquet`` writes one file
    with the metadata in its schema (needs pyarrow). Written whole or not at all
    (:func:`stream_recording`).

    :param recording: the recording; it is re-validated (allowing non-uniform sampling).
    :param path: destination, ending in ``.csv`` or ``.parquet``.
    :return: the path of the data file.
    :raises ValueError: unsupported suffix or an invalid recording.
    :raises marine_envs.files.WriteError: the file cannot be written (names it).
    """
    path = Path(path)
    _format(path)
    recording.validate(require_uniform=False)
    with stream_recording(path, recording.model, list(recording.units), recording.params,
                          recording.meta) as stream:
        stream.extend(recording.data.to_numpy())
    return path


@contextlib.contextmanager
def stream_recording(path: str | Path, model: str, columns: Sequence[str],
                     params: Mapping[str, float] | None = None,
                     meta: Mapping[str, Any] | None = None,
                     chunk_rows: int = CHUNK_ROWS) -> Iterator[RecordingStream]:
    """Write a recording while it is being made, in memory bounded by ``chunk_rows`` rows.

    The rows go to a temporary file beside ``path``, ``chunk_rows`` at a time; when the block
    ends, the metadata (:attr:`RecordingStream.meta` as it is then: e.g. why the run stopped)
    is written and the file (and the CSV's sidecar) renamed into place. An exception in the
    block, or a full disk, leaves ``path`` as it was (its earlier content, or nothing), never
    a part of a recording.

    :param path: destination, ``.csv`` (with its sidecar) or ``.parquet``.
    :param model: model name.
    :param columns: the order of the values in each row: ``time``, the model's inputs, measured
        disturbances and channels, any order (the file has the format's).
    :param params: parameter overrides by docs/models.md symbol.
    :param meta: free-form metadata, JSON-serialisable; may change until the block ends.
    :raises ValueError: a bad suffix, column, metadata or row (naming it), or fewer than two
        rows when the block ends.
    :raises marine_envs.files.WriteError: the file cannot be written (names it).
    """
    path = Path(path)
    csv = _format(path) is _read_csv
    if chunk_rows < 1:
        raise ValueError(f"chunk_rows={chunk_rows!r} is invalid: an integer >= 1")
    stream = RecordingStream(model, columns, params, meta, chunk_rows)
    with contextlib.ExitStack() as files:
        # the sidecar is renamed after the table: a failure on either leaves both as they were
        metadata = files.enter_context(atomic_path(sidecar(path))) if csv else None
        data = files.enter_context(atomic_path(path))
        with stream.open(data, csv):
            yield stream
            stream.finish(metadata)


class RecordingStream:
    """Rows of a recording on their way to its file (made by :func:`stream_recording`); each
    row is checked as it comes (finite values, increasing time), so that the file is a valid
    recording whenever the stream ends with two rows or more."""

    def __init__(self, model: str, columns: Sequence[str], params: Mapping[str, float] | None,
                 meta: Mapping[str, Any] | None, chunk_rows: int) -> None:
        vehicle = _vehicle(model, params or {})
        self.model, self.params, self.meta = model, dict(params or {}), dict(meta or {})
        _check_meta(self.meta)
        given = pd.DataFrame(columns=list(columns))
        _check_columns(given, vehicle)
        self.columns = _canonical(given, vehicle)
        self._order = [list(columns).index(name) for name in self.columns]
        si = _si_units(vehicle)
        self.units = {name: si[name] for name in self.columns}
        # a measured channel may miss a sample (NaN), never be infinite; the rest must be finite
        self._complete = np.array([name not in vehicle.output_names for name in self.columns])
        self._buffer = np.empty((chunk_rows, len(self.columns)))
        self._pending = 0
        #: Time of the last row written to the file, s.
        self.last_time = -math.inf
        #: Rows taken so far (written or held).
        self.rows = 0
        self._metadata()  # a metadata value JSON cannot hold fails before any row
        self._file: Any = None
        self._parquet: Any = None

    def append(self, row: ArrayLike) -> None:
        """One row, its values in the order of the ``columns`` given (SI units)."""
        self._buffer[self._pending] = row
        self._pending += 1
        self.rows += 1
        if self._pending == len(self._buffer):
            self._flush()

    def extend(self, rows: ArrayLike) -> None:
        """Several rows, shape ``(n, len(columns))``."""
        rows = np.asarray(rows, dtype=float)
        self._flush()
        for start in range(0, len(rows), len(self._buffer)):
            block = rows[start:start + len(self._buffer)]
            self.rows += len(block)
            self._write(block[:, self._order])

    @contextlib.contextmanager
    def open(self, path: Path, csv: bool) -> Iterator[None]:
        """The data file ``path`` open for the rows (closed whatever happens)."""
        self._path, self._csv = path, csv
        if csv:
            self._file = open(path, "w", newline="", encoding="utf-8")
            pd.DataFrame(columns=self.columns).to_csv(self._file, index=False)
        try:
            yield
        finally:
            if self._file is not None:
                self._file.close()
            if self._parquet is not None:
                self._parquet.close()

    def finish(self, sidecar_path: Path | None) -> None:
        """Write the rows held and the metadata; the file is then complete."""
        self._flush()
        if self.rows < 2:
            raise ValueError(f"recording has {self.rows} row(s); at least 2 rows are needed")
        if self._csv:
            self._file.close()
            sidecar_path.write_text(json.dumps(self._metadata(), indent=2,
                                               default=_json_default) + "\n", encoding="utf-8")
        else:
            # key-value metadata written with the footer, i.e. after the rows: the metadata
            # may change until then (no stored Arrow schema: it would hide them from readers)
            self._parquet.add_key_value_metadata(
                {**self._pandas, METADATA_KEY: json.dumps(self._metadata(),
                                                          default=_json_default)})
            with _arrow_errors():
                self._parquet.close()

    def _metadata(self) -> dict[str, Any]:
        _check_meta(self.meta)
        metadata = {"model": self.model, "params": self.params, "units": self.units, **self.meta}
        json.dumps(metadata, default=_json_default)
        return metadata

    def _flush(self) -> None:
        if self._pending:
            block, self._pending = self._buffer[:self._pending, self._order], 0  # a copy
            self._write(block)

    def _write(self, block: np.ndarray) -> None:
        """Check ``block`` (rows in the file's column order) and append it to the file."""
        first = self.rows - len(block)  # the block's first row in the recording
        bad = np.argwhere(np.isinf(block) | (self._complete & np.isnan(block)))
        if bad.size:
            row, column = bad[0]
            raise ValueError(f"column {self.columns[column]!r} has non-finite value "
                             f"{block[row, column]} at row {first + row}")
        time = np.concatenate(([self.last_time], block[:, 0]))
        bad = np.flatnonzero(np.diff(time) <= 0)
        if bad.size:
            row = first + bad[0]
            raise ValueError(f"time is not strictly increasing at row {row}: "
                             f"{time[bad[0] + 1]:.10g} s follows {time[bad[0]]:.10g} s")
        self.last_time = block[-1, 0]
        frame = pd.DataFrame(block, columns=self.columns)
        if self._csv:
            frame.to_csv(self._file, header=False, index=False)  # repr: exact round trip
            self._file.flush()  # on disk as it is made: a reader sees the file grow
            return
        pa, pq = _pyarrow()
        table = pa.Table.from_pandas(frame, preserve_index=False)
        with _arrow_errors():
            if self._parquet is None:
                self._pandas = table.schema.metadata or {}  # pandas' own, kept next to ours
                self._parquet = pq.ParquetWriter(self._path, table.schema, store_schema=False)
            self._parquet.write_table(table)


@contextlib.contextmanager
def _arrow_errors() -> Iterator[None]:
    """pyarrow's I/O errors as Python's own: its OSError has the errno only in its text
    (``... [errno 28] No space left on device``), so the message would not be the usual one."""
    try:
        yield
    except OSError as error:
        found = re.search(r"\[errno (\d+)\]", str(error))
        if found is None:
            raise
        number = int(found[1])
        raise OSError(number, os.strerror(number)) from error


def _json_default(value: Any) -> Any:
    """Let numpy scalars and arrays (seeds, dt, ...) into the JSON metadata."""
    if isinstance(value, np.generic | np.ndarray):
        return value.tolist()
    raise TypeError(f"metadata value {value!r} of type {type(value).__name__} is not "
                    "JSON-serialisable")


# -- reading ---------------------------------------------------------------------------------
def read_recording(
    path: str | Path, model: str | None = None, *, require_uniform: bool = True
) -> Recording:
    """Read and validate a recording, converting its columns to SI units.

    :param path: a ``.csv`` (with sidecar ``<path>.json`` or ``<stem>.json``) or ``.parquet``
        file.
    :param model: expected model name; required for a file without metadata.
    :param require_uniform: reject a non-uniform time step.
    :raises FileNotFoundError: ``path`` does not exist.
    :raises ValueError: unsupported suffix, wrong or unknown model, invalid parameters, unknown
        units, or a table that breaks the format; the message names the file and the offending
        column, row, unit or parameter.
    :raises ImportError: a Parquet file without pyarrow installed.
    """
    path = Path(path)
    reader = _format(path)
    if not path.is_file():
        raise FileNotFoundError(f"recording not found: {path}")
    try:
        data, metadata, where = reader(path)
        recording = _from_table(data, metadata, where, model, require_uniform)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc
    plausibility.warn((f"{path.name}: {line}" for line in recording.warnings), stacklevel=2)
    return recording


def _from_table(data: pd.DataFrame, metadata: dict[str, Any] | None, where: str,
                model: str | None, require_uniform: bool) -> Recording:
    """The recording of a freshly read table and its metadata (``None`` if the file had none)."""
    if metadata is None and model is None:
        raise ValueError(f"no metadata found ({where}); pass model=... to read the file as SI "
                         "units with nominal parameters")
    meta = dict(metadata or {})
    named = meta.pop("model", None)
    if named is None and model is None:
        raise ValueError(f"metadata ({where}) has no 'model' key; pass model=...")
    if named is not None and model is not None and named != model:
        raise ValueError(f"recording is for model {named!r}, not {model!r}")
    name = named if named is not None else model
    params = meta.pop("params", None) or {}
    units = meta.pop("units", None) or {}
    data = _to_si(data, units, get_model(name))
    return Recording(data, name, params, meta, require_uniform=require_uniform,
                     declared_units=units)


def _read_csv(path: Path) -> tuple[pd.DataFrame, dict[str, Any] | None, str]:
    data = pd.read_csv(path, skipinitialspace=True, **_CSV_READ_OPTIONS)
    sidecars = _sidecars(path)
    where = f"sidecar {sidecars[0].name} or {sidecars[1].name}"
    for sidecar in sidecars:  # the canonical name wins if both exist
        if sidecar.is_file():
            return data, _parse_metadata(sidecar.read_text(encoding="utf-8"), sidecar.name), where
    return data, None, where


def _read_parquet(path: Path) -> tuple[pd.DataFrame, dict[str, Any] | None, str]:
    _, pq = _pyarrow()
    table = pq.read_table(path)
    raw = (table.schema.metadata or {}).get(METADATA_KEY.encode())
    where = f"Parquet schema metadata key {METADATA_KEY!r}"
    metadata = None if raw is None else _parse_metadata(raw.decode("utf-8"), where)
    # the table's columns are freed as they are converted: one copy of a long record at a time
    return table.to_pandas(self_destruct=True, split_blocks=True), metadata, where


def _sidecars(path: Path) -> tuple[Path, Path]:
    """Sidecar names of a CSV file: ``run.csv.json`` (written) and ``run.json`` (also read)."""
    return path.with_name(path.name + ".json"), path.with_suffix(".json")


def _parse_metadata(text: str, source: str) -> dict[str, Any]:
    try:
        metadata = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ValueError(f"invalid JSON in {source}: {exc}") from None
    if not isinstance(metadata, dict):
        raise ValueError(f"{source} must hold a JSON object, got {type(metadata).__name__}")
    return metadata


def _to_si(data: pd.DataFrame, units: Any, vehicle: VehicleModel) -> pd.DataFrame:
    """``data`` with every column converted from its unit in the metadata to SI."""
    if not isinstance(units, Mapping):
        raise ValueError(f"'units' metadata must map column names to units, got {units!r}")
    si = _si_units(vehicle)
    unknown = [name for name in units if name not in si]
    if unknown:
        raise ValueError(f"units given for unknown column(s) {unknown} of model "
                         f"{vehicle.name!r}; allowed: {', '.join(si)}")
    converted = {}
    for name, unit in units.items():
        factor = _si_factor(name, unit, si[name])
        # A non-numeric column is left for validate() to report with its row.
        if factor != 1.0 and name in data.columns and _is_numeric(data[name]):
            converted[name] = data[name].astype(float) * factor
    return data.assign(**converted) if converted else data  # a copy only if converted


def _si_factor(column: str, unit: Any, expected: str) -> float:
    """Factor converting ``column`` from ``unit`` to its SI unit ``expected``."""
    if unit == expected:
        return 1.0
    target, factor = UNIT_CONVERSIONS.get(unit, ("", 0.0)) if isinstance(unit, str) else ("", 0.0)
    if target != expected:
        convertible = sorted(u for u, (si, _) in UNIT_CONVERSIONS.items() if si == expected)
        raise ValueError(f"column {column!r} has unit {unit!r}, which does not convert to its SI "
                         f"unit {expected!r}; accepted: {', '.join([expected, *convertible])}")
    return factor


def check_suffix(path: str | Path) -> Path:
    """``path`` as a Path if its suffix names a recording format (.csv, .parquet) that can be
    written here (Parquet needs pyarrow).

    :raises ValueError: any other suffix (before any work is done, e.g. a long simulation).
    :raises ImportError: a Parquet file without pyarrow installed.
    """
    path = Path(path)
    _format(path)
    if path.suffix.lower() == ".parquet" and importlib.util.find_spec("pyarrow") is None:
        raise ImportError(_PARQUET_HINT)
    return path


def sidecar(path: str | Path) -> Path:
    """The JSON sidecar :func:`write_recording` writes beside a CSV ``path``."""
    return _sidecars(Path(path))[0]


def _format(path: Path) -> Callable[[Path], Any]:
    """The reader for the suffix of ``path`` (which also tells the format to write).

    :raises ValueError: a suffix that names no recording format.
    """
    formats = {".csv": _read_csv, ".parquet": _read_parquet}
    try:
        return formats[path.suffix.lower()]
    except KeyError:
        raise ValueError(f"unsupported recording suffix {path.suffix!r} ({path}); use .csv or "
                         ".parquet") from None


def _pyarrow() -> tuple[Any, Any]:
    """``(pyarrow, pyarrow.parquet)``, imported lazily so that CSV works without them."""
    try:
        import pyarrow as pa
        import pyarrow.parquet as pq
    except ImportError as exc:
        raise ImportError(_PARQUET_HINT) from exc
    return pa, pq


# -- validation ------------------------------------------------------------------------------
def _vehicle(model: str, params: Any) -> VehicleModel:
    """The model named ``model`` with ``params`` applied; raises ``ValueError`` if invalid."""
    if not isinstance(params, Mapping):
        raise ValueError(f"params must map parameter names to values, got {params!r}")
    try:
        return get_model(model, **params)
    except TypeError as exc:  # e.g. a string where a number is due
        raise ValueError(f"invalid params {dict(params)!r} for model {model!r}: {exc}") from exc


def _check_meta(meta: Any) -> None:
    if not isinstance(meta, Mapping):
        raise ValueError(f"meta must be a mapping, got {type(meta).__name__}")
    clash = [key for key in RESERVED_KEYS if key in meta]
    if clash:
        raise ValueError(f"meta key(s) {clash} are reserved; use Recording.model, .params and "
                         "the column units instead")


def _check_columns(data: pd.DataFrame, vehicle: VehicleModel) -> None:
    columns = list(data.columns)
    allowed = (TIME, *vehicle.input_names, *vehicle.output_names, *vehicle.disturbance_names,
               *_applied_names(vehicle))
    duplicated = sorted({str(c) for c in data.columns[data.columns.duplicated()]})
    if duplicated:
        raise ValueError(f"duplicate column(s) {duplicated}")
    unknown = [c for c in columns if c not in allowed]
    if unknown:
        raise ValueError(f"unknown column(s) {unknown} for model {vehicle.name!r}; allowed: "
                         f"{', '.join(allowed)}")
    if TIME not in columns:
        raise ValueError(f"missing column {TIME!r} (sample times in s)")
    missing = [name for name in vehicle.input_names if name not in columns]
    if missing:
        raise ValueError(f"missing input column(s) {missing} for model {vehicle.name!r}; every "
                         f"input is required: {', '.join(vehicle.input_names)}")
    if not any(name in columns for name in vehicle.output_names):
        raise ValueError(f"no measured channel: at least one of the columns "
                         f"{', '.join(vehicle.output_names)} is required")


def _canonical(data: pd.DataFrame, vehicle: VehicleModel) -> list[str]:
    """Column order of the format: time, inputs, actuator position sensors, measured
    disturbances and measured channels in model order."""
    present = set(data.columns)
    applied = [name for name in _applied_names(vehicle) if name in present]
    disturbances = [name for name in vehicle.disturbance_names if name in present]
    measured = [name for name in vehicle.output_names if name in present]
    return [TIME, *vehicle.input_names, *applied, *disturbances, *measured]


def _applied_names(vehicle: VehicleModel) -> list[str]:
    """The columns of actuator position sensors the model allows: ``<input>_applied``."""
    return [name + APPLIED for name in vehicle.input_names]


def _is_numeric(column: pd.Series) -> bool:
    # Booleans and complex numbers are not measurements; nullable Int64/Float64 are fine.
    return pd.api.types.is_integer_dtype(column) or pd.api.types.is_float_dtype(column)


def _numeric(column: pd.Series, name: str) -> np.ndarray:
    """``column`` as float64; raises ``ValueError`` naming the column and first bad row."""
    if not _is_numeric(column):
        coerced = pd.to_numeric(column, errors="coerce")
        bad = np.flatnonzero(coerced.isna().to_numpy() & column.notna().to_numpy())
        where = f": row {bad[0]} is {column.iloc[bad[0]]!r}" if bad.size else ""
        raise ValueError(f"column {name!r} is not numeric (dtype {column.dtype}){where}")
    return column.to_numpy(dtype=float, na_value=np.nan)


def _check_finite(values: dict[str, np.ndarray], measured: tuple[str, ...]) -> None:
    """Every value finite, but for missing samples (NaN) in the ``measured`` channels."""
    time = values[TIME]
    for name, column in values.items():  # time first, so a later row's time is trustworthy
        dropped = name in measured  # NaN there is a sample the logger dropped
        if dropped and np.isnan(column).all():
            raise ValueError(f"column {name!r} has no value: every row is missing (NaN or "
                             "empty); leave an unmeasured channel out")
        bad = np.flatnonzero(np.isinf(column) if dropped else ~np.isfinite(column))
        if bad.size:
            row = bad[0]
            when = "" if name == TIME else f" (time {time[row]:.10g} s)"
            raise ValueError(f"column {name!r} has non-finite value {column[row]} at row "
                             f"{row}{when}")


def _check_time(time: np.ndarray, require_uniform: bool) -> None:
    step = np.diff(time)
    bad = np.flatnonzero(step <= 0)
    if bad.size:
        row = bad[0] + 1
        raise ValueError(f"time is not strictly increasing at row {row}: {time[row]:.10g} s "
                         f"follows {time[row - 1]:.10g} s at row {row - 1}")
    if not require_uniform:
        return
    expected = float(np.median(step))
    bad = np.flatnonzero(np.abs(step - expected) > UNIFORM_RTOL * expected)
    if bad.size:
        row = bad[0] + 1
        raise ValueError(f"non-uniform time step at row {row}: step {step[row - 1]:.6g} s (from "
                         f"{time[row - 1]:.10g} s to {time[row]:.10g} s) vs expected "
                         f"{expected:.6g} s (median step); pass require_uniform=False to accept "
                         "non-uniform sampling")


def _si_units(vehicle: VehicleModel) -> dict[str, str]:
    """SI unit of every column the model allows."""
    return {TIME: "s", **dict(zip(vehicle.input_names, vehicle.input_units, strict=True)),
            **dict(zip(_applied_names(vehicle), vehicle.input_units, strict=True)),
            **dict(zip(vehicle.disturbance_names, vehicle.disturbance_units, strict=True)),
            **dict(zip(vehicle.output_names, vehicle.output_units, strict=True))}


__all__ = ["APPLIED", "METADATA_KEY", "UNIT_CONVERSIONS", "Recording", "RecordingStream",
           "read_recording", "stream_recording", "write_recording"]
