"""The linear-system numerics every layer shares (marine_envs.models.linear): zero-order-hold
discretisation and the LQR designs, against analytic solutions, the Riccati equations and brute
force."""

import numpy as np
import pytest
import scipy.linalg

from marine_envs.models import get_model
from marine_envs.models.linear import dlqe, dlqr, lqr, lqr_gain, lqr_integral, zoh

# docs/models.md 2.4: the hydrofoil's continuous LQR, printed to 5 decimals (u = -K x)
K_HYDROFOIL = np.array([[-0.00102, 1.76250, -0.06278, 6.63080],
                        [0.00097, -9.07009, 0.11474, -30.74975]])
POLES_HYDROFOIL = [-8846, -25.25, -0.316, -0.0052]


def test_zoh_is_the_exact_step_of_a_held_input():
    A, B = np.array([[0.0, 1.0], [-4.0, -0.4]]), np.array([[0.0], [2.0]])
    Phi, Gamma = zoh(A, B, 0.3)
    # the augmented system [x; w] with w_dot = 0, integrated finely
    x, w, h = np.array([0.5, -0.2]), 1.5, 1e-4
    for _ in range(3000):
        x = x + h * (A @ x + B[:, 0] * w)
    np.testing.assert_allclose(Phi @ np.array([0.5, -0.2]) + Gamma[:, 0] * w, x, atol=1e-4)
    np.testing.assert_allclose(Phi, scipy.linalg.expm(0.3 * A), rtol=1e-12)


@pytest.mark.parametrize("args, message", [
    ((np.eye(2), np.ones((3, 1)), 0.1), "shapes do not match"),
    ((np.eye(2), np.ones((2, 1)), 0.0), "dt=0.0 is invalid"),
    ((np.eye(2), np.ones((2, 1)), float("nan")), "dt=nan is invalid"),
    ((np.array([[np.nan, 0], [0, 1]]), np.ones((2, 1)), 0.1), "A has non-finite"),
])
def test_zoh_refuses_bad_input_naming_it(args, message):
    with pytest.raises(ValueError, match=message):
        zoh(*args)


def test_continuous_lqr_of_a_double_integrator_is_the_analytic_care_solution():
    A, B = np.array([[0, 1], [0, 0]]), np.array([[0], [1]])
    np.testing.assert_allclose(lqr_gain(A, B, np.eye(2), np.eye(1)), [[1, np.sqrt(3)]],
                               atol=1e-10)
    # Q = diag(q1, q2), R = r: p12 = sqrt(q1 r), p22 = sqrt(r (q2 + 2 p12)), p11 = p12 p22 / r
    q1, q2, r = 4.0, 1.0, 0.5
    p12 = np.sqrt(q1 * r)
    p22 = np.sqrt(r * (q2 + 2 * p12))
    K, P, poles = lqr(A, B, np.diag([q1, q2]), [[r]])
    np.testing.assert_allclose(P, [[p12 * p22 / r, p12], [p12, p22]], rtol=1e-10)
    np.testing.assert_allclose(K, [[p12 / r, p22 / r]], rtol=1e-10)
    np.testing.assert_allclose(np.sort_complex(poles),
                               np.sort_complex(np.linalg.eigvals(A - B @ K)))
    assert poles.real.max() < 0


def test_hydrofoil_continuous_gain_matches_models_md():
    A, B, _ = get_model("hydrofoil").linearize()
    Q, R = np.diag([0.0, 100.0, 0.0, 1000.0]), np.eye(2)
    K, _, poles = lqr(A, B, Q, R)
    np.testing.assert_allclose(K, K_HYDROFOIL, rtol=0, atol=5.1e-6)  # half the last digit
    np.testing.assert_allclose(np.sort(poles.real), POLES_HYDROFOIL, rtol=1e-3)


def test_discrete_gain_solves_the_dare_and_matches_the_zoh_model():
    A, B, _ = get_model("usv").linearize()
    Q, R, dt = np.diag([0, 0, 100.0, 0, 800.0]), np.eye(1) * 30, 0.1
    K, P, poles = lqr(A, B, Q, R, dt=dt)
    Ad, Bd = zoh(A, B, dt)
    residual = Ad.T @ P @ Ad - P - Ad.T @ P @ Bd @ np.linalg.solve(R + Bd.T @ P @ Bd,
                                                                    Bd.T @ P @ Ad) + Q
    assert np.abs(residual).max() < 1e-8 * np.abs(P).max()
    np.testing.assert_allclose(K, np.linalg.solve(R + Bd.T @ P @ Bd, Bd.T @ P @ Ad))
    np.testing.assert_allclose(dlqr(Ad, Bd, Q, R).K, K, rtol=1e-12)
    assert np.abs(poles).max() < 1
    np.testing.assert_allclose(np.sort(np.abs(poles)), np.sort(np.abs(np.linalg.eigvals(
        Ad - Bd @ K))), rtol=1e-10)


def test_discrete_lqr_stabilises_and_is_optimal_against_perturbed_gains():
    model_A, model_B, _ = get_model("usv").linearize()
    Q, R, dt = np.diag([0, 0, 100.0, 0, 800.0]), np.eye(1) * 30, 0.1
    K = lqr_gain(model_A, model_B, Q, R, dt=dt)
    block = scipy.linalg.expm(np.block([[model_A, model_B], [np.zeros((1, 6))]]) * dt)
    Ad, Bd = block[:5, :5], block[:5, 5:]
    assert np.abs(np.linalg.eigvals(Ad - Bd @ K)).max() < 1

    def cost(gain):
        x, total = np.array([0.0, 0.0, 0.2, 0.0, 0.05]), 0.0
        for _ in range(3000):
            u = -gain @ x
            total += x @ Q @ x + u @ R @ u
            x = Ad @ x + Bd @ u
        return total

    best = cost(K)
    rng = np.random.default_rng(0)
    for _ in range(5):
        assert cost(K * (1 + 0.1 * rng.standard_normal(K.shape))) > best


def test_integral_design_is_the_lqr_of_the_augmented_model():
    A, B = np.array([[-1.0]]), np.array([[1.0]])
    K, P, poles = lqr_integral(A, B, [[1.0]], [[1.0]], [0], [4.0])
    A_aug, B_aug = np.array([[-1.0, 0.0], [1.0, 0.0]]), np.array([[1.0], [0.0]])
    np.testing.assert_allclose(K, lqr_gain(A_aug, B_aug, np.diag([1.0, 4.0]), [[1.0]]))
    assert K.shape == (1, 2) and poles.real.max() < 0
    dt = 0.1
    Kd = lqr_integral(A, B, [[1.0]], [[1.0]], [0], [4.0], dt=dt).K
    Ad, Bd = zoh(A, B, dt)
    expected = dlqr([[Ad[0, 0], 0.0], [dt, 1.0]], [[Bd[0, 0]], [0.0]], np.diag([1.0, 4.0]),
                    [[1.0]]).K
    np.testing.assert_allclose(Kd, expected, rtol=1e-12)



def test_discount_one_is_the_undiscounted_design_to_the_bit():
    A, B, _ = get_model("usv").linearize()
    Ad, Bd = zoh(A, B, 0.1)
    Q, R = np.diag([0, 0, 100.0, 0, 800.0]) + 1e-6 * np.eye(5), np.eye(1) * 30
    assert np.array_equal(dlqr(Ad, Bd, Q, R, discount=1.0).K, dlqr(Ad, Bd, Q, R).K)


def test_discounted_design_solves_the_discounted_bellman_equation():
    A, B, _ = get_model("usv").linearize()
    Ad, Bd = zoh(A, B, 0.1)
    Q, R, g = np.diag([1.0, 1.0, 100.0, 1.0, 800.0]), np.eye(1) * 30, 0.95
    K, P, poles = dlqr(Ad, Bd, Q, R, discount=g)
    # x'Px = min_u x'Qx + u'Ru + g (Ax + Bu)' P (Ax + Bu), attained at u = -K x
    gain = np.linalg.solve(R + g * Bd.T @ P @ Bd, g * Bd.T @ P @ Ad)
    residual = Q + g * Ad.T @ P @ Ad - g * Ad.T @ P @ Bd @ gain - P
    assert np.abs(residual).max() < 1e-8 * np.abs(P).max()
    np.testing.assert_allclose(K, gain, rtol=1e-9)
    assert np.abs(poles).max() < 1 / np.sqrt(g)


def test_a_discount_designs_around_an_immovable_marginal_mode():
    # a second, uncontrollable integrator that Q weighs: no stabilising undiscounted design
    Ad, Bd = np.array([[1.0, 0.0], [0.0, 1.0]]), np.array([[0.1], [0.0]])
    Q, R = np.eye(2), np.eye(1)
    with pytest.raises(ValueError, match="not stabilisable"):
        dlqr(Ad, Bd, Q, R)
    K, _, poles = dlqr(Ad, Bd, Q, R, discount=0.99)
    assert np.abs(poles).max() < 1 / np.sqrt(0.99)
    assert abs(poles[np.argmin(np.abs(poles - 1))] - 1) < 1e-12  # the immovable mode stays
    assert np.abs(np.linalg.eigvals(Ad[:1, :1] - Bd[:1] @ K[:, :1])).max() < 1


@pytest.mark.parametrize("discount", [0.0, -0.5, 1.5, float("nan")])
def test_discount_out_of_range_is_refused(discount):
    with pytest.raises(ValueError, match="discount"):
        dlqr(np.eye(1), np.eye(1), np.eye(1), np.eye(1), discount=discount)


def test_dlqe_is_the_fixed_point_of_the_kalman_covariance_recursion():
    A, _, E = get_model("usv").linearize()
    F, G = zoh(A, E, 0.1)
    H = np.eye(5)[1:]  # v is not measured
    Q, R = G @ G.T * 1e-4 + 1e-9 * np.eye(5), np.diag([1e-6, 4e-6, 1e-6, 1e-6])
    P_pred, P_upd = dlqe(F, H, Q, R)
    P = np.eye(5)
    for _ in range(5000):  # predict, update: the filter's own recursion
        P = F @ P @ F.T + Q
        P = P - P @ H.T @ np.linalg.solve(H @ P @ H.T + R, H @ P)
    np.testing.assert_allclose(P_upd, P, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(P_pred, F @ P_upd @ F.T + Q, rtol=1e-8, atol=1e-16)


def test_dlqe_refuses_an_unstable_mode_the_measurements_cannot_see():
    F, H = np.diag([1.05, 0.5]), np.array([[0.0, 1.0]])
    with pytest.raises(ValueError, match="not stabilisable"):
        dlqe(F, H, np.eye(2), np.eye(1))
