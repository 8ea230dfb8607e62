"""The ``marine`` command line: demo, simulate, episode, envs, and their errors."""

import json

import numpy as np
import pytest

from agents.cli import main
from marine_envs.models import get_model
from marine_envs.recording import read_recording


def test_demo_prints_a_summary_and_writes_a_plot(tmp_path, capsys):
    plot, summary = tmp_path / "demo.png", tmp_path / "demo.json"
    assert main(["demo", "--seconds", "40", "--plot", str(plot), "--json", str(summary)]) == 0
    out = capsys.readouterr().out
    assert "rudder fixed" in out and "LQR on sensors" in out and "reduces RMS roll" in out
    assert plot.stat().st_size > 10_000 and plot.read_bytes()[:4] == b"\x89PNG"
    numbers = json.loads(summary.read_text())
    # rudder-roll stabilisation: the LQR on the raw sensors damps the roll and costs less
    assert numbers["LQR on sensors"]["rms_roll_deg"] < 0.8 * numbers["rudder fixed"][
        "rms_roll_deg"]
    assert numbers["LQR on sensors"]["return"] > numbers["rudder fixed"]["return"]


@pytest.mark.parametrize("suffix, policy", [(".csv", "prbs"), (".parquet", "lqr")])
def test_simulate_writes_a_valid_recording(tmp_path, suffix, policy):
    out = tmp_path / f"run{suffix}"
    args = ["simulate", "--steps", "300", "--seed", "4", "--policy", policy, "--out", str(out),
            "--quiet", "--env-kwargs", '{"hs": 1.5}']
    assert main(args) == 0
    recording = read_recording(out, model="usv")
    assert recording.measured_names == ("r", "psi", "p", "phi")
    assert recording.input_names == ("delta",)
    assert len(recording.time) == 300 and recording.dt == pytest.approx(0.1)
    assert recording.meta["seed"] == 4 and recording.meta["env_kwargs"] == {"hs": 1.5}
    assert recording.params["wn"] == 0.63
    assert np.abs(recording.inputs).max() <= np.radians(35) + 1e-12
    assert np.ptp(recording.inputs) > 0  # excited


def test_simulate_is_reproducible_by_seed(tmp_path):
    paths = [tmp_path / f"{name}.csv" for name in "abc"]
    for path, seed in zip(paths, (1, 1, 2), strict=True):
        main(["simulate", "--steps", "50", "--seed", str(seed), "--out", str(path), "--quiet"])
    a, b, c = (read_recording(p).data.to_numpy() for p in paths)
    np.testing.assert_array_equal(a, b)
    assert not np.array_equal(a, c)


def test_errors_are_reported_without_a_traceback(tmp_path, capsys):
    assert main(["simulate", "--steps", "10", "--out", str(tmp_path / "x.txt"), "--quiet"]) == 2
    assert "suffix" in capsys.readouterr().err
    assert main(["simulate", "--steps", "10", "--out", str(tmp_path / "x.csv"), "--quiet",
                 "--env-kwargs", '{"hs": -2}']) == 2
    assert "hs=-2" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["simulate", "--policy", "bogus", "--out", "x.csv"])


def test_envs_lists_the_environments(capsys):
    assert main(["envs"]) == 0
    out = capsys.readouterr().out
    assert "marine_envs/USV-v0" in out and "r, psi, p, phi" in out
    for name in ("Hydrofoil", "ROV", "DPVessel", "Hovercraft"):
        assert f"marine_envs/{name}-v0" in out


@pytest.mark.parametrize("env, model, channels", [
    ("Hydrofoil", "hydrofoil", ("xi", "theta", "xi_dot", "theta_dot")),
    ("ROV", "rov", ("u", "v", "w", "p", "q", "r", "z", "phi", "theta", "psi")),
    ("DPVessel", "dp_vessel", ("north", "east", "psi")),
    ("Hovercraft", "hovercraft", ("u", "v", "r", "psi")),
])
def test_simulate_records_every_vehicle(tmp_path, env, model, channels):
    out = tmp_path / "run.csv"
    assert main(["simulate", "--env", f"marine_envs/{env}-v0", "--steps", "60", "--seed", "1",
                 "--policy", "sine", "--amplitude", "0.05", "--out", str(out), "--quiet"]) == 0
    recording = read_recording(out)
    assert recording.model == model and recording.measured_names == channels
    assert len(recording.time) == 60 and np.isfinite(recording.measurements).all()
    # the excitation perturbs the nominal input, it does not replace it
    nominal = get_model(model).u0
    assert np.abs(recording.inputs - nominal).max() > 0


def test_episode_prints_rms_errors_and_writes_a_plot(tmp_path, capsys):
    plot = tmp_path / "dp.png"
    assert main(["episode", "marine_envs/DPVessel-v0", "--seconds", "30", "--plot", str(plot),
                 "--json", str(tmp_path / "s.json")]) == 0
    out = capsys.readouterr().out
    assert "rms_north_lf" in out and plot.stat().st_size > 10_000
    summary = json.loads((tmp_path / "s.json").read_text())
    assert summary["seconds"] == pytest.approx(30.0) and summary["failed"] == 0.0
    assert summary["cost"] == pytest.approx(-summary["return"], rel=1e-9)
    with pytest.raises(SystemExit) as stopped:  # argparse's own check, before any work
        main(["episode", "marine_envs/ROV-v0", "--seconds", "-1"])
    assert stopped.value.code == 2
    assert "argument --seconds: -1 is invalid" in capsys.readouterr().err


def test_episode_with_a_kalman_filter_controls_the_dp_vessel_on_its_estimate(tmp_path, capsys):
    """The DP vessel measures LF + WF motion, not states: LQR needs the KF's estimate."""
    out = tmp_path / "s.json"
    assert main(["episode", "marine_envs/DPVessel-v0", "--policy", "lqr", "--estimator", "kf",
                 "--seconds", "100", "--json", str(out)]) == 0
    summary = json.loads(out.read_text())
    assert summary["failed"] == 0.0
    assert 0 < summary["estimation_rms_north_lf"] < 2.0
    assert main(["episode", "marine_envs/DPVessel-v0", "--policy", "lqr"]) == 2
    assert "wrap the environment in an estimator" in capsys.readouterr().err


def test_help_explains_every_command(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    out = capsys.readouterr().out
    for command in ("demo", "simulate", "episode", "reproduce", "envs"):
        assert command in out


def test_lqr_with_a_dither_is_a_closed_loop_identification_experiment(tmp_path, capsys):
    runs = {}
    for name, extra in (("plain", []), ("dithered", ["--amplitude", "0.15", "--hold", "2"])):
        out = tmp_path / f"{name}.csv"
        assert main(["simulate", "--env", "marine_envs/Hovercraft-v0", "--steps", "600",
                     "--seed", "3", "--policy", "lqr", "--out", str(out), "--quiet", *extra]) == 0
        runs[name] = read_recording(out)
    plain, dithered = (runs[k] for k in ("plain", "dithered"))
    rudder = plain.input_names.index("delta")
    # the dither moves every input well beyond what the loop alone does ...
    assert np.all(np.std(dithered.inputs, axis=0) > 2 * np.std(plain.inputs, axis=0))
    # ... while the loop still holds the heading (within 5 deg of the plain run's)
    psi = plain.measured_names.index("psi")
    assert np.abs(dithered.measurements[:, psi] - plain.measurements[:, psi]).max() < np.radians(5)
    assert np.abs(dithered.inputs[:, rudder]).max() <= np.radians(35) + 1e-12
    assert dithered.meta["policy_options"] == {"amplitude": 0.15, "hold": 2.0}
    assert main(["simulate", "--policy", "lqr", "--period", "3", "--steps", "10", "--quiet",
                 "--out", str(tmp_path / "x.csv")]) == 2
    assert "amplitude and hold" in capsys.readouterr().err


def test_simulate_records_named_disturbances(tmp_path, capsys):
    out = tmp_path / "rov.csv"
    assert main(["simulate", "--env", "marine_envs/ROV-v0", "--steps", "20", "--seed", "1",
                 "--policy", "zero", "--disturbances", "s_cmd,current_n", "--quiet",
                 "--out", str(out)]) == 0
    assert "disturbances current_n, s_cmd" in capsys.readouterr().out
    recording = read_recording(out)
    assert recording.disturbance_names == ("current_n", "s_cmd")
    assert recording.data["s_cmd"].iloc[0] == 0.0  # cruise shape at the start
    assert np.ptp(recording.data["current_n"]) > 0  # the env's current, as it flowed
    assert main(["simulate", "--env", "marine_envs/ROV-v0", "--steps", "20", "--quiet",
                 "--disturbances", "wind", "--out", str(tmp_path / "x.csv")]) == 2
    assert "unknown disturbance(s) ['wind']" in capsys.readouterr().err


@pytest.mark.parametrize("suffix", [".csv", ".parquet"])
def test_a_streamed_recording_equals_the_one_made_in_memory(tmp_path, suffix):
    from agents.evaluation import run_episode
    from agents.simulate import _Run, record, simulate

    # chunks of 7 rows: many chunk boundaries, and a last chunk part full
    done = record(tmp_path / f"run{suffix}", "marine_envs/ROV-v0", 60, seed=5,
                  disturbances=["current_n", "s_cmd"], chunk_rows=7)
    streamed = read_recording(done.path)
    in_memory = simulate("marine_envs/ROV-v0", 60, seed=5, disturbances=["current_n", "s_cmd"])
    assert streamed.data.equals(in_memory.data)
    assert streamed.meta == in_memory.meta and streamed.params == in_memory.params
    assert done.steps == 60 and done.signal is None
    assert done.stopped == streamed.meta["stopped"] == "the requested 60 steps were reached"
    assert done.disturbance_names == ("current_n", "s_cmd") == streamed.disturbance_names
    # the rows are what an episode of the same seed saw and did
    run = _Run("marine_envs/ROV-v0", 60, 5, "prbs", None, (), {})
    episode = run_episode(run.env, run.policy, 60, seed=5)
    np.testing.assert_array_equal(streamed.inputs, episode.inputs)
    np.testing.assert_array_equal(streamed.time, episode.time)
