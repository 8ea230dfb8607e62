"""The DP supply-vessel model against docs/models.md section 4 and the model protocol."""

import dataclasses
import math

import numpy as np
import pytest
from scipy.linalg import expm
from scipy.signal import lfilter, ss2tf, welch

from marine_envs.models import get_model
from marine_envs.models.base import VehicleModel
from marine_envs.models.dp_vessel import DPVesselModel, DPVesselParams, wf_matrices

# docs/models.md 4.1, printed digits
M_PRINTED = np.array([[6.7644e6, 0, 0], [0, 1.13412e7, -3.401568e7], [0, -3.401568e7, 4.452378e9]])
D_PRINTED = np.array([[7.707105e4, 0, 0], [0, 2.546789e5, -2.034159e6],
                      [0, -6.725849e5, 3.850073e8]])
EIG_PRINTED = np.array([-0.087124, -0.022492, -0.011394])
K_W_PRINTED = np.array([0.6928, 0.6325, 0.02262])  # docs/models.md 4.2 [PROPOSED]

# a state away from the nominal point: heading 1 rad, moving, biased, waves running
X_TEST = np.array([3.0, -2.0, 1.0, 0.8, -0.3, 0.01, 4e4, -2e4, 5e5,
                   0.2, -0.1, 0.003, 0.5, -0.4, 0.02])
U_TEST = np.array([1e5, -5e4, 2e6])


@pytest.fixture(scope="module")
def model():
    return get_model("dp_vessel")


def test_registry_and_protocol(model):
    assert isinstance(model, DPVesselModel) and model.name == "dp_vessel"
    assert len(model.state_names) == len(model.state_units) == 15
    assert len(model.input_names) == len(model.input_units) == 3
    assert len(model.disturbance_names) == len(model.disturbance_units) == 6
    assert model.output_names == model.state_names + ("north", "east", "psi")
    assert len(model.output_units) == 18 and model.output_units[-3:] == ("m", "m", "rad")
    assert not model.is_linear
    low, high = model.u_bounds
    np.testing.assert_array_equal(low, -high)
    assert get_model("dp_vessel", w0=[1.0, 1.0, 1.0]).params.w0 == (1.0, 1.0, 1.0)


def test_mass_and_damping_match_models_md(model):
    p = model.params
    # each printed entry to its printed significant digits
    np.testing.assert_allclose(p.M, M_PRINTED, rtol=5e-7, atol=0)
    np.testing.assert_allclose(p.D, D_PRINTED, rtol=5e-7, atol=0)
    eig = np.sort(np.linalg.eigvals(-np.linalg.solve(p.M, p.D)).real)
    np.testing.assert_allclose(eig, EIG_PRINTED, atol=5e-7)
    np.testing.assert_allclose(p.K_w, K_W_PRINTED, atol=5e-5)


def test_nominal_point_is_an_equilibrium(model):
    np.testing.assert_array_equal(model.x0, np.zeros(15))
    np.testing.assert_array_equal(model.u0, np.zeros(3))
    np.testing.assert_array_equal(model.rhs(model.x0, model.u0, np.zeros(6)), np.zeros(15))


def test_linearisation_at_nominal_point(model):
    A, B, E = model.linearize()
    p = model.params
    Minv = np.linalg.inv(p.M)
    np.testing.assert_allclose(A[0:3, 3:6], np.eye(3), atol=1e-15)  # R(0) = I
    np.testing.assert_allclose(A[3:6, 3:6], -Minv @ p.D, rtol=1e-12)
    np.testing.assert_allclose(A[3:6, 6:9], Minv, rtol=1e-12)  # R(0)^T b
    np.testing.assert_allclose(A[6:9, 6:9], -np.eye(3) / 1000.0, rtol=1e-12)
    np.testing.assert_array_equal(A[9:15, 9:15], p.A_w)
    np.testing.assert_allclose(B[3:6], Minv, rtol=1e-12)
    np.testing.assert_allclose(np.diag(E[6:9, :3]), p.E_b, rtol=1e-12)
    np.testing.assert_array_equal(E[9:15, 3:], p.E_w)
    # and the finite-difference default of the base class agrees
    for exact, numeric in zip((A, B, E), VehicleModel.linearize(model), strict=True):
        np.testing.assert_allclose(numeric, exact, rtol=1e-6, atol=1e-12)


def test_analytic_linearisation_agrees_with_finite_differences_away_from_nominal(model):
    exact = model.linearize(X_TEST, U_TEST)
    numeric = VehicleModel.linearize(model, X_TEST, U_TEST)
    for m_exact, m_numeric in zip(exact, numeric, strict=True):
        np.testing.assert_allclose(m_numeric, m_exact, rtol=1e-6, atol=1e-12)
    A = exact[0]
    c, s = math.cos(1.0), math.sin(1.0)
    np.testing.assert_allclose(A[0:3, 3:6], [[c, -s, 0], [s, c, 0], [0, 0, 1]], atol=1e-15)
    assert A[0, 2] == pytest.approx(-s * 0.8 + c * 0.3)  # d(north_dot)/d(psi) = -s u - c v


def test_wave_frequency_poles(model):
    p = model.params
    poles = np.linalg.eigvals(p.A_w)
    for lam, w0 in zip(p.lambda_, p.w0, strict=True):
        expected = -lam * w0 + 1j * w0 * math.sqrt(1 - lam**2)
        assert np.min(np.abs(poles - expected)) < 1e-12
        assert np.min(np.abs(poles - expected.conjugate())) < 1e-12
    A_w, E_w, C_w = wf_matrices(p.w0, p.lambda_, p.K_w)
    np.testing.assert_array_equal(C_w, np.hstack([np.zeros((3, 3)), np.eye(3)]))
    np.testing.assert_array_equal(E_w[:3], 0)


def test_wave_frequency_peak_at_the_set_frequency_and_rms_on_target(model):
    """WF states driven by held seeded white noise (std 1/sqrt(dt)), exact ZOH discretisation."""
    p = model.params
    dt, duration = 0.1, 20000.0
    n = int(duration / dt)
    augmented = np.zeros((9, 9))
    augmented[:6, :6], augmented[:6, 6:] = p.A_w, p.E_w
    phi = expm(augmented * dt)
    Ad, Bd = phi[:6, :6], phi[:6, 6:]
    noise = np.random.default_rng(3).standard_normal((n, 3)) / math.sqrt(dt)
    for i in range(3):
        dof = [i, i + 3]  # (xi_1, xi_2) of this DOF; the blocks are decoupled
        num, den = ss2tf(Ad[np.ix_(dof, dof)], Bd[dof, i:i + 1], [[0.0, 1.0]], [[0.0]])
        eta_w = lfilter(num[0], den, noise[:, i])[1000:]  # drop a 100 s transient
        f, psd = welch(eta_w, fs=1 / dt, nperseg=2048)
        peak = 2 * math.pi * f[np.argmax(psd)]
        assert abs(peak - p.w0[i]) < 0.05, (model.state_names[12 + i], peak)
        rms = math.sqrt(np.mean(eta_w**2))
        assert rms == pytest.approx(p.sigma_eta[i], rel=0.15)


def test_steady_bias_gives_steady_drift(model):
    """b_north = 1e5 N held (T_b = inf): surge speed b / D11 = 1.2975 m/s at heading 0."""
    frozen = model.with_params(T_b=(math.inf,) * 3)
    np.testing.assert_array_equal(frozen.params.E_b, 0.0)
    b = np.array([1e5, 0.0, 0.0])
    nu = np.linalg.solve(frozen.params.D, b)  # M nu_dot = 0 = R(0)^T b - D nu
    assert nu[0] == pytest.approx(1e5 / 7.707105e4, rel=1e-6)
    assert nu[0] == pytest.approx(1.2975, abs=5e-5)
    np.testing.assert_allclose(nu[1:], 0.0, atol=1e-15)
    x = np.concatenate([[0.0, 0.0, 0.0], nu, b, np.zeros(6)])
    x_dot = frozen.rhs(x, np.zeros(3))
    np.testing.assert_allclose(x_dot[3:], 0.0, atol=1e-15)
    assert x_dot[0] == pytest.approx(nu[0]) and x_dot[1] == 0.0
    # the same NED force at heading 90 deg acts in (negative) sway and still pushes north
    x_turned = x.copy()
    x_turned[2] = math.pi / 2
    x_turned[3:6] = np.linalg.solve(frozen.params.D, [0.0, -1e5, 0.0])
    x_dot = frozen.rhs(x_turned, np.zeros(3))
    np.testing.assert_allclose(x_dot[3:6], 0.0, atol=1e-15)
    assert x_dot[0] == pytest.approx(-x_turned[4]) and x_dot[0] > 0
    assert x_dot[1] == pytest.approx(0.0, abs=1e-12)


def test_thrusters_hold_the_default_bias_at_three_sigma(model):
    """Station keeping (nu = 0) needs tau = -R(psi)^T b; a 3-sigma bias in any heading fits."""
    _, high = model.u_bounds
    for psi in np.linspace(0, 2 * math.pi, 73):
        c, s = math.cos(psi), math.sin(psi)
        for signs in ((1, 1, 1), (1, -1, 1)):
            b = 3 * np.array(model.params.sigma_b) * signs
            tau = -np.array([c * b[0] + s * b[1], -s * b[0] + c * b[1], b[2]])
            assert np.all(np.abs(tau) < 0.6 * high), (psi, tau)
            x = np.zeros(15)
            x[2], x[6:9] = psi, b
            np.testing.assert_allclose(model.rhs(x, tau)[3:6], 0.0, atol=1e-15)


def test_output_is_lf_plus_wf_motion(model):
    y = model.output(X_TEST)
    np.testing.assert_array_equal(y[:15], X_TEST)
    np.testing.assert_array_equal(y[15:], X_TEST[0:3] + X_TEST[12:15])
    batch = np.random.default_rng(1).normal(size=(4, 5, 15))
    out = model.output(batch)
    assert out.shape == (4, 5, 18)
    np.testing.assert_array_equal(out[..., 15:], batch[..., 0:3] + batch[..., 12:15])


def test_batched_rhs_agrees_with_a_loop(model):
    rng = np.random.default_rng(2)
    scale = np.array([10, 10, 3, 2, 1, 0.05, 1e5, 1e5, 1e6, 1, 1, 0.05, 1, 1, 0.05])
    x = rng.normal(size=(1024, 15)) * scale
    u = rng.normal(size=(1024, 3)) * np.array([3e5, 2e5, 5e6])
    d = rng.normal(size=(1024, 6))
    batched = model.rhs(x, u, d)
    loop = np.array([model.rhs(x[i], u[i], d[i]) for i in range(1024)])
    assert np.all(np.abs(batched - loop) <= 1e-12 * np.abs(loop).max(axis=0))  # per state
    # broadcasting: one input for the whole batch, no disturbance
    np.testing.assert_allclose(model.rhs(x, u[0]), model.rhs(x, np.tile(u[0], (1024, 1))),
                               rtol=1e-12)
    assert model.rhs(x.reshape(32, 32, 15), u.reshape(32, 32, 3)).shape == (32, 32, 15)


@pytest.mark.parametrize(("name", "value"), [
    ("L", 0.0), ("m", -1.0), ("g", math.nan),
    ("Mbis", ((1, 0, 0), (0, 1, 0.5), (0, 0.4, 1))),  # not symmetric
    ("Mbis", ((1, 0, 0), (0, 1, 2), (0, 2, 1))),  # indefinite
    ("Mbis", ((1, 0), (0, 1))),  # wrong shape
    ("Dbis", ((-0.1, 0, 0), (0, 0.1, 0), (0, 0, 0.1))),
    ("T_b", (1000.0, 0.0, 1000.0)), ("sigma_b", (1e4, -1.0, 1e5)), ("w0", (1.2, 1.0)),
    ("w0", (1.2, 0.0, 1.05)), ("lambda_", (0.1, 0.1, 1.0)), ("lambda_", (0.0, 0.1, 0.1)),
    ("sigma_eta", (1.0, math.inf, 0.03)), ("tau_max", (6e5, 4e5, 0.0)), ("w0", "fast"),
])
def test_bad_params_raise_naming_the_parameter(model, name, value):
    with pytest.raises(ValueError, match=f"^{name}="):
        model.with_params(**{name: value})
    with pytest.raises(ValueError, match=f"^{name}="):
        DPVesselParams(**{name: value})


def test_params_are_frozen_and_variants_recompute_matrices(model):
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.params.m = 1.0  # type: ignore[misc]
    heavier = model.with_params(m=1.2e7)
    np.testing.assert_allclose(heavier.params.M, 2 * model.params.M)
    # same WF target RMS at a new peak frequency: K_w follows w0
    shifted = model.with_params(w0=(0.6, 0.6, 0.6))
    np.testing.assert_allclose(shifted.params.K_w, np.sqrt(0.24) * np.array(model.params.sigma_eta))
