"""Faults during ``marine train`` (issue 56): SIGTERM and SIGKILL, truncated and corrupt files,
a full disk, two writers on one run folder, bad YAML settings. Each is refused in one line with
exit code 2, or recovered from as documented; nothing is lost, and two runs never mix."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agents import sb3
from agents.cli import main

ROOT = Path(__file__).resolve().parents[1]
USV = "marine_envs/USV-v0"
#: How long to wait for an event of a training process (s): generous, for a loaded machine; the
#: tests go on as soon as the event happens.
PATIENCE = 300.0


def tiny(timesteps: int) -> str:
    """A small PPO's settings: a checkpoint every fifth of ``timesteps``."""
    return f"""\
default:
  ppo:
    n_timesteps: {timesteps}
    n_envs: 2
    policy: MlpPolicy
    normalize: true
    n_steps: 64
    batch_size: 64
    n_epochs: 1
    learning_rate: lin_3e-4
    policy_kwargs: {{net_arch: [16]}}
"""


def wait_for(condition, what: str) -> None:
    """Poll ``condition`` until it holds; fail after :data:`PATIENCE`."""
    deadline = time.monotonic() + PATIENCE
    while not condition():
        if time.monotonic() > deadline:
            pytest.fail(f"no {what} within {PATIENCE} s")
        time.sleep(0.05)


def start_training(root: Path, timesteps: int) -> tuple[Path, subprocess.Popen]:
    """``marine train`` of :func:`tiny` settings into ``root/run``, in a process of its own."""
    (root / "tiny.yaml").write_text(tiny(timesteps))
    run = root / "run"
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(ROOT), os.environ.get(
        "PYTHONPATH", "")])}
    process = subprocess.Popen(
        [sys.executable, "-m", "agents.cli", "train", USV, "--out", str(run),
         "--config", str(root / "tiny.yaml"), "--seed", "3", "--quiet"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    return run, process


def run_cli(args: list[str], capsys) -> tuple[int, str, list[str]]:
    """``marine ARGS`` in this process: exit code, stdout and the lines of stderr."""
    try:
        code = main([str(a) for a in args])
    except SystemExit as stopped:  # argparse's own errors
        code = stopped.code
    out, err = capsys.readouterr()
    return code, out, err.splitlines()


# -- two writers, SIGTERM ---------------------------------------------------------------------

@pytest.fixture(scope="module")
def live_run(tmp_path_factory):
    """A training process with a budget it never reaches, once it holds its folder's lock and
    handles signals (its config.json is written then)."""
    run, process = start_training(tmp_path_factory.mktemp("live"), 1_000_000)
    try:
        wait_for(lambda: (run / "config.json").exists() or process.poll() is not None,
                  "config.json")
        assert process.poll() is None, process.communicate()
        yield run, process
    finally:
        process.kill()
        process.communicate()


def test_a_second_writer_is_refused_while_the_first_runs(live_run, capsys):
    run, process = live_run
    config = (run / "config.json").read_text()
    refused = f"{run} is being written by another training (pid {process.pid})"
    for args in (["train", USV, "--out", run, "--quiet"],
                 ["train", USV, "--out", run, "--quiet", "--force"],  # forced or not
                 ["train", "--resume", run, "--quiet"]):
        code, out, err = run_cli(args, capsys)
        assert code == 2 and out == "", err
        assert len(err) == 1 and err[0].startswith("marine train: error: ") and refused in err[0]
    assert process.poll() is None  # the first runs on, its files untouched
    assert (run / "config.json").read_text() == config


def test_sigterm_saves_the_run_exits_143_and_it_resumes(live_run, capsys):
    run, process = live_run
    process.send_signal(signal.SIGTERM)
    out, err = process.communicate(timeout=PATIENCE)
    assert process.returncode == 143, err  # 128 + SIGTERM: the shell's convention
    assert out == "" and "Traceback" not in err
    (line,) = err.splitlines()  # the line Ctrl-C gives
    steps = int(re.fullmatch(rf"marine train: interrupted at (\d+) steps, saved to {run} "
                             rf"\(continue: marine train --resume {run}\)", line)[1])
    config = json.loads((run / "config.json").read_text())
    assert config["status"] == "interrupted" and config["timesteps"] == steps > 0
    assert (run / "model.zip").exists() and (run / "vecnormalize.pkl").exists()
    # its lock went with it: the run resumes from what SIGTERM saved
    code, out, err = run_cli(["train", "--resume", run, "--timesteps", steps + 200, "--quiet"],
                             capsys)
    assert code == 0 and err == [] and f"(from {steps})" in out
    assert json.loads((run / "config.json").read_text())["status"] == "complete"


def test_a_folder_locked_in_this_process_is_refused_and_a_failed_start_leaves_no_trace(
        tmp_path, capsys):
    (tmp_path / "tiny.yaml").write_text(tiny(256))
    run = tmp_path / "run"
    with sb3.run_lock(run):
        code, _, err = run_cli(["train", USV, "--out", run, "--config", tmp_path / "tiny.yaml",
                                "--force", "--quiet"], capsys)
        assert code == 2 and err == [f"marine train: error: {run} is being written by another "
                                     f"training (pid {os.getpid()}): wait for it to end, or "
                                     "train into another folder"]
    assert not run.exists()  # made for the lock, removed with it: nothing of a run was written
    # a setting refused only when the environments are built: the folder goes again
    with pytest.raises(ValueError, match="no true-state observation"):
        sb3.train(USV, estimator="true", backend="dummy", timesteps=256, out=tmp_path / "a" / "b",
                  hyperparams_file=tmp_path / "tiny.yaml", progress_bar=False)
    assert not (tmp_path / "a").exists()
    assert run_cli(["train", USV, "--out", run, "--config", tmp_path / "tiny.yaml", "--quiet"],
                   capsys)[0] == 0  # unlocked: trains


# -- SIGKILL, truncated and corrupt files --------------------------------------------------------

@pytest.fixture(scope="module")
def killed(tmp_path_factory) -> Path:
    """The folder of a training killed (SIGKILL) once it had written a checkpoint."""
    run, process = start_training(tmp_path_factory.mktemp("killed"), 2000)
    try:
        wait_for(lambda: sb3.checkpoints(run) or process.poll() is not None, "checkpoint")
        process.kill()
        _, err = process.communicate(timeout=PATIENCE)
    finally:
        process.kill()
    assert process.returncode == -signal.SIGKILL, f"it ended first: {err}"
    assert json.loads((run / "config.json").read_text())["status"] == "running"
    assert not (run / "model.zip").exists()
    return run


def _copy(run: Path, tmp_path: Path) -> Path:
    return Path(shutil.copytree(run, tmp_path / "run"))


def _truncate(path: Path) -> None:
    path.write_bytes(path.read_bytes()[: path.stat().st_size // 2])


def test_after_sigkill_evaluate_and_resume_use_the_last_checkpoint_and_say_so(
        killed, tmp_path, capsys):
    run = _copy(killed, tmp_path)
    steps, last = sb3.checkpoints(run)[-1]
    code, out, err = run_cli(["evaluate", run, "--episodes", 1, "--quiet"], capsys)
    assert code == 0 and f"{last} ({steps} steps)" in out and "cost" in out
    assert err == [f"marine evaluate: warning: using checkpoint {last} ({steps} steps): {run} "
                   "has no model.zip (its training is running, or was stopped before saving)"]
    code, out, err = run_cli(["train", "--resume", run, "--timesteps", steps + 200, "--quiet"],
                             capsys)
    assert code == 0 and f"(from {steps})" in out
    assert err == [f"marine train: warning: using checkpoint {last} ({steps} steps): {run} was "
                   "not saved at its end (its config.json says 'running': it was killed, or "
                   "stopped by an error)"]
    assert json.loads((run / "config.json").read_text())["status"] == "complete"


def test_a_truncated_or_corrupt_file_is_passed_over_and_named(killed, tmp_path, capsys):
    run = _copy(killed, tmp_path)
    steps, last = sb3.checkpoints(run)[-1]
    # a newer checkpoint cut short, as a full disk left one before writes were atomic
    newer = last.with_name(f"model_{steps + 400}_steps.zip")
    shutil.copyfile(last, newer)
    shutil.copyfile(sb3.runs._statistics_of(last), sb3.runs._statistics_of(newer))
    _truncate(newer)
    code, out, err = run_cli(["train", "--resume", run, "--timesteps", steps + 200, "--quiet"],
                             capsys)
    assert code == 0 and f"(from {steps})" in out
    (line,) = err
    assert line.startswith(f"marine train: warning: using checkpoint {last} ({steps} steps): ")
    assert f"{newer} is unreadable (" in line
    # the final model.zip corrupt in the middle (its size unchanged): its checksum tells
    model = run / "model.zip"
    data = bytearray(model.read_bytes())
    data[len(data) // 2: len(data) // 2 + 64] = bytes(64)
    model.write_bytes(bytes(data))
    code, out, err = run_cli(["evaluate", run, "--episodes", 1, "--quiet"], capsys)
    assert code == 0 and f"{last} ({steps} steps)" in out
    (line,) = err
    assert line.startswith(f"marine evaluate: warning: using checkpoint {last} ({steps} steps): "
                           f"{model} is unreadable (")
    assert f"{newer} is unreadable" in line
    # named by hand, an unreadable file is an error, not replaced by another
    code, _, err = run_cli(["evaluate", newer, "--quiet"], capsys)
    assert code == 2 and len(err) == 1
    assert err[0].startswith(f"marine evaluate: error: {newer} is unreadable (")
    # nothing loadable: one line, exit 2, for evaluate and --resume alike
    for _, path in sb3.checkpoints(run):
        _truncate(path)
    for command in (["evaluate", run, "--quiet"], ["train", "--resume", run, "--quiet"]):
        code, out, err = run_cli(command, capsys)
        assert code == 2 and out == "" and len(err) == 1, err
        assert err[0].startswith(f"marine {command[0]}: error: {run} holds no loadable agent: ")
        assert f"{last} is unreadable (" in err[0]


# -- a full disk ----------------------------------------------------------------------------

@pytest.fixture
def small_disk(tmp_path):
    """A 100 kB file system (tmpfs): room for a run's first checkpoints, not for all of them."""
    mount = tmp_path / "disk"
    mount.mkdir()
    try:
        done = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=100k", "tmpfs", str(mount)],
                              capture_output=True, text=True)
    except FileNotFoundError:
        pytest.skip("no mount command here to make a small file system")
    if done.returncode != 0:
        pytest.skip(f"mounting a small tmpfs is not permitted here: {done.stderr.strip()}")
    yield mount
    subprocess.run(["umount", str(mount)], check=True)


def test_a_full_disk_names_the_file_and_leaves_every_checkpoint_whole(small_disk, tmp_path,
                                                                         capsys):
    (tmp_path / "tiny.yaml").write_text(tiny(2000))
    run = small_disk / "run"
    code, out, err = run_cli(["train", USV, "--out", run, "--config", tmp_path / "tiny.yaml",
                              "--quiet"], capsys)
    assert code == 2 and out == "" and len(err) == 1, err
    failed = re.fullmatch(r"marine train: error: cannot write (\S+): No space left on device",
                          err[0])
    assert failed and Path(failed[1]).is_relative_to(run), err
    assert not list(run.rglob(".*.part*"))  # no temporary file left behind
    assert json.loads((run / "config.json").read_text())["status"] == "running"
    saved = sb3.checkpoints(run)
    assert saved  # the first checkpoints had room
    for _, path in saved:
        sb3.find_agent(path)  # each whole: it loads
    code, out, err = run_cli(["evaluate", run, "--episodes", 1, "--quiet"], capsys)
    assert code == 0 and f"{saved[-1][1]} ({saved[-1][0]} steps)" in out
    assert len(err) == 1 and "using checkpoint" in err[0]


# -- the YAML settings ------------------------------------------------------------------------

#: (a change to :func:`tiny`'s settings, what the one line must say besides the file's name)
BAD_SETTINGS = [
    ("USV-v0:\n  ppo: {n_steps: 64}\n",
     "unknown section 'USV-v0' (did you mean 'marine_envs/USV-v0'?)"),
    ("marine_envs/Dinghy-v0:\n  ppo: {n_steps: 64}\n", "unknown section 'marine_envs/Dinghy-v0'"),
    ("marine_envs/USV-v0:\n  dqn: {n_steps: 64}\n",
     "marine_envs/USV-v0: unknown algorithm 'dqn': one of ppo, sac, td3, a2c, ppo_lstm"),
    ("marine_envs/USV-v0:\n  ppo: {n_step: 64}\n",
     "marine_envs/USV-v0: ppo: unknown setting 'n_step' (did you mean 'n_steps'?)"),
    ("marine_envs/USV-v0:\n  ppo: {normalize: maybe}\n",
     "ppo: normalize='maybe' is invalid: true, false or VecNormalize's keyword arguments"),
    ("marine_envs/USV-v0:\n  ppo: {normalize: {clip_rewards: 10}}\n",
     "normalize: unknown setting 'clip_rewards' (did you mean 'clip_reward'?)"),
    ("marine_envs/USV-v0:\n  ppo: {n_steps: -64}\n", "n_steps=-64 is invalid: an integer >= 1"),
    ("marine_envs/USV-v0:\n  ppo: {n_steps: 0}\n", "n_steps=0 is invalid: an integer >= 1"),
    ("marine_envs/USV-v0:\n  ppo: {batch_size: 0}\n", "batch_size=0 is invalid"),
    ("marine_envs/USV-v0:\n  ppo: {n_timesteps: 1.5}\n", "n_timesteps=1.5 is invalid"),
    ("marine_envs/USV-v0:\n  ppo: {learning_rate: -3.0e-4}\n",
     "learning_rate=-0.0003 is invalid: a number > 0, or 'lin_<x>'"),
    ("marine_envs/USV-v0:\n  ppo: {learning_rate: 0}\n", "learning_rate=0 is invalid"),
    ("marine_envs/USV-v0:\n  ppo: {learning_rate: lin_-1}\n", "learning_rate='lin_-1' is invalid"),
    ("marine_envs/USV-v0:\n  ppo: {learning_rate: 3e-4}\n",
     "learning_rate='3e-4' is invalid: a number > 0, or 'lin_<x>' (decayed linearly from x > 0 "
     "to 0), e.g. 'lin_3e-4' (YAML reads it as text: write the number with a decimal point, "
     "e.g. 3.0e-4)"),
    ("marine_envs/USV-v0:\n  ppo: {gamma: 1.5}\n", "gamma=1.5 is invalid: a number in [0, 1]"),
    ("marine_envs/USV-v0:\n  ppo: {policy: MlpPolcy}\n",
     "policy='MlpPolcy' is invalid: one of MlpPolicy, CnnPolicy, MultiInputPolicy (did you mean "
     "'MlpPolicy'?)"),
    ("marine_envs/USV-v0:\n  sac: {buffer_size: 0}\n", "marine_envs/USV-v0: sac: buffer_size=0"),
    ("marine_envs/USV-v0: [ppo]\n", "marine_envs/USV-v0: must map algorithms to their settings"),
]


@pytest.mark.parametrize("extra, text", BAD_SETTINGS, ids=[t for _, t in BAD_SETTINGS])
def test_a_bad_setting_is_named_with_its_file_before_any_work(tmp_path, capsys, extra, text):
    settings = tmp_path / "settings.yaml"
    settings.write_text(tiny(256) + extra)
    code, out, err = run_cli(["train", USV, "--out", tmp_path / "run", "--config", settings,
                              "--quiet"], capsys)
    assert code == 2 and out == "" and len(err) == 1, err
    assert err[0].startswith(f"marine train: error: {settings}: ") and text in err[0], err[0]
    assert not (tmp_path / "run").exists()


def test_the_packaged_settings_are_valid_for_every_environment_and_algorithm():
    import marine_envs

    for env_id in marine_envs.ENVIRONMENTS:
        for algo in sb3.ALGOS:
            params = sb3.load_hyperparams(env_id, algo)  # checks the whole file each time
            assert params["n_timesteps"] >= 1 and params["n_envs"] >= 1
