"""The innovation sensitivities the diagnosis fits: exact for a linear model."""

import numpy as np
from scipy import signal

from estimators.diagnosis.innovations import AR_ORDER, Innovations, _ar_fit
from estimators.diagnosis.residuals import displacements
from estimators.diagnosis.synthetic import synthesize
from estimators.ekf import ExtendedKalmanFilter
from marine_envs.models import get_model

CHANNELS = ("phi",)  # roll angle alone: a roll-moment term acts on the unmeasured p


def _run(model, recording, moment: float):
    ekf = ExtendedKalmanFilter.from_model(
        model, recording.dt, measured=CHANNELS, Q=np.diag([1e-8, 1e-7, 1e-8, 1e-7, 1e-8]),
        R=np.diag([1e-6]), disturbance=[0.0, moment])
    return ekf, ekf.filter(recording.inputs, recording.measurements)


def test_a_missing_term_changes_the_innovations_as_the_sensitivity_says():
    model = get_model("usv")
    recording = synthesize(model, seed=3, noise=0.05, duration=60, measured=CHANNELS)
    ekf, nominal = _run(model, recording, 0.0)
    innovations = Innovations.from_filter(ekf, nominal, recording.dt)
    innovations.ar = None  # compare the plain whitened innovations
    nu = (innovations.L_inv @ nominal.innovation[:, 0, :, None])[:, :, 0]
    w = np.zeros((len(recording.time), 5, 1))
    w[:, 3, 0] = 1.0  # a unit roll moment, rad/s^2, in the p equation
    g = innovations.response(w)[:, :, 0]
    b = 2e-4
    _, shifted = _run(model, recording, b)  # the filter of the model with the moment in it
    nu_b = (innovations.L_inv @ shifted.innovation[:, 0, :, None])[:, :, 0]
    assert np.abs(g).max() > 1.0  # the roll angle sees it
    # to the trapezoidal one-step integral of the term
    np.testing.assert_allclose(nu_b, nu - b * g, atol=1e-3 * np.abs(b * g).max())
    shift = innovations.smoothed_shift(b * w[:, :, 0])
    assert np.all(np.isfinite(shift)) and np.abs(shift[:, 3]).max() > 0


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
