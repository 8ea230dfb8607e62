"""Files written whole or not at all.

Every file the project writes (recordings, reports, plots, JSON, models, checkpoints) goes
through :func:`atomic_path`: the writer fills a temporary file beside the target, which is
renamed over the target only when the writer returned. A full disk, a crash or Ctrl-C in the
middle leaves the earlier file (or none), never a truncated one, and the error names the file
the user asked for, not the temporary one.
"""

from __future__ import annotations

import contextlib
import errno
import json
import os
import stat
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import Any

__all__ = ["WriteError", "atomic_path", "write_text", "write_json"]


class WriteError(OSError):
    """A file could not be written; ``filename`` is the file asked for, the message says why."""

    def __str__(self) -> str:
        return str(self.strerror)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path`` with the same suffix; rename it over ``path`` after.

    The temporary file sits in the target's folder (a rename is atomic only within one file
    system) and keeps the target's suffix, so writers that choose a format by suffix
    (``savefig``, ``to_parquet``, SB3's ``save``) see the one the user asked for. On any error
    the temporary file is removed and an :class:`OSError` becomes a :class:`WriteError`
    naming ``path``.

    :param path: the file to write.
    :raises WriteError: when the file cannot be written (full disk, no permission, ...).
    """
    target = Path(path)
    if _is_stream(target):
        # a device or a pipe (/dev/stdout, /dev/null, a fifo) cannot be replaced: write through it
        yield from _direct(target)
        return
    target = target.resolve()  # through a symbolic link: replace the file, keep the link
    try:
        fd, name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=f".part{target.suffix}",
                                    dir=target.parent)
        os.close(fd)
        os.chmod(name, _mode(target))  # mkstemp's 0600 would hide the file from others
    except OSError as error:
        raise _write_error(target, error) from error
    temporary = Path(name)
    try:
        yield temporary
        _fsync(temporary)
        os.replace(temporary, target)
    except WriteError:  # a file written inside this one's writer names itself: keep its message
        temporary.unlink(missing_ok=True)
        raise
    except OSError as error:
        temporary.unlink(missing_ok=True)
        raise _write_error(target, error) from error
    except BaseException:
        temporary.unlink(missing_ok=True)
        raise


def _is_stream(path: Path) -> bool:
    if path.exists() and not path.is_file():
        return True
    first = Path(os.path.abspath(path)).parts[1:2]
    return first in (("dev",), ("proc",)) or \
        Path(os.path.realpath(path)).parts[1:2] in (("dev",), ("proc",))


def _direct(target: Path) -> Iterator[Path]:
    try:
        yield target
    except WriteError:
        raise
    except OSError as error:
        raise _write_error(target, error) from error


def write_text(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` (UTF-8) to ``path`` atomically; :class:`WriteError` names ``path``."""
    with atomic_path(path) as temporary:
        temporary.write_text(text, encoding="utf-8")


def write_json(path: str | os.PathLike[str], document: Any, **dump_options: Any) -> None:
    """Write ``document`` as JSON (indented by 2 unless told, a newline at the end) atomically."""
    dump_options.setdefault("indent", 2)
    write_text(path, json.dumps(document, **dump_options) + "\n")


def _mode(target: Path) -> int:
    """The permissions the file gets: those of the file it replaces, else what ``open`` gives a
    new file under the process's umask."""
    try:
        return stat.S_IMODE(target.stat().st_mode)
    except FileNotFoundError:
        umask = os.umask(0)
        os.umask(umask)
        return 0o666 & ~umask


def _fsync(path: Path) -> None:
    # a rename is durable only after the data: flush it to the disk first
    with open(path, "rb+") as f:
        os.fsync(f.fileno())


def _write_error(target: Path, error: OSError) -> WriteError:
    reason = error.strerror or os.strerror(error.errno or errno.EIO)
    return WriteError(error.errno or errno.EIO, f"cannot write {target}: {reason}", str(target))
