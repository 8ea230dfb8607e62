"""LQR gains, integral action with anti-windup, and the SB3-style LQR policy."""

from types import SimpleNamespace

import gymnasium as gym
import numpy as np
import pytest

import marine_envs  # noqa: F401
from agents.evaluation import run_episode
from agents.excitation import RandomSteps, Sine, Zero
from agents.lqr import LQRPolicy, lqr, lqr_gain, lqr_integral, zoh
from marine_envs.envs.system import Actuation
from marine_envs.models import get_model


class FirstOrder:
    """``x_dot = -x + u + d`` with ``|u| <= 1``: the smallest model of the protocol."""

    state_names, input_names = ("x",), ("u",)
    x0, u0 = np.zeros(1), np.zeros(1)
    u_bounds = (np.array([-1.0]), np.array([1.0]))

    def linearize(self, x0=None, u0=None):
        return np.array([[-1.0]]), np.array([[1.0]]), np.array([[1.0]])


def first_order_run(policy, disturbance, steps, dt=0.1):
    """States and integral states of the first-order plant (exact ZOH) under ``policy``."""
    a, x, xs, zs = np.exp(-dt), np.zeros(1), [], []
    for k in range(steps):
        action, _ = policy.predict(x)
        x = a * x + (1 - a) * (action.astype(float) + disturbance(k))
        xs.append(x[0])
        zs.append(np.nan if policy.integral_state is None else policy.integral_state[0, 0])
    return np.array(xs), np.array(zs)


# -- gains ---------------------------------------------------------------------------------------
def test_for_model_designs_through_the_model_protocol():
    # the hydrofoil's continuous design (tests/test_linear.py), weights given by name
    A, B, _ = get_model("hydrofoil").linearize()
    K = lqr(A, B, np.diag([0.0, 100.0, 0.0, 1000.0]), np.eye(2)).K
    policy = LQRPolicy.for_model(get_model("hydrofoil"), {"theta": 100.0, "theta_dot": 1000.0},
                                 [1.0, 1.0])
    np.testing.assert_allclose(policy.K, K, rtol=1e-12, atol=1e-12)


# -- integral action -----------------------------------------------------------------------------
def test_integral_action_removes_the_heading_offset_of_a_constant_yaw_moment():
    model, dt = get_model("usv"), 0.1
    A, B, E = model.linearize()
    Ad, BEd = zoh(A, np.hstack([B, E]), dt)
    Q, R = {"psi": 365.0, "phi": 820.0}, [32.8]
    plain = LQRPolicy.for_model(model, Q, R, dt=dt)
    integral = LQRPolicy.for_model(model, Q, R, dt=dt, integral={"psi": 50.0})
    d = np.array([0.003, 0.0])  # rad/s^2: a steady yaw moment (wind, current)
    actuation = Actuation.direct(model)
    final = {}
    for name, policy in (("plain", plain), ("integral", integral)):
        x = np.zeros(5)
        for _ in range(3000):  # 300 s
            action, _ = policy.predict(x)
            u = actuation.to_input(action)
            x = Ad @ x + BEd @ np.concatenate([u, d])
        final[name] = x
    assert abs(final["plain"][2]) > 0.02  # rad: plain LQR leaves a heading offset (2.6 deg)
    assert abs(final["integral"][2]) < 1e-6  # integral action removes it
    assert abs(final["integral"][1]) < 1e-6  # and the boat is at rest in yaw


def test_integral_action_removes_a_constant_input_bias_of_a_first_order_plant():
    plain = LQRPolicy.for_model(FirstOrder(), [1.0], [1.0], dt=0.1)
    integral = LQRPolicy.for_model(FirstOrder(), [1.0], [1.0], dt=0.1, integral={"x": 1.0})
    sampled = LQRPolicy.for_model(FirstOrder(), [1.0], [1.0], dt=0.1, integral={"x": 1.0},
                                  continuous=True)  # continuous gains, Euler integrator
    bias = lambda k: 0.5  # noqa: E731
    assert first_order_run(plain, bias, 600)[0][-1] == pytest.approx(0.5 / (1 + plain.K[0, 0]),
                                                                      rel=1e-6)
    assert abs(first_order_run(integral, bias, 600)[0][-1]) < 1e-9
    assert abs(first_order_run(sampled, bias, 600)[0][-1]) < 1e-9


def test_anti_windup_holds_the_integrator_while_saturated_and_limits_the_overshoot():
    # 30 s of a disturbance the input cannot cancel (|u| <= 1 < 3), then none
    disturbance = lambda k: -3.0 if k < 300 else 0.0  # noqa: E731
    runs = {}
    for anti_windup in (True, False):
        policy = LQRPolicy.for_model(FirstOrder(), [1.0], [1.0], dt=0.1, integral={"x": 1.0},
                                     anti_windup=anti_windup)
        runs[anti_windup] = first_order_run(policy, disturbance, 1000)
    x, z = runs[True]
    assert np.abs(z[:300]).max() < 0.5 and z[299] == z[100]  # bounded, held while saturated
    assert x[300:].max() < 0.2 and abs(x[-1]) < 1e-6  # small overshoot, then back to 0
    x_windup, z_windup = runs[False]  # the same without anti-windup: the test can fail
    assert z_windup[299] < 2.5 * z_windup[100] < -40  # grows linearly, without bound
    assert x_windup[300:].max() > 0.9


# -- the policy ----------------------------------------------------------------------------------
def test_policy_predicts_like_sb3_for_one_or_many_observations():
    env = gym.make("marine_envs/USV-v0")
    policy = LQRPolicy.for_env(env)
    obs, _ = env.reset(seed=0)
    action, state = policy.predict(obs)
    assert state is None and action.shape == (1,) and action.dtype == np.float32
    batch, _ = policy.predict(np.stack([obs, -obs]))
    assert batch.shape == (2, 1) and np.all(np.abs(batch) <= 1)
    np.testing.assert_allclose(batch[0], action)


def test_batch_equals_singles_and_episode_start_resets_only_flagged_rows():
    model, rng = get_model("usv"), np.random.default_rng(1)

    def make():
        return LQRPolicy.for_model(model, {"psi": 365.0, "phi": 820.0}, [32.8], dt=0.1,
                                   integral={"psi": 50.0})

    batch, singles = make(), [make() for _ in range(3)]
    # large enough that some rows saturate: anti-windup is per row too
    observations = rng.normal(0.0, [0.05, 0.05, 0.5, 0.05, 0.1], size=(40, 3, 5))
    saturated = 0
    for k, obs in enumerate(observations):
        starts = np.array([False, k == 20, k == 30])
        actions, _ = batch.predict(obs, episode_start=starts)
        for i, single in enumerate(singles):
            action, _ = single.predict(obs[i], episode_start=starts[i])
            np.testing.assert_array_equal(actions[i], action)
            np.testing.assert_array_equal(batch.integral_state[i], single.integral_state[0])
        saturated += int((np.abs(actions) == 1).sum())
        if k == 20:  # row 1 restarted: it acts like a fresh policy; rows 0 and 2 do not
            for i in range(3):
                fresh = make()
                action, _ = fresh.predict(obs[i])
                if i == 1:
                    np.testing.assert_array_equal(actions[1], action)
                same = np.array_equal(fresh.integral_state[0], batch.integral_state[i])
                assert same == (i == 1)
                assert saturated > 0
    row0 = batch.integral_state[0].copy()
    batch.reset([2])
    assert np.all(batch.integral_state[2] == 0) and np.all(batch.integral_state[0] == row0)
    with pytest.raises(ValueError, match="reset"):
        batch.predict(observations[0, :2])
    batch.reset()
    assert batch.predict(observations[0, :2])[0].shape == (2, 1)  # sized anew


def test_full_state_lqr_beats_sensor_lqr_beats_no_control():
    returns = {}
    for name in ("none", "sensors", "state"):
        env = gym.make("marine_envs/USV-v0", max_episode_steps=600)
        if name == "none":
            policy = Zero(1, 0.1)
        else:
            policy = LQRPolicy.for_env(env, observed="sensors" if name == "sensors" else None)
        if name == "state":  # feed the true state: a wrapper-free way via the info dict
            obs, info = env.reset(seed=3)
            total = 0.0
            for _ in range(600):
                obs, reward, _, _, info = env.step(policy.predict(info["state"])[0])
                total += reward
            returns[name] = total
        else:
            returns[name] = run_episode(env, policy, 600, seed=3).episode_return
    assert returns["state"] >= returns["sensors"] * 1.001 - 1  # v known helps (or ties)
    assert returns["sensors"] > 2 * returns["none"]  # returns are negative: LQR costs < half


class TrueStateEstimate(gym.Wrapper):
    """Stands in for an estimator wrapper: the observation is the true state plus one appended
    'parameter', and the wrapper has an ``estimator`` with matching state names."""

    def __init__(self, env, names=None):
        super().__init__(env)
        model_names = env.unwrapped.system.model.state_names
        self.estimator = SimpleNamespace(state_names=names or (*model_names, "bias"))
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (len(model_names) + 1,))

    def reset(self, **kwargs):
        _, info = self.env.reset(**kwargs)
        return np.append(info["state"], 123.0).astype(np.float32), info

    def step(self, action):
        _, reward, terminated, truncated, info = self.env.step(action)
        obs = np.append(info["state"], 123.0).astype(np.float32)
        return obs, reward, terminated, truncated, info


@pytest.mark.parametrize("env_id", ["marine_envs/USV-v0", "marine_envs/DPVessel-v0"])
def test_auto_reads_an_estimate_when_a_wrapper_has_an_estimator(env_id):
    env = gym.make(env_id)
    wrapped = gym.wrappers.RecordEpisodeStatistics(TrueStateEstimate(env))  # deeper in the chain
    auto = LQRPolicy.for_env(wrapped)
    on_state = LQRPolicy.for_env(env, observed="state")
    obs, info = wrapped.reset(seed=0)
    assert obs.shape == (len(info["state"]) + 1,)
    np.testing.assert_array_equal(auto.predict(obs)[0],
                                  on_state.predict(obs[:-1].astype(float))[0])
    with pytest.raises(ValueError, match="do not start with the model's"):
        LQRPolicy.for_env(TrueStateEstimate(env, names=("x", "y")))


def test_auto_without_an_estimator_uses_the_sensors_or_says_an_estimator_is_needed():
    env = gym.make("marine_envs/USV-v0")
    obs, _ = env.reset(seed=1)
    np.testing.assert_array_equal(LQRPolicy.for_env(env).predict(obs)[0],
                                  LQRPolicy.for_env(env, observed="sensors").predict(obs)[0])
    for observed in ("auto", "sensors"):
        with pytest.raises(ValueError, match="not states.*estimator"):
            LQRPolicy.for_env(gym.make("marine_envs/DPVessel-v0"), observed=observed)


def test_continuous_flag_applies_the_continuous_gain_at_the_env_period():
    env = gym.make("marine_envs/Hydrofoil-v0")
    system = env.unwrapped.system
    A, B, _ = system.model.linearize(system.task.x_ref, system.task.u_ref)
    continuous = LQRPolicy.for_env(env, observed="state", continuous=True)
    np.testing.assert_allclose(continuous.K, lqr_gain(A, B, np.diag(system.task.q),
                                                      np.diag(system.task.r)), rtol=1e-9)
    discrete = LQRPolicy.for_env(env, observed="state")
    assert np.abs(discrete.K - continuous.K).max() > 0.01 * np.abs(continuous.K).max()


def test_integral_policy_runs_in_envs_and_in_sb3_evaluation():
    from stable_baselines3.common.evaluation import evaluate_policy
    from stable_baselines3.common.monitor import Monitor

    env = gym.make("marine_envs/USV-v0", max_episode_steps=100)
    policy = LQRPolicy.for_env(env, integral={"psi": 50.0})
    episode = run_episode(env, policy, 100, seed=0)
    assert not episode.terminated and np.all(np.abs(episode.actions) <= 1)
    policy.reset()
    mean, _ = evaluate_policy(policy, Monitor(env), n_eval_episodes=2)  # passes episode_start
    assert np.isfinite(mean) and mean < 0
    vector = gym.make_vec("marine_envs/USV-v0", num_envs=3, vectorization_mode="vector_entry_point")
    obs, _ = vector.reset(seed=0)
    policy.reset()
    actions, _ = policy.predict(obs, episode_start=np.ones(3, dtype=bool))
    assert actions.shape == (3, 1) and policy.integral_state.shape == (3, 1)


def test_bad_inputs_name_the_problem():
    A, B, I2, I1 = np.array([[0.0, 1.0], [0.0, 0.0]]), np.array([[0.0], [1.0]]), np.eye(2), \
        np.eye(1)
    with pytest.raises(ValueError, match="shapes"):
        lqr_gain(np.eye(2), np.ones((3, 1)), np.eye(2), np.eye(1))
    with pytest.raises(ValueError, match="R must be positive definite"):
        lqr_gain(A, B, I2, np.zeros((1, 1)))
    with pytest.raises(ValueError, match="Q must be positive semi-definite"):
        lqr_gain(A, B, -I2, I1)
    with pytest.raises(ValueError, match="Q must be symmetric"):
        lqr_gain(A, B, [[1.0, 1.0], [0.0, 1.0]], I1)
    with pytest.raises(ValueError, match="A has non-finite"):
        lqr_gain([[np.nan, 0.0], [0.0, 0.0]], B, I2, I1)
    with pytest.raises(ValueError, match="dt"):
        lqr_gain(A, B, I2, I1, dt=0.0)
    # an unstable mode the input cannot reach, continuous and discrete
    unreachable = np.diag([1.0, -1.0])
    for dt in (None, 0.1):
        with pytest.raises(ValueError, match=r"not stabilisable: the mode at [\d.]+ \(in states "
                                             r"\[0\]\)"):
            lqr_gain(unreachable, B, I2, I1, dt=dt)
    # an integrator Q does not weigh: scipy returns a non-stabilising "solution"
    with pytest.raises(ValueError, match=r"marginal mode at 0 \(in states \[0\]\) is not "
                                         "weighted"):
        lqr_gain([[0.0, 0.0], [0.0, -1.0]], [[1.0], [1.0]], np.diag([0.0, 1.0]), I1)
    # integrating a state the input cannot move
    with pytest.raises(ValueError, match="not stabilisable"):
        lqr_integral(np.diag([-1.0, -1.0]), [[1.0], [0.0]], I2, I1, [1], [1.0])
    model = get_model("usv")
    with pytest.raises(ValueError, match=r"'usv' \(design states .*'integral of phi'\]\): "
                                         r"integral action on states \[2, 4\] is not "
                                         "stabilisable: the 1 input"):
        LQRPolicy.for_model(model, {"psi": 1.0}, [1.0], dt=0.1, integral={"psi": 1, "phi": 1})
    with pytest.raises(ValueError, match="integral: unknown state"):
        LQRPolicy.for_model(model, {"psi": 1.0}, [1.0], dt=0.1, integral={"heading": 1.0})
    with pytest.raises(ValueError, match="weights must be finite and > 0"):
        LQRPolicy.for_model(model, {"psi": 1.0}, [1.0], dt=0.1, integral={"psi": 0.0})
    with pytest.raises(ValueError, match="integral action needs dt"):
        LQRPolicy.for_model(model, {"psi": 1.0}, [1.0], integral={"psi": 1.0})
    with pytest.raises(ValueError, match="Q: unknown name"):
        LQRPolicy.for_model(model, {"yaw": 1.0}, [1.0])
    with pytest.raises(ValueError, match="R has shape"):
        LQRPolicy.for_model(model, {"psi": 1.0}, [1.0, 1.0])
    env = gym.make("marine_envs/USV-v0")
    with pytest.raises(ValueError, match=r"integral action on \['v'\] needs them observed"):
        LQRPolicy.for_env(env, observed="sensors", integral={"v": 1.0})
    with pytest.raises(ValueError, match="observed='estimate' is invalid"):
        LQRPolicy.for_env(env, observed="estimate")
    policy = LQRPolicy.for_env(env, integral={"psi": 1.0})
    with pytest.raises(ValueError, match=r"observation has shape \(5,\); expected \(4,\)"):
        policy.predict(np.zeros(5))
    with pytest.raises(ValueError, match="NaN"):
        policy.predict(np.array([0.0, np.nan, 0.0, 0.0]))
    with pytest.raises(ValueError, match="episode_start has 2 entries"):
        policy.predict(np.zeros((3, 4)), episode_start=[True, False])


def test_excitation_signals():
    sine = Sine(1, 0.1, amplitude=0.5, period=2.0)
    values = [sine.predict()[0][0] for _ in range(20)]
    assert max(values) == pytest.approx(0.5, abs=1e-6) and min(values) == pytest.approx(-0.5)
    prbs = RandomSteps(2, 0.1, amplitude=0.4, hold=1.0, binary=True, seed=1)
    levels = np.array([prbs.predict()[0] for _ in range(100)])
    np.testing.assert_allclose(np.abs(levels), 0.4)
    assert (np.diff(levels[:, 0]) != 0).sum() <= 10  # held for 1 s = 10 steps
    again = RandomSteps(2, 0.1, amplitude=0.4, hold=1.0, binary=True, seed=1)
    np.testing.assert_array_equal(levels, [again.predict()[0] for _ in range(100)])
    assert np.all(Zero(3, 0.1).predict()[0] == 0)
    with pytest.raises(ValueError, match="amplitude"):
        Sine(1, 0.1, amplitude=2.0)
