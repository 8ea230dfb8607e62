"""One name a policy: every place that takes a policy by name takes the registry's names, and
an old name resolves to exactly one policy (with a warning)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import marine_envs
from agents import policies
from agents.benchmark.grid import CONTROLLERS, SB3_ALGOS, Grid
from agents.episode import EPISODE_POLICIES
from agents.evaluation import evaluate
from agents.excitation import Zero
from agents.policies import ALIASES, POLICIES, DeprecatedPolicyName, canonical, names
from agents.simulate import POLICIES as SIMULATE_POLICIES
from agents.simulate import simulate

USV = "marine_envs/USV-v0"


def test_each_name_resolves_to_exactly_one_policy():
    assert not set(ALIASES) & set(POLICIES)
    for name in POLICIES:
        assert canonical(name) == name
    for old, new in ALIASES.items():
        with pytest.warns(DeprecatedPolicyName, match=f"'{old}' is now called '{new}'"):
            assert canonical(old) == new
    with pytest.raises(ValueError, match="unknown policy 'bogus'"):
        canonical("bogus")


def test_every_place_that_names_policies_takes_the_registrys_names():
    assert EPISODE_POLICIES == names()
    assert set(SIMULATE_POLICIES) == set(names()) - {policies.LQR_STATE}
    assert [c for c in CONTROLLERS if c not in SB3_ALGOS] == sorted(names(batched=True))
    with pytest.warns(DeprecatedPolicyName):
        assert Grid(controllers=("zero", "lqr")).controllers == ("nominal", "lqr")
    with pytest.raises(ValueError, match="'lqr', 'nominal' or a factory"):
        evaluate(USV, "sine", seeds=1)  # one boat at a time only: refused before any work


@pytest.mark.parametrize("env_id", marine_envs.ENVIRONMENTS)
def test_the_do_nothing_baseline_is_one_policy_with_the_old_excitations_actions(env_id):
    env = gym.make(env_id)
    nominal = policies.make_policy("nominal", env)
    with pytest.warns(DeprecatedPolicyName):
        old_name = policies.make_policy("zero", env)
    zero = Zero(env.action_space.shape[0], env.unwrapped.dt)  # what "zero" was
    system = env.unwrapped.system
    zero.centre = system.actuation.nominal_action(system.model)
    obs = env.observation_space.sample()
    for policy in (nominal, old_name):
        action, _ = policy.predict(obs)
        assert action.dtype == np.float32
        assert action.tobytes() == zero.predict(obs)[0].tobytes()
    batch, _ = nominal.predict(np.stack([obs, obs, obs]))  # and a batch of boats
    assert batch.shape == (3, env.action_space.shape[0])
    with pytest.raises(ValueError, match="policy 'nominal' takes no options"):
        policies.make_policy("nominal", env, amplitude=0.3)


def test_a_recording_names_the_policy_by_its_one_name():
    new = simulate(USV, 20, seed=3, policy="nominal")
    with pytest.warns(DeprecatedPolicyName):
        old = simulate(USV, 20, seed=3, policy="zero")
    assert old.meta["policy"] == new.meta["policy"] == "nominal"
    assert np.array_equal(old.inputs, new.inputs)
    assert np.array_equal(old.measurements, new.measurements)
    with pytest.raises(ValueError, match="unknown policy 'lqr-state'"):
        simulate(USV, 20, seed=3, policy="lqr-state")  # sees the true state: not a trial's
