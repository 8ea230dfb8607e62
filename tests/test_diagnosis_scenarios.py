"""Scenarios drawn from seeds (estimators.diagnosis.scenarios) and their benchmark
(benchmarks/diagnosis_scenarios.py): reproducible draws, effects that move the motion, valid
recordings from every generator, the same row locally and on Ray, the command line end to end.
The cheap cases are the DP vessel's (a 0.5-s period): seeds 1 (no effect, 600 s) and 9 (linear
damping of sway in its environment, 220 s)."""

import dataclasses
import json
import math

import numpy as np
import pytest
from benchmark_module import load_benchmark

from estimators.diagnosis import scenarios
from estimators.diagnosis.scenarios import (
    GENERATORS,
    MIN_CHANGE,
    VEHICLES,
    Scenario,
    draw,
    motion_change,
    record,
)
from marine_envs.models import get_model

DP = ("dp_vessel",)


def test_a_draw_is_reproducible_from_its_seed_and_plain_data():
    first, again, other = draw(9, DP), draw(9, DP), draw(1, DP)
    assert first == again and first != other
    assert Scenario.from_dict(json.loads(json.dumps(first.to_dict()))) == first
    assert first.generator == "environment" and first.effects[0].effect == "linear_damping"
    np.testing.assert_array_equal(record(first)[0].measurements, record(again)[0].measurements)


@pytest.mark.parametrize("seed", [9, 5])
def test_every_drawn_effect_changes_the_motion_by_15_percent(seed):
    scenario = draw(seed, DP)
    assert scenario.effects and scenario.change >= MIN_CHANGE
    nominal = scenarios._clean(dataclasses.replace(scenario, effects=()))
    change = motion_change(nominal, scenarios._clean(scenario))
    assert change == pytest.approx(scenario.change, abs=1e-3)


def test_a_draw_keeps_to_its_filters_and_refuses_unknown_names():
    filtered = draw(1, DP, ("open_loop", "independent"))
    assert filtered.vehicle == "dp_vessel"
    assert filtered.generator in ("open_loop", "independent")
    with pytest.raises(ValueError, match="unknown vehicle"):
        draw(0, ("boat",))
    with pytest.raises(ValueError, match="open-loop stable"):
        draw(0, ("hydrofoil",), ("open_loop",))


def test_an_environment_hides_only_what_its_equations_can_carry():
    """No parameter change or wave-frequency term in an environment (``effects=`` refuses
    them); actuator effects only because the environments report the command."""
    from marine_envs.models.effects import INPUT_EFFECTS

    for vehicle in scenarios.VEHICLES:
        drawn = {effect for effect, *_ in scenarios.effect_entries(vehicle, "environment")}
        assert drawn <= set(scenarios.ENVIRONMENT_EFFECTS) | set(INPUT_EFFECTS), vehicle
        assert scenarios.commands_recorded(vehicle)


@pytest.mark.parametrize("generator", GENERATORS)
def test_each_generator_records_its_vehicles(generator):
    for vehicle in VEHICLES:
        if not scenarios._applies(generator, vehicle):
            assert vehicle in ("hydrofoil", "rov")  # open-loop unstable
            continue
        model = get_model(vehicle)
        partial = scenarios._draw_channels(vehicle, generator, _AlwaysPartial())
        scenario = Scenario(seed=3, vehicle=vehicle, generator=generator, duration=30.0,
                            measured=partial,
                            sea=scenarios._draw_sea(vehicle, generator,
                                                    np.random.default_rng(0)))
        recording, truth = record(scenario)
        assert recording.model == vehicle and truth == ()
        assert recording.measured_names == (partial or
                                            scenarios._usual_channels(vehicle, generator))
        assert recording.time[-1] == pytest.approx(30.0, abs=recording.dt)
        assert np.all(np.isfinite(recording.measurements))
        low, high = model.u_bounds
        assert np.all((recording.inputs >= low - 1e-9) & (recording.inputs <= high + 1e-9))
        assert np.std(recording.inputs, axis=0).max() > 0  # something drives the record


class _AlwaysPartial:
    """A generator whose draws ask for the partial channels."""

    def random(self):
        return 0.0


def test_a_concealed_effect_is_in_the_record_and_not_in_the_truth_free_one():
    scenario = draw(9, DP)
    with_effect, truth = record(scenario)
    without, _ = record(dataclasses.replace(scenario, effects=()))
    assert truth == scenario.effects
    assert not np.allclose(with_effect.measurements, without.measurements)


bench = load_benchmark("diagnosis_scenarios")


def _same(row, other):
    timing = ("seconds", "cpu_seconds")
    return {k: v for k, v in row.items() if k not in timing} == \
        {k: v for k, v in other.items() if k not in timing}


def test_ray_and_local_give_the_same_row():
    pytest.importorskip("ray")
    local = scenarios.run_seed(1, DP)
    (remote,) = list(bench.run_rows([1], DP, GENERATORS, scenarios.TIMEOUT, 1, None, True))
    assert local["verdict"] in ("clean", "false", "refused")
    assert _same(json.loads(json.dumps(local)), json.loads(json.dumps(remote)))


def test_the_benchmark_runs_two_cases_end_to_end(tmp_path, capsys):
    out, page = tmp_path / "rows.json", tmp_path / "page.md"
    assert bench.main(["--seeds", "1,9", "--vehicles", "dp_vessel", "--workers", "1",
                       "--json", str(out), "--docs", str(page)]) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [r["seed"] for r in rows] == [1, 9]
    assert rows[1]["true"] == ["linear_damping:v"] and rows[1]["verdict"] in (
        "right", "wrong", "missed", "refused", "timeout")
    printed = capsys.readouterr().out
    assert "tuning: per generator" in printed and "seeds (given): 1,9" in printed
    text = page.read_text()
    assert "| environment | 1 |" in text and "no refusal of an effect" in text
    # the same tables again from the saved rows, without a run
    assert bench.main(["--report", str(out)]) == 0
    assert "| **all** | 1 |" in capsys.readouterr().out


def test_a_diagnosis_past_its_cpu_limit_is_a_timeout():
    with pytest.raises(scenarios.Timeout):
        with scenarios._cpu_limit(0.05):
            while True:
                math.sqrt(2.0)


@pytest.mark.parametrize("argv, message", [
    (["--vehicles", "boat"], "unknown vehicle(s) ['boat']"),
    (["--seeds", "1,x"], "comma-separated integers"),
    (["--tuning", "--cases", "1000"], "tuning seeds"),
])
def test_the_command_line_answers_a_mistake_in_one_line(argv, message, capsys):
    with pytest.raises(SystemExit) as exit_:
        bench.main(argv)
    assert exit_.value.code == 2
    assert message in capsys.readouterr().err
