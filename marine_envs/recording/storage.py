"""Where a recording is stored: its format named by the file's suffix (``.csv``, ``.parquet``),
the CSV's JSON sidecar, and pyarrow, imported only for Parquet."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from typing import Any

_PARQUET_HINT = 'Parquet recordings need pyarrow: pip install "marine-envs[parquet]"'

#: Recording formats by file suffix (lower case).
_FORMATS = {".csv": "csv", ".parquet": "parquet"}


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


def _sidecars(path: Path) -> tuple[Path, Path]:
    """Sidecar names of a CSV file: ``run.csv.json`` (written) and ``run.json`` (also read)."""
    return path.with_name(path.name + ".json"), path.with_suffix(".json")


def _format(path: Path) -> str:
    """The format the suffix of ``path`` names: ``"csv"`` or ``"parquet"``.

    :raises ValueError: a suffix that names no recording format.
    """
    try:
        return _FORMATS[path.suffix.lower()]
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
