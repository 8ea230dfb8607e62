"""The recording format's names and checks (:mod:`marine_envs.recording` documents the format):
which columns a model allows and in which order, the metadata keys, the time step, and the
checks that raise ``ValueError`` naming the offending column, row or key.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import pandas as pd

from ..models import VehicleModel, get_model

#: Key of the metadata in the Parquet schema metadata.
METADATA_KEY = "marine_envs"
#: Metadata keys with a meaning of their own; every other key goes to
#: :attr:`~marine_envs.recording.Recording.meta`.
RESERVED_KEYS = ("model", "params", "units")
TIME = "time"
#: An actuator position sensor's column: the input's name plus this (``delta_applied``).
APPLIED = "_applied"
#: A time step may differ from the median step by this fraction before it counts as non-uniform.
UNIFORM_RTOL = 1e-3


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
