"""The project's one integrator (marine_envs.models.integrate): RK4's order and time stages, the
simulator's step on it, and the exact step of a linear model."""

import math

import numpy as np
import pytest

from marine_envs.models import get_model
from marine_envs.models.integrate import ExactStep, RK4Step, rk4
from marine_envs.models.linear import zoh


def test_rk4_is_fourth_order():
    # a harmonic oscillator over one period: halving the step cuts the error 16-fold
    def f(x, _t):
        return np.array([x[1], -x[0]])

    errors = []
    for n in (20, 40, 80):
        x = rk4(f, np.array([1.0, 0.0]), 2 * math.pi / n, n)
        errors.append(np.abs(x - [1.0, 0.0]).max())
    ratios = [errors[0] / errors[1], errors[1] / errors[2]]
    assert all(14 < r < 18 for r in ratios), ratios


def test_rk4_evaluates_time_at_the_stages_and_carries_it_across_substeps():
    # x_dot = t^3 integrates exactly (Simpson is exact for cubics): x(t) = t^4 / 4
    x = rk4(lambda _x, t: np.array([t**3]), np.zeros(1), 0.25, 8, t=1.0)
    assert x[0] == pytest.approx((3.0**4 - 1.0) / 4, rel=1e-12)


def test_rk4_keeps_batch_rows_independent():
    rates = np.array([[-1.0], [-2.0], [0.5]])
    x = rk4(lambda z, _t: rates * z, np.ones((3, 1)), 0.01, 100)
    np.testing.assert_allclose(x[:, 0], np.exp(rates[:, 0]), rtol=1e-8)


def test_rk4_step_of_a_model_is_rk4_of_its_rhs_with_inputs_held():
    model = get_model("hovercraft")
    rng = np.random.default_rng(3)
    x = model.x0 + 0.1 * rng.standard_normal((4, 6))
    u = np.tile(model.u0, (4, 1))
    d = rng.standard_normal((4, 2))
    step = RK4Step(model, dt=0.1, substeps=2)
    expected = rk4(lambda z, _t: model.rhs(z, u, d), x, 0.05, 2)
    assert np.array_equal(step(np.hstack([x, u, d])), expected)


def test_rk4_step_names_the_boat_that_diverged():
    model = get_model("usv")
    xud = np.zeros((3, 5 + 1 + 2))
    xud[2, 0] = np.inf
    with np.errstate(invalid="ignore"), pytest.raises(FloatingPointError, match="boat 2"):
        RK4Step(model, dt=0.1)(xud)


def test_exact_step_agrees_with_fine_rk4_and_with_the_zoh_matrices():
    model = get_model("usv")
    rng = np.random.default_rng(0)
    xud = np.hstack([0.1 * rng.standard_normal((5, 5)), 0.05 * rng.standard_normal((5, 1)),
                     0.01 * rng.standard_normal((5, 2))])
    exact = ExactStep(model, dt=0.1)
    np.testing.assert_allclose(exact(xud), RK4Step(model, dt=0.1, substeps=64)(xud),
                               rtol=0, atol=1e-12)
    A, B, E = model.linearize()
    Phi, Gamma = zoh(A, np.hstack([B, E]), 0.1)
    np.testing.assert_allclose(exact(xud), xud[:, :5] @ Phi.T + xud[:, 5:] @ Gamma.T,
                               atol=1e-15)
