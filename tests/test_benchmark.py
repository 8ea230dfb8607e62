"""The estimator benchmark grid: scores, the ordering theory predicts, resuming, backends."""

import json

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

from agents import benchmark
from agents.benchmark import Grid, ordering, parse_sensor, run_grid, write_outputs, write_report
from agents.episode import run
from agents.evaluation import evaluate

USV = "marine_envs/USV-v0"


def test_a_batch_of_boats_scores_as_single_episodes_with_the_same_seeds():
    rows = evaluate(USV, "lqr", "kf", seeds=range(7, 9), max_episode_steps=200)
    for row in rows:
        single = run(USV, "lqr", seconds=20.0, seed=row["seed"], estimator="kf")
        assert row["cost"] == pytest.approx(-single["return"], rel=1e-9)
        assert row["rms_phi_deg"] == pytest.approx(single["rms_phi_deg"], rel=1e-9)
        assert row["estimation_rms_v"] == pytest.approx(single["estimation_rms_v"], rel=1e-9)


def test_the_true_state_estimator_has_no_estimation_error_and_lqr_beats_doing_nothing():
    true = evaluate(USV, "lqr", "true", seeds=3, max_episode_steps=300)
    nominal = evaluate(USV, "nominal", "true", seeds=3, max_episode_steps=300)
    assert "estimation_rms_phi_deg" not in true[0]
    assert all(t["cost"] < 0.8 * n["cost"] for t, n in zip(true, nominal, strict=True))
    assert nominal[0]["rms_delta_deg"] == 0.0 and nominal[0]["saturated"] == 0.0


@pytest.mark.parametrize(("spec", "message"), [
    ("noise", "kind=level"), ("blur=2", "noise, quant, dropout, delay"),
    ("dropout=1.5", "probability"), ("noise=-1", "kind=level")])
def test_a_bad_sensor_degradation_is_refused_naming_it(spec, message):
    with pytest.raises(ValueError, match=message):
        parse_sensor(spec)


def test_a_sensor_degradation_scales_the_environments_own_noise():
    assert parse_sensor("noise=4+dropout=0.1") == {"noise": 4.0, "dropout": 0.1}
    kwargs = benchmark.sensor_kwargs("noise=4+delay=2", gym.make(USV).unwrapped.system.sensors)
    assert kwargs["noise_std"]["psi"] == pytest.approx(4 * np.radians(0.2))
    assert kwargs["delay"] == 2


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"vehicles": ("submarine",)}, "usv"), ({"estimators": ("ukf",)}, "akf"),
    ({"controllers": ("mpc",)}, "sb3:DIR"), ({"seas": ("storm",)}, "rough"),
    ({"seeds": 0}, "seeds"), ({"seconds": -1.0}, "seconds")])
def test_a_bad_grid_is_refused_naming_the_choices(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Grid(**kwargs)


def test_with_noisy_sensors_the_true_state_beats_the_kf_which_beats_the_raw_sensors(tmp_path):
    """LQG's separation: on the linear vehicles (the USV's and the DP vessel's models are linear),
    once the sensors are noisy enough for filtering to matter, LQR on the Kalman estimate costs
    less than on the raw sensors and more than on the true state."""
    grid = Grid(vehicles=("usv", "dp"), estimators=("true", "raw", "kf"), sensors=("noise=32",),
                seeds=5, seconds=60.0)
    rows = run_grid(grid, tmp_path, workers=1, progress=False)
    order = ordering(rows).set_index("vehicle")
    assert order.loc["usv", "kf<=raw"] and order.loc["usv", "true<=kf"]
    assert order.loc["dp", "true"] < order.loc["dp", "kf"]  # raw: LQR needs the LF position
    assert "LQR on the sensors needs measured states" in \
        rows.set_index(["vehicle", "estimator"]).loc[("dp", "raw"), "status"]


def test_a_rerun_resumes_and_different_settings_are_refused(tmp_path, monkeypatch):
    grid = Grid(vehicles=("usv",), estimators=("true", "pd"), controllers=("lqr", "nominal"),
                seeds=2, seconds=5.0)
    first = run_grid(grid, tmp_path, workers=1, progress=False)
    assert len(first) == 8 and (first["status"] == "ok").all()

    def fail(*args):
        raise AssertionError("a finished cell ran again")

    monkeypatch.setattr(benchmark.run, "run_cell", fail)  # where run_grid looks it up
    again = run_grid(grid, tmp_path, workers=1, progress=False)
    pd.testing.assert_frame_equal(first, again)
    with pytest.raises(ValueError, match="seeds"):
        run_grid(Grid(vehicles=("usv",), seeds=3, seconds=5.0), tmp_path, workers=1,
                 progress=False)


def test_outputs_and_report(tmp_path):
    grid = Grid(vehicles=("usv", "hovercraft"), estimators=("true", "raw", "kf", "pd"),
                controllers=("lqr",), sensors=("default", "noise=4"), seeds=2, seconds=5.0)
    rows = run_grid(grid, tmp_path, workers=1, progress=False)
    written = write_outputs(rows, tmp_path)
    names = {p.name for p in written}
    assert {"rows.csv", "rows.parquet", "summary.md", "cost_by_estimator.png",
            "degradation.png"} <= names
    summary = (tmp_path / "summary.md").read_text()
    assert "| usv | moderate | noise=4 | lqr |" in summary
    assert ("hovercraft / pd / lqr / moderate / default: the USV observer patent's PD observer"
            in summary)
    page = write_report(rows, tmp_path, tmp_path / "report", grid).read_text()
    assert page.count("data:image/png;base64,") == 2 and "<table" in page
    assert pd.read_parquet(tmp_path / "rows.parquet").shape == rows.shape


def test_the_cli_runs_a_grid_with_a_trained_agent_and_writes_json(tmp_path, capsys):
    from agents.cli import main

    out = tmp_path / "bench"
    assert main(["bench", "--vehicles", "usv", "--estimators", "kf", "--controllers", "lqr",
                 "ppo", "--seeds", "2", "--seconds", "5", "--timesteps", "512", "--out",
                 str(out), "--workers", "1", "--quiet", "--json", str(tmp_path / "b.json")]) == 0
    assert "| usv | moderate | default | lqr |" in capsys.readouterr().out
    rows = json.loads((tmp_path / "b.json").read_text())["rows"]
    assert {r["controller"] for r in rows} == {"lqr", "ppo"} and len(rows) == 4
    assert all(r["status"] == "ok" and r["cost"] > 0 for r in rows)
    assert (out / "agents" / "usv-kf-ppo" / "model.zip").exists()
    assert main(["bench", "--sensors", "fog=3", "--out", str(out)]) == 2
    assert "fog=3" in capsys.readouterr().err


def test_a_saved_agent_applies_only_where_it_was_trained(tmp_path):
    from agents.sb3 import train

    train(USV, "ppo", "kf", 256, tmp_path / "agent", n_envs=2, progress_bar=False,
          hyperparams={"n_steps": 128, "batch_size": 64, "n_epochs": 1})
    grid = Grid(vehicles=("usv",), estimators=("kf", "true"),
                controllers=(f"sb3:{tmp_path / 'agent'}",), seeds=2, seconds=5.0)
    rows = run_grid(grid, tmp_path / "bench", workers=1, progress=False).set_index("estimator")
    assert rows.loc["kf", "status"].eq("ok").all()
    assert "trained on marine_envs/USV-v0 behind kf" in rows.loc["true", "status"]


def test_ray_gives_the_local_numbers(tmp_path):
    pytest.importorskip("ray")
    grid = Grid(vehicles=("usv",), estimators=("true", "kf"), controllers=("lqr", "ppo"),
                seeds=2, seconds=5.0, timesteps=256)
    local = run_grid(grid, tmp_path / "local", workers=1, progress=False)
    remote = run_grid(grid, tmp_path / "ray", backend="ray", workers=2, progress=False)
    key = ["vehicle", "estimator", "controller", "seed"]
    pd.testing.assert_frame_equal(local.sort_values(key).reset_index(drop=True),
                                  remote.sort_values(key).reset_index(drop=True))
    assert (local["status"] == "ok").all() and gym.spec("marine_envs/ROV-v0") is not None


def test_the_summary_says_n_a_and_all_failed_rather_than_none_or_a_truncated_cost():
    from agents.benchmark import markdown_summary

    cell = {"vehicle": "usv", "controller": "lqr", "sea": "moderate", "sensor": "default"}
    rows = pd.DataFrame([{**cell, "estimator": estimator, "status": "ok", "seed": seed,
                          "cost": cost + seed, "failed": failed}
                         for estimator, cost, failed in (("true", 10.0, 0.0), ("kf", 5.0, 1.0),
                                                         ("raw", 20.0, 1.0))
                         for seed in (0, 1)])
    text = markdown_summary(rows)
    assert "None" not in text and "nan" not in text
    assert "all 2 failed" in text and "20.5" not in text and "5.5" not in text
    order = ordering(rows).iloc[0]
    assert bool(order["true<=kf"]) is True  # fewer failures rank first, whatever the cost
    assert order["kf<=raw"] is None and np.isnan(order["kf"]) and np.isnan(order["raw"])
    assert "| usv | moderate | default | 10.5 | n/a | n/a | n/a | True |" in text
