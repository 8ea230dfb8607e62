"""The hydrofoil model against docs/models.md section 2, and its wave coupling (2.5)."""

import dataclasses
import math

import numpy as np
import pytest
import scipy.linalg

from agents.lqr import lqr_gain
from marine_envs.models import get_model
from marine_envs.models.hydrofoil import HydrofoilModel, HydrofoilParams
from marine_envs.sea import SeaState, WaveRealisation, wave_coupling
from marine_envs.sea.coupling import HydrofoilWaveCoupling

# docs/models.md 2.4, as printed
A_PRINTED = np.array([[0, 0, 1, 0],
                      [0, 0, 0, 1],
                      [-0.05882, -139.67344, -22.84472, -2.42760],
                      [-0.31715, -215.15425, -35.36386, -46.91524]])
B_PRINTED = np.array([[0, 0], [0, 0], [-103.44674, -35.44915], [58.52698, -273.53925]])
E_PRINTED = np.array([[0, 0], [0, 0], [-17.01427, -5.83045], [9.62615, -44.99001]])
E_ETA_PRINTED = np.array([[0, 0], [0, 0], [-0.05476, -0.00405], [-0.12744, -0.18971]])
E_U_PRINTED = np.array([[0, 0], [0, 0], [2.59328, 0.62134], [-1.55341, 4.95867]])
K_PRINTED = np.array([[-0.00102, 1.76250, -0.06278, 6.63080],
                      [0.00097, -9.07009, 0.11474, -30.74975]])
Q_SEED, R_SEED = np.diag([0.0, 100.0, 0.0, 1000.0]), np.eye(2)
HALF_ULP_5 = 5.1e-6  # half a unit in the 5th decimal, the printed precision


def assert_close_per_entry(actual, expected, atol) -> None:
    """Each entry within its own tolerance (half a unit in its last printed digit)."""
    error = np.abs(np.asarray(actual) - expected)
    assert np.all(error <= atol), f"{actual} vs {expected}: errors {error} > {atol}"


def integral(f, x) -> float:
    """Trapezoid rule (np.trapezoid needs numpy >= 2)."""
    return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(x)))


@pytest.fixture(scope="module")
def model():
    return get_model("hydrofoil")


@pytest.fixture(scope="module")
def linear(model):
    return model.linearize()


def test_protocol_and_nominal_point(model):
    assert isinstance(model, HydrofoilModel) and model.name == "hydrofoil"
    assert model.state_names == ("xi", "theta", "xi_dot", "theta_dot")
    assert model.input_names == ("alpha_s1", "alpha_s2")
    assert model.disturbance_names == ("zeta_dot_1", "zeta_dot_2", "eta_1", "eta_2", "u_w1",
                                       "u_w2")
    assert model.state_units == ("m", "rad", "m/s", "rad/s")
    assert model.input_units == ("rad", "rad")
    assert model.disturbance_units == ("m/s", "m/s", "m", "m", "m/s", "m/s")
    assert not model.is_linear
    np.testing.assert_array_equal(model.x0, [-1.04, math.radians(2), 0, 0])
    np.testing.assert_array_equal(model.u0, model.trim.alpha_s0)
    low, high = model.u_bounds
    np.testing.assert_array_equal(high, -low)
    np.testing.assert_allclose(high, np.radians([15, 15]))


def test_trim_matches_models_md(model):
    trim = model.trim
    np.testing.assert_allclose(np.degrees(trim.alpha_s0), [2.36646, 1.05296], rtol=0, atol=5.1e-6)
    assert trim.F0 == pytest.approx(80.513, abs=5.1e-4)
    assert model.F0 == trim.F0
    np.testing.assert_allclose(trim.L, [804.44, 192.74], rtol=0, atol=5.1e-3)
    np.testing.assert_allclose(trim.C_L, [0.28807, 0.20066], rtol=0, atol=5.1e-6)
    np.testing.assert_allclose(trim.D, [46.56, 11.79], rtol=0, atol=5.1e-3)
    assert trim.f == pytest.approx(22.11, abs=5.1e-3)
    np.testing.assert_allclose(trim.h, [0.9518, 0.9937], rtol=0, atol=5.1e-5)
    np.testing.assert_allclose(model.params.lift_curve_slope, [3.79255, 3.76991], atol=5.1e-6)
    # the trim's thrust balance, and equilibrium of rhs at (x0, u0), calm water
    assert trim.F0 * math.cos(model.params.theta0) == pytest.approx(trim.D.sum() + trim.f,
                                                                      rel=1e-12)
    np.testing.assert_allclose(model.rhs(model.x0, model.u0), np.zeros(4), atol=1e-12)
    np.testing.assert_allclose(model.rhs(model.x0, model.u0, np.zeros(6)), np.zeros(4),
                               atol=1e-12)


def test_linearisation_matches_models_md(linear):
    A, B, E = linear
    assert A.shape == (4, 4) and B.shape == (4, 2) and E.shape == (4, 6)
    np.testing.assert_allclose(A, A_PRINTED, rtol=0, atol=HALF_ULP_5)
    np.testing.assert_allclose(B, B_PRINTED, rtol=0, atol=HALF_ULP_5)
    np.testing.assert_allclose(E[:, 0:2], E_PRINTED, rtol=0, atol=HALF_ULP_5)
    np.testing.assert_allclose(E[:, 2:4], E_ETA_PRINTED, rtol=0, atol=HALF_ULP_5)
    np.testing.assert_allclose(E[:, 4:6], E_U_PRINTED, rtol=0, atol=HALF_ULP_5)


def test_open_loop_eigenvalues_one_slow_heave_instability(linear):
    A = linear[0]
    eig = np.linalg.eigvals(A)
    assert np.all(np.abs(eig.imag) < 1e-9)  # all real
    eig = np.sort(eig.real)
    assert_close_per_entry(eig, [-38.744, -31.033, -0.15395, 0.17094],
                           [5.1e-4, 5.1e-4, 5.1e-6, 5.1e-6])
    assert np.sum(eig > 0) == 1


def test_lqr_matches_models_md_and_closes_the_heave_instability(linear):
    A, B, _ = linear
    K = lqr_gain(A, B, Q_SEED, R_SEED)
    np.testing.assert_allclose(K, K_PRINTED, rtol=0, atol=HALF_ULP_5)
    closed = np.linalg.eigvals(A - B @ K)
    assert np.all(np.abs(closed.imag) < 1e-9)
    assert_close_per_entry(np.sort(closed.real), [-8846, -25.25, -0.316, -0.0052],
                           [0.51, 5.1e-3, 5.1e-4, 5.1e-5])
    # the discrete LQR of the ZOH model (a 10 ms control period) also stabilises it
    dt = 0.01
    Kd = lqr_gain(A, B, Q_SEED, R_SEED, dt=dt)
    phi = scipy.linalg.expm(np.block([[A, B], [np.zeros((2, 6))]]) * dt)
    Ad, Bd = phi[:4, :4], phi[:4, 4:]
    assert np.abs(np.linalg.eigvals(Ad)).max() > 1  # open loop: the heave pole
    assert np.abs(np.linalg.eigvals(Ad - Bd @ Kd)).max() < 1


def test_helmbold_lowers_the_control_and_wave_gains_by_eleven_percent(model, linear):
    helmbold = get_model("hydrofoil", lift_slope="helmbold")
    np.testing.assert_allclose(helmbold.params.lift_curve_slope, [3.391, 3.363], atol=5.1e-4)
    # same lift at trim needs the same C_L, hence the same drag and thrust
    np.testing.assert_allclose(helmbold.trim.C_L, model.trim.C_L, rtol=1e-9)
    assert helmbold.trim.F0 == pytest.approx(model.trim.F0, rel=1e-9)
    _, B_h, E_h = helmbold.linearize()
    ratio = helmbold.params.lift_curve_slope / model.params.lift_curve_slope  # per foil
    B, E = linear[1], linear[2]
    np.testing.assert_allclose(B_h[2:] / B[2:], np.tile(ratio, (2, 1)), rtol=1e-6)
    np.testing.assert_allclose(E_h[2:, :2] / E[2:, :2], np.tile(ratio, (2, 1)), rtol=1e-6)
    assert np.all((0.10 < 1 - ratio) & (1 - ratio < 0.12))


def test_rhs_batched_equals_loop(model):
    rng = np.random.default_rng(1234)
    n = 1024
    x = model.x0 + rng.normal(scale=[0.3, 0.05, 0.5, 0.3], size=(n, 4))
    u = model.u0 + rng.normal(scale=0.1, size=(n, 2))  # some beyond the 12 deg stall
    d = rng.normal(scale=[0.3, 0.3, 0.5, 0.5, 0.3, 0.3], size=(n, 6))  # some foils broached
    batched = model.rhs(x, u, d)
    assert batched.shape == (n, 4)
    looped = np.array([model.rhs(x[i], u[i], d[i]) for i in range(n)])
    np.testing.assert_allclose(batched, looped, rtol=0, atol=1e-12)
    # leading axes of any shape, broadcast between x, u and d
    grid = model.rhs(x.reshape(8, 128, 4), model.u0, d.reshape(8, 128, 6)[:, :1])
    assert grid.shape == (8, 128, 4)
    np.testing.assert_allclose(grid[3, 5], model.rhs(x[3 * 128 + 5], model.u0, d[3 * 128]),
                               rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="u must have last axis 2"):
        model.rhs(model.x0, np.zeros(1))


def test_broached_craft_falls(model):
    p, F0 = model.params, model.F0
    x = np.array([-3.0, p.theta0, 0.2, 0.0])  # both foils out of the water: h <= 0
    x_dot = model.rhs(x, model.u0)
    assert x_dot[2] == pytest.approx(p.g - F0 * math.sin(p.theta0) / p.m, rel=1e-14)
    assert x_dot[3] == pytest.approx(p.l3 * F0 / p.J, rel=1e-14)  # only thrust; no strut drag
    assert x_dot[2] > 0  # xi is positive down: the craft drops back into the water
    # a deep trough above the front foil only: the rear foil keeps its trim lift and drag
    trim = model.trim
    d = np.array([0, 0, -2.0, 0, 0, 0])
    x_dot = model.rhs(model.x0, model.u0, d)
    assert x_dot[2] == pytest.approx(p.g - (trim.L[1] + F0 * math.sin(p.theta0)) / p.m, rel=1e-12)
    # mean strut depth (0.95 - 2 + 0.99)/2 < 0: the strut is dry too
    assert x_dot[3] == pytest.approx((-p.l2 * trim.L[1] + p.l3 * F0 - p.l * trim.D[1]) / p.J,
                                     rel=1e-12)


def test_stall_clips_the_angle_of_attack(model):
    theta0 = model.params.theta0
    a, b = (model.rhs(model.x0, [math.radians(deg) - theta0, model.u0[1]]) for deg in (13, 14))
    np.testing.assert_array_equal(a, b)  # both beyond the 12 deg stall
    c = model.rhs(model.x0, [math.radians(11.9) - theta0, model.u0[1]])
    assert c[2] > a[2]  # less lift below stall: the craft is pushed down less


def test_added_mass_option(model):
    p = model.params
    np.testing.assert_allclose(p.foil_added_mass, [19.7, 4.0], atol=0.05)
    heavy = model.with_params(added_mass=True)
    assert heavy.F0 == model.F0  # no effect on the trim
    np.testing.assert_allclose(heavy.rhs(heavy.x0, heavy.u0), np.zeros(4), atol=1e-12)
    # same forces, coupled mass matrix: M_added @ acc_added = diag(m, J) @ acc_plain
    rng = np.random.default_rng(7)
    x = model.x0 + rng.normal(scale=0.05, size=(16, 4))
    u = model.u0 + rng.normal(scale=0.02, size=(16, 2))
    ma, xs = p.foil_added_mass, p.foil_x
    M = np.array([[p.m + ma.sum(), -(ma * xs).sum()], [-(ma * xs).sum(), p.J + ma @ xs**2]])
    plain, added = model.rhs(x, u)[:, 2:], heavy.rhs(x, u)[:, 2:]
    np.testing.assert_allclose(added @ M.T, plain * [p.m, p.J], rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize("name, value", [
    ("m", -1.0), ("J", 0.0), ("chord1", float("nan")), ("U", 0.0), ("CD0", -0.1),
    ("alpha_stall", 2.0), ("alpha_max", 0.0), ("theta0", 1.0), ("l1", -0.2),
    ("lift_slope", "glauert"), ("added_mass", "yes"),
])
def test_bad_parameters_raise_naming_the_parameter(name, value):
    with pytest.raises(ValueError, match=rf"^{name}="):
        get_model("hydrofoil", **{name: value})


def test_parameters_that_cannot_trim_raise():
    with pytest.raises(ValueError, match="xi0"):  # foils above the surface at trim
        get_model("hydrofoil", xi0=-3.0)
    with pytest.raises(ValueError, match="alpha_max"):  # trim foil angle beyond the limit
        get_model("hydrofoil", alpha_max=math.radians(2.0))
    with pytest.raises(ValueError, match="U=1.0"):  # far too slow to fly
        get_model("hydrofoil", U=1.0)


def test_params_are_frozen_and_variants_validated(model):
    with pytest.raises(dataclasses.FrozenInstanceError):
        model.params.m = 1.0  # type: ignore[misc]
    faster = model.with_params(U=7.0)
    assert faster.params.U == 7.0 and model.params.U == 6.08
    assert np.all(faster.u0 < model.u0)  # more dynamic pressure, smaller foil angles
    assert HydrofoilModel(HydrofoilParams()).F0 == model.F0


# -- waves ------------------------------------------------------------------------------------
def test_coupling_transfer_functions(model):
    beta, g = math.radians(120), 9.81
    omega = np.array([0.5, 1.7, 3.0])
    k = omega**2 / g
    rich = HydrofoilWaveCoupling(heading=beta, rich=True)(omega, model)
    assert rich.shape == (3, 6) and rich.dtype == complex
    x, hbar = np.array([0.2, -1.0]), model.trim.h
    for i in range(2):
        travel = np.exp(-1j * k * x[i] * math.cos(beta))
        decay = omega * np.exp(-k * hbar[i])
        np.testing.assert_allclose(rich[:, 2 + i], travel, rtol=1e-14)
        np.testing.assert_allclose(rich[:, i], 1j * decay * travel, rtol=1e-14)
        np.testing.assert_allclose(rich[:, 4 + i], math.cos(beta) * decay * travel, rtol=1e-14)
    lean = HydrofoilWaveCoupling(heading=beta)(omega, model)
    np.testing.assert_array_equal(lean[:, :2], rich[:, :2])
    assert not lean[:, 2:].any()


def test_realised_orbital_velocity_has_the_spectral_rms(model):
    beta, speed = math.radians(120), model.params.U
    sea = SeaState(hs=0.3, tp=None)
    realisation = WaveRealisation(sea, wave_coupling(model, beta), dt=0.01, speed=speed,
                                  heading=beta)
    sample = realisation.sample(60_000, np.random.default_rng(2023))  # 600 s
    assert sample.shape == (60_000, 6)
    assert not sample[:, 2:].any()  # rich=False: no eta, no u_w
    omega = np.linspace(0.01, 40.0, 100_001)
    k = omega**2 / 9.81
    for i, hbar in enumerate(model.trim.h):
        density = sea.density(omega, 0.3) * omega**2 * np.exp(-2 * k * hbar)
        expected = math.sqrt(integral(density, omega))
        rms = math.sqrt(np.mean(sample[:, i] ** 2))
        assert rms == pytest.approx(expected, rel=0.05)
    rich = WaveRealisation(sea, wave_coupling(model, beta, rich=True), dt=0.01, speed=speed,
                           heading=beta).sample(60_000, np.random.default_rng(2023))
    np.testing.assert_allclose(rich[:, :2], sample[:, :2], rtol=0, atol=1e-12)
    eta_rms = np.sqrt(np.mean(rich[:, 2:4] ** 2, axis=0))
    np.testing.assert_allclose(eta_rms, 0.3 / 4, rtol=0.05)  # Hs = 4 sigma
    # u_w = cos(beta) x (the in-phase twin of zeta_dot): RMS ratio |cos(beta)| = 0.5
    np.testing.assert_allclose(np.sqrt(np.mean(rich[:, 4:6] ** 2, axis=0)),
                               0.5 * np.sqrt(np.mean(rich[:, :2] ** 2, axis=0)), rtol=0.05)
