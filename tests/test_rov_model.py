"""The ROV model against docs/models.md section 3 and independent reference implementations."""

import dataclasses
import itertools

import numpy as np
import pytest

from marine_envs.models import get_model
from marine_envs.models.integrate import rk4
from marine_envs.models.rov import (
    THRUSTER_ALLOCATION,
    THRUSTER_LIMITS,
    ROVModel,
    ROVParams,
    allocate,
)

# docs/models.md 3.5, printed
B_T_PRINTED = np.array([[1, 1, 0, 0, 0, 0], [0, 0, 1, 1, 0, 0], [0, 0, 0, 0, 1, 1],
                        [0, 0, 0, 0, 0, 0], [0, 0, 0, 0, -0.35, 0.40],
                        [0.10, -0.10, 0.40, -0.45, 0, 0]])
# docs/models.md 3.4 table: name -> (cruise, work)
MORPH_TABLE = {
    "Xuu": (-1.62, -15.30), "Yvv": (-131, -142.33), "Zww": (-131, -139.01),
    "Yrr": (0.632, -6.52), "Zqq": (-0.632, 4.42), "Mww": (3.18, 9.49), "Mqq": (-188, -192.11),
    "Nvv": (-3.18, -12.11), "Nrr": (-94.0, -99.82), "Kpp": (-1.3e-3, -0.214),
    "xG": (0, 0.0480), "yG": (0, 0), "zG": (0.0196, 0.0419),
    "xB": (0, 0.0101), "yB": (0, 0), "zB": (0, 0.0047),
    "Ixx": (0.177, 0.331), "Iyy": (3.45, 5.196), "Izz": (3.45, 5.042),
}
UNCHANGED = {"Yuv": -28.6, "Zuw": -28.6, "Yur": 5.22, "Zuq": -5.22, "Muw": 24.0, "Muq": -2.0,
             "Nuv": -24.0, "Nur": -2.0, "Xwq": -35.5, "Ywp": 35.5, "Zvp": -35.5, "Xvr": 35.5,
             "Xqq": -1.93, "Xrr": -1.93, "Ypq": 1.93, "Zrp": 1.93, "Mvp": -1.93, "Nwp": -1.93,
             "Mrp": 4.86, "Npq": -4.86}
U, W_, Q, THETA, S = 0, 2, 4, 10, 12  # state indices


def hover(s=0.0, speed=0.0):
    x = np.zeros(13)
    x[[U, 8, S]] = speed, 5.0, s
    return x


def skew(a):
    return np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])


def reference_rhs(model, x, u, d):
    """docs/models.md 3.2 written literally with Fossen's matrices, one boat at a time."""
    k = model.params
    s = x[S]
    c = model.coefficients(s)
    nu, (phi, th, psi) = x[:6], x[9:12]
    cf, sf, ct, st, cp, sp = np.cos(phi), np.sin(phi), np.cos(th), np.sin(th), np.cos(psi), \
        np.sin(psi)
    Rx = np.array([[1, 0, 0], [0, cf, -sf], [0, sf, cf]])
    Ry = np.array([[ct, 0, st], [0, 1, 0], [-st, 0, ct]])
    Rz = np.array([[cp, -sp, 0], [sp, cp, 0], [0, 0, 1]])
    R = Rz @ Ry @ Rx
    T = np.array([[1, sf * st / ct, cf * st / ct], [0, cf, -sf], [0, sf / ct, cf / ct]])
    nu_c = R.T @ d[:3]
    ur, vr, wr = nu[:3] - nu_c
    p, q, r = nu[3:]
    r_G = np.array([c["xG"], c["yG"], c["zG"]])
    r_B = np.array([c["xB"], c["yB"], c["zB"]])
    inertia = np.diag([c["Ixx"], c["Iyy"], c["Izz"]])
    M_RB = np.block([[k.m * np.eye(3), -k.m * skew(r_G)], [k.m * skew(r_G), inertia]])
    M_A = -np.array([[k.Xud, 0, 0, 0, 0, 0], [0, k.Yvd, 0, 0, 0, k.Yrd],
                     [0, 0, k.Zwd, 0, k.Zqd, 0], [0, 0, 0, k.Kpd, 0, 0],
                     [0, 0, k.Mwd, 0, k.Mqd, 0], [0, k.Nvd, 0, 0, 0, k.Nrd]])
    w = nu[3:]
    C_RB = np.block([[k.m * skew(w), -k.m * skew(w) @ skew(r_G)],
                     [k.m * skew(r_G) @ skew(w), -skew(inertia @ w)]])
    hyd = np.array([
        c["Xuu"] * ur * abs(ur) + c["Xwq"] * wr * q + c["Xqq"] * q * q + c["Xvr"] * vr * r
        + c["Xrr"] * r * r,
        c["Yvv"] * vr * abs(vr) + c["Yrr"] * r * abs(r) + c["Yuv"] * ur * vr + c["Ywp"] * wr * p
        + c["Yur"] * ur * r + c["Ypq"] * p * q,
        c["Zww"] * wr * abs(wr) + c["Zqq"] * q * abs(q) + c["Zuw"] * ur * wr + c["Zvp"] * vr * p
        + c["Zuq"] * ur * q + c["Zrp"] * r * p,
        c["Kpp"] * p * abs(p),
        c["Mww"] * wr * abs(wr) + c["Mqq"] * q * abs(q) + c["Muw"] * ur * wr + c["Muq"] * ur * q
        + c["Mvp"] * vr * p + c["Mrp"] * r * p,
        c["Nvv"] * vr * abs(vr) + c["Nrr"] * r * abs(r) + c["Nuv"] * ur * vr + c["Nur"] * ur * r
        + c["Nwp"] * wr * p + c["Npq"] * p * q,
    ])
    wb = k.W - k.B
    gx, gy, gz = r_G * k.W - r_B * k.B
    restoring = np.array([-wb * st, wb * ct * sf, wb * ct * cf,
                          gy * ct * cf - gz * ct * sf, -gz * st - gx * ct * cf,
                          gx * ct * sf + gy * st])
    current = -M_A @ np.concatenate([np.cross(w, nu_c), np.zeros(3)])
    nu_dot = np.linalg.solve(M_RB + M_A, -C_RB @ nu + hyd + restoring + u + current)
    return np.concatenate([nu_dot, R @ nu[:3], T @ w, [(d[3] - s) / k.T_m]])


def random_batch(n, seed):
    rng = np.random.default_rng(seed)
    x = np.concatenate([rng.normal(0, [1.0, 0.3, 0.3, 0.3, 0.3, 0.3], (n, 6)),
                        rng.normal(0, 10, (n, 3)), rng.uniform(-np.pi, np.pi, (n, 1)),
                        rng.uniform(-1.3, 1.3, (n, 1)), rng.uniform(-4, 4, (n, 1)),
                        rng.uniform(0, 1, (n, 1))], axis=1)
    x[::4, S] = 0.0  # cruise, work and in-between shapes
    x[1::4, S] = 1.0
    u = rng.normal(0, 10, (n, 6))
    d = np.concatenate([rng.normal(0, 0.5, (n, 3)), rng.uniform(0, 1, (n, 1))], axis=1)
    d[::3, :3] = 0.0  # some boats in still water
    return x, u, d


# -- thrusters -----------------------------------------------------------------------------------
def test_allocation_matrix_matches_models_md():
    np.testing.assert_array_equal(THRUSTER_ALLOCATION, B_T_PRINTED)
    assert np.linalg.matrix_rank(THRUSTER_ALLOCATION) == 5
    assert not THRUSTER_ALLOCATION[3].any()  # no roll authority


def test_input_bounds_are_the_thruster_box_plus_an_idealised_roll_range():
    low, high = ROVModel().u_bounds
    np.testing.assert_allclose(low, [-40, -20, -50, -1, -18.75, -13.5], atol=1e-14)
    np.testing.assert_allclose(high, [60, 20, 50, 1, 18.75, 13.5], atol=1e-14)
    corners = np.array(list(itertools.product(*zip(*THRUSTER_LIMITS, strict=True))))
    reach = corners @ THRUSTER_ALLOCATION.T  # every vertex of the thrust box
    keep = [0, 1, 2, 4, 5]
    np.testing.assert_allclose(reach.min(axis=0)[keep], low[keep], atol=1e-14)
    np.testing.assert_allclose(reach.max(axis=0)[keep], high[keep], atol=1e-14)


def test_allocate_reproduces_feasible_forces_and_saturates():
    rng = np.random.default_rng(3)
    tau = rng.uniform(-3, 3, (4, 5, 6)) @ THRUSTER_ALLOCATION.T
    f = allocate(tau)
    assert f.shape == (4, 5, 6)
    np.testing.assert_allclose(f @ THRUSTER_ALLOCATION.T, tau, atol=1e-12)
    saturated = allocate([1000.0, 0, 0, 5.0, 0, 0])
    np.testing.assert_allclose(saturated, [30, 30, 0, 0, 0, 0], atol=1e-12)


# -- nominal point, parameters, morph ------------------------------------------------------------
def test_equilibrium_at_the_nominal_point():
    model = get_model("rov")
    assert isinstance(model, ROVModel)
    x0, u0 = model.x0, model.u0
    np.testing.assert_allclose(u0, [1.62 * 1.5**2, 0, 299 - 306 + 14, 0, 0, 0], atol=1e-12)
    x_dot = model.rhs(x0, u0)
    np.testing.assert_allclose(x_dot[:6], 0, atol=1e-12)  # zero acceleration
    assert x_dot[6] == pytest.approx(1.5)  # still moving north
    np.testing.assert_allclose(x_dot[7:], 0, atol=1e-12)
    low, high = model.u_bounds
    assert np.all(low <= u0) and np.all(u0 <= high)


def test_coefficients_follow_the_models_md_morph_table():
    model = ROVModel()
    for s, column in ((0.0, 0), (1.0, 1)):
        c = model.coefficients(s)
        for name, values in MORPH_TABLE.items():
            assert c[name] == pytest.approx(values[column], abs=1e-12), (name, s)
        for name, value in UNCHANGED.items():
            assert c[name] == value, name
    half = model.coefficients(0.5)
    for name, (cruise, work) in MORPH_TABLE.items():
        assert half[name] == pytest.approx(0.5 * (cruise + work), abs=1e-12)
    # added mass does not morph; the rigid-body part follows r_G and I_b
    np.testing.assert_allclose(model.mass_matrix(1.0)[:3, :3], model.mass_matrix(0.0)[:3, :3])
    assert model.mass_matrix(1.0)[3, 3] - model.mass_matrix(0.0)[3, 3] == pytest.approx(0.154)


def test_with_params_changes_the_cruise_value_by_its_models_md_name():
    model = ROVModel().with_params(Xuu=-2.0)
    assert model.coefficients(0.0)["Xuu"] == -2.0
    assert model.coefficients(1.0)["Xuu"] == -15.30
    assert model.u0[0] == pytest.approx(2.0 * 1.5**2)
    with pytest.raises(ValueError, match="unknown parameter"):
        ROVModel().with_params(X_uu=-2.0)


@pytest.mark.parametrize(("changes", "name"), [
    ({"m": 0.0}, "m="), ({"W": -1.0}, "W="), ({"Iyy": 0.0}, "Iyy="),
    ({"work_Ixx": -0.1}, "work_Ixx="), ({"T_m": 0.0}, "T_m="), ({"Xuu": 1.0}, "Xuu="),
    ({"work_Nrr": 5.0}, "work_Nrr="), ({"Xud": 0.5}, "Xud="), ({"Zww": float("nan")}, "Zww="),
    ({"K_max": 0.0}, "K_max="), ({"work_zG": 1.0}, "M_RB \\+ M_A at s=1"),
    ({"current_inertia": "water"}, "current_inertia="),
])
def test_bad_parameters_raise_naming_the_parameter(changes, name):
    with pytest.raises(ValueError, match=name):
        dataclasses.replace(ROVParams(), **changes)


def test_work_shape_needs_a_bow_up_pitch_trim():
    model = ROVModel()
    x = hover(s=1.0)
    d = np.array([0, 0, 0, 1.0])
    moment = 0.0480 * 299 - 0.0101 * 306  # x_G W - x_B B = 11.26 N m bow-down
    assert model.forces(x, np.zeros(6), d)[4] == pytest.approx(-moment, abs=1e-12)
    assert model.forces(hover(), np.zeros(6))[4] == 0.0
    trim = model.trim_forces(0.0, s=1.0)
    assert trim[4] == pytest.approx(moment, abs=1e-12)
    np.testing.assert_allclose(model.rhs(x, trim, d)[:6], 0, atol=1e-12)
    # the thrusters can hold it: the vertical tunnels share the pitch moment and buoyancy trim
    from marine_envs.models.rov import THRUSTER_ALLOCATION, THRUSTER_LIMITS, allocate
    forces = allocate(trim)
    assert np.all(forces > THRUSTER_LIMITS[0]) and np.all(forces < THRUSTER_LIMITS[1])
    np.testing.assert_allclose((THRUSTER_ALLOCATION @ forces)[[2, 4]], trim[[2, 4]], atol=1e-9)


# -- equations -----------------------------------------------------------------------------------
def test_forces_match_the_scalar_remus_listing_in_cruise_shape():
    """remus100_withM.m (DSTO/Sgarioto) without fins and propeller, x_G = y_G = 0."""
    model = ROVModel()
    k, c = model.params, model.coefficients(0.0)
    m, zg, W, B = k.m, k.zG, k.W, k.B
    x, _, _ = random_batch(64, seed=4)
    x[:, S] = 0.0
    got = model.forces(x, np.zeros(6))
    for xi, fi in zip(x, got, strict=True):
        u, v, w, p, q, r = xi[:6]
        phi, theta = xi[9:11]
        expected = [
            -(W - B) * np.sin(theta) + c["Xuu"] * u * abs(u) + (c["Xwq"] - m) * w * q
            + c["Xqq"] * q**2 + (c["Xvr"] + m) * v * r + c["Xrr"] * r**2 - m * zg * p * r,
            (W - B) * np.cos(theta) * np.sin(phi) + c["Yvv"] * v * abs(v) + c["Yrr"] * r * abs(r)
            + c["Yuv"] * u * v + (c["Ywp"] + m) * w * p + (c["Yur"] - m) * u * r
            - m * zg * q * r + c["Ypq"] * p * q,
            (W - B) * np.cos(theta) * np.cos(phi) + c["Zww"] * w * abs(w) + c["Zqq"] * q * abs(q)
            + c["Zuw"] * u * w + (c["Zuq"] + m) * u * q + (c["Zvp"] - m) * v * p
            + m * zg * p**2 + m * zg * q**2 + c["Zrp"] * r * p,
            -(zg * W) * np.cos(theta) * np.sin(phi) + c["Kpp"] * p * abs(p)
            - (k.Izz - k.Iyy) * q * r - m * zg * w * p + m * zg * u * r,
            -(zg * W) * np.sin(theta) + c["Mww"] * w * abs(w) + c["Mqq"] * q * abs(q)
            + (c["Mrp"] - (k.Ixx - k.Izz)) * r * p + m * zg * v * r - m * zg * w * q
            + c["Muq"] * u * q + c["Muw"] * u * w + c["Mvp"] * v * p,
            c["Nvv"] * v * abs(v) + c["Nrr"] * r * abs(r) + c["Nuv"] * u * v
            + (c["Npq"] - (k.Iyy - k.Ixx)) * p * q + c["Nwp"] * w * p + c["Nur"] * u * r,
        ]
        np.testing.assert_allclose(fi, expected, rtol=1e-12, atol=1e-11)


@pytest.mark.parametrize("changes", [{}, {"Nvd": 2.5, "Mwd": -1.5}])  # also non-symmetric M_A
def test_rhs_matches_the_literal_matrix_form_with_morph_and_current(changes):
    model = ROVModel().with_params(**changes)
    x, u, d = random_batch(200, seed=5)
    got = model.rhs(x, u, d)
    expected = np.array([reference_rhs(model, *args) for args in zip(x, u, d, strict=True)])
    np.testing.assert_allclose(got, expected, rtol=1e-10, atol=1e-10)
    one = np.array([model.rhs(*args) for args in zip(x[:20], u[:20], d[:20], strict=True)])
    np.testing.assert_allclose(one, expected[:20], rtol=1e-10, atol=1e-10)


def test_ground_current_inertia_drops_exactly_the_added_mass_current_term():
    relative = ROVModel()
    ground = ROVModel(dataclasses.replace(ROVParams(), current_inertia="ground"))
    k = relative.params
    M_A = -np.array([[k.Xud, 0, 0], [0, k.Yvd, 0], [0, 0, k.Zwd],
                     [0, 0, 0], [0, 0, k.Mwd], [0, k.Nvd, 0]])  # columns u, v, w of M_A
    x, u, d = random_batch(50, seed=6)
    diff = relative.forces(x, u, d) - ground.forces(x, u, d)
    for xi, di, fi in zip(x, d, diff, strict=True):
        phi, th, psi = xi[9:12]
        R = (np.array([[np.cos(psi), -np.sin(psi), 0], [np.sin(psi), np.cos(psi), 0], [0, 0, 1]])
             @ np.array([[np.cos(th), 0, np.sin(th)], [0, 1, 0], [-np.sin(th), 0, np.cos(th)]])
             @ np.array([[1, 0, 0], [0, np.cos(phi), -np.sin(phi)],
                         [0, np.sin(phi), np.cos(phi)]]))
        np.testing.assert_allclose(fi, -M_A @ np.cross(xi[3:6], R.T @ di[:3]), atol=1e-12)
    still = d * [0, 0, 0, 1]
    np.testing.assert_allclose(relative.rhs(x, u, still), ground.rhs(x, u, still), atol=1e-13)


def test_batched_rhs_agrees_with_a_per_sample_loop():
    model = ROVModel()
    x, u, d = random_batch(1024, seed=7)
    batched = model.rhs(x, u, d)
    looped = np.array([model.rhs(*args) for args in zip(x, u, d, strict=True)])
    np.testing.assert_allclose(batched, looped, rtol=1e-12, atol=1e-12)
    # the whole batch in cruise shape in still water takes the one-GEMM path
    x[:, S], d[:, :3] = 0.0, 0.0
    batched = model.rhs(x, u, d)
    looped = np.array([model.rhs(*args) for args in zip(x, u, d, strict=True)])
    np.testing.assert_allclose(batched, looped, rtol=1e-12, atol=1e-12)


def test_rhs_broadcasts_over_leading_axes():
    model = ROVModel()
    x, u, d = random_batch(6, seed=8)
    out = model.rhs(x.reshape(2, 3, 13), u[0], None)
    assert out.shape == (2, 3, 13)
    np.testing.assert_allclose(out.reshape(6, 13), model.rhs(x, np.tile(u[0], (6, 1)),
                                                              np.zeros((6, 4))), atol=1e-13)
    with pytest.raises(ValueError, match="last axis 13"):
        model.rhs(np.zeros(12), np.zeros(6))


# -- linearisation and stability -----------------------------------------------------------------
def test_linearize_agrees_with_an_independent_finite_difference():
    model = ROVModel()
    rng = np.random.default_rng(9)
    x0 = hover(s=0.3, speed=1.0) + np.concatenate([rng.normal(0, 0.05, 12), [0]])
    u0 = model.trim_forces(1.0, 0.3) + rng.normal(0, 1, 6)
    A, B, E = model.linearize(x0, u0)
    h = 1e-4  # fourth-order central stencil, one boat at a time
    for args, jac in (((0, x0), A), ((1, u0), B), ((2, np.zeros(4)), E)):
        i, z0 = args
        for j in range(z0.size):
            def f(step, i=i, j=j, z0=z0):
                z = z0.copy()
                z[j] += step
                call = [x0, u0, np.zeros(4)]
                call[i] = z
                return model.rhs(*call)
            column = (8 * (f(h) - f(-h)) - (f(2 * h) - f(-2 * h))) / (12 * h)
            np.testing.assert_allclose(jac[:, j], column, rtol=1e-6, atol=1e-7)
    # the input enters through M(s)^-1 only
    np.testing.assert_allclose(B[:6], np.linalg.inv(model.mass_matrix(0.3)), atol=1e-9)


@pytest.mark.parametrize("s", [0.0, 1.0])
def test_bg_pendulum_at_hover_matches_the_restoring_stiffness(s):
    """At hover Prestero's damping is quadratic: roll and pitch are undamped BG pendulums with
    omega^2 = -eig((M^-1 G)[p, q rows]), G the restoring stiffness of docs/models.md 3.2."""
    model = ROVModel()
    k, c = model.params, model.coefficients(s)
    A, _, _ = model.linearize(hover(s), model.trim_forces(0.0, s))
    wb = k.W - k.B
    gx = c["xG"] * k.W - c["xB"] * k.B
    gz = c["zG"] * k.W - c["zB"] * k.B
    G = np.array([[0, wb, 0, -gz, 0, gx], [-wb, 0, 0, 0, -gz, 0]]).T  # columns: phi, theta
    K = (np.linalg.solve(model.mass_matrix(s), G))[[3, 4]]
    omega = np.sort(np.sqrt(-np.linalg.eigvals(K).real))
    eig = np.linalg.eigvals(A)
    oscillatory = np.sort(eig[eig.imag > 1e-3].imag)
    np.testing.assert_allclose(oscillatory, omega, rtol=1e-6)
    assert np.abs(eig.real).max() < 0.2 + 1e-9  # only the morph lag (-1/T_m) is damped
    # zero up to the central difference of v|v| at 0, which is eps * Yvv
    np.testing.assert_allclose(eig[eig.imag > 1e-3].real, 0, atol=1e-4)
    if s == 0:
        assert omega == pytest.approx([0.852, 5.649], abs=1e-3)


LONGITUDINAL, LATERAL = [0, 2, 4, 10], [1, 3, 5, 9]


def modes(model, speed, s):
    A, _, _ = model.linearize(hover(s, speed), model.trim_forces(speed, s))
    lon = np.linalg.eigvals(A[np.ix_(LONGITUDINAL, LONGITUDINAL)])
    lat = np.linalg.eigvals(A[np.ix_(LATERAL, LATERAL)])
    roll = lat[np.argmax(np.abs(lat.imag))]  # the BG roll pendulum, ~5.6 rad/s
    return lon, lat, roll


@pytest.mark.parametrize("s", [0.0, 1.0])
def test_roll_and_pitch_are_stable_at_low_speed(s):
    lon, _, roll = modes(ROVModel(), 0.3, s)
    assert np.all(lon.real < 0)  # surge, heave and the damped pitch pendulum
    assert roll.real < 0 and abs(roll.imag) > 5


def test_munk_moments_destabilise_pitch_and_yaw_at_cruise_speed():
    """A property of Prestero's combined coefficients (Muw > 0, Nuv < 0; see module docstring):
    pinned here so that a change of coefficients is noticed."""
    lon, lat, roll = modes(ROVModel(), 1.5, 0.0)
    assert roll.real < 0
    assert lon.real.max() == pytest.approx(0.4162, abs=1e-3)
    assert lat.real.max() == pytest.approx(1.0092, abs=1e-3)


# -- simulations ---------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def simulation():
    """One RK4 run (dt = 0.1 s, 200 s) of four boats: surge thrust X = 10 N in cruise and in work
    shape (pitch held by a PD loop: pitch is Munk-unstable above 0.6 m/s), a neutrally trimmed
    boat in a current, and a morph from cruise to work shape at hover."""
    model = ROVModel()
    dt, steps = 0.1, 2000
    x = np.array([hover(0.0), hover(1.0), hover(0.0), hover(0.0)])
    d = np.array([[0, 0, 0, 0.0], [0, 0, 0, 1.0], [0.3, 0.2, 0, 0.0], [0, 0, 0, 1.0]])
    trim = np.array([model.trim_forces(0.0, s) for s in (0.0, 1.0)])
    current = np.array([0.3, 0.2, 0.0])

    def control(x):
        u = trim[[0, 1, 0, 0]]
        u[3] += x[3, S] * (trim[1] - trim[0])  # the morphing boat's trim follows its shape
        u[:2, 0] = 10.0
        u[:2, 4] -= 200.0 * x[:2, THETA] + 100.0 * x[:2, Q]
        return u

    def relative_speed(x):
        return np.linalg.norm(model.rhs(x[2], control(x)[2], d[2])[6:9] - current)

    record = {"s_at_T_m": None, "relative": [relative_speed(x)]}
    for i in range(1, steps + 1):
        u = control(x)
        x = rk4(lambda z, _t, u=u: model.rhs(z, u, d), x, dt)
        if i * dt == pytest.approx(model.params.T_m):
            record["s_at_T_m"] = x[3, S]
        if i % 400 == 0:
            record["relative"].append(relative_speed(x))
    record["final"] = x
    return record


def test_terminal_speed_under_constant_surge_thrust(simulation):
    cruise, work = simulation["final"][:2, U]
    assert cruise == pytest.approx(np.sqrt(10 / 1.62), rel=1e-3)  # 2.48 m/s
    assert work == pytest.approx(np.sqrt(10 / 15.30), rel=1e-3)  # 0.81 m/s: the arm's drag
    np.testing.assert_allclose(simulation["final"][:2, [1, 2, 3, 4, 5]], 0, atol=1e-6)


def test_morph_follows_the_command_with_time_constant_t_m(simulation):
    assert simulation["s_at_T_m"] == pytest.approx(1 - np.exp(-1), abs=1e-8)
    assert simulation["final"][3, S] == pytest.approx(1 - np.exp(-200 / 5.0), abs=1e-8)


def test_drifting_boat_settles_to_the_current(simulation):
    relative = np.array(simulation["relative"])  # |NED velocity - current| every 40 s
    assert relative[0] == pytest.approx(np.hypot(0.3, 0.2))
    assert np.all(np.diff(relative) < 0)
    assert relative[-1] < 0.1 * relative[0]
