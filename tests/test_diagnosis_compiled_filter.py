"""The diagnosis's filter and smoother compiled: the same numbers as their numpy references."""

import numpy as np
import pytest

from estimators.diagnosis import residuals
from estimators.diagnosis.innovations import response_loop
from estimators.diagnosis.residuals import AugmentedDynamics, Forcing, compiled_augmented
from estimators.diagnosis.synthetic import synthesize
from estimators.ekf import ExtendedKalmanFilter, FilterResult, SmootherResult, rts_smooth
from marine_envs.models import MeasuredDisturbances, get_model
from marine_envs.models.effects import Effect, EffectModel


def test_compiled_filter_dynamics_of_a_rov_with_a_logged_morph_command_and_a_current():
    # the ROV's morph command among its inputs, its current as the filter's states (the first
    # channel with a steady part), an own forcing in two equations
    rng = np.random.default_rng(1)
    model = MeasuredDisturbances(get_model("rov"), ["s_cmd"])
    own = [Forcing(0, 2.0, 0.1), Forcing(5, 5.0, 0.2)]
    environment = [Forcing(None, 60.0, 0.01, c, (0, 1, 2), 0.04 if c == 0 else 0.0)
                   for c in range(3)]
    dynamics = AugmentedDynamics(model, own, environment)
    made = compiled_augmented(dynamics)
    assert made is not None and made.n == dynamics.width
    z = np.concatenate([model.x0, np.zeros(dynamics.width - len(model.x0))]) \
        + 0.2 * rng.standard_normal((6, dynamics.width))
    u = model.u0 + 0.2 * rng.standard_normal((6, len(model.input_names)))
    u[:, -1] = rng.uniform(0.0, 1.0, 6)  # the morph command
    got = np.empty((6, dynamics.width))
    for b in range(6):
        made.f(z[b], u[b], np.zeros(0), made.constants, got[b])
    want = dynamics.reference(z, u)
    np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-13 * np.abs(want).max())


def test_a_model_without_compiled_equations_has_no_compiled_filter_dynamics():
    model = EffectModel(get_model("usv"), [Effect("current", "r", {"b": 0.01})])
    assert compiled_augmented(AugmentedDynamics(model, [], [])) is None


def test_the_compiled_smoothing_is_the_numpy_one(monkeypatch):
    # a hovercraft record in wind: the smoother with its own forcings and the wind as states,
    # compiled and on the numpy path (the reference)
    model = get_model("hovercraft")
    recording = synthesize(model, duration=40.0, seed=2)
    compiled = residuals.estimate(recording, model)
    monkeypatch.setattr(residuals, "compiled_augmented", lambda dynamics: None)
    reference = residuals.estimate(recording, model)
    assert compiled.forcing and len(compiled.forcing) == len(reference.forcing)
    spread = np.std(reference.x, axis=0) + 1e-12
    assert np.abs((compiled.x - reference.x) / spread).max() < 1e-7
    np.testing.assert_allclose(compiled.innovations.nu, reference.innovations.nu, atol=1e-6)
    for a, b in zip(compiled.forcing, reference.forcing, strict=True):
        assert a.tau == pytest.approx(b.tau, rel=1e-6)
        assert a.variance == pytest.approx(b.variance, rel=1e-6)


def test_the_compiled_rts_recursion_is_the_numpy_one():
    # a filter run of a random stable linear system, smoothed both ways
    rng = np.random.default_rng(3)
    T, N, n = 50, 2, 4
    A = np.eye(n) * 0.9 + 0.05 * rng.standard_normal((n, n))
    ekf = ExtendedKalmanFilter(lambda x, u, th: x @ (A - np.eye(n)).T * 10, np.eye(n)[:2],
                               dt=0.1, Q=np.eye(n) * 1e-3, R=np.eye(2) * 1e-2, n_inputs=1,
                               state_names=list("abcd"), measurement_names=["a", "b"],
                               batch_size=N)
    run = ekf.filter(np.zeros((T, 1)), rng.standard_normal((T, N, 2)))
    compiled = rts_smooth(run)
    nan = FilterResult(**{**run.__dict__, "x": run.x.copy()})
    nan.x[0, 0, 0] = np.nan  # a non-finite run takes the numpy loop: NaNs, not an error
    reference = rts_smooth(nan)
    assert isinstance(compiled, SmootherResult) and np.isnan(reference.x[0, 0, 0])
    np.testing.assert_allclose(compiled.x[1:], reference.x[1:], rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(compiled.P, reference.P, rtol=1e-12, atol=1e-14)


def test_the_response_reads_only_the_states_a_term_enters():
    # w in one equation (as every state candidate): the same response as w spelled out in full
    rng = np.random.default_rng(4)
    T, m, n, R = 30, 2, 5, 3
    M = 0.3 * rng.standard_normal((T - 1, n, n))
    Gamma, PhiK = rng.standard_normal((T - 1, n, n)), rng.standard_normal((T - 1, n, m))
    H, L_inv = rng.standard_normal((T, m, n)), rng.standard_normal((T, m, m))
    ar = np.array([[1.0, -0.5], [1.0, 0.2]])
    w = np.zeros((T, n, R))
    w[:, 2] = rng.standard_normal((T, R))
    v = np.zeros((T, 0, R))
    out = np.empty((T, m, R))
    response_loop(M, Gamma, PhiK, H, L_inv, w, v, ar, out)
    d, want = np.zeros((n, R)), np.empty((T, m, R))
    for k in range(T):
        want[k] = H[k] @ d
        if k < T - 1:
            d = M[k] @ d + Gamma[k] @ w[k]
    want[1:] = want[1:] + ar[:, 1, None] * want[:-1]
    np.testing.assert_allclose(out, want, rtol=1e-12, atol=1e-12)
