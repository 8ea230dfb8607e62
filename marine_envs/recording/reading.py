"""Reading a recording (:func:`read_recording`): the table and its metadata from a CSV with its
sidecar or a Parquet file, every column converted to SI units, validated, and the columns that
look like unit mistakes issued as warnings."""

from __future__ import annotations

import json
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import pandas as pd

from .. import plausibility
from ..models import VehicleModel, get_model
from ..units import UNIT_CONVERSIONS
from .format import METADATA_KEY, _is_numeric, _si_units
from .record import Recording
from .storage import _format, _pyarrow, _sidecars

# pandas < 3 parses floats with a fast but not always exact converter; 3.x is exact by default.
_CSV_READ_OPTIONS: dict[str, Any] = (
    {} if int(pd.__version__.split(".")[0]) >= 3 else {"float_precision": "round_trip"}
)


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
    reader = _READERS[_format(path)]
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


#: The reader of each format, by the name the file's suffix gives it.
_READERS = {"csv": _read_csv, "parquet": _read_parquet}
