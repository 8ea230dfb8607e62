"""The catalogue of effects and the recording generator."""

import numpy as np
import pytest

from estimators.diagnosis.synthetic import synthesize, typical_effect
from marine_envs.models import get_model
from marine_envs.models.effects import (
    CATALOGUE,
    ActuatorStream,
    Effect,
    EffectModel,
    applied_inputs,
    resonator,
)

USV = get_model("usv")


def test_effect_validation_names_the_problem():
    with pytest.raises(ValueError, match="not in the catalogue"):
        Effect("drag", "r", {"c": 1.0})
    with pytest.raises(ValueError, match=r"needs parameter\(s\) \['c'\]"):
        Effect("quadratic_damping", "r", {})
    with pytest.raises(ValueError, match="finite"):
        Effect("current", "r", {"b": float("nan")})
    with pytest.raises(ValueError, match="target 'q'"):
        EffectModel(USV, [Effect("current", "q", {"b": 1.0})])
    with pytest.raises(ValueError, match="neither a state nor an input"):
        EffectModel(USV, [Effect("unlisted", "r", {"expression": "r*zz", "c": 1.0})])


@pytest.mark.parametrize("effect", [
    Effect("input_gain", "delta", {"k": 0.6}),
    Effect("input_delay", "delta", {"tau": 0.35}),
    Effect("input_saturation", "delta", {"limit": 0.1}),
    Effect("input_deadzone", "delta", {"width": 0.05}),
    Effect("input_rate_limit", "delta", {"rate": 0.2}),
])
def test_streamed_actuator_equals_the_whole_sequence(effect):
    rng = np.random.default_rng(0)
    commanded = rng.uniform(-0.3, 0.3, (200, 1))
    stream = ActuatorStream(USV, [effect], dt=0.1)
    streamed = np.array([stream.step(u) for u in commanded])
    np.testing.assert_allclose(streamed, applied_inputs(effect, USV, commanded, 0.1),
                               atol=1e-12)


def test_input_effects_do_what_they_say():
    u = np.linspace(-0.4, 0.4, 81)[:, None]
    assert np.max(np.abs(applied_inputs(Effect("input_saturation", "delta", {"limit": 0.1}),
                                        USV, u, 0.1))) == pytest.approx(0.1)
    dead = applied_inputs(Effect("input_deadzone", "delta", {"width": 0.1}), USV, u, 0.1)
    assert np.all(dead[np.abs(u) <= 0.1] == 0) and dead[-1, 0] == pytest.approx(0.3)
    slew = applied_inputs(Effect("input_rate_limit", "delta", {"rate": 0.05}), USV,
                          np.r_[np.zeros(5), np.ones(20)][:, None], 0.1)
    assert np.max(np.diff(slew[:, 0])) == pytest.approx(0.005)
    late = applied_inputs(Effect("input_delay", "delta", {"tau": 0.5}), USV,
                          np.r_[np.zeros(5), np.ones(20)][:, None], 0.1)
    assert np.flatnonzero(late[:, 0] > 0)[0] == 10


def test_state_terms_enter_the_target_equation_only():
    x = np.array([0.1, 0.02, 0.3, -0.01, 0.05])
    u = np.array([0.1])
    base = USV.rhs(x, u)
    effect = Effect("quadratic_damping", "r", {"c": -2.0})
    change = EffectModel(USV, [effect]).rhs(x, u) - base
    np.testing.assert_allclose(change, [0, -2.0 * 0.02 * 0.02, 0, 0, 0])


def test_resonator_has_its_frequency_and_spread():
    w = resonator(1.2, 0.05, 0.3, 20000, 0.1, np.random.default_rng(1))
    spectrum = np.abs(np.fft.rfft(w)) ** 2
    omega = 2 * np.pi * np.fft.rfftfreq(len(w), 0.1)
    assert np.std(w) == pytest.approx(0.3)
    assert omega[np.argmax(spectrum)] == pytest.approx(1.2, abs=0.08)


def test_synthesize_is_seeded_and_noise_is_a_share_of_each_channel():
    clean = synthesize("usv", duration=120, noise=0.0, seed=3)
    again = synthesize("usv", duration=120, noise=0.0, seed=3)
    noisy = synthesize("usv", duration=120, noise=0.1, seed=3)
    np.testing.assert_array_equal(clean.measurements, again.measurements)
    ratio = np.std(noisy.measurements - clean.measurements, axis=0) / np.std(
        clean.measurements, axis=0)
    np.testing.assert_allclose(ratio, 0.1, rtol=0.15)
    assert clean.measured_names == ("r", "psi", "p", "phi")
    assert np.ptp(clean.inputs) > 0  # closed loop plus dither


@pytest.mark.parametrize("vehicle, targets", [
    ("usv", {"state": "r", "input": "delta", "output": "r", "source": "phi"}),
    ("hydrofoil", {"state": "theta_dot", "input": "alpha_s2", "output": "theta_dot",
                   "source": "xi"}),
])
def test_every_catalogue_entry_can_be_generated(vehicle, targets):
    for name in CATALOGUE:
        kind = "input" if name.startswith("input_") else \
            "output" if name == "sensor_bias" else "state"
        extra = {"source": targets["source"]} if name in ("coupling",
                                                          "nonlinear_restoring") else {}
        if name == "unlisted":
            extra = {"expression": f"{targets['state']}*{targets['source']}"}
        effect = typical_effect(vehicle, name, targets[kind], duration=60, **extra)
        recording = synthesize(vehicle, [effect], duration=60, noise=0.05, seed=1)
        assert np.all(np.isfinite(recording.measurements)), name
        assert recording.meta["effects"][0]["effect"] == name


def test_a_closed_loop_that_loses_the_vehicle_is_refused():
    # the hydrofoil's autopilot cannot fly it on a front flap with 30 % less gain: the craft
    # leaves the water; a record of that is no sea trial (before: heave 1e6 m, recorded)
    weak_front_flap = typical_effect("hydrofoil", "input_gain", "alpha_s1", duration=60)
    with pytest.raises(FloatingPointError, match=r"hydrofoil diverged at t=.*theta_dot"):
        synthesize("hydrofoil", [weak_front_flap], duration=60, noise=0.05, seed=2)


def test_an_effect_changes_the_recording():
    effect = typical_effect("usv", "current", "r", duration=120)
    with_effect = synthesize("usv", [effect], duration=120, noise=0.0, seed=2)
    without = synthesize("usv", duration=120, noise=0.0, seed=2)
    assert not np.allclose(with_effect.measurements, without.measurements)
