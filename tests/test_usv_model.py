"""The USV model against docs/models.md section 1 and the model protocol."""

import dataclasses

import numpy as np
import pytest

from marine_envs.models import USVModel, get_model, model_names
from marine_envs.models.base import VehicleModel

# docs/models.md 1.2, printed to 6 decimals
A_PRINTED = np.array([[-0.100000, 0, 0, 0, 0],
                      [-0.275994, -0.599988, 0, 0, 0],
                      [0, 1, 0, 0, 0],
                      [0.650122, 0, 0, -0.117936, -0.396900],
                      [0, 0, 0, 1, 0]])
B_PRINTED = np.array([0.0078, -0.012660, 0, -0.033816, 0])
D_PRINTED = np.array([[0, 0], [1, 0], [0, 0], [0, 1], [0, 0]])


def test_linearisation_matches_models_md():
    A, B, E = get_model("usv").linearize()
    np.testing.assert_allclose(A, A_PRINTED, atol=5e-7)
    np.testing.assert_allclose(B[:, 0], B_PRINTED, atol=5e-7)
    np.testing.assert_array_equal(E, D_PRINTED)


def test_eigenvalues_and_static_gains_match_models_md():
    model = get_model("usv")
    A, B, _ = model.linearize()
    eig = np.sort_complex(np.linalg.eigvals(A))
    expected = np.sort_complex(np.array([0, -0.1, -0.6, -0.05897 + 0.62723j, -0.05897 - 0.62723j]))
    np.testing.assert_allclose(eig, expected, atol=2e-5)
    # steady state of the subsystem without the heading integrator, per rad of rudder
    keep = [0, 1, 3, 4]
    v, r, p, phi = -np.linalg.solve(A[np.ix_(keep, keep)], B[keep, 0])
    assert v == pytest.approx(0.078, abs=5e-7)
    assert r == pytest.approx(-0.05698, abs=5e-6)
    assert phi == pytest.approx(0.04256, abs=5e-6)
    assert p == pytest.approx(0.0, abs=1e-12)


def test_observable_from_the_measured_channels():
    model = get_model("usv")
    A, _, _ = model.linearize()
    C = model.C
    assert C.shape == (4, 5) and not C[:, 0].any()  # sway speed is not measured
    observability = np.vstack([C @ np.linalg.matrix_power(A, k) for k in range(5)])
    assert np.linalg.matrix_rank(observability) == 5


def test_analytic_linearisation_agrees_with_finite_differences_of_rhs():
    for model in (get_model("usv"), get_model("usv", wave_input="angle", wn=0.9, zeta=0.2)):
        exact = model.linearize()
        numeric = VehicleModel.linearize(model, np.array([0.1, -0.02, 0.3, 0.01, -0.05]),
                                         np.array([0.05]))
        for m_exact, m_numeric in zip(exact, numeric, strict=True):
            np.testing.assert_allclose(m_numeric, m_exact, atol=1e-8)


def test_rhs_is_vectorised_over_leading_axes():
    model = get_model("usv")
    rng = np.random.default_rng(0)
    x, u, d = rng.normal(size=(3, 4, 5)), rng.normal(size=(3, 4, 1)), rng.normal(size=(3, 4, 2))
    batched = model.rhs(x, u, d)
    assert batched.shape == (3, 4, 5)
    looped = np.array([[model.rhs(x[i, j], u[i, j], d[i, j]) for j in range(4)] for i in range(3)])
    np.testing.assert_allclose(batched, looped, rtol=0, atol=1e-15)
    A, B, E = model.linearize()
    np.testing.assert_allclose(batched, x @ A.T + u @ B.T + d @ E.T, atol=1e-14)


def test_disturbance_entry_variants():
    moment = get_model("usv").linearize()[2]
    angle = get_model("usv", wave_input="angle").linearize()[2]
    assert moment[1, 0] == moment[3, 1] == 1  # r_dot and p_dot rows (decision (a))
    assert angle[2, 0] == angle[4, 1] == 1  # psi_dot and phi_dot rows (variant (b))


def test_equilibrium_at_the_nominal_point():
    model = get_model("usv")
    np.testing.assert_array_equal(model.rhs(model.x0, model.u0), np.zeros(5))
    low, high = model.u_bounds
    assert low[0] == -high[0] == pytest.approx(-np.radians(35))


def test_parameters_by_symbol_and_validation():
    model = get_model("usv", wn=0.7, Kdr=-0.03)
    assert model.params.wn == 0.7 and model.params.Kdr == -0.03
    assert get_model("usv").params.wn == 0.63  # the nominal model is untouched
    assert dataclasses.replace(model.params, zeta=0.2).zeta == 0.2
    for name, value in [("wn", -1.0), ("Tr", 0.0), ("zeta", -0.1), ("Kvr", float("nan"))]:
        with pytest.raises(ValueError, match=name):
            get_model("usv", **{name: value})
    with pytest.raises(ValueError, match="unknown parameter.*Kxx"):
        get_model("usv", Kxx=1.0)


def test_get_model_names_and_errors():
    assert "usv" in model_names()
    assert isinstance(get_model("usv"), USVModel)
    with pytest.raises(ValueError, match="unknown model 'ship'"):
        get_model("ship")
    assert set(model_names()) == {"usv", "hydrofoil", "rov", "dp_vessel", "hovercraft",
                                 "nomoto", "mmg"}


def test_rhs_rejects_wrong_shapes():
    with pytest.raises(ValueError, match="x must have last axis 5"):
        get_model("usv").rhs(np.zeros(4), np.zeros(1))


def test_linearized_model_is_the_affine_model_of_the_nonlinear_one():
    from marine_envs.models.base import LinearizedModel

    hovercraft = get_model("hovercraft")
    linear = LinearizedModel(hovercraft)
    assert linear.is_linear and linear.name == "hovercraft"
    assert linear.output_names == hovercraft.output_names
    x, u = hovercraft.x0, hovercraft.u0
    # exact at the point (where a moving craft's position still changes) ...
    np.testing.assert_allclose(linear.rhs(x, u), hovercraft.rhs(x, u), atol=1e-9)
    # ... and first-order accurate near it
    dx = np.array([0.2, 0.05, 0.002, 0.0, 0.0, 0.01])
    err = linear.rhs(x + dx, u) - hovercraft.rhs(x + dx, u)
    err_half = linear.rhs(x + dx / 2, u) - hovercraft.rhs(x + dx / 2, u)
    assert np.abs(err).max() > 0 and np.abs(err_half).max() < 0.3 * np.abs(err).max()
    assert linear.with_params(N_Hr=-1e6).A[2, 2] != linear.A[2, 2]


@pytest.mark.parametrize("names", [("N_Hr", "Y_Hv", "C_R4"), ("T0", "N_Hr"), ("m",)])
def test_rhs_with_replaces_parameters_row_by_row(names):
    """Affine parameters take the fast path, others one model per value; both are exact."""
    model = get_model("hovercraft")
    rng = np.random.default_rng(0)
    x = model.x0 + rng.normal(0, [1, 0.5, 0.02, 0, 0, 0.1], (5, 6))
    u = model.u0 + rng.normal(0, [0.1, 0.1, 0.2], (5, 3))
    values = {n: getattr(model.params, n) * rng.uniform(0.5, 1.5, 5) for n in names}
    got = model.rhs_with(x, u, None, values)
    for i in range(5):
        alone = model.with_params(**{n: v[i] for n, v in values.items()}).rhs(x[i], u[i])
        np.testing.assert_allclose(got[i], alone, rtol=1e-10, atol=1e-12)


def test_rhs_with_refuses_unknown_parameters():
    model = get_model("hovercraft")
    with pytest.raises(ValueError, match="unknown parameter.*N_Xyz"):
        model.rhs_with(model.x0, model.u0, None, {"N_Xyz": 1.0})


def test_parameter_jacobian_is_exact_for_affine_parameters_and_none_otherwise():
    model = get_model("hovercraft")
    x = model.x0 + np.array([0.5, 0.8, 0.03, 0, 0, 0.1])
    u = model.u0 + np.array([0.05, -0.05, 0.2])
    names = ("N_Hr", "N_Hrrr", "C_R4")
    values = {n: 1.2 * getattr(model.params, n) for n in names}
    J = model.parameter_jacobian(x, u, None, values)
    for j, name in enumerate(names):
        h = 1e-4 * abs(values[name])
        plus = model.rhs_with(x, u, None, {**values, name: values[name] + h})
        minus = model.rhs_with(x, u, None, {**values, name: values[name] - h})
        np.testing.assert_allclose(J[:, j], (plus - minus) / (2 * h), rtol=1e-6, atol=1e-15)
    assert model.parameter_jacobian(x, u, None, {"T0": 8e4}) is None
