"""Environments with a diagnosis's findings added: the vessel as recorded, to train on."""

from __future__ import annotations

import json
import math

import gymnasium as gym
import numpy as np
import pandas as pd
import pytest

import marine_envs  # noqa: F401  (registers the environments)
from estimators.diagnosis import diagnose
from marine_envs.models.effects import Effect
from marine_envs.recording import Recording
from marine_envs.vessel import read_effects

DAMPING = Effect("quadratic_damping", "p", {"c": -1.0})
#: A lightly damped roll, so that a decay lasts long enough to show how damping grows.
LIGHT = {"waves": False, "params": {"zeta": 0.02}}


def roll_decay(env: gym.Env, phi0: float = math.radians(20), steps: int = 1200) -> Recording:
    """The environment's own record of a free roll decay (rudder held at zero)."""
    obs, info = env.reset(seed=1, options={"state": np.array([0, 0, 0, 0, phi0])})
    channels = env.unwrapped.system.channels
    rows = []
    for k in range(steps):
        rows.append((k * env.unwrapped.dt, 0.0, obs[channels.index("phi")]))
        obs, *_ = env.step(np.zeros(1))
    return Recording(pd.DataFrame(rows, columns=["time", "delta", "phi"]), model="usv")


def test_a_diagnosed_damping_in_the_environment_is_found_again_by_the_diagnosis():
    """Close the loop: an environment given a finding makes records in which the diagnosis
    finds that finding (no sea, the environment's own sensors)."""
    env = gym.make("marine_envs/USV-v0", effects=[DAMPING], **LIGHT)
    diagnosis = diagnose(roll_decay(env), "usv", calibrate="wn,zeta")
    top = diagnosis.findings[0]
    assert (top.effect, top.target) == ("quadratic_damping", "p")
    assert top.parameters["c"] == pytest.approx(-1.0, rel=0.1)
    nominal = diagnose(roll_decay(gym.make("marine_envs/USV-v0", **LIGHT)), "usv",
                       calibrate="wn,zeta")
    assert nominal.mismatch is False and not nominal.findings


def test_effects_come_from_a_diagnosis_json_and_act_on_inputs_and_sensors(tmp_path):
    path = tmp_path / "diagnosis.json"
    findings = [DAMPING.to_dict(), Effect("input_rate_limit", "delta", {"rate": 0.05}).to_dict(),
                Effect("sensor_bias", "phi", {"b": 0.02}).to_dict()]
    path.write_text(json.dumps({"model": "usv", "findings": findings}))
    env = gym.make("marine_envs/USV-v0", effects=str(path), waves=False, noise_std=0.0,
                   quantization=None)
    env.reset(seed=0, options={"state": np.zeros(5)})
    obs, _, _, _, info = env.step(np.ones(1))
    assert info["action_applied"][0] == pytest.approx(0.05 * env.unwrapped.dt)  # slew-limited
    channels = env.unwrapped.system.channels
    assert obs[channels.index("phi")] == pytest.approx(0.02, abs=1e-3)  # the bias, at rest
    vec = gym.make_vec("marine_envs/USV-v0", num_envs=2, vectorization_mode="vector_entry_point",
                       effects=str(path), waves=False)
    vec.reset(seed=0)
    _, _, _, _, info = vec.step(np.ones((2, 1)))
    np.testing.assert_allclose(info["action_applied"][:, 0], 0.05 * vec.unwrapped.dt)


def test_bad_effects_are_refused_naming_the_problem(tmp_path):
    with pytest.raises(ValueError, match="'delta' is not one of the model's inputs"):
        gym.make("marine_envs/ROV-v0", effects=[Effect("input_rate_limit", "delta",
                                                       {"rate": 0.1})])
    with pytest.raises(ValueError, match="not a diagnosis JSON"):
        path = tmp_path / "x.json"
        path.write_text("{}")
        read_effects(str(path))
    with pytest.raises(ValueError, match="only time-invariant state effects"):
        gym.make("marine_envs/USV-v0", effects=[Effect("parameter_change", "p",
                                                       {"time": 5.0, "c": 0.1})])
