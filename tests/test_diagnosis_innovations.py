"""The innovation sensitivities the diagnosis fits: exact for a linear model."""

import numpy as np
import pytest
from scipy import signal

from estimators.diagnosis.innovations import AR_ORDER, Innovations, _ar_fit, fir
from estimators.diagnosis.residuals import displacements, substeps_for
from estimators.diagnosis.synthetic import synthesize
from estimators.ekf import ExtendedKalmanFilter
from marine_envs.models import get_model
from marine_envs.models.effects import Effect, EffectModel

#: (model, measured channels, process noise per step, the state a constant term is added to,
#: its size, the agreement asked for as a share of the largest change): the USV's roll angle
#: alone, so a roll moment acts on the unmeasured p (linear: exact); the hydrofoil's heave and
#: pitch, with a stiff pitch mode (47 1/s, |lambda| dt = 4.7 at 10 Hz), where a trapezoidal
#: one-step integral of the term is 17 % off (nonlinear: 1.5 %).
CASES = [("usv", ("phi",), [1e-8, 1e-7, 1e-8, 1e-7, 1e-8], "p", 2e-4, 1e-6),
         ("hydrofoil", ("xi", "theta"), [1e-5, 1e-5, 1e-3, 1e-3], "theta_dot", 0.2, 0.03)]


def _run(model, recording, channels, q, target: str, b: float):
    truth = EffectModel(model, [Effect("current", target, {"b": b})])
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


# -- the compiled loops against their numpy references -------------------------------------------
def _random_innovations(rng, T=300, m=3, n=6, n_model=4, ar=True):
    """Closed-loop matrices of a stable random filter (as :meth:`Innovations.from_filter`
    builds them), strided and broadcast like the filter's."""
    def stable(shape):
        a = rng.normal(size=shape)
        return a * 0.9 / np.abs(np.linalg.eigvals(a)).max(axis=-1)[..., None, None]

    Phi = stable((T - 1, n, n))
    K = rng.normal(size=(T, n, m))
    H_raw = np.broadcast_to(rng.normal(size=(m, n)), (T, m, n))
    L_inv = np.tril(rng.normal(size=(T, m, m)))
    taps = np.concatenate([np.ones((m, 1)), 0.3 * rng.normal(size=(m, AR_ORDER))], axis=1)
    return Innovations(nu=rng.normal(size=(T, m)), M=stable((T - 1, n, n)),
                       Gamma=rng.normal(size=(T - 1, n, 2 * n))[:, :, :n],
                       PhiK=Phi @ K[:-1], H=L_inv @ H_raw, L_inv=L_inv, K=K, H_raw=H_raw,
                       Phi=Phi, C=stable((T - 1, n, n)).transpose(0, 2, 1),
                       ar=taps if ar else None, n_model=n_model)


def _whiten_reference(ar, x):
    return x if ar is None else np.stack(
        [signal.lfilter(a, [1.0], x[:, j], axis=0) for j, a in enumerate(ar)], axis=1)


def _response_reference(inn, w=None, v=None):
    """:meth:`Innovations.response` in numpy (batched products, the recursion in Python)."""
    T, m, n = inn.shape
    R = (w if w is not None else v).shape[2]
    drive = np.zeros((T - 1, n, R))
    if w is not None:
        drive += inn.Gamma[:, :, :w.shape[1]] @ w[:-1]
    if v is not None:
        drive -= inn.PhiK @ v[:-1]
    d = np.zeros((T, n, R))
    for k in range(T - 1):
        d[k + 1] = inn.M[k] @ d[k] + drive[k]
    g = inn.H @ d
    if v is not None:
        g += inn.L_inv @ v
    return _whiten_reference(inn.ar, g)


def _shift_reference(inn, w=None, v=None):
    """:meth:`Innovations.smoothed_shift` in numpy."""
    T, m, n = inn.shape
    w = np.zeros((T, n)) if w is None else np.pad(w, [(0, 0), (0, n - w.shape[1])])
    v = np.zeros((T, m)) if v is None else v
    before, after = np.zeros((T, n)), np.zeros((T, n))
    for k in range(T):
        after[k] = before[k] - inn.K[k] @ (inn.H_raw[k] @ before[k] + v[k])
        if k < T - 1:
            before[k + 1] = inn.Phi[k] @ after[k] + inn.Gamma[k] @ w[k]
    smoothed = after.copy()
    for k in range(T - 2, -1, -1):
        smoothed[k] = after[k] + inn.C[k] @ (smoothed[k + 1] - before[k + 1])
    return smoothed[:, :inn.n_model]


def _close(got, want):
    assert np.abs(want).max() > 0
    np.testing.assert_allclose(got, want, rtol=1e-12, atol=1e-12 * np.abs(want).max())


@pytest.mark.parametrize("terms", ["w", "v", "both", "w, no filter"])
def test_compiled_response_equals_its_numpy_reference(terms):
    rng = np.random.default_rng(11)
    inn = _random_innovations(rng, ar=terms != "w, no filter")
    T, m, _ = inn.shape
    w = rng.normal(size=(T, inn.n_model, 7)) if "w" in terms or terms == "both" else None
    v = rng.normal(size=(T, m, 7)) if terms in ("v", "both") else None
    _close(inn.response(w, v), _response_reference(inn, w, v))


@pytest.mark.parametrize("terms", ["w", "v", "both", "none"])
def test_compiled_smoothed_shift_equals_its_numpy_reference(terms):
    rng = np.random.default_rng(12)
    inn = _random_innovations(rng)
    T, m, _ = inn.shape
    w = rng.normal(size=(T, inn.n_model)) if terms in ("w", "both") else None
    v = rng.normal(size=(T, m)) if terms in ("v", "both") else None
    want = _shift_reference(inn, w, v)
    if terms == "none":
        assert not inn.smoothed_shift(w, v).any() and not want.any()
    else:
        _close(inn.smoothed_shift(w, v), want)


def test_compiled_fir_equals_lfilter_and_whitening_keeps_its_input():
    rng = np.random.default_rng(13)
    a = rng.normal(size=(3, AR_ORDER + 1))
    x = rng.normal(size=(500, 3, 4))
    inn = _random_innovations(rng)
    inn.ar = a
    kept = x.copy()
    _close(inn._whiten(x), _whiten_reference(a, x))
    assert np.array_equal(x, kept)
    short = x[:5].copy()  # fewer samples than taps: from rest
    fir(a, short)
    _close(short, _whiten_reference(a, x[:5]))
