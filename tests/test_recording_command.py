"""A recording holds the command, as a trial's log does, and optionally an actuator position
sensor (``<input>_applied``); the diagnosis reads an actuator effect off the pair (issue 57
item 6)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import marine_envs  # noqa: F401  (registers the environments)
from agents.cli import main
from agents.simulate import simulate
from estimators.diagnosis import actuators, diagnose
from estimators.diagnosis.residuals import model_inputs
from estimators.diagnosis.selection import DiagnosisConfig
from marine_envs.models import get_model
from marine_envs.models.effects import INPUT_EFFECTS, rate_limited
from marine_envs.recording import Recording, read_recording, write_recording

USV = "marine_envs/USV-v0"
RATE = 0.05  # rad/s: far slower than the autopilot's rudder moves
RATE_LIMIT = [{"effect": "input_rate_limit", "target": "delta", "parameters": {"rate": RATE}}]


@pytest.fixture(scope="module")
def rate_limited_record() -> Recording:
    """150 s of the USV under its dithered autopilot with a rate-limited rudder, the rudder's
    position recorded by an ideal sensor."""
    return simulate(USV, 1500, seed=4, policy="lqr", amplitude=0.15,
                    env_kwargs={"effects": RATE_LIMIT}, actuator_sensors=True)


def test_the_command_is_what_the_controller_asked_the_position_is_rate_limited(
        rate_limited_record):
    rec = rate_limited_record
    commanded, applied = rec.data["delta"].to_numpy(), rec.applied("delta")
    assert rec.actuator_names == ("delta",)
    assert np.max(np.abs(np.diff(commanded))) / rec.dt > 5 * RATE  # asked faster than it can
    assert np.max(np.abs(np.diff(applied))) / rec.dt <= RATE * (1 + 1e-9)
    # the actuator starts at rest and slews towards each command: exactly the catalogue's law
    expected = rate_limited(np.concatenate(([0.0], commanded)), RATE * rec.dt)[1:]
    np.testing.assert_allclose(applied, expected, atol=1e-12)
    assert np.std(commanded - applied) > 0.1 * np.std(commanded)


def test_the_hull_is_diagnosed_on_the_position(rate_limited_record):
    model = get_model("usv")
    u = model_inputs(rate_limited_record, model)
    np.testing.assert_allclose(u[:, 0], rate_limited_record.applied("delta"),
                               atol=1e-6 * np.std(u[:, 0]))


def test_the_diagnosis_names_the_rate_limit_from_command_and_position(rate_limited_record):
    rec = rate_limited_record
    noisy = rec.data.copy()
    noisy["delta_applied"] += 0.003 * np.random.default_rng(0).standard_normal(len(noisy))
    diagnosis = diagnose(Recording(noisy, rec.model, rec.params, rec.meta))
    first = diagnosis.findings[0]
    assert (first.effect, first.target) == ("input_rate_limit", "delta")
    assert first.parameters["rate"] == pytest.approx(RATE, rel=0.05)
    assert first.confidence >= 0.99 and first.improvement > 0.9
    assert diagnosis.mismatch is True
    assert "delta_applied" in first.explanation
    # the rudder's position was recorded: no input effect of it is searched through the hull
    hull = diagnosis.findings[1:] + diagnosis.unconfirmed
    assert not [f for f in hull if f.effect in INPUT_EFFECTS and f.target == "delta"]


def test_no_actuator_effect_where_the_position_follows_the_command():
    rec = simulate(USV, 1500, seed=5, policy="lqr", amplitude=0.15, actuator_sensors=True,
                   actuator_noise=0.003)
    assert np.std(rec.applied("delta") - rec.data["delta"]) == pytest.approx(0.003, rel=0.1)
    found, (hull,) = actuators.judge([rec], get_model("usv"), DiagnosisConfig())
    assert found == []
    # the hull's input is then the command, free of the sensor's noise
    np.testing.assert_array_equal(hull.applied("delta"), rec.data["delta"])


def test_info_holds_the_command_and_the_applied_input():
    saturated = [{"effect": "input_saturation", "target": "delta", "parameters": {"limit": 0.1}}]
    env = gym.make(USV, effects=saturated)
    env.reset(seed=0)
    _, _, _, _, info = env.step(np.array([0.8]))
    assert info["action_commanded"][0] > 0.1 and info["action_applied"][0] == pytest.approx(0.1)
    plain = gym.make(USV)
    plain.reset(seed=0)
    _, _, _, _, info = plain.step(np.array([0.8]))
    np.testing.assert_array_equal(info["action_commanded"], info["action_applied"])
    vector = gym.make_vec(USV, num_envs=2, vectorization_mode="vector_entry_point",
                          effects=saturated)
    vector.reset(seed=0)
    _, _, _, _, info = vector.step(np.array([[0.8], [-0.05]]))
    assert info["action_commanded"].shape == (2, 1) and info["_action_commanded"].all()
    np.testing.assert_allclose(info["action_applied"][:, 0],
                               np.clip(info["action_commanded"][:, 0], -0.1, 0.1))


def test_the_position_column_survives_a_file(tmp_path, rate_limited_record):
    path = write_recording(rate_limited_record, tmp_path / "run.csv")
    back = read_recording(path)
    assert list(back.data.columns[:3]) == ["time", "delta", "delta_applied"]
    assert back.units["delta_applied"] == "rad"
    np.testing.assert_array_equal(back.applied("delta"), rate_limited_record.applied("delta"))
    built = Recording.from_arrays("usv", back.time, back.inputs, {"psi": back.data["psi"]},
                                  applied={"delta": back.applied("delta")})
    assert built.actuator_names == ("delta",)
    with pytest.raises(ValueError, match=r"unknown actuator\(s\) \['rudder'\]"):
        Recording.from_arrays("usv", back.time, back.inputs, {"psi": back.data["psi"]},
                              applied={"rudder": back.applied("delta")})


@pytest.mark.parametrize("kwargs, message", [
    ({"actuator_sensors": ["rudder"]}, r"actuator sensor\(s\) \['rudder'\] are not inputs"),
    ({"actuator_sensors": True, "actuator_noise": -0.1}, "actuator_noise=-0.1 is invalid"),
    ({"actuator_noise": {"delta": 0.1}}, r"names \['delta'\], which have no actuator sensor"),
])
def test_simulate_refuses_a_bad_actuator_sensor(kwargs, message):
    with pytest.raises(ValueError, match=message):
        simulate(USV, 10, seed=0, **kwargs)


def test_the_command_line_records_the_position(tmp_path, capsys):
    out = tmp_path / "run.csv"
    assert main(["simulate", "--steps", "20", "--seed", "0", "--out", str(out), "--quiet",
                 "--actuator-sensors", "--actuator-noise", "0.001"]) == 0
    assert "actuator positions delta_applied" in capsys.readouterr().out
    assert read_recording(out).meta["actuator_noise"] == {"delta": 0.001}
    assert main(["simulate", "--steps", "20", "--out", str(tmp_path / "x.csv"),
                 "--actuator-noise", "0.1"]) == 2
    assert capsys.readouterr().err.strip() == \
        "marine simulate: error: --actuator-noise goes with --actuator-sensors"
