"""Writing a recording whole or not at all: :func:`write_recording` for a recording in memory,
:func:`stream_recording` for one made row by row, in bounded memory."""

from __future__ import annotations

import contextlib
import json
import math
import os
import re
from collections.abc import Iterator, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd
from numpy.typing import ArrayLike

from ..files import atomic_path
from .format import METADATA_KEY, _canonical, _check_columns, _check_meta, _si_units, _vehicle
from .storage import _format, _pyarrow, sidecar

if TYPE_CHECKING:
    from .record import Recording

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
    csv = _format(path) == "csv"
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
