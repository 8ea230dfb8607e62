"""Paths, sample rates and the recording writer shared by both conversions."""

from __future__ import annotations

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
FS_IN = 100.0  #: original sample rate of both data sets' fast channel, Hz
FS_OUT = 10.0  #: sample rate of the recordings, Hz
DECIMATION = 10


def _write(recording, path: Path, dry_run: bool) -> None:
    from marine_envs.recording import read_recording, write_recording

    if dry_run:
        print(f"  (dry run: not writing {path})")
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    write_recording(recording, path)
    back = read_recording(path)  # the shipped file must read back as a valid recording
    print(f"  wrote {path.relative_to(REPO) if path.is_relative_to(REPO) else path} "
          f"({path.stat().st_size / 1e3:.0f} kB, {len(back.data)} rows)")
