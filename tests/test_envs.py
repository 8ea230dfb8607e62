"""Every environment and its native vector twin: API conformance, equality, reproducibility,
bad input, and each vehicle's task and events."""

import math
import pickle
import warnings

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from gymnasium.vector import SyncVectorEnv
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import marine_envs
from agents.evaluation import run_episode
from agents.lqr import LQRPolicy
from agents.policies import OnTrueState, make_policy
from marine_envs import ENVIRONMENTS, MarineEnv, MarineVectorEnv
from marine_envs.envs import task_weights
from marine_envs.models.rov import THRUSTER_ALLOCATION

# settings per environment that exercise every random and stateful sensor stage
BUSY = {
    "marine_envs/USV-v0": {"dropout": {"psi": 0.2}, "delay": {"r": 2}, "sample_period": {"p": 3}},
    "marine_envs/Hydrofoil-v0": {"dropout": {"theta": 0.2}, "delay": {"xi": 2},
                                 "sample_period": {"xi_dot": 3}},
    "marine_envs/ROV-v0": {"dropout": {"z": 0.2}, "delay": {"psi": 1}, "morph_time": 5.0},
    "marine_envs/DPVessel-v0": {"dropout": {"north": 0.3}, "delay": {"psi": 2},
                                "sample_period": {"east": 2}},
    "marine_envs/Hovercraft-v0": {"dropout": {"v": 0.2}, "sample_period": {"u": 2}},
}
IDS = list(ENVIRONMENTS)


def run(env, actions, seed):
    """(observations, rewards, terminated, truncated, true states) of an episode as arrays."""
    obs, info = env.reset(seed=seed)
    observations, states, steps = [obs], [np.array(info["state"])], []
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        observations.append(obs)
        states.append(np.array(info["state"]))
        steps.append((reward, terminated, truncated))
    rewards, terminated, truncated = (np.array(c) for c in zip(*steps, strict=True))
    return np.array(observations), rewards, terminated, truncated, np.array(states)


@pytest.mark.parametrize("env_id", IDS)
def test_gymnasium_and_sb3_env_checkers_pass(env_id):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the checkers report problems as warnings
        check_env(gym.make(env_id, render_mode="rgb_array").unwrapped, skip_render_check=False)
        check_env(gym.make(env_id, **BUSY[env_id]).unwrapped)
    sb3_check_env(gym.make(env_id, **BUSY[env_id]).unwrapped, warn=True)


@pytest.mark.parametrize("env_id", IDS)
def test_vector_twin_steps_exactly_like_single_envs(env_id):
    n, steps, horizon = 3, 280, 120  # two auto-resets and a refill of the 256-step blocks
    env = gym.make(env_id)
    rng = np.random.default_rng(7)
    # small actions around the middle: most vehicles survive them, so both ends are exercised
    actions = rng.uniform(-0.3, 0.3, size=(steps, n, *env.action_space.shape)).astype(np.float32)
    kwargs = dict(max_episode_steps=horizon, **BUSY[env_id])
    vector = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point", **kwargs)
    singles = SyncVectorEnv([lambda: gym.make(env_id, **kwargs) for _ in range(n)])
    obs_v, rew_v, term_v, trunc_v, state_v = run(vector, actions, seed=11)
    obs_s, rew_s, term_s, trunc_s, state_s = run(singles, actions, seed=11)
    assert (trunc_v | term_v).sum() >= n  # the comparison crossed episode boundaries
    np.testing.assert_array_equal(trunc_v, trunc_s)
    np.testing.assert_array_equal(term_v, term_s)
    np.testing.assert_allclose(state_v, state_s, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(obs_v, obs_s, rtol=1e-6, atol=1e-6)
    np.testing.assert_allclose(rew_v, rew_s, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("env_id", IDS)
def test_same_seed_same_episode_other_seed_other_episode(env_id):
    env = gym.make(env_id)
    actions = np.zeros((100, *env.action_space.shape), dtype=np.float32)
    first, again, other = (run(gym.make(env_id), actions, seed=s) for s in (3, 3, 4))
    for a, b in zip(first, again, strict=True):
        np.testing.assert_array_equal(a, b)
    assert not np.allclose(first[4], other[4])
    assert not np.allclose(first[0], other[0])


@pytest.mark.parametrize("env_id", IDS)
def test_bad_actions_raise_and_lose_nothing(env_id):
    env = gym.make(env_id)
    env.reset(seed=0)
    good = np.zeros(env.action_space.shape, dtype=np.float32)
    env.step(good)
    sim = env.unwrapped._sim
    before = sim.x.copy(), sim.u.copy(), sim.steps.copy()
    for bad in (np.nan, np.inf):
        action = good.copy()
        action[-1] = bad
        with pytest.raises(ValueError, match="action contains NaN or inf"):
            env.step(action)
    with pytest.raises(ValueError, match="action has shape"):
        env.step(np.zeros(good.size + 1, dtype=np.float32))
    for now, then in zip((sim.x, sim.u, sim.steps), before, strict=True):
        np.testing.assert_array_equal(now, then)
    env.step(good)  # still usable


@pytest.mark.parametrize("env_id", IDS)
def test_reward_is_minus_the_stage_cost_and_observation_is_the_sensors(env_id):
    env = gym.make(env_id, noise_std=0.0, quantization={})
    system = env.unwrapped.system
    obs, info = env.reset(seed=2)
    model = system.model
    outputs = model.output(info["state"][None])[0]
    channels = [model.output_names.index(c) for c in system.sensors.channels]
    np.testing.assert_allclose(obs, outputs[channels].astype(np.float32), atol=1e-6)
    rng = np.random.default_rng(0)
    for _ in range(3):
        x = info["state"].copy()
        _, reward, _, _, info = env.step(rng.uniform(-0.5, 0.5, env.action_space.shape))
        task = system.task
        e, v = x - task.x_ref, info["action_applied"] - task.u_ref
        assert reward == pytest.approx(-(e @ (task.q * e) + v @ (task.r * v)), rel=1e-9)


@pytest.mark.parametrize("env_id", IDS)
def test_bad_arguments_name_the_problem(env_id):
    with pytest.raises(ValueError, match="noise_std: unknown channel"):
        gym.make(env_id, noise_std={"nonsense": 1.0})
    with pytest.raises(ValueError, match="unknown parameter"):
        gym.make(env_id, params={"nonsense": 1.0})
    with pytest.raises(ValueError, match="unknown argument.*noise_sd"):
        gym.make(env_id, noise_sd=0.1)
    with pytest.raises(ValueError, match="options\\['state'\\]"):
        gym.make(env_id).reset(seed=0, options={"state": [0.0]})


@pytest.mark.parametrize("env_id", [i for i in IDS if i != "marine_envs/USV-v0"])
def test_lqr_on_the_true_state_does_the_task_better_than_doing_nothing(env_id):
    """The task is achievable and its cost meaningful: LQR (from the model's linearisation, on
    the task's weights) beats the neutral action, and keeps the vehicle alive."""
    env = gym.make(env_id, max_episode_steps=300)
    lqr = OnTrueState(env, LQRPolicy.for_env(env, observed=None))
    idle = make_policy("nominal", env, seed=None)  # the nominal input, open loop
    controlled = run_episode(env, lqr, 300, seed=5)
    neutral = run_episode(env, idle, 300, seed=5)
    assert not controlled.terminated
    assert controlled.episode_return > neutral.episode_return


def test_hydrofoil_linear_and_nonlinear_agree_near_trim():
    kwargs = dict(noise_std=0.0, hs=0.05, initial_spread={}, disturbance_seed=1)
    actions = np.zeros((200, 2), dtype=np.float32)
    trim = gym.make("marine_envs/Hydrofoil-v0").unwrapped.model.u0
    low, high = gym.make("marine_envs/Hydrofoil-v0").unwrapped.model.u_bounds
    actions[:] = (trim - (low + high) / 2) / ((high - low) / 2)  # hold the trim foil angles
    nonlinear = run(gym.make("marine_envs/Hydrofoil-v0", **kwargs), actions, seed=0)[4]
    linear = run(gym.make("marine_envs/Hydrofoil-v0", model="linear", **kwargs), actions,
                 seed=0)[4]
    assert np.abs(nonlinear[:, 1] - nonlinear[0, 1]).max() > 1e-4  # the sea moved it
    np.testing.assert_allclose(linear[:, :2], nonlinear[:, :2], atol=2e-3)


def test_rov_morph_event_changes_the_shape_at_the_given_time():
    env = gym.make("marine_envs/ROV-v0", morph_time=3.0)
    _, info = env.reset(seed=0)
    s, commands = [], []
    for _ in range(100):
        _, _, _, _, info = env.step(np.zeros(6, dtype=np.float32))
        s.append(info["state"][-1])
        commands.append(info["disturbance"][-1])
    commands = np.array(commands)
    assert commands[29] == 0.0 and commands[30] == 1.0  # the command comes at 3.0 s
    time_constant = env.unwrapped.model.params.T_m
    # first-order response: 1 - exp(-t/T_m) after the command
    assert s[29 + 50] == pytest.approx(1 - math.exp(-5.0 / time_constant), abs=0.02)


def test_rov_thruster_actions_pass_through_the_allocation_matrix():
    env = gym.make("marine_envs/ROV-v0", actuation="thrusters")
    assert env.action_space.shape == (6,)
    env.reset(seed=0)
    action = np.array([1.0, -1.0, 0.5, 0.0, -0.5, 1.0], dtype=np.float32)
    info = env.step(action)[4]
    low, high = env.unwrapped.system.actuation.low, env.unwrapped.system.actuation.high
    forces = (low + high) / 2 + (high - low) / 2 * action
    np.testing.assert_allclose(info["action_applied"], THRUSTER_ALLOCATION @ forces)
    assert info["action_applied"][3] == 0.0  # no roll authority


def test_dp_drive_off_terminates():
    env = gym.make("marine_envs/DPVessel-v0", max_offset=5.0, initial_spread={})
    env.reset(seed=0)
    for _ in range(400):
        _, _, terminated, _, info = env.step(np.array([1.0, 0.0, 0.0], dtype=np.float32))
        if terminated:
            break
    assert terminated and abs(info["state"][0]) > 5.0


@pytest.mark.parametrize("test", ["5/5", "25/25"])
def test_hovercraft_zigzag_mode_runs_the_manoeuvre_whatever_the_actions(test):
    amplitude = float(test.split("/")[0])
    env = gym.make("marine_envs/Hovercraft-v0", zigzag=test, wind_speed=0.0, wind_gust=0.0,
                   initial_spread={})
    env.reset(seed=0)
    rudder, heading = [], []
    rng = np.random.default_rng(0)
    for _ in range(600):
        info = env.step(rng.uniform(-1, 1, 3).astype(np.float32))[4]
        rudder.append(math.degrees(info["action_applied"][2]))
        heading.append(math.degrees(info["state"][5]))
    assert set(np.round(rudder, 9)) == {amplitude, -amplitude}
    assert max(heading) > amplitude and min(heading) < -amplitude  # it overshoots both ways
    with pytest.raises(ValueError, match="zigzag"):
        gym.make("marine_envs/Hovercraft-v0", zigzag="20 by 20")


def test_dp_vessel_in_a_calm_sea_starts_without_wave_motion():
    env = gym.make("marine_envs/DPVessel-v0", params={"sigma_eta": [0.0, 0.0, 0.0]})
    _, info = env.reset(seed=0)
    assert np.all(info["state"][9:15] == 0)


@pytest.mark.parametrize("env_id", IDS)
def test_each_vector_twin_is_made_by_the_one_factory_and_exported(env_id):
    module, prefix, steps = ENVIRONMENTS[env_id]
    single, twin = getattr(marine_envs, f"{prefix}Env"), getattr(marine_envs, f"{prefix}VectorEnv")
    assert issubclass(twin, MarineVectorEnv) and issubclass(single, MarineEnv)
    assert twin.__module__ == single.__module__ == f"marine_envs.envs.{module}"
    assert pickle.loads(pickle.dumps(twin)) is twin  # importable by name (SB3, Ray)
    assert f":class:`{prefix}Env`" in twin.__doc__
    venv = twin(num_envs=2)
    assert venv.max_episode_steps == steps and venv.num_envs == 2
    with pytest.raises(ValueError, match="unknown argument"):
        twin(num_envs=2, not_an_option=1)


def test_task_weights_are_the_environments_cost():
    for model, env_id in (("usv", "USV"), ("rov", "ROV"), ("dp_vessel", "DPVessel")):
        q, r = task_weights(model)
        system = gym.make(f"marine_envs/{env_id}-v0").unwrapped.system
        np.testing.assert_array_equal(system.task.q,
                                      [q.get(n, 0.0) for n in system.model.state_names])
    with pytest.raises(ValueError, match="has no environment"):
        task_weights("nomoto")
