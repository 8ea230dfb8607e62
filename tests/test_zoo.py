"""The zoo of shipped agents: published from a finished run, loaded by name, listed, re-trained
from its YAML alone; and every agent the repository ships loads and runs a full episode."""

import json
import math

import gymnasium as gym
import numpy as np
import pytest
import yaml

from agents import evaluation
from agents.cli import main
from agents.sb3 import Agent, agent_section, evaluate, load_agent, train, zoo

USV = "marine_envs/USV-v0"
TINY = {"n_steps": 256, "batch_size": 256, "n_epochs": 2}
SCORES = {"tuning": {"seeds": list(range(1000, 1010)), "cost_ratio": 0.97, "cost": 9.7,
                     "lqr_cost": 10.0, "failed": 0}}


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A finished PPO run on the USV behind kf: 2048 steps, 4 boats."""
    out = tmp_path_factory.mktemp("run") / "USV-ppo-kf-seed0"
    train(USV, "ppo", estimator="kf", timesteps=2048, out=out, n_envs=4, progress_bar=False,
          hyperparams=TINY)
    return out


@pytest.fixture
def shipped(tiny_run, tmp_path, monkeypatch):
    """The tiny run published into a zoo of its own (``agents/zoo`` under ``tmp_path``), which
    the library and ``marine`` then use."""
    folder = tmp_path / "agents" / "zoo"
    monkeypatch.setattr(zoo, "ZOO", folder)
    return zoo.publish(tiny_run, SCORES)


def test_publish_ships_the_agent_small_and_described(shipped, tiny_run, tmp_path):
    assert shipped.name == "zoo:USV-v0/ppo" and zoo.names() == ["zoo:USV-v0/ppo"]
    assert shipped.path == tmp_path / "agents" / "zoo" / "USV-v0" / "ppo"
    assert sorted(p.name for p in shipped.path.iterdir()) == \
        ["card.json", "config.json", "model.zip", "vecnormalize.pkl"]  # no checkpoints, tb
    config = json.loads((shipped.path / "config.json").read_text())
    assert config["hyperparams_file"] == "agents/zoo/USV-v0/ppo.yaml"  # no path of this machine
    assert str(tmp_path) not in (shipped.path / "config.json").read_text()
    card = json.loads((shipped.path / "card.json").read_text())
    trained = json.loads((tiny_run / "config.json").read_text())
    assert card["env_id"] == USV and card["kind"] == "ppo" and card["estimator"] == "kf"
    assert card["seed"] == 0 and card["timesteps"] == trained["timesteps"] >= 2048
    assert card["wall_seconds"] == trained["wall_seconds"] > 0
    assert card["steps_per_second"] == pytest.approx(card["timesteps"] / card["wall_seconds"])
    assert card["machine"]["cpu_count"] >= 1 and card["machine"]["platform"]
    assert card["trained"][:4].isdigit() and card["scores"] == SCORES
    assert zoo.entries()[0].card == card


def test_a_published_agent_loads_by_name_and_evaluates(shipped, tiny_run, capsys):
    agent = load_agent("zoo:USV-v0/ppo")
    assert Agent.load("zoo:USV-v0/ppo").config["env_id"] == USV
    trained = load_agent(tiny_run)
    obs = np.linspace(-1, 1, agent.model.observation_space.shape[0]).astype(np.float32)
    np.testing.assert_array_equal(agent.predict(obs)[0], trained.predict(obs)[0])
    rows = evaluate("zoo:USV-v0/ppo", episodes=1, seed=3)
    assert rows == evaluate(tiny_run, episodes=1, seed=3)  # the same agent, the same numbers
    assert math.isfinite(rows[0]["cost"]) and not rows[0]["failed"]
    assert main(["evaluate", "zoo:USV-v0/ppo", "--episodes", "1", "--seed", "3",
                 "--quiet"]) == 0
    assert f"{rows[0]['cost']:.5g}" in capsys.readouterr().out


def test_marine_zoo_lists_the_agents_with_their_scores(shipped, tmp_path, capsys):
    assert main(["zoo", "--json", str(tmp_path / "zoo.json")]) == 0
    out = capsys.readouterr().out
    line = next(line for line in out.splitlines() if line.startswith("zoo:USV-v0/ppo"))
    assert line.split()[:5] == ["zoo:USV-v0/ppo", "USV-v0", "ppo", "kf",
                                str(shipped.card["timesteps"])]
    assert "0.97 (10 seeds)" in line and line.rstrip().endswith("-")  # held-out: not measured
    listed = json.loads((tmp_path / "zoo.json").read_text())["agents"]
    assert [a["name"] for a in listed] == ["zoo:USV-v0/ppo"] and listed[0]["estimator"] == "kf"
    zoo.record_scores("zoo:USV-v0/ppo", {"held_out": {"seeds": [2000, 2001, 2002],
                                                      "cost_ratio": 0.91, "failed": 1}})
    assert main(["zoo"]) == 0
    assert "0.91 (3 seeds, 1 failed)" in capsys.readouterr().out
    retrain = (shipped.path.parent / "ppo.yaml").read_text()
    assert "tuning seeds 1000-1009: 0.97" in retrain
    assert "held-out seeds 2000-2002: 0.91, 1 failed" in retrain


def test_an_empty_zoo_says_so(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(zoo, "ZOO", tmp_path / "nothing")
    assert zoo.entries() == [] and zoo.names() == []
    assert main(["zoo"]) == 0
    assert "the zoo is empty" in capsys.readouterr().out


@pytest.mark.parametrize(("name", "message"), [
    ("zoo:USV-v0/ppo_lstm", r"no agent 'zoo:USV-v0/ppo_lstm' in the zoo \(did you mean "
                            r"'zoo:USV-v0/ppo'\?\): it holds zoo:USV-v0/ppo"),
    ("zoo:USV/ppo", r"did you mean 'zoo:USV-v0/ppo'\?\): it holds zoo:USV-v0/ppo"),
    ("zoo:ROV-v0/residual_ppo", "it holds zoo:USV-v0/ppo"),
    ("zoo:", "it holds zoo:USV-v0/ppo"),
])
def test_a_bad_name_is_refused_naming_the_agents_shipped(shipped, name, message, capsys):
    with pytest.raises(ValueError, match=message):
        load_agent(name)
    assert main(["evaluate", name, "--quiet"]) == 2
    assert "it holds zoo:USV-v0/ppo" in capsys.readouterr().err


def test_publish_refuses_what_is_not_a_finished_run_or_bad_scores(tiny_run, tmp_path):
    folder = tmp_path / "zoo"
    with pytest.raises(ValueError, match="not a zoo name"):
        zoo.path_of("USV-v0/ppo", folder)
    with pytest.raises(ValueError, match="is empty"):
        zoo.path_of("zoo:USV-v0/ppo", folder)
    with pytest.raises(FileNotFoundError, match="not a 'marine train' folder"):
        zoo.publish(tmp_path, zoo=folder)
    config = json.loads((tiny_run / "config.json").read_text())
    unfinished = tmp_path / "unfinished"
    unfinished.mkdir()
    (unfinished / "config.json").write_text(json.dumps({**config, "status": "interrupted"}))
    with pytest.raises(ValueError, match="not a complete run.*'interrupted'.*--resume"):
        zoo.publish(unfinished, zoo=folder)
    for scores, message in [({"heldout": {}}, "unknown set 'heldout'"),
                            ({"tuning": {"seeds": [1]}}, "tuning: missing cost_ratio"),
                            ({"tuning": {"seeds": [], "cost_ratio": 1.0}}, "seeds=.. is invalid"),
                            ({"tuning": {"seeds": [1], "cost_ratio": float("nan")}},
                             "cost_ratio=nan is invalid"),
                            ({"tuning": {"seeds": [1], "cost_ratio": 1.0, "ratio": 1}},
                             "unknown entry 'ratio'")]:
        with pytest.raises(ValueError, match=message):
            zoo.publish(tiny_run, scores, zoo=folder)
    assert not folder.exists() or zoo.entries(folder) == []  # nothing written
    zoo.publish(tiny_run, zoo=folder)
    with pytest.raises(FileExistsError, match="holds zoo:USV-v0/ppo already"):
        zoo.publish(tiny_run, zoo=folder)
    assert zoo.publish(tiny_run, zoo=folder, replace=True).card["scores"] == {}
    assert sorted(p.name for p in (folder / "USV-v0").iterdir()) == ["ppo", "ppo.yaml"]


def test_the_retrain_yaml_alone_trains_the_agent_again(shipped, tmp_path, capsys):
    path = shipped.path.parent / "ppo.yaml"
    text = path.read_text()
    assert text.startswith("# zoo:USV-v0/ppo: ") and \
        "marine train --config agents/zoo/USV-v0/ppo.yaml" in text
    assert "net_arch: [64, 64]" in text  # written as people write it
    document = yaml.safe_load(text)
    assert document["agent"] == {"env_id": USV, "algo": "ppo", "estimator": "kf", "seed": 0,
                                 "out": "runs/zoo/USV-v0/ppo"}
    assert agent_section(path) == document["agent"]
    settings = document[USV]["ppo"]
    assert settings["n_envs"] == 4 and settings["n_timesteps"] == 2048
    assert {k: settings[k] for k in TINY} == TINY
    out = tmp_path / "again"
    assert main(["train", "--config", str(path), "--timesteps", "512", "--out", str(out),
                 "--quiet"]) == 0
    assert "saved to" in capsys.readouterr().out
    config = json.loads((out / "config.json").read_text())
    assert (config["env_id"], config["estimator"], config["seed"], config["n_envs"]) == \
        (USV, "kf", 0, 4)
    assert config["hyperparams"] == json.loads((shipped.path / "config.json").read_text()
                                               )["hyperparams"]
    assert config["target_timesteps"] == 512  # the command line wins over the YAML


def test_the_retrain_yaml_gives_the_output_folder_too(shipped, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    path = shipped.path.parent / "ppo.yaml"
    assert main(["train", "--config", str(path), "--timesteps", "256", "--seed", "5",
                 "--quiet"]) == 0
    config = json.loads((tmp_path / "runs/zoo/USV-v0/ppo/config.json").read_text())
    assert (config["env_id"], config["seed"], config["status"]) == (USV, 5, "complete")


@pytest.mark.parametrize(("agent", "message"), [
    ({"env": "x"}, r"agent: unknown entry 'env' \(did you mean 'env_id'\?\)"),
    ({"env_id": "USV-v0"}, r"env_id='USV-v0' is invalid \(did you mean 'marine_envs/USV-v0'"),
    ({"algo": "dqn"}, "algo='dqn' is invalid: one of ppo"),
    ({"estimator": "ukf"}, "estimator='ukf' is invalid"),
    ({"seed": -1}, "seed=-1 is invalid: an integer >= 0"),
    ({"out": ""}, "out='' is invalid"),
    ([1], "agent: must map env_id"),
])
def test_a_bad_agent_section_is_refused(tmp_path, agent, message, capsys):
    path = tmp_path / "bad.yaml"
    path.write_text(yaml.safe_dump({USV: {"ppo": TINY}, "agent": agent}))
    with pytest.raises(ValueError, match=message):
        agent_section(path)
    assert main(["train", "--config", str(path), "--out", str(tmp_path / "x"), "--quiet"]) == 2
    assert "bad.yaml: agent:" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_train_without_an_env_id_needs_one_from_the_config(tmp_path, capsys):
    path = tmp_path / "settings.yaml"
    path.write_text(yaml.safe_dump({USV: {"ppo": TINY}, "agent": {"out": str(tmp_path / "r")}}))
    with pytest.raises(SystemExit) as stopped:
        main(["train", "--config", str(path)])
    assert stopped.value.code == 2 and "agent: section" in capsys.readouterr().err


# -- the agents the repository ships ----------------------------------------------------------

@pytest.mark.parametrize("entry", zoo.entries(), ids=lambda entry: entry.name)
def test_each_shipped_agent_loads_and_runs_a_full_episode(entry):
    agent = Agent.load(entry.name)
    assert agent.config["env_id"] == entry.env_id == entry.card["env_id"]
    steps = evaluation.episode_steps(entry.env_id, agent.config.get("max_episode_steps"))
    dt = gym.make(entry.env_id).unwrapped.system.dt
    rows = evaluate(entry.name, episodes=1, seed=1000)
    assert math.isfinite(rows[0]["cost"]) and not rows[0]["failed"]
    assert rows[0]["seconds"] == pytest.approx(steps * dt)  # the whole episode ran


def test_every_shipped_agent_says_how_it_was_trained_and_what_it_scored():
    """A card states the training (steps, time, speed, machine) and the held-out score the
    comparison measured; a residual agent is shipped only if it beats its LQR there."""
    for entry in zoo.entries():
        card = entry.card
        assert card["timesteps"] > 0 and card["wall_seconds"] > 0 and card["steps_per_second"] > 0
        assert card["machine"]
        held_out = card["scores"]["held_out"]
        assert held_out["failed"] == 0 and len(held_out["seeds"]) >= 10
        assert set(held_out["seeds"]).isdisjoint(range(1000, 1010))  # not the tuning seeds
        if entry.kind.startswith("residual_"):
            assert held_out["cost_ratio"] < 1.0, entry.name


@pytest.mark.skipif("zoo:Hydrofoil-v0/residual_ppo" not in zoo.names(),
                    reason="no hydrofoil residual agent shipped")
def test_the_shipped_hydrofoil_correction_beats_its_lqr_on_fresh_seeds():
    first = int(np.random.default_rng(60).integers(10**6, 2**31))  # seeded, never tuned on
    seeds = range(first, first + 2)
    agent = Agent.load("zoo:Hydrofoil-v0/residual_ppo")
    mine = [r["cost"] for r in evaluation.evaluate(agent.config["env_id"], agent, "kf", seeds)]
    lqr = [r["cost"] for r in evaluation.evaluate(agent.config["env_id"], "lqr", "kf", seeds)]
    assert np.mean(mine) < 0.8 * np.mean(lqr)
