"""Plausibility: legal values far outside a model's range warn, impossible ones raise."""

import math
import warnings

import gymnasium as gym
import pytest

import marine_envs  # noqa: F401
from marine_envs.plausibility import PlausibilityWarning


@pytest.mark.parametrize("env", ["USV", "Hydrofoil", "ROV", "DPVessel", "Hovercraft"])
@pytest.mark.parametrize("dt", [0, -0.1, math.nan])
def test_every_env_refuses_a_bad_time_step_by_name(env, dt):
    with pytest.raises(ValueError, match=r"dt=.* is invalid"):
        gym.make(f"marine_envs/{env}-v0", dt=dt)


def test_a_time_step_that_makes_rk4_diverge_is_refused_up_front():
    with pytest.raises(ValueError, match=r"dt=100 is invalid: RK4 .* above dt = 4.63 s"):
        gym.make("marine_envs/DPVessel-v0", dt=100)
    with pytest.raises(ValueError, match=r"hydrofoil model's fastest mode"):
        gym.make("marine_envs/Hydrofoil-v0", dt=0.2)


@pytest.mark.parametrize("kwargs, text", [
    ({"hs": 300}, "hs=300 m is 150x the environment's default 2 m"),
    ({"dt": 100}, "dt=100 s is 1000x the environment's default 0.1 s"),
    ({"wave_heading": 60}, "wave_heading=60 rad is beyond 2 pi: degrees given as rad?"),
])
def test_far_out_arguments_warn_on_make_and_make_vec(kwargs, text):
    with pytest.warns(PlausibilityWarning, match=text):
        gym.make("marine_envs/USV-v0", **kwargs)
    with pytest.warns(PlausibilityWarning, match=text):
        gym.make_vec("marine_envs/USV-v0", num_envs=2, vectorization_mode="vector_entry_point",
                     **kwargs)


def test_defaults_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error", PlausibilityWarning)
        for env_id in marine_envs.ENVIRONMENTS:
            gym.make(env_id)


def test_a_dp_setpoint_that_is_not_a_mapping_names_the_format():
    with pytest.raises(ValueError, match=r"setpoint=\(0, 0, 180\) is invalid: a mapping of "
                                         r"north \(m\), east \(m\) and psi \(rad\)"):
        gym.make("marine_envs/DPVessel-v0", setpoint=(0, 0, 180))
    with pytest.warns(PlausibilityWarning, match="setpoint psi=180 rad is beyond 2 pi"):
        gym.make("marine_envs/DPVessel-v0", setpoint={"psi": 180})


def test_a_heading_in_degrees_is_told_from_one_unwrapped_over_many_turns():
    from pathlib import Path

    import numpy as np

    from agents.simulate import simulate
    from marine_envs.recording import Recording, read_recording

    real = Path(marine_envs.__file__).parent / "data" / "real"
    for path in real.glob("hovercraft_*.csv"):  # up to 19 turns, in rad: plausible
        rec = read_recording(path, require_uniform=False)
        assert np.abs(rec.data["psi"]).max() > 40 and rec.warnings == []
    rec = simulate("marine_envs/USV-v0", 400, seed=1, policy="lqr")
    assert rec.warnings == []
    data = rec.data.assign(psi=np.degrees(rec.data["psi"]))
    (line,) = Recording(data, "usv", rec.params).warnings
    assert line.startswith("psi: turns 5") and "degrees declared as rad" in line
