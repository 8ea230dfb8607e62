"""Stable-Baselines3 glue: the native adapter matches DummyVecEnv; train, load, evaluate."""

from __future__ import annotations

import json

import gymnasium as gym
import numpy as np
import pytest
from stable_baselines3.common.vec_env import DummyVecEnv

import marine_envs  # noqa: F401  (registers the environments)
from agents.sb3 import VALIDATION_SEED, SB3VecEnv, evaluate, load_agent, make_vec_env, train
from estimators import EstimatorWrapper, KalmanFilter, wrap

USV = "marine_envs/USV-v0"


def _step_both(a, b, steps: int, seed: int = 0):
    """Feed both VecEnvs the same random actions; yield their step results."""
    rng = np.random.default_rng(seed)
    for _ in range(steps):
        actions = rng.uniform(-1, 1, (a.num_envs, *a.action_space.shape)).astype(np.float32)
        a.step_async(actions)
        b.step_async(actions)
        yield a.step_wait(), b.step_wait()


@pytest.mark.parametrize("estimator", [None, "kf"])
def test_native_matches_dummy_across_episode_end(estimator):
    kwargs = dict(n_envs=3, estimator=estimator, seed=7, max_episode_steps=10)
    native = make_vec_env(USV, backend="native", **kwargs)
    dummy = make_vec_env(USV, backend="dummy", **kwargs)
    np.testing.assert_array_equal(native.reset(), dummy.reset())
    ends = 0
    for (oa, ra, da, ia), (ob, rb, db, ib) in _step_both(native, dummy, 30):
        np.testing.assert_array_equal(da, db)
        np.testing.assert_allclose(ra, rb, rtol=1e-6)
        np.testing.assert_allclose(oa, ob, rtol=1e-6, atol=1e-6)  # after a done: reset obs
        for i in np.flatnonzero(da):
            ends += 1
            assert ia[i]["TimeLimit.truncated"] and ib[i]["TimeLimit.truncated"]
            np.testing.assert_allclose(ia[i]["terminal_observation"],
                                       ib[i]["terminal_observation"], rtol=1e-6, atol=1e-6)
            assert ia[i]["episode"]["l"] == 10
    assert ends == 9  # three episode ends of three envs


@pytest.mark.parametrize("estimator", [None, "kf"])
def test_native_restarts_one_boat_at_once(estimator):
    """Boats failing at different steps: the others run on undisturbed, the failed one starts
    over within the step (SB3's convention), with the first observation DummyVecEnv gives."""
    kwargs = dict(max_episode_steps=40, max_roll=0.03)
    vector = gym.make_vec(USV, num_envs=3, vectorization_mode="vector_entry_point", **kwargs)
    singles = [gym.make(USV, **kwargs) for _ in range(3)]
    if estimator:
        vector = wrap(vector, KalmanFilter.for_env(vector))
        singles = [EstimatorWrapper(env, KalmanFilter.for_env(env)) for env in singles]
    native = SB3VecEnv(vector)
    dummy = DummyVecEnv([lambda env=env: env for env in singles])
    native.seed(1)
    dummy.seed(1)
    native.reset()
    dummy.reset()
    restarted = np.zeros(3, dtype=bool)
    partial = 0
    for (oa, ra, da, ia), (ob, rb, db, ib) in _step_both(native, dummy, 40):
        np.testing.assert_array_equal(da, db)
        np.testing.assert_allclose(ra, rb, rtol=1e-6)  # rewards follow the true state
        np.testing.assert_array_equal(oa[~restarted], ob[~restarted])
        np.testing.assert_array_equal(oa[da], ob[da])  # the new episodes' first observations
        for i in np.flatnonzero(da):
            if not restarted[i]:  # a restarted boat's sensors sample one step late
                np.testing.assert_array_equal(ia[i]["terminal_observation"],
                                              ib[i]["terminal_observation"])
            assert ia[i]["TimeLimit.truncated"] == ib[i]["TimeLimit.truncated"]
        partial += bool(da.any() and not da.all())
        restarted |= da
    assert partial >= 2


def test_train_load_evaluate(tmp_path):
    out = tmp_path / "run"
    result = train(USV, "ppo", estimator="kf", timesteps=1024, out=out, n_envs=2,
                   progress_bar=False, hyperparams={"n_steps": 256, "batch_size": 128,
                                                    "n_epochs": 2, "learning_rate": "lin_1e-3"})
    assert result.timesteps >= 1024 and result.steps_per_second > 0
    assert (out / "model.zip").exists() and (out / "vecnormalize.pkl").exists()
    assert list((out / "checkpoints").glob("model_*_steps.zip"))
    config = json.loads((out / "config.json").read_text())
    assert config["estimator"] == "kf" and config["n_envs"] == 2
    assert config["hyperparams"]["n_steps"] == 256
    agent = load_agent(out)
    assert agent.model.lr_schedule(0.5) == pytest.approx(5e-4)  # "lin_1e-3" halfway through
    obs = np.zeros(agent.model.observation_space.shape, dtype=np.float32)
    action, _ = agent.predict(obs)
    assert action.shape == agent.model.action_space.shape
    first, second = evaluate(out, episodes=2), evaluate(out, episodes=2)
    assert [row["seed"] for row in first] == [0, 1]
    assert all(np.isfinite(row["cost"]) and row["cost"] > 0 for row in first)
    assert "estimation_rms_phi_deg" in first[0] and "rms_delta_deg" in first[0]
    assert first == second


def test_validation_keeps_the_best_agent_and_the_last(tmp_path):
    out = tmp_path / "run"
    train(USV, "ppo", estimator="kf", timesteps=2048, out=out, n_envs=2, progress_bar=False,
          hyperparams={"n_steps": 256, "batch_size": 128, "n_epochs": 2,
                       "validation_episodes": 2})
    assert (out / "last_model.zip").exists() and (out / "last_vecnormalize.pkl").exists()
    validation = json.loads((out / "config.json").read_text())["validation"]
    history, best = validation["history"], validation["selected"]
    assert [h["timesteps"] for h in history] == [410, 820, 1230, 1640, 2048]  # 4 + the end
    assert best == min(history, key=lambda h: (h["failed"], h["cost"]))
    # model.zip is the selected agent: on the validation seeds it scores what it scored then
    rows = evaluate(out, episodes=2, seed=VALIDATION_SEED)
    assert np.mean([row["cost"] for row in rows]) == pytest.approx(best["cost"], rel=1e-9)


@pytest.mark.parametrize(("kwargs", "message"), [
    ({"algo": "dqn"}, "ppo"),
    ({"estimator": "ukf"}, "akf"),
    ({"backend": "async"}, "dummy"),
    ({"timesteps": 0}, "timesteps"),
    ({"env_id": "marine_envs/Nope-v0"}, "USV-v0"),
    ({"hyperparams": {"validation_episodes": -1}}, "validation_episodes"),
    ({"hyperparams": {"learning_rate": "lin_fast"}}, "lin_3e-4"),
    ({"hyperparams": {"n_step": 64}}, r"hyperparams: unknown setting 'n_step' \(did you mean "
                                      r"'n_steps'\?\)"),
    ({"hyperparams": {"batch_size": 0}}, "hyperparams: batch_size=0 is invalid: an integer >= 1"),
    ({"hyperparams": {"normalize": "maybe"}}, "normalize='maybe' is invalid"),
])
def test_bad_input_is_refused(tmp_path, kwargs, message):
    args = {"env_id": USV, "out": tmp_path, "progress_bar": False, **kwargs}
    with pytest.raises(ValueError, match=message):
        train(**args)
    assert not (tmp_path / "model.zip").exists()


def test_cli_trains_and_evaluates(tmp_path, capsys):
    from agents.cli import main

    out = tmp_path / "cli"
    assert main(["train", USV, "--estimator", "kf", "--timesteps", "256", "--n-envs", "2",
                 "--out", str(out), "--quiet"]) == 0
    assert "saved to" in capsys.readouterr().out and (out / "model.zip").exists()
    assert main(["evaluate", str(out), "--episodes", "1", "--json", str(tmp_path / "e.json")]) == 0
    assert "cost" in capsys.readouterr().out
    assert len(json.loads((tmp_path / "e.json").read_text())["rows"]) == 1
    with pytest.raises(SystemExit) as stopped:  # argparse's own choice check
        main(["train", USV, "--algo", "dqn", "--out", str(out)])
    assert stopped.value.code == 2 and "ppo" in capsys.readouterr().err


def test_a_failure_costs_the_penalty_and_the_time_limit_does_not():
    from agents.sb3 import FailurePenalty

    venv = make_vec_env("marine_envs/Hydrofoil-v0", 2, seed=0, max_episode_steps=400)
    plain = make_vec_env("marine_envs/Hydrofoil-v0", 2, seed=0, max_episode_steps=400)
    penalised = FailurePenalty(venv, 100.0)
    penalised.reset(), plain.reset()
    action = np.zeros((2, 2), dtype=np.float32)  # foils held: the unstable craft broaches
    for _ in range(400):
        _, reward, done, infos = penalised.step(action)
        _, base, _, _ = plain.step(action)
        failed = done & ~np.array([i.get("TimeLimit.truncated", False) for i in infos])
        np.testing.assert_allclose(reward, base - 100.0 * failed, rtol=1e-6)
        if failed.any():
            break
    assert failed.any()
    with pytest.raises(ValueError, match="failure_penalty"):
        FailurePenalty(plain, -1.0)


def test_a_failure_with_cost_to_go_costs_the_rest_of_its_episode_at_its_own_rate():
    from agents.sb3 import FailurePenalty

    steps = 400
    venv = make_vec_env("marine_envs/Hydrofoil-v0", 2, seed=0, max_episode_steps=steps)
    plain = make_vec_env("marine_envs/Hydrofoil-v0", 2, seed=0, max_episode_steps=steps)
    penalised = FailurePenalty(venv, 100.0, episode_steps=steps)
    penalised.reset(), plain.reset()
    action = np.zeros((2, 2), dtype=np.float32)  # foils held: the unstable craft broaches
    cost = np.zeros(2)
    for k in range(1, steps + 1):
        _, reward, done, infos = penalised.step(action)
        _, base, _, _ = plain.step(action)
        cost -= base
        failed = done & ~np.array([i.get("TimeLimit.truncated", False) for i in infos])
        expected = base - failed * (100.0 + (steps - k) * cost / k)
        np.testing.assert_allclose(reward, expected, rtol=1e-5)
        if failed.any():
            break
    assert failed.any() and k < steps
    with pytest.raises(ValueError, match="episode_steps"):
        FailurePenalty(plain, 1.0, episode_steps=0)


def test_a_recurrent_agent_carries_its_memory_and_clears_it_at_an_episode_start(tmp_path):
    pytest.importorskip("sb3_contrib")
    out = tmp_path / "lstm"
    train(USV, "ppo_lstm", timesteps=256, out=out, n_envs=2, progress_bar=False,
          hyperparams={"n_steps": 128, "batch_size": 256, "n_epochs": 1})
    agent = load_agent(out)
    assert agent.recurrent
    obs = np.random.default_rng(0).normal(size=(3, 2, *agent.model.observation_space.shape))
    first = [agent.predict(o, episode_start=np.array([k == 0] * 2))[0] for k, o in enumerate(obs)]
    again = [agent.predict(o, episode_start=np.array([k == 0] * 2))[0] for k, o in enumerate(obs)]
    np.testing.assert_array_equal(first, again)  # the start cleared what the first run left
    # the memory matters: the same observation after another history gives another action
    agent.predict(obs[1], episode_start=np.array([True, True]))
    other = agent.predict(obs[0])[0]
    assert not np.array_equal(other, first[0])
    # a batch of another size starts afresh rather than failing on the old memory's shape
    action, _ = agent.predict(obs[0][:1], episode_start=np.array([True]))
    assert action.shape == (1, *agent.model.action_space.shape)


def test_an_algorithm_of_a_missing_extra_is_named(monkeypatch):
    from agents import sb3

    monkeypatch.setitem(sb3.ALGOS, "ppo_lstm", "no_such_module:RecurrentPPO")
    with pytest.raises(ValueError, match=r"needs no-such-module: pip install .*\[recurrent\]"):
        sb3.algorithm("ppo_lstm")
