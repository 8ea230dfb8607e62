"""The first-order Nomoto yaw model (docs/models.md section 7) and the model protocol."""

import math

import numpy as np
import pytest

from marine_envs.manoeuvres import zigzag
from marine_envs.models import get_model
from marine_envs.models.base import LinearizedModel, _jacobian
from marine_envs.models.integrate import ExactStep, rk4
from marine_envs.models.nomoto import NomotoModel, NomotoParams


def test_defaults_names_and_registry():
    model = get_model("nomoto")
    assert isinstance(model, NomotoModel) and model.params == NomotoParams()
    assert (model.params.K, model.params.T, model.params.delta0) == (-0.08, 10.0, 0.0)
    assert model.params.delta_max == pytest.approx(math.radians(35.0))
    assert model.state_names == ("r", "psi") and model.input_names == ("delta",)
    assert model.disturbance_names == ("w_r",) and model.measured_names == ("r", "psi")
    np.testing.assert_array_equal(model.C, np.eye(2))
    assert get_model("nomoto", K=0.1).params.K == 0.1
    assert get_model("nomoto").params.K == -0.08  # the nominal model is untouched


def test_step_response_reaches_k_delta_with_time_constant_t():
    model, delta, dt = get_model("nomoto"), math.radians(10.0), 0.01
    K, T = model.params.K, model.params.T
    x = np.zeros(2)
    x_at_T = rk4(lambda z, _t: model.rhs(z, [delta]), x, dt, int(round(T / dt)))
    assert x_at_T[0] == pytest.approx(K * delta * (1 - math.exp(-1)), rel=0.01)
    x_end = rk4(lambda z, _t: model.rhs(z, [delta]), x_at_T, dt, int(round(10 * T / dt)))
    assert x_end[0] == pytest.approx(K * delta, rel=1e-3)
    assert x_end[0] < 0  # HSVA convention: a positive (port) rudder gives r < 0


@pytest.mark.parametrize("delta0", [0.0, 0.03])
def test_linearize_matches_finite_differences(delta0):
    model = get_model("nomoto", K=0.12, T=7.0, delta0=delta0)
    x0, u0, d0 = np.array([0.02, 0.4]), np.array([0.1]), np.zeros(1)
    A, B, E = model.linearize(x0, u0)
    np.testing.assert_allclose(A, _jacobian(lambda z: model.rhs(z, u0, d0), x0, 1e-6), atol=1e-9)
    np.testing.assert_allclose(B, _jacobian(lambda z: model.rhs(x0, z, d0), u0, 1e-6), atol=1e-9)
    np.testing.assert_allclose(E, _jacobian(lambda z: model.rhs(x0, u0, z), d0, 1e-6), atol=1e-9)
    np.testing.assert_allclose(A, [[-1 / 7.0, 0], [1, 0]])


@pytest.mark.parametrize(("name", "value"), [("T", 0.0), ("T", math.inf), ("T", math.nan),
                                             ("K", 0.0), ("K", math.nan), ("K", math.inf),
                                             ("delta0", math.nan), ("delta_max", 0.0)])
def test_invalid_params_are_refused_naming_the_parameter(name, value):
    with pytest.raises(ValueError, match=f"^{name}="):
        get_model("nomoto", **{name: value})


def test_the_nominal_input_holds_a_straight_course():
    model = get_model("nomoto", delta0=0.05)
    np.testing.assert_allclose(model.u0, [-0.05])
    np.testing.assert_allclose(model.rhs(model.x0, model.u0), 0.0, atol=1e-15)


@pytest.mark.parametrize("delta0", [0.0, 0.04])
def test_exact_step_equals_rk4_with_small_steps(delta0):
    model, dt = get_model("nomoto", delta0=delta0), 0.5
    rng = np.random.default_rng(0)
    x, u, d = rng.normal(0, 0.05, (4, 2)), rng.normal(0, 0.2, (4, 1)), rng.normal(0, 1e-3, (4, 1))
    exact = ExactStep(model, dt)(np.hstack([x, u, d]))
    reference = rk4(lambda z, _t: model.rhs(z, u, d), x, dt / 100, 100)
    np.testing.assert_allclose(exact, reference, rtol=0, atol=1e-12)
    assert (ExactStep(model, dt).offset is None) == (delta0 == 0)  # the affine offset K delta0/T
    # the linearisation about any point is the model itself (it is affine)
    linear = LinearizedModel(model, [0.01, 0.2], [0.1])
    np.testing.assert_allclose(linear.rhs(x, u, d), model.rhs(x, u, d), atol=1e-15)


def test_rhs_is_vectorised_over_batch_axes():
    model = get_model("nomoto", delta0=0.01)
    rng = np.random.default_rng(1)
    x, u, d = rng.normal(size=(7, 2)), rng.normal(size=(7, 1)), rng.normal(size=(7, 1))
    out = model.rhs(x, u, d)
    assert out.shape == (7, 2)
    rows = np.array([model.rhs(x[i], u[i], d[i]) for i in range(7)])
    np.testing.assert_allclose(out, rows)
    assert model.rhs(x, [0.1]).shape == (7, 2)  # inputs broadcast; d=None is zero
    with pytest.raises(ValueError, match="last axis 2"):
        model.rhs(np.zeros(3), [0.0])


def test_delta0_is_an_affine_parameter_handled_exactly():
    model = get_model("nomoto")
    x, u = np.array([[0.01, 0.0], [0.0, 0.3]]), np.array([[0.1], [-0.2]])
    values = np.array([0.02, -0.05])
    out = model.rhs_with(x, u, None, {"delta0": values})
    expected = np.array([model.with_params(delta0=v).rhs(x[i], u[i])
                         for i, v in enumerate(values)])
    np.testing.assert_allclose(out, expected, atol=1e-15)
    jac = model.parameter_jacobian(x, u, None, {"delta0": values})
    np.testing.assert_allclose(jac[..., 0, 0], model.params.K / model.params.T)
    # K and T (not affine) row by row: exact too
    rows = {"K": np.array([-0.05, 0.1]), "T": np.array([5.0, 20.0])}
    expected = np.array([model.with_params(K=k, T=t).rhs(x[i], u[i])
                         for i, (k, t) in enumerate(zip(rows["K"], rows["T"], strict=True))])
    np.testing.assert_allclose(model.rhs_with(x, u, None, rows), expected, atol=1e-15)


def test_zigzag_runs_on_the_nomoto_model():
    # K < 0: the heading turns against the rudder, so turn_sign=-1
    result = zigzag(get_model("nomoto"), math.radians(10.0), math.radians(10.0), turn_sign=-1)
    assert result.first_overshoot_deg > 0
