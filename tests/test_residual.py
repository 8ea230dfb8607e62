"""Residual RL: a bounded correction to the LQR on the same estimate, starting at nothing."""

from __future__ import annotations

import json

import numpy as np
import pytest
from stable_baselines3 import SAC, TD3

import marine_envs  # noqa: F401  (registers the environments)
from agents import evaluation
from agents.cli import main
from agents.sb3 import VALIDATION_SEED, load_agent, load_hyperparams, make_vec_env, settings, train
from agents.sb3.residual import ResidualVectorEnv, combine, zero_output

USV = "marine_envs/USV-v0"
SMALL = {"n_steps": 128, "batch_size": 128, "n_epochs": 2, "residual": "lqr",
         "validation_episodes": 2}


def _costs(rows):
    return [row["cost"] for row in rows]


def test_the_correction_is_bounded_and_clipped():
    base = np.array([[0.9, -0.2]], dtype=np.float32)
    np.testing.assert_allclose(combine(base, np.array([[1.0, -5.0]]), 0.5), [[1.0, -0.7]])
    np.testing.assert_allclose(combine(base, np.zeros((1, 2)), 0.5), base)


def test_an_untrained_residual_agent_is_the_lqr_and_validation_starts_from_it(tmp_path):
    out = tmp_path / "run"
    result = train(USV, "ppo", "kf", timesteps=512, out=out, n_envs=2, progress_bar=False,
                   max_episode_steps=60, hyperparams={**SMALL, "learning_rate": 1e-12})
    history = json.loads((out / "config.json").read_text())["validation"]["history"]
    assert history[0]["timesteps"] == 0
    seeds = range(VALIDATION_SEED, VALIDATION_SEED + 2)
    lqr = evaluation.evaluate(USV, "lqr", "kf", seeds, max_episode_steps=60)
    assert history[0]["cost"] == pytest.approx(np.mean(_costs(lqr)), rel=1e-12)
    agent = load_agent(out)
    assert agent.kind == "residual_ppo" and result.selected is not None
    # a learning rate of 1e-12 learns nothing: on fresh seeds the agent acts as the LQR does
    rows = evaluation.evaluate(USV, agent, "kf", range(7, 10), max_episode_steps=60)
    lqr = evaluation.evaluate(USV, "lqr", "kf", range(7, 10), max_episode_steps=60)
    np.testing.assert_allclose(_costs(rows), _costs(lqr), rtol=1e-5)


def test_a_trained_correction_changes_the_action_within_its_bound(tmp_path):
    out = tmp_path / "run"
    train(USV, "ppo", "kf", timesteps=1024, out=out, n_envs=2, progress_bar=False,
          max_episode_steps=60, hyperparams={**SMALL, "learning_rate": 3e-3,
                                             "residual_scale": 0.2})
    agent = load_agent(out.joinpath("last_model.zip"))
    venv = evaluation.make_env(USV, 4, "kf", max_episode_steps=60)
    obs, _ = venv.reset(seed=3)
    policy = agent(venv)
    start = np.ones(4, dtype=bool)
    lqr, _ = policy.base.predict(obs, episode_start=start)
    action, _ = policy.predict(obs, episode_start=start)
    moved = np.abs(action - lqr)
    assert moved.max() > 0 and moved.max() <= 0.2 + 1e-6


def test_the_wrapper_restarts_the_controller_with_each_episode():
    """The LQR's memory restarts on boats whose episode starts: at the reset, after the env's
    next-step autoreset, and at a same-step restart (SB3's adapter)."""

    class Recorder:
        def __init__(self):
            self.starts = []

        def predict(self, obs, state=None, episode_start=None, deterministic=True):
            self.starts.append(np.array(episode_start))
            return np.zeros((len(obs), 1), dtype=np.float32), None

    native = evaluation.make_env(USV, 2, "kf", max_episode_steps=3)
    base = Recorder()
    env = ResidualVectorEnv(native, base, 0.5)
    env.reset(seed=0)
    for _ in range(5):
        env.step(np.zeros((2, 1), dtype=np.float32))
    env.restart(np.array([1]))
    env.step(np.zeros((2, 1), dtype=np.float32))
    starts = np.array(base.starts)
    # episodes of 3 steps: ended at step 3, reset by the env at step 4, so step 5 starts anew
    np.testing.assert_array_equal(starts[:, 0], [True, False, False, False, True, False])
    np.testing.assert_array_equal(starts[:, 1], [True, False, False, False, True, True])


@pytest.mark.parametrize("algo", [SAC, TD3])
def test_an_off_policy_actor_starts_at_no_correction(algo):
    venv = make_vec_env(USV, 1, "kf", max_episode_steps=20)
    model = algo("MlpPolicy", venv, seed=0, device="cpu", learning_starts=0,
                 policy_kwargs={"net_arch": [16, 16]})
    zero_output(model)
    obs = np.random.default_rng(0).normal(size=(5, *venv.observation_space.shape))
    action, _ = model.predict(obs.astype(np.float32), deterministic=True)
    np.testing.assert_array_equal(action, 0.0)


def test_residual_settings_come_from_their_own_yaml_entry(tmp_path):
    path = tmp_path / "h.yaml"
    path.write_text("default:\n  ppo: {n_timesteps: 1000, n_envs: 2, policy: MlpPolicy}\n"
                    "  residual_ppo: {n_timesteps: 500, n_envs: 2, policy: MlpPolicy, "
                    "residual: lqr, residual_scale: 0.3, learning_rate: 1.0e-4}\n")
    assert load_hyperparams(USV, "ppo", path)["n_timesteps"] == 1000
    own = load_hyperparams(USV, "ppo", path, residual=True)
    assert own["residual_scale"] == 0.3 and own["n_timesteps"] == 500
    config = settings(USV, "ppo", "kf", hyperparams={"residual": "lqr"}, hyperparams_file=path)
    assert config["hyperparams"]["learning_rate"] == 1e-4
    # an algorithm without a residual entry takes its own settings
    config = settings(USV, "a2c", "kf", hyperparams={"residual": "lqr"})
    assert config["hyperparams"]["residual"] == "lqr"


@pytest.mark.parametrize(("text", "message"), [
    ("default:\n  residual_pop: {n_timesteps: 5}\n", "unknown algorithm 'residual_pop'"),
    ("default:\n  ppo: {residual: pid}\n", "residual='pid' is invalid: one of lqr"),
    ("default:\n  ppo: {residual_scale: 3.0}\n", "residual_scale=3.0 is invalid"),
])
def test_bad_residual_settings_are_named(tmp_path, text, message):
    path = tmp_path / "h.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        load_hyperparams(USV, "ppo", path)


def test_a_residual_needs_the_native_backend():
    with pytest.raises(ValueError, match="needs backend='native'"):
        make_vec_env(USV, 1, "kf", backend="dummy", residual="lqr")


def test_cli_refuses_a_scale_without_a_residual(tmp_path, capsys):
    with pytest.raises(SystemExit) as exit_:
        main(["train", USV, "--out", str(tmp_path / "r"), "--residual-scale", "0.3"])
    assert exit_.value.code == 2
    assert "--residual-scale needs --residual" in capsys.readouterr().err
