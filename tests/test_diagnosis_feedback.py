"""Input effects under feedback (:mod:`estimators.diagnosis.feedback`): an autopilot's rudder
follows a narrow-band sea, and only the part of it the autopilot did not choose tells a
rudder's gain from the sea."""

from types import SimpleNamespace

import numpy as np
import pytest
from scipy import signal

from estimators.diagnosis import Diagnosis, DiagnosisConfig, Finding, feedback, seaway
from estimators.diagnosis.residuals import Residuals, equation_error, rk4_step
from estimators.diagnosis.synthetic import _gain
from marine_envs.models import get_model
from marine_envs.models.effects import Effect

DT, STEPS = 0.1, 3000


def closed_loop(gain: float, seed: int) -> Residuals:
    """The USV under LQR on its sensors plus a +-2 deg random-step dither, a narrow-band sea
    (a resonator at the roll's natural frequency) in its roll and yaw equations, the rudder
    applied times ``gain``; the "smoothed" states are the true ones, so that the equation
    errors are exactly the sea plus the gain's term."""
    usv = get_model("usv")
    rng = np.random.default_rng(seed)
    wn = usv.params.wn
    b, a = signal.bilinear([2 * 0.05 * wn, 0], [1, 2 * 0.05 * wn, wn**2], fs=1 / DT)
    sea = np.zeros((STEPS, len(usv.state_names)))
    for name, size in (("p", 0.02), ("r", 0.004)):
        sea[:, usv.state_names.index(name)] = size * signal.lfilter(
            b, a, rng.standard_normal(STEPS))
    K = _gain(usv, DT)
    measured = [usv.state_names.index(n) for n in usv.measured_names]
    dither = np.repeat(rng.uniform(-1, 1, STEPS // 20), 20) * 2 * np.pi / 180
    x, u = np.zeros((STEPS, len(usv.state_names))), np.zeros((STEPS, 1))
    for k in range(STEPS - 1):
        seen = np.zeros(len(usv.state_names))
        seen[measured] = x[k, measured] + 1e-4 * rng.standard_normal(len(measured))
        u[k] = -K @ seen + dither[k]
        x[k + 1] = rk4_step(usv, x[k:k + 1], gain * u[k:k + 1], DT)[0] + DT * sea[k]
    y = x[:, measured] + 1e-4 * rng.standard_normal((STEPS, len(measured)))
    return Residuals(usv, DT * np.arange(STEPS), DT, u, y, usv.measured_names, x,
                     np.zeros_like(x), equation_error(usv, x, u, DT), np.full(4, 1e-4),
                     np.ones(len(usv.state_names), bool))


@pytest.mark.parametrize("seed", [0, 1])
def test_a_rudder_that_follows_the_sea_is_not_taken_for_a_rudder_gain(seed):
    check = feedback.check(closed_loop(1.0, seed), Effect("input_gain", "delta", {"k": 0.7}))
    assert not check.holds(alpha=0.01)
    assert abs(check.instrumental) < abs(check.least_squares)  # the sea's share is gone


@pytest.mark.parametrize("seed", [0, 1])
def test_a_real_rudder_gain_holds_on_the_dither(seed):
    check = feedback.check(closed_loop(0.7, seed), Effect("input_gain", "delta", {"k": 0.7}))
    assert check.holds(alpha=0.01)
    assert check.instrumental == pytest.approx(-0.3, abs=0.1)  # k - 1


def test_the_confirmation_withdraws_it_and_says_why():
    res = closed_loop(1.0, seed=0)
    found = SimpleNamespace(effect=Effect("input_gain", "delta", {"k": 0.7}), held_out_p=1e-6,
                            alone=0.2, alone_z=2.0, innovation_gain=0.05)  # the held-out
    # tests passed: the innovations (an actuator effect is judged on them) and the predictions
    why = seaway._unconfirmed_because(found, res, DiagnosisConfig())
    assert why.startswith("the input follows the controller")
    finding = Finding("input_gain", "delta", {"k": 0.7}, {}, 1.0, 0.2, "", withdrawn=why)
    diagnosis = Diagnosis("usv", False, unconfirmed=[finding])
    assert diagnosis.to_dict()["unconfirmed"][0]["withdrawn"] == why
    assert why in diagnosis.summary()
