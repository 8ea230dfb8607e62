"""benchmarks/rl_vs_lqr.py: trained runs and LQR behind true, raw and kf are scored on the tuning
seeds and on fresh held-out seeds, each row with its ratio to LQR behind kf and its verdict; the
README block is rewritten between its markers, and refused without them; missing runs are
listed, no run at all is an error."""

import json
import re
import sys

import gymnasium as gym
import pytest
from benchmark_module import load_benchmark

from agents import sb3

bench = load_benchmark("rl_vs_lqr")
report = sys.modules["_rl_vs_lqr_report"]
README = "# Project\n\nbefore\n\n{begin}\nold table\n{end}\n\nafter\n"


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """Two tiny PPO runs on the USV behind kf (2048 steps, seeds 0 and 1), named as the
    comparison names them."""
    folder = tmp_path_factory.mktemp("runs")
    for seed in (0, 1):
        sb3.train("marine_envs/USV-v0", "ppo", "kf", 2048, folder / f"USV-ppo-kf-seed{seed}",
                  seed=seed, progress_bar=False, hyperparams={"n_steps": 256})
    return folder


def _run(monkeypatch, *args):
    monkeypatch.setattr(sys, "argv", ["rl_vs_lqr.py", *args])
    bench.main()


def test_two_runs_are_scored_on_tuning_and_fresh_held_out_seeds(runs, tmp_path, monkeypatch,
                                                                 capsys):
    out, readme = tmp_path / "rows.json", tmp_path / "README.md"
    readme.write_text(README.format(begin=report.BEGIN, end=report.END))
    _run(monkeypatch, "--runs", str(runs), "--envs", "USV", "--agents", "ppo", "residual_ppo",
         "--episodes", "2", "--held-out-episodes", "2", "--max-episode-steps", "200",
         "--json", str(out), "--readme", str(readme))
    printed = capsys.readouterr().out
    for seed in (0, 1):
        assert f"| USV | ppo | kf | {seed} | 2048 |" in printed
    for estimator in ("true", "raw", "kf"):
        assert f"| USV | lqr | {estimator} | - |" in printed
    assert "Missing runs (not scored): USV-residual_ppo-kf-seed0, USV-residual_ppo-kf-seed1" \
        in printed
    first, last = map(int, re.search(r"Held-out seeds (\d+)-(\d+)", printed).groups())
    assert bench.HELD_OUT_LOW <= first and last == first + 1 < bench.HELD_OUT_HIGH

    result = json.loads(out.read_text())
    tuning, held = result["sets"]["tuning"], result["sets"]["held-out"]
    assert tuning["seeds"] == [1000, 1001] and held["seeds"] == [first, last]
    assert not set(held["seeds"]) & set(tuning["seeds"])
    for rows in (tuning["rows"], held["rows"]):
        assert [(r["kind"], r["estimator"], r["seed"]) for r in rows] == [
            ("lqr", "true", None), ("lqr", "raw", None), ("lqr", "kf", None),
            ("ppo", "kf", 0), ("ppo", "kf", 1)]
        reference = rows[2]["cost"]
        for r in rows:
            assert r["ratio"] == pytest.approx(r["cost"] / reference)
            assert r["verdict"] == report.verdict(r) and r["eval_seconds"] > 0
        assert rows[2]["verdict"] == "reference" and rows[3]["timesteps"] == 2048
    # the two sets are different episodes: the same agent scores differently
    assert tuning["rows"][3]["costs"] != held["rows"][3]["costs"]

    text = readme.read_text()
    assert text.startswith("# Project\n\nbefore\n\n") and text.endswith("\n\nafter\n")
    assert "old table" not in text and f"held-out seeds {first}-{last}" in text
    best = held["summary"][0]
    assert f"| USV | {best['best']} | {best['best_ratio']:.2f} | ppo: " in text


def test_held_out_seeds_are_fresh_and_their_seas_differ_from_the_registered(monkeypatch):
    parser, args = bench.parse(["--held-out-sea", "--held-out-episodes", "10"])
    one, two = bench.seed_sets(args)[1], bench.seed_sets(args)[1]
    assert one.seeds != two.seeds and len(one.seeds) == 10
    assert min(one.seeds) >= bench.HELD_OUT_LOW and max(one.seeds) < bench.HELD_OUT_HIGH
    for vehicle, sea in one.seas.items():
        env = gym.make(bench.SHORT[vehicle], **sea)  # the environment takes the drawn sea
        env.reset(seed=one.seeds[0])
        env.close()
    assert one.seas["USV"]["hs"] != 2.0 and one.seas != two.seas
    # --held-out-first repeats a printed set, seas included
    _, again = bench.parse(["--held-out-sea", "--held-out-first", str(one.seeds[0])])
    assert bench.seed_sets(again)[1].seas == one.seas


def test_verdicts_follow_the_acceptance():
    def row(kind, ratio, failed=0):
        return {"kind": kind, "estimator": "kf", "ratio": ratio, "failed": failed}

    assert report.verdict(row("ppo", 1.24)) == "within 25 %"
    assert report.verdict(row("ppo", 1.26)) == "not within 25 %"
    assert report.verdict(row("ppo", 0.5, failed=1)).startswith("fails")
    assert report.verdict(row("residual_ppo", 1.0)) == "learnt nothing"  # the untrained one
    assert report.verdict(row("residual_ppo", 0.97)) == "matches LQR"
    assert report.verdict(row("residual_sac", 0.90)) == "clearly better"
    assert report.verdict(row("residual_ppo", 1.02)) == "loses to LQR"
    assert report.verdict(row("lqr", 1.0)) == "reference"


def test_readme_without_markers_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    readme = tmp_path / "README.md"
    readme.write_text(f"# Project\n{report.BEGIN}\nno end marker\n")
    with pytest.raises(SystemExit):
        _run(monkeypatch, "--runs", str(tmp_path), "--readme", str(readme))
    error = capsys.readouterr().err
    assert "--readme" in error and report.END in error and "no trained run" not in error
    assert readme.read_text() == f"# Project\n{report.BEGIN}\nno end marker\n"


def test_no_run_at_all_is_an_error_naming_the_folder(tmp_path, monkeypatch, capsys):
    with pytest.raises(SystemExit):
        _run(monkeypatch, "--envs", "Hydrofoil", "--runs", str(tmp_path))
    assert f"no trained run of Hydrofoil in {tmp_path}" in capsys.readouterr().err


def test_an_unknown_agent_kind_is_refused(monkeypatch, capsys, tmp_path):
    with pytest.raises(SystemExit):
        _run(monkeypatch, "--runs", str(tmp_path), "--agents", "residual_dqn")
    assert "--agents residual_dqn" in capsys.readouterr().err
