"""The effect catalogue compiled: state terms in a model's equations, input effects per boat and
environments with effects in the step kernel, equal to the numpy implementations they replaced
(recorded in tests/data/effects_reference.npz by make_effects_reference.py at b31a8e0, and
the numpy path of a diagnosed vessel in step_reference.npz by make_step_reference.py)."""

import json
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import marine_envs  # noqa: F401 - registers the environments
from marine_envs.models import get_model
from marine_envs.models.base import LinearizedModel
from marine_envs.models.effects import (
    ActuatorStream,
    BatchActuators,
    Effect,
    EffectModel,
    state_term,
)

REFERENCE = np.load(Path(__file__).parent / "data" / "effects_reference.npz")
SPEC = json.loads(str(REFERENCE["spec"]))
sys.path.insert(0, str(Path(__file__).parent / "data"))
import make_effects_reference as recorded  # noqa: E402
import make_step_reference as episodes  # noqa: E402

STEPS = np.load(Path(__file__).parent / "data" / "step_reference.npz")

effects = recorded.effects


@pytest.mark.parametrize("name", list(SPEC["state_terms"]))
def test_compiled_state_terms_equal_the_numpy_terms_they_replaced(name):
    model, entries = get_model(name), SPEC["state_terms"][name]
    x, u, d = (REFERENCE[f"terms/{name}/{k}"] for k in "xud")
    together = EffectModel(model, effects(entries))
    assert together.equations is not None  # compiled: the kernel can step it
    np.testing.assert_array_equal(together.rhs(x, u, d), REFERENCE[f"terms/{name}/rhs"])
    for k, entry in enumerate(entries):
        alone = EffectModel(model, effects([entry]))
        np.testing.assert_array_equal(alone.rhs(x, u, d), REFERENCE[f"terms/{name}/{k}"])
        one_boat = alone.rhs(x[3], u[3], d[3])
        np.testing.assert_array_equal(one_boat, REFERENCE[f"terms/{name}/{k}"][3])


def test_a_model_without_compiled_equations_adds_the_terms_in_numpy():
    nominal = get_model("usv")
    host = LinearizedModel(nominal, nominal.x0, nominal.u0)  # a numpy rhs of its own
    damping = Effect("quadratic_damping", "p", {"c": -1.0})
    model = EffectModel(host, [damping])
    assert model.equations is None
    x, u = np.random.default_rng(1).normal(size=(5, 5)), np.zeros((5, 1))
    expected = host.rhs(x, u)
    expected[:, 3] += state_term(damping, host, x, u, 0.0)
    np.testing.assert_array_equal(model.rhs(x, u), expected)
    env = gym.make("marine_envs/USV-v0", effects=[damping])
    assert env.unwrapped._sim.compiled  # the USV's own equations are compiled


@pytest.mark.parametrize("dt", [0.1, 0.05])
def test_input_effects_equal_the_python_streams_they_replaced(dt):
    usv, commanded = get_model("usv"), REFERENCE[f"inputs/{dt}/commanded"]
    for k, chain in enumerate(SPEC["chains"]):
        stream = ActuatorStream(usv, effects(chain), dt)
        np.testing.assert_array_equal([stream.step(c) for c in commanded],
                                      REFERENCE[f"inputs/{dt}/stream/{k}"], err_msg=str(chain))
        rows = recorded.batch_rows(BatchActuators(usv, effects(chain), dt), commanded)
        np.testing.assert_array_equal(rows, REFERENCE[f"inputs/{dt}/batch/{k}"], err_msg=str(chain))


@pytest.mark.parametrize("key", list(SPEC["envs"]))
def test_a_diagnosed_vessel_steps_compiled_as_it_stepped_in_numpy(key):
    """State terms, actuator effects and a sensor bias: the kernel runs them, and the episode
    (resets included) is the one the numpy path recorded, bit for bit."""
    env_id, entries, kwargs = SPEC["envs"][key]
    env = gym.make(env_id, effects=effects(entries), **kwargs)
    assert env.unwrapped._sim.compiled
    env.reset(seed=7)
    for k, action in enumerate(REFERENCE[f"env/{key}/actions"]):
        obs, reward, term, trunc, info = env.step(action)
        got = {"obs": obs, "reward": reward, "state": info["state"],
               "applied": info["action_applied"], "commanded": info["action_commanded"]}
        for name, value in got.items():
            np.testing.assert_array_equal(value, REFERENCE[f"env/{key}/{name}"][k],
                                          err_msg=f"{name} at step {k}")
        assert (term or trunc) == REFERENCE[f"env/{key}/ended"][k]
        if term or trunc:
            env.reset()


@pytest.mark.parametrize("in_numpy", [False, True], ids=["kernel", "numpy"])
def test_a_diagnosed_vessel_steps_as_its_numpy_path_recorded_in_numpy_too(in_numpy):
    """The numpy path of a diagnosed vessel, once a second implementation, recorded
    (make_step_reference.py): the kernel and today's numpy path give its numbers bit for bit."""
    env = episodes.usv_with_effects()
    if in_numpy:
        env = episodes.in_numpy(env)
    assert env._sim.compiled != in_numpy
    got = episodes.run(env, episodes.USV_SEED, episodes.usv_actions(env))
    for name in ("obs", "reward", "state", "action_applied", "action_commanded"):
        np.testing.assert_array_equal(got[name], STEPS[f"usv_effects/{name}"], err_msg=name)


def test_a_vector_env_with_effects_equals_n_single_ones():
    env_id, entries, kwargs = SPEC["envs"]["hovercraft"]
    n = 3
    vector = gym.make_vec(env_id, num_envs=n, vectorization_mode="vector_entry_point",
                          effects=effects(entries), **kwargs)
    singles = [gym.make(env_id, effects=effects(entries), **kwargs) for _ in range(n)]
    vector.reset(seed=20)
    for i, single in enumerate(singles):
        single.reset(seed=20 + i)
    rng = np.random.default_rng(6)
    for step in range(150):
        action = rng.uniform(-1, 1, vector.action_space.shape)
        obs, reward, *_, info = vector.step(action)
        for i, single in enumerate(singles):
            obs_i, reward_i, *_, info_i = single.step(action[i])
            np.testing.assert_array_equal(obs[i], obs_i, err_msg=f"boat {i} at step {step}")
            assert reward[i] == reward_i
            np.testing.assert_array_equal(info["action_applied"][i], info_i["action_applied"])
