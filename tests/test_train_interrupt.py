"""Ctrl-C in ``marine train``: the run is saved, evaluated and resumed with its step count."""

from __future__ import annotations

import json
import re
import signal

import pytest
from test_train_faults import PATIENCE, start_training, wait_for

from agents.cli import main

#: A small PPO: a checkpoint within a few seconds of learning (2000 steps), five in the run.
TIMESTEPS = 10_000


@pytest.fixture(scope="module")
def interrupted(tmp_path_factory):
    """A ``marine train`` process stopped by SIGINT once it has written a checkpoint."""
    run, process = start_training(tmp_path_factory.mktemp("interrupt"), TIMESTEPS)
    try:
        wait_for(lambda: any((run / "checkpoints").glob("model_*_steps.zip"))
                 or process.poll() is not None, "checkpoint")
        process.send_signal(signal.SIGINT)
        out, err = process.communicate(timeout=PATIENCE)
    finally:
        process.kill()
    return run, process.returncode, out, err


def test_ctrl_c_saves_the_run_and_says_so_in_one_line(interrupted):
    run, code, out, err = interrupted
    assert code == 130, err  # 128 + SIGINT: the shell's convention
    assert out == "" and "Traceback" not in err
    (line,) = err.splitlines()
    steps = int(re.fullmatch(rf"marine train: interrupted at (\d+) steps, saved to {run} "
                             rf"\(continue: marine train --resume {run}\)", line)[1])
    config = json.loads((run / "config.json").read_text())
    assert config["status"] == "interrupted" and config["timesteps"] == steps
    assert config["estimator"] == "raw" and config["target_timesteps"] == 10_000
    assert 0 < steps < 10_000
    assert (run / "model.zip").exists() and (run / "vecnormalize.pkl").exists()


def test_the_interrupted_run_evaluates_and_resumes_from_its_steps(interrupted, capsys):
    run, _, _, _ = interrupted
    saved = json.loads((run / "config.json").read_text())["timesteps"]
    assert main(["evaluate", str(run), "--episodes", "1", "--quiet"]) == 0
    assert "cost" in capsys.readouterr().out
    checkpoint = sorted((run / "checkpoints").glob("model_*_steps.zip"))[0]
    assert main(["evaluate", str(checkpoint), "--episodes", "1", "--quiet"]) == 0
    assert f"{checkpoint} (" in capsys.readouterr().out
    assert main(["train", "--resume", str(run), "--timesteps", str(saved + 500),
                 "--quiet"]) == 0
    assert f"(from {saved})" in capsys.readouterr().out
    config = json.loads((run / "config.json").read_text())
    assert config["status"] == "complete" and config["timesteps"] >= saved + 500
    assert config["seed"] == 3 and config["hyperparams"]["n_steps"] == 64  # its own settings
    assert config["target_timesteps"] == saved + 500  # what it trained to, from now on
    assert main(["train", "--resume", str(run), "--quiet"]) == 2  # done: nothing to resume
    assert "nothing to resume; give --timesteps beyond it" in capsys.readouterr().err
