"""Every mistake of issue 25 through the real command line: exit code 2, one line
``marine CMD: error: ...`` on stderr, no traceback, and nothing written or overwritten."""

from __future__ import annotations

import importlib.util
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from agents.cli import main

ROOT = Path(__file__).resolve().parents[1]
USV = "marine_envs/USV-v0"


@pytest.fixture(scope="module")
def workspace(tmp_path_factory) -> Path:
    """Outputs of earlier runs that no mistake may touch: a recording, a training run, a
    report and a figure."""
    root = tmp_path_factory.mktemp("workspace")
    assert main(["simulate", "--steps", "200", "--seed", "1", "--out", str(root / "run.csv"),
                 "--quiet"]) == 0
    run = root / "run"
    (run / "checkpoints").mkdir(parents=True)
    (run / "model.zip").write_bytes(b"an earlier agent")
    (run / "checkpoints" / "model_2000_steps.zip").write_bytes(b"an earlier checkpoint")
    (run / "config.json").write_text(json.dumps({"env_id": USV, "algo": "ppo",
                                                 "hyperparams": {}}))
    (root / "report").mkdir()
    (root / "report" / "report.md").write_text("# an earlier report\n")
    (root / "report" / "spectra.png").write_bytes(b"an earlier figure")
    (root / "figure.png").write_bytes(b"an earlier plot")
    (root / "stray.zip").write_bytes(b"not a model")
    (root / "bad.txt").write_text("time,delta\n0,0\n")
    (root / "bad.yaml").write_text("default: [1\n")
    return root


def _snapshot(root: Path) -> dict[str, bytes | None]:
    return {str(p.relative_to(root)): p.read_bytes() if p.is_file() else None
            for p in sorted(root.rglob("*"))}


def run_cli(args: list[str], capsys) -> tuple[int, str, str]:
    """``marine ARGS`` in this process: exit code, stdout, stderr."""
    try:
        code = main(args)
    except SystemExit as stopped:  # argparse's own errors
        code = stopped.code
    out, err = capsys.readouterr()
    return code, out, err


#: (command line with {w} for the workspace, text the error must contain)
MISTAKES = [
    # unknown environments: gymnasium's 20-line traceback and CartPole's AttributeError before
    ("episode marine_envs/Foo-v0", "'marine_envs/Foo-v0' is not a marine environment"),
    ("episode CartPole-v1", "'CartPole-v1' is not a marine environment: one of "
                            "marine_envs/USV-v0"),
    ("simulate --env marine_envs/Foo-v0 --out {w}/new.csv", "is not a marine environment"),
    ("train marine_envs/Foo-v0 --out {w}/new", "is not a marine environment"),
    # numbers
    ("train USV-v0 --n-envs 0 --out {w}/new", "argument --n-envs: 0 is invalid: an integer >= 1"),
    ("train USV-v0 --timesteps -5 --out {w}/new", "argument --timesteps: -5 is invalid"),
    ("simulate --steps 1 --out {w}/new.csv", "argument --steps: 1 is invalid: an integer >= 2"),
    ("evaluate {w}/run --episodes 0", "argument --episodes: 0 is invalid"),
    ("demo --hs -1", "argument --hs: -1 is invalid: a finite number > 0"),
    ("bench --seeds 0 --out {w}/new", "argument --seeds: 0 is invalid"),
    ("bench --vehicles boat --out {w}/new", "unknown vehicle(s) ['boat']"),
    ("diagnose {w}/run.csv --decimate 0", "argument --decimate: 0 is invalid"),
    ("diagnose {w}/run.csv --start 50 --stop 10", "start < stop"),
    # the DP vessel's time step and set-point, as the other four envs report them
    ('episode DPVessel-v0 --env-kwargs {{"dt":0}}', "dt=0 is invalid"),
    ('episode DPVessel-v0 --env-kwargs {{"dt":-0.1}}', "dt=-0.1 is invalid"),
    ('episode DPVessel-v0 --env-kwargs {{"dt":NaN}}', "dt=nan is invalid"),
    ('episode DPVessel-v0 --env-kwargs {{"dt":100}}', "dt=100 is invalid: RK4"),
    ('episode DPVessel-v0 --env-kwargs {{"setpoint":[0,0,180]}}',
     "setpoint=[0, 0, 180] is invalid: a mapping of north (m), east (m) and psi (rad)"),
    ('simulate --out {w}/new.csv --env-kwargs {{"hss":3}}', "unknown argument(s) ['hss']"),
    ("simulate --out {w}/new.csv --env-kwargs [1]", "a JSON object"),
    # paths
    ("simulate --out /missing/dir/x.csv", "the folder /missing/dir does not exist"),
    ("simulate --out {w}/x.txt", "unsupported recording suffix '.txt'"),
    ("evaluate {w}/missing", "no such run folder or model file"),
    ("evaluate {w}/stray.zip", "is not a model saved by 'marine train'"),
    ("evaluate {w}/run.csv", "is not a model saved by 'marine train'"),
    ("evaluate {w}/report", "is not a 'marine train' folder: no config.json"),
    ("diagnose {w}/missing.csv", "recording not found"),
    ("diagnose {w}/bad.txt", "unsupported recording suffix"),
    ("diagnose {w}/run.csv --params {w}/missing.json", "cannot read it"),
    ("train --resume {w}/missing", "is not a 'marine train' folder"),
    ("train --resume {w}/run --algo sac", "--resume takes the run's settings"),
    ("train USV-v0 --out {w}/new --config {w}/missing.yaml", "--config"),
    ("train USV-v0", "--out DIR are required"),
    ("train USV-v0 --out {w}/new --config {w}/bad.yaml", "bad.yaml: invalid YAML"),
    ("bench --controllers sb3:{w}/missing --out {w}/new", "no such run folder or model file"),
    ("bench --sensors noise=x --out {w}/new", "sensor degradation 'noise=x' is invalid"),
    ("diagnose {w}/run.csv --calibrate nonsense", "calibrate"),
    ("demo --plot {w}/figure.bmpx", "unknown format '.bmpx'"),
    # no silent overwrite: an earlier run, recording, report or figure
    ("train USV-v0 --out {w}/run", "--out {w}/run already holds model.zip, config.json, "
                                   "checkpoints"),
    ("simulate --steps 50 --out {w}/run.csv", "run.csv and {w}/run.csv.json exist: use --force"),
    ("diagnose {w}/run.csv --report {w}/report", "already holds report.md, spectra.png"),
    ("episode USV-v0 --plot {w}/figure.png", "figure.png exists: use --force"),
    ("demo --plot {w}/figure.png", "figure.png exists: use --force"),
    ("evaluate {w}/run --json {w}/run.csv", "run.csv exists: use --force"),
    ("bench --out {w}/run.csv", "is a file, not a folder"),
]


@pytest.mark.parametrize("command, text", MISTAKES, ids=[m[0].split(" {")[0] for m in MISTAKES])
def test_a_mistake_is_one_line_and_writes_nothing(workspace, capsys, command, text):
    before = _snapshot(workspace)
    args = [a.format(w=workspace) for a in command.split()]
    code, out, err = run_cli(args, capsys)
    lines = err.splitlines()
    assert code == 2, (code, err)
    assert len(lines) == 1 and lines[0].startswith(f"marine {args[0]}: error: "), err
    assert text.format(w=workspace) in lines[0]
    assert "Traceback" not in err + out
    assert _snapshot(workspace) == before  # nothing overwritten, no folder created


@pytest.mark.parametrize("extra, module, command, text", [
    ("pd", "cvxpy", "train USV-v0 --estimator pd --out {w}/new",
     '--estimator pd needs cvxpy: pip install "marine-envs[estimators]"'),
    ("pd", "cvxpy", "episode USV-v0 --estimator pd", "--estimator pd needs cvxpy"),
    ("parquet", "pyarrow", "simulate --out {w}/new.parquet",
     'Parquet recordings need pyarrow: pip install "marine-envs[parquet]"'),
])
def test_a_missing_extra_is_named_before_any_work(workspace, capsys, monkeypatch, extra, module,
                                                  command, text):
    find_spec = importlib.util.find_spec
    monkeypatch.setattr(importlib.util, "find_spec",
                        lambda name, *a: None if name == module else find_spec(name, *a))
    before = _snapshot(workspace)
    code, _, err = run_cli([a.format(w=workspace) for a in command.split()], capsys)
    assert code == 2 and len(err.splitlines()) == 1 and text in err
    assert _snapshot(workspace) == before  # no empty output folder left behind


def test_forced_outputs_replace_what_the_command_owns_only(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["simulate", "--steps", "100", "--seed", "1", "--out", str(out), "--quiet"]) == 0
    assert main(["simulate", "--steps", "50", "--seed", "1", "--out", str(out), "--quiet",
                 "--force"]) == 0
    assert len(out.read_text().splitlines()) == 51  # the new recording, whole
    report = tmp_path / "report"
    report.mkdir()
    (report / "finding_3_old_effect.png").write_bytes(b"an earlier run's figure")
    (report / "notes.txt").write_text("the user's own")
    assert main(["diagnose", str(out), "--report", str(report), "--force", "--quiet"]) == 0
    assert not (report / "finding_3_old_effect.png").exists()  # runs never mix
    assert (report / "notes.txt").exists() and (report / "report.md").exists()
    capsys.readouterr()


def test_implausible_values_warn_in_one_line_and_the_work_goes_on(tmp_path, capsys):
    code, out, err = run_cli(["simulate", "--steps", "50", "--seed", "1", "--quiet",
                              "--out", str(tmp_path / "a.csv"), "--env-kwargs",
                              '{"hs": 300}'], capsys)
    assert code == 0 and "wrote" in out
    assert err.splitlines() == ["marine simulate: warning: hs=300 m is 150x the environment's "
                                "default 2 m: far outside the range the model was built for "
                                "(expect a diverging or meaningless run)",
                                "marine simulate: the episode terminated at step 8 of 50: "
                                "phi = -41.05 deg left its limits [-40, 40] deg"]


def test_the_installed_entry_point_reports_the_same_line():
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    done = subprocess.run([sys.executable, "-m", "agents.cli", "episode", "CartPole-v1"],
                          capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 2 and "Traceback" not in done.stderr
    assert done.stderr.splitlines() == [
        "marine episode: error: argument env: 'CartPole-v1' is not a marine environment: one "
        "of marine_envs/USV-v0, marine_envs/Hydrofoil-v0, marine_envs/ROV-v0, "
        "marine_envs/DPVessel-v0, marine_envs/Hovercraft-v0 (see marine episode --help)"]


def test_the_demo_rewrites_its_own_figure_but_not_one_the_user_names(tmp_path, monkeypatch,
                                                                     capsys):
    monkeypatch.chdir(tmp_path)
    for _ in range(2):  # the README's first command, run twice
        assert main(["demo", "--seconds", "5"]) == 0
    assert (tmp_path / "marine_demo.png").stat().st_size > 10_000
    named = tmp_path / "mine.png"
    assert main(["demo", "--seconds", "5", "--plot", str(named)]) == 0
    code, _, err = run_cli(["demo", "--seconds", "5", "--plot", str(named)], capsys)
    assert code == 2 and "mine.png exists: use --force" in err
