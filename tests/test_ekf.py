"""The extended Kalman filter: agreement with the linear filter, joint parameter estimation,
tracking with artificial process noise, the RTS smoother, missing data and bad input."""

import math

import numpy as np
import pytest

from estimators.ekf import ExtendedKalmanFilter, rts_smooth
from estimators.kalman import KalmanFilter
from estimators.ukf import UnscentedKalmanFilter
from marine_envs.models import get_model, zoh

DT = 0.1
A = np.array([[0.0, 1.0], [-1.0, -0.2]])
B = np.array([[0.0], [1.0]])


def oscillator(x, u, theta):
    """A lightly damped oscillator whose natural frequency (rad/s) is the parameter."""
    return np.column_stack([x[:, 1], -theta[:, 0] ** 2 * x[:, 0] - 0.2 * x[:, 1] + u[:, 0]])


def oscillator_ekf(**kwargs):
    kwargs = {"x0": [0.0, 0.0, 0.8], "P0": np.diag([1.0, 1.0, 1.0]), "substeps": 2,
              "parameter_names": ["w"], "Q": [1e-8, 1e-6], "R": [1e-4], **kwargs}
    return ExtendedKalmanFilter(oscillator, [[1.0, 0.0]], dt=DT, n_inputs=1,
                                state_names=["x", "x_dot"], measurement_names=["x"], **kwargs)


def simulate_oscillator(w, steps, seed=0, noise=0.01):
    """Inputs and noisy position measurements of the oscillator with frequency ``w(t)``."""
    rng = np.random.default_rng(seed)
    x, ys, us = np.array([1.0, 0.0]), [], []
    for k in range(steps):
        ys.append([x[0] + noise * rng.normal()])
        u = [np.sin(0.5 * k * DT)]
        us.append(u)
        for _ in range(20):
            x = x + DT / 20 * oscillator(x[None], np.array([u]), np.array([[w(k * DT)]]))[0]
    return np.array(us), np.array(ys)


@pytest.mark.parametrize("kind", [ExtendedKalmanFilter, UnscentedKalmanFilter])
def test_filter_of_a_linear_model_is_the_kalman_filter(kind):
    rng = np.random.default_rng(1)
    F, G = zoh(A, B, DT)
    Q, R = np.diag([1e-4, 1e-3]), np.array([[0.01]])
    kf = KalmanFilter(F, G, [[1.0, 0.0]], Q, R, dt=DT, batch_size=3)
    filt = kind(lambda x, u, t: x @ A.T + u @ B.T, [[1.0, 0.0]], dt=DT, Q=Q, R=R, n_inputs=1,
                state_names=["a", "b"], measurement_names=["y"], substeps=4, batch_size=3)
    for _ in range(100):
        u, y = rng.normal(size=(3, 1)), rng.normal(size=(3, 1))
        kf.update(y)
        filt.update(y)
        kf.predict(u)
        filt.predict(u)
    np.testing.assert_allclose(filt.P, kf.P, rtol=1e-6, atol=1e-14)
    np.testing.assert_allclose(filt.x, kf.x, atol=1e-6)  # RK4 vs exact hold
    np.testing.assert_allclose(filt.transition[0], F, atol=1e-6)


def test_parameter_converges_to_the_truth_within_its_uncertainty():
    us, ys = simulate_oscillator(lambda t: 1.3, 600)
    res = oscillator_ekf().filter(us, ys)
    w, std = res.x[-1, 0, 2], res.std[-1, 0, 2]
    assert abs(w - 1.3) < max(3 * std, 2e-3)
    assert std < 0.01 < res.std[0, 0, 2]


def test_held_input_response_is_the_exact_integral_for_a_stiff_mode():
    """``x_dot = -a x`` held over 0.1 s with ``a = 47`` 1/s: ``(1 - exp(-a dt)) / a``, where the
    trapezoid ``dt (Phi + 1) / 2`` is 2.4x too large."""
    a, dt = 47.0, 0.1
    ekf = ExtendedKalmanFilter(lambda x, u, _theta: -a * x, lambda x: x, dt=dt, Q=[[1e-6]],
                               R=[[1e-4]], n_inputs=1, state_names=["x"],
                               measurement_names=["x"], substeps=10)
    gamma = ekf.held_input_response([[0.3], [-2.0]], [[0.0], [0.0]])
    np.testing.assert_allclose(gamma[:, 0, 0], (1 - math.exp(-a * dt)) / a, rtol=1e-9)


def test_analytic_jacobian_gives_the_same_filter():
    def jacobian(x, u, theta):
        N = x.shape[0]
        dfdx = np.zeros((N, 2, 2))
        dfdx[:, 0, 1] = 1.0
        dfdx[:, 1, 0] = -theta[:, 0] ** 2
        dfdx[:, 1, 1] = -0.2
        dfdt = np.zeros((N, 2, 1))
        dfdt[:, 1, 0] = -2 * theta[:, 0] * x[:, 0]
        return dfdx, dfdt

    us, ys = simulate_oscillator(lambda t: 1.3, 200)
    fd = oscillator_ekf().filter(us, ys)
    exact = oscillator_ekf(jacobian=jacobian).filter(us, ys)
    np.testing.assert_allclose(exact.x, fd.x, atol=1e-6)


def test_artificial_parameter_noise_tracks_a_change_that_a_constant_parameter_misses():
    us, ys = simulate_oscillator(lambda t: 1.3 if t < 30 else 1.6, 900, seed=2)
    frozen = oscillator_ekf().filter(us, ys).x[-1, 0, 2]
    tracking = oscillator_ekf(parameter_noise=[0.02]).filter(us, ys).x[-1, 0, 2]
    assert abs(tracking - 1.6) < 0.02
    assert abs(frozen - 1.6) > 3 * abs(tracking - 1.6)


def test_smoother_beats_the_filter_and_meets_it_at_the_end():
    us, ys = simulate_oscillator(lambda t: 1.3, 300, seed=3)
    ekf = oscillator_ekf(x0=[0.0, 0.0, 1.3], P0=np.diag([1.0, 1.0, 1e-8]))
    sm = ekf.smooth(us, ys)
    truth = simulate_truth(us)
    filt_err = np.abs(sm.filtered.x[20:, 0, 1] - truth[20:, 1]).mean()
    smooth_err = np.abs(sm.x[20:, 0, 1] - truth[20:, 1]).mean()
    assert smooth_err < 0.7 * filt_err
    np.testing.assert_allclose(sm.x[-1], sm.filtered.x[-1])
    # smoothing never increases the uncertainty
    assert (sm.std[:, 0, :2] <= sm.filtered.std[:, 0, :2] + 1e-12).all()
    np.testing.assert_allclose(rts_smooth(sm.filtered).x, sm.x)


def simulate_truth(us):
    x, out = np.array([1.0, 0.0]), []
    for u in us:
        out.append(x)
        for _ in range(20):
            x = x + DT / 20 * oscillator(x[None], np.array([u]), np.array([[1.3]]))[0]
    return np.array(out)


def test_batch_of_filters_equals_filters_run_alone():
    us, ys = simulate_oscillator(lambda t: 1.3, 100, seed=4)
    y3 = np.stack([ys, ys + 0.01, ys[::-1]], axis=1)
    batch = oscillator_ekf(batch_size=3).filter(us, y3)
    for i in range(3):
        alone = oscillator_ekf().filter(us, y3[:, i])
        np.testing.assert_allclose(batch.x[:, i], alone.x[:, 0], atol=1e-12)


def test_missing_channels_get_no_gain():
    ekf = oscillator_ekf(batch_size=2)
    before = ekf.x.copy(), ekf.P.copy()
    ekf.update(np.array([[np.nan], [0.5]]))
    np.testing.assert_array_equal(ekf.x[0], before[0][0])
    np.testing.assert_array_equal(ekf.P[0], before[1][0])
    assert ekf.dof.tolist() == [0, 1] and ekf.x[1, 0] > 0.4
    ekf.update(np.array([[0.5], [0.5]]), mask=np.array([[False], [True]]))
    np.testing.assert_array_equal(ekf.x[0], before[0][0])


def test_a_wrong_model_is_flagged_as_diverged():
    us, ys = simulate_oscillator(lambda t: 1.3, 300, seed=5)
    ekf = oscillator_ekf(x0=[1.0, 0.0, 3.0], P0=np.diag([1e-6, 1e-6, 1e-12]))
    ekf.filter(us, ys)
    assert ekf.diverged.all()


def test_from_model_identifies_a_hovercraft_coefficient_through_rhs_with():
    model = get_model("hovercraft")
    truth = model.with_params(N_Hr=-2.5e6)
    x, u = model.x0.copy(), model.u0.copy()
    rng = np.random.default_rng(6)
    ys, us = [], []
    for k in range(300):
        u[2] = 0.2 * np.sign(np.sin(0.05 * k))  # a square-wave rudder excites the yaw damping
        ys.append(x[[0, 1, 2, 5]] + rng.normal(0, [0.05, 0.05, 1e-3, 3e-3]))
        us.append(u.copy())
        for _ in range(4):
            x = x + 0.025 * truth.rhs(x, u)
    ekf = ExtendedKalmanFilter.from_model(
        model, 0.1, measured=["u", "v", "r", "psi"], Q=np.full(6, 1e-8),
        R=[0.05**2, 0.05**2, 1e-6, 9e-6], parameters=["N_Hr"],
        P0=np.diag([1, 1, 1e-4, 1, 1, 1e-4, 1e12]), substeps=2)
    res = ekf.filter(np.array(us), np.array(ys))
    assert ekf.state_names[-1] == "N_Hr"
    assert abs(res.x[-1, 0, -1] / -2.5e6 - 1) < 0.05


def test_bad_input_is_refused_with_a_message_naming_it():
    with pytest.raises(ValueError, match="parameter_noise"):
        oscillator_ekf(parameter_noise=[-1.0])
    with pytest.raises(ValueError, match="H has shape"):
        ExtendedKalmanFilter(oscillator, [[1.0, 0.0, 0.0]], dt=DT, Q=[1, 1], R=[1], n_inputs=1,
                             state_names=["a", "b"], measurement_names=["y"])
    with pytest.raises(ValueError, match="R must be positive definite"):
        oscillator_ekf(R=[0.0])
    ekf = oscillator_ekf()
    with pytest.raises(ValueError, match="non-finite"):
        ekf.predict([np.nan])
    with pytest.raises(ValueError, match="y has shape"):
        ekf.update(np.zeros((1, 2)))
    with pytest.raises(ValueError, match="u has 3 steps but y has 2"):
        ekf.filter(np.zeros((3, 1)), np.zeros((2, 1)))
    model = get_model("hovercraft")
    with pytest.raises(ValueError, match="not outputs"):
        ExtendedKalmanFilter.from_model(model, 0.1, measured=["q"], Q=np.ones(6), R=[1.0])
    with pytest.raises(ValueError, match=r"\['N_Xyz'\] are unknown"):
        ExtendedKalmanFilter.from_model(model, 0.1, measured=["r"], Q=np.ones(6), R=[1.0],
                                        parameters=["N_Xyz"])


def ukf(**kwargs):
    kwargs = {"x0": [0.0, 0.0, 0.8], "P0": np.diag([1.0, 1.0, 1.0]), "substeps": 2,
              "parameter_names": ["w"], "Q": [1e-8, 1e-6], "R": [1e-4], **kwargs}
    return UnscentedKalmanFilter(oscillator, [[1.0, 0.0]], dt=DT, n_inputs=1,
                                 state_names=["x", "x_dot"], measurement_names=["x"], **kwargs)


def test_unscented_filter_is_honest_about_its_error_where_the_ekf_is_not():
    """From a far initial guess the EKF's linearisation makes it overconfident early on; the
    sigma points carry the spread through the nonlinearity (NEES = error^2 / variance)."""
    honest = {"ekf": 0, "ukf": 0}
    for seed in range(10):
        us, ys = simulate_oscillator(lambda t: 1.3, 31, seed=seed)
        for name, make in (("ekf", oscillator_ekf), ("ukf", ukf)):
            res = make(x0=[0.0, 0.0, 0.5]).filter(us, ys)
            nees = (res.x[30, 0, 2] - 1.3) ** 2 / res.P[30, 0, 2, 2]
            honest[name] += bool(nees < 9)
    assert honest["ukf"] >= 7 and honest["ekf"] <= 3, honest


def test_unscented_filter_identifies_and_smooths():
    us, ys = simulate_oscillator(lambda t: 1.3, 300, seed=8)
    sm = ukf().smooth(us, ys)
    assert abs(sm.filtered.x[-1, 0, 2] - 1.3) < 3e-3
    truth = simulate_truth(us)
    assert np.abs(sm.x[20:, 0, 1] - truth[20:, 1]).mean() < \
        np.abs(sm.filtered.x[20:, 0, 1] - truth[20:, 1]).mean()


def test_a_saturated_reading_is_taken_as_missing():
    """A reading at the sensor's full scale says only that the value is beyond it: no gain."""
    ekf = oscillator_ekf(batch_size=2, sensor_range=([-0.5], [0.5]))
    before = ekf.x.copy(), ekf.P.copy()
    ekf.update(np.array([[0.5], [0.49]]))
    np.testing.assert_array_equal(ekf.x[0], before[0][0])
    np.testing.assert_array_equal(ekf.P[0], before[1][0])
    assert ekf.dof.tolist() == [0, 1] and ekf.x[1, 0] > 0.4
    with pytest.raises(ValueError, match="sensor_range"):
        oscillator_ekf(sensor_range=([0.5], [-0.5]))


def test_rov_filter_under_full_random_thrust_stays_finite_and_in_the_model_domain():
    """ROV-v0 under uniform random actions in [-1.2, 1.2] (seed 11): its roll rate passes the
    gyro's full scale (1.57 rad/s) at step 16. Read as a measurement, the clipped value pulled
    the unmeasured morph fraction out of [0, 1], where the model's coefficients are
    extrapolated, and the estimate overflowed to NaN at step 31; a saturated reading is now
    missing, and the estimate stays finite with the morph fraction near its true 0."""
    import gymnasium as gym

    import marine_envs  # noqa: F401
    from estimators.registry import observe

    env = observe(gym.make("marine_envs/ROV-v0", disable_env_checker=True), "ekf")
    rng = np.random.default_rng(11)
    obs, _ = env.reset(seed=11)
    saturated = 0
    for _ in range(60):
        action = rng.uniform(-1.2, 1.2, env.action_space.shape).astype(np.float32)
        obs, _, _, _, info = env.step(action)
        saturated += env.estimator.dof[0] < np.sum(info.get("measurement_mask", True))
        assert np.isfinite(obs).all()
        assert abs(info["estimate"][12]) < 0.1  # the morph fraction: truly 0
    assert saturated > 0  # the case did arise
