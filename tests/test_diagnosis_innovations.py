"""The innovation sensitivities the diagnosis fits: exact for a linear model."""

import numpy as np
import pytest
from scipy import signal

from estimators.diagnosis.innovations import AR_ORDER, Innovations, _ar_fit
from estimators.diagnosis.residuals import displacements, substeps_for
from estimators.diagnosis.synthetic import synthesize
from estimators.ekf import ExtendedKalmanFilter
from marine_envs.models import get_model
from marine_envs.models.effects import Effect, ModelWithEffects

#: (model, measured channels, process noise per step, the state a constant term is added to,
#: its size, the agreement asked for as a share of the largest change): the USV's roll angle
#: alone, so a roll moment acts on the unmeasured p (linear: exact); the hydrofoil's heave and
#: pitch, with a stiff pitch mode (47 1/s, |lambda| dt = 4.7 at 10 Hz), where a trapezoidal
#: one-step integral of the term is 17 % off (nonlinear: 1.5 %).
CASES = [("usv", ("phi",), [1e-8, 1e-7, 1e-8, 1e-7, 1e-8], "p", 2e-4, 1e-6),
         ("hydrofoil", ("xi", "theta"), [1e-5, 1e-5, 1e-3, 1e-3], "theta_dot", 0.2, 0.03)]


def _run(model, recording, channels, q, target: str, b: float):
    truth = ModelWithEffects(model, [Effect("current", target, {"b": b})])
    ekf = ExtendedKalmanFilter.from_model(
        truth, recording.dt, measured=channels, Q=np.diag(q),
        R=np.diag(np.full(len(channels), 1e-6)), x0=model.x0,
        substeps=substeps_for(model, recording.dt))
    return ekf, ekf.filter(recording.inputs, recording.measurements)


@pytest.mark.parametrize(("name", "channels", "q", "target", "b", "share"), CASES)
def test_a_missing_term_changes_the_innovations_as_the_sensitivity_says(name, channels, q,
                                                                         target, b, share):
    model = get_model(name)
    recording = synthesize(model, seed=3, noise=0.05, duration=60, measured=channels)
    ekf, nominal = _run(model, recording, channels, q, target, 0.0)
    innovations = Innovations.from_filter(ekf, nominal, recording.inputs)
    innovations.ar = None  # compare the plain whitened innovations
    nu = (innovations.L_inv @ nominal.innovation[:, 0, :, None])[:, :, 0]
    w = np.zeros((len(recording.time), len(model.state_names), 1))
    w[:, model.state_names.index(target), 0] = 1.0  # a unit term, state units per s
    g = innovations.response(w)[:, :, 0]
    _, shifted = _run(model, recording, channels, q, target, b)  # the model with the term in it
    nu_b = (innovations.L_inv @ shifted.innovation[:, 0, :, None])[:, :, 0]
    assert np.abs(g).max() > 0.5  # the channels see it
    np.testing.assert_allclose(nu_b, nu - b * g, atol=share * np.abs(b * g).max())
    shift = innovations.smoothed_shift(b * w[:, :, 0])
    assert np.all(np.isfinite(shift)) and np.abs(shift).max() > 0


def test_whitening_removes_broad_colour_but_keeps_a_narrow_peak():
    rng = np.random.default_rng(0)
    t = np.arange(6000) * 0.1
    coloured = signal.lfilter([1.0], [1.0, -0.8], rng.standard_normal(t.size))  # AR(1) sea
    a = _ar_fit(coloured, AR_ORDER)
    assert abs(a[1] + 0.8) < 0.1  # the colour is modelled...
    wave = coloured + 2.0 * np.sin(1.0 * t)  # ...a 1 rad/s line on top is not
    _, response = signal.freqz(_ar_fit(wave, AR_ORDER), worN=[1.0 * 0.1])
    _, colour_only = signal.freqz(a, worN=[1.0 * 0.1])
    assert abs(response[0]) > 0.7 * abs(colour_only[0])


def test_restoring_terms_depend_on_positions_and_angles():
    names = {m: get_model(m).state_names for m in ("usv", "hovercraft")}
    assert {names["usv"][i] for i in displacements(get_model("usv"))} == {"psi", "phi"}
    assert {names["hovercraft"][i] for i in displacements(get_model("hovercraft"))} == \
        {"north", "east", "psi"}
