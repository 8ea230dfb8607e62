"""Issue 56's "nothing lost, ever", through the real command line (a subprocess per case): a
full disk (``/dev/full``, or a tiny tmpfs), two outputs on one path, a closed pipe, SIGINT and
SIGTERM during ``marine simulate``. Every fault ends with exit code 2 and one line
``marine CMD: error: ...`` naming the file, or with its documented recovery; what was there
before survives byte for byte and no temporary file is left."""

from __future__ import annotations

import dataclasses
import os
import signal
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest

import marine_envs
from agents.cli import main
from marine_envs.recording import Recording, read_recording, write_recording

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])}
#: Generous: the command's imports alone take seconds on a loaded machine.
TIMEOUT = 300.0
NO_SPACE = "No space left on device"


def marine(*args: str, **options) -> subprocess.CompletedProcess:
    """``marine ARGS`` as its own process: exit code, stdout and stderr."""
    return subprocess.run([sys.executable, "-m", "agents.cli", *args], capture_output=True,
                          text=True, env=ENV, timeout=TIMEOUT, **options)


def _snapshot(root: Path) -> dict[str, bytes | None]:
    """Every file (its content) and folder (None) under ``root``, hidden ones too: a temporary
    file or folder left behind would show."""
    return {str(p.relative_to(root)): p.read_bytes() if p.is_file() else None
            for p in sorted(root.rglob("*"))}


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    """A recording to diagnose (and its variants a command-line user gets wrong)."""
    root = tmp_path_factory.mktemp("workspace")
    for seed, name in ((1, "run.csv"), (2, "run2.csv")):
        assert main(["simulate", "--steps", "200", "--seed", str(seed), "--out",
                     str(root / name), "--quiet"]) == 0
    t = np.arange(50) * 0.1
    t[30:] += 0.05  # a logger that slipped once
    uneven = Recording.from_arrays("usv", t, np.zeros(50), {"psi": np.zeros(50)},
                                   require_uniform=False)
    write_recording(uneven, root / "uneven.csv")
    (root / "no_sidecar.csv").write_text((root / "run.csv").read_text())
    (root / "rep").mkdir()
    return root


@pytest.fixture(scope="module")
def tiny_disk(tmp_path_factory) -> Iterator[Path]:
    """A 64 KiB tmpfs, so that a write fails for want of space."""
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root")
    mount = tmp_path_factory.mktemp("tiny_disk")
    done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(mount)],
                          capture_output=True, text=True)
    if done.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs: {done.stderr.strip()}")
    try:
        yield mount
    finally:
        subprocess.run(["umount", str(mount)], check=True)


def _fill(disk: Path, earlier: dict[str, bytes]) -> None:
    """``disk`` holding only ``earlier`` (name: content) and a ballast that leaves no space."""
    for path in sorted(disk.rglob("*"), reverse=True):
        path.rmdir() if path.is_dir() else path.unlink()
    for name, content in earlier.items():
        (disk / name).parent.mkdir(parents=True, exist_ok=True)
        (disk / name).write_bytes(content)
    with open(disk / "ballast", "wb", buffering=0) as ballast:
        try:
            while True:
                ballast.write(b"\0" * 4096)
        except OSError:  # full
            pass


@dataclasses.dataclass(frozen=True)
class Fault:
    """A command line that must fail cleanly: ``{w}`` the workspace, ``{d}`` the full tmpfs."""

    name: str
    command: str
    #: What the one stderr line says after ``marine CMD: error: ``.
    error: str
    #: Files (under the tmpfs) that exist before and must survive: name -> earlier content.
    earlier: dict[str, str] | None = None
    #: Text the line must not say (a Python-only option, to a command-line user).
    not_said: str | None = None


#: An earlier recording and its sidecar ("workspace": the workspace's file of that name).
EARLIER_RUN = {"run.csv": "workspace", "run.csv.json": "workspace"}
FAULTS = [
    # a full disk: /dev/full where the output may be a device
    Fault("demo --json /dev/full", "demo --seconds 5 --no-plot --json /dev/full",
          f"cannot write /dev/full: {NO_SPACE}"),
    Fault("episode --json /dev/full", "episode USV-v0 --seconds 5 --json /dev/full",
          f"cannot write /dev/full: {NO_SPACE}"),
    Fault("diagnose --json /dev/full", "diagnose {w}/run.csv --quiet --json /dev/full",
          f"cannot write /dev/full: {NO_SPACE}"),
    # a full disk: a tiny tmpfs, with an earlier output in place (replaced with --force)
    Fault("simulate --out CSV", "simulate --steps 2000 --seed 2 --quiet --force --out {d}/run.csv",
          f"cannot write {{d}}/run.csv: {NO_SPACE}", EARLIER_RUN),
    Fault("simulate --out Parquet",
          "simulate --steps 2000 --seed 2 --quiet --force --out {d}/run.parquet",
          f"cannot write {{d}}/run.parquet: {NO_SPACE}", {"run.parquet": "workspace"}),
    Fault("episode --plot", "episode USV-v0 --seconds 20 --force --plot {d}/plot.png",
          f"cannot write {{d}}/plot.png: {NO_SPACE}", {"plot.png": "an earlier figure"}),
    Fault("demo --plot", "demo --seconds 5 --force --plot {d}/plot.png",
          f"cannot write {{d}}/plot.png: {NO_SPACE}", {"plot.png": "an earlier figure"}),
    Fault("diagnose --report", "diagnose {w}/run.csv --quiet --force --report {d}/report",
          "cannot write {d}/report/", {"report/report.md": "# an earlier report\n",
                                       "report/diagnosis.json": "{}\n",
                                       "report/spectra.png": "an earlier figure"}),
    # two outputs of one command on one path: the second would overwrite the first
    Fault("episode --plot X --json X", "episode USV-v0 --plot {w}/same.png --json {w}/same.png",
          "--plot and --json name the same file {w}/same.png"),
    Fault("demo --plot X --json X", "demo --plot {w}/same.png --json {w}/same.png",
          "--plot and --json name the same file {w}/same.png"),
    Fault("reproduce --plot X --json X",
          "reproduce hydrofoil-akf --quick --plot {w}/same.png --json {w}/same.png",
          "--plot and --json name the same file {w}/same.png"),
    Fault("diagnose --json in --report", "diagnose {w}/run.csv --json {w}/rep/diagnosis.json "
          "--report {w}/rep", "--json and --report name the same file {w}/rep/diagnosis.json"),
    # hints speak to command-line users
    Fault("diagnose an uneven record", "diagnose {w}/uneven.csv",
          "resample the record to a uniform time step", not_said="require_uniform"),
    Fault("diagnose a CSV without sidecar", "diagnose {w}/no_sidecar.csv",
          "give --model", not_said="model=..."),
    Fault("diagnose a series by innovations",
          "diagnose {w}/run.csv {w}/run2.csv --quiet --method innovations",
          "use --method free (or auto)", not_said="method='free'"),
    Fault("diagnose one recording twice", "diagnose {w}/run.csv {w}/run.csv --quiet",
          "the same recording is given twice"),
]


@pytest.mark.parametrize("fault", FAULTS, ids=[f.name for f in FAULTS])
def test_a_fault_is_one_line_and_loses_nothing(workspace, request, fault):
    disk = request.getfixturevalue("tiny_disk") if fault.earlier is not None else workspace
    if fault.earlier is not None:
        sources = {"run.csv": workspace / "run.csv", "run.csv.json": workspace / "run.csv.json"}
        if "run.parquet" in fault.earlier:
            parquet = workspace / "run.parquet"
            if not parquet.exists():
                write_recording(read_recording(workspace / "run.csv"), parquet)
            sources["run.parquet"] = parquet
        _fill(disk, {name: sources[name].read_bytes() if text == "workspace" else text.encode()
                     for name, text in fault.earlier.items()})
    before = _snapshot(disk)
    args = fault.command.format(w=workspace, d=disk).split()
    done = marine(*args)
    lines = done.stderr.splitlines()
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1, done.stderr
    assert lines[0].startswith(f"marine {args[0]}: error: ")
    assert fault.error.format(w=workspace, d=disk) in lines[0]
    if fault.not_said:
        assert fault.not_said not in lines[0]
    assert _snapshot(disk) == before  # the earlier files whole, no temporary file, nothing new


def _temporary(out: Path) -> Path | None:
    """The temporary file a run is filling for ``out`` (see marine_envs.files), if any."""
    found = list(out.parent.glob(f".{out.name}.*.part{out.suffix}"))
    return found[0] if found else None


def _wait_for(condition, what: str) -> None:
    deadline = time.monotonic() + TIMEOUT
    while not condition():
        assert time.monotonic() < deadline, f"timed out waiting for {what}"
        time.sleep(0.05)


@pytest.mark.parametrize("stop, code, suffix", [(signal.SIGINT, 130, ".csv"),
                                                (signal.SIGTERM, 143, ".parquet")],
                         ids=["SIGINT-csv", "SIGTERM-parquet"])
def test_a_stopped_simulation_keeps_its_complete_rows(tmp_path, stop, code, suffix):
    out = tmp_path / f"run{suffix}"
    requested = 10_000_000
    run = subprocess.Popen([sys.executable, "-m", "agents.cli", "simulate", "--steps",
                            str(requested), "--seed", "3", "--quiet", "--out", str(out)],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ENV)
    try:
        # rows on disk: a first chunk written (the CSV's header alone is < 100 bytes)
        _wait_for(lambda: run.poll() is not None or (
            (part := _temporary(out)) is not None and part.stat().st_size > 1000),
            "the recording to grow")
        assert run.poll() is None, run.communicate()
        run.send_signal(stop)
        _, err = run.communicate(timeout=TIMEOUT)
    finally:
        run.kill()
    assert run.returncode == code, err
    recording = read_recording(out)
    kept = len(recording.time)
    assert err.splitlines() == [
        f"marine simulate: interrupted by {stop.name} after {kept} of {requested} steps: "
        f"kept {kept} steps in {out}"]
    assert recording.meta["stopped"] == f"interrupted by {stop.name} after {kept} of " \
                                        f"{requested} steps"
    assert recording.meta["steps_requested"] == requested and not recording.meta["terminated"]
    assert np.allclose(np.diff(recording.time), recording.meta["dt"])  # every row, in order
    assert _temporary(out) is None


def test_a_terminated_episode_says_why_it_stopped(tmp_path):
    out = tmp_path / "run.csv"
    done = marine("simulate", "--steps", "2000", "--seed", "0", "--quiet", "--policy", "prbs",
                  "--amplitude", "1", "--hold", "20", "--env-kwargs",
                  '{"hs": 6, "max_roll": 0.1}', "--out", str(out))
    assert done.returncode == 0, done.stderr
    recording = read_recording(out)
    steps = len(recording.time)
    assert steps < 2000 and recording.meta["terminated"]
    (line,) = done.stderr.splitlines()
    assert line.startswith(f"marine simulate: the episode terminated at step {steps} of 2000: "
                           "phi = ")
    assert "left its limits [-5.73, 5.73] deg" in line
    assert recording.meta["stopped"] == line.removeprefix("marine simulate: ")


@pytest.mark.parametrize("args, code", [
    (("envs",), 128 + signal.SIGPIPE),  # the shell's code for a process a closed pipe stopped
    (("--help",), 0), (("--version",), 0),  # argparse drops what it cannot print, and exits
], ids=["envs", "--help", "--version"])
def test_output_into_a_closed_pipe_is_silent(args, code):
    read, write = os.pipe()
    os.close(read)  # the reader is gone before the first line
    try:
        done = subprocess.run([sys.executable, "-m", "agents.cli", *args], stdout=write,
                              stderr=subprocess.PIPE, text=True, env=ENV, timeout=TIMEOUT)
    finally:
        os.close(write)
    assert done.stderr == ""  # no traceback, no "Broken pipe"
    assert done.returncode == code


def test_envs_into_head_prints_one_line_and_no_error():
    done = subprocess.run(f"{sys.executable} -m agents.cli envs | head -1", shell=True,
                          capture_output=True, text=True, env=ENV, timeout=TIMEOUT)
    assert done.stdout == "marine_envs/USV-v0\n" and done.stderr == ""


def test_version_names_the_package():
    done = marine("--version")
    assert done.returncode == 0 and done.stdout == f"marine-envs {marine_envs.__version__}\n"
