"""The diagnosis acceptance set's scoring (estimators.diagnosis.cases) on hand-made diagnoses:
no diagnosis is run, only the grading, the aggregates and the cases' effects."""

from __future__ import annotations

import numpy as np
import pytest

from estimators.diagnosis import Diagnosis, Finding, typical_effect
from estimators.diagnosis.cases import (
    LEFT_OUT,
    PAIRS,
    PARTIAL,
    TARGETS,
    Case,
    build_effect,
    catalogue_cases,
    confusion,
    score,
    sindy_term_to_effect,
    summarize,
)
from estimators.diagnosis.residuals import observable_states
from marine_envs.models import get_model
from marine_envs.models.effects import CATALOGUE, Effect

DAMPING = Effect("quadratic_damping", "r", {"c": -2.0})
BIAS = Effect("sensor_bias", "phi", {"b": 0.005})
CHANGE = Effect("parameter_change", "r", {"time": 165.0, "c": -0.1, "what": "damping"})


def finding(effect: str, target: str, confidence: float = 0.9, **parameters: float) -> Finding:
    return Finding(effect=effect, target=target, parameters=dict(parameters), std={},
                   confidence=confidence, improvement=0.5, explanation="")


def diagnosis(*findings: Finding, improvement: float = 0.5) -> Diagnosis:
    return Diagnosis("usv", bool(findings), findings=list(findings),
                     fit={"improvement": improvement})


def case(*effects: Effect) -> Case:
    return Case("usv", effects, 0.1, 0)


def test_right_finding_is_ranked_right_and_named():
    outcome = score(case(DAMPING), diagnosis(finding("quadratic_damping", "r", c=-2.1)), 1.0)
    assert outcome.ranked_right and outcome.parameter_ok and outcome.improvement_ok
    assert outcome.false_alarm is None and outcome.found == ["quadratic_damping:r"]
    assert case(DAMPING).name == "usv/quadratic_damping:r/noise=0.10/seed=0"
    assert case().name == "usv/none/noise=0.10/seed=0"


def test_wrong_target_or_rank_is_not_ranked_right():
    wrong_target = score(case(DAMPING), diagnosis(finding("quadratic_damping", "p", c=-2.0)), 1)
    assert not wrong_target.ranked_right and wrong_target.parameter_ok is None
    second = score(case(DAMPING), diagnosis(finding("current", "r", b=0.1),
                                            finding("quadratic_damping", "r", c=-2.0)), 1)
    assert not second.ranked_right


def test_pair_needs_both_in_the_top_two():
    both = diagnosis(finding("sensor_bias", "phi", b=0.005), finding("quadratic_damping", "r",
                                                                      c=-2.0))
    assert score(case(DAMPING, BIAS), both, 1).ranked_right
    third = diagnosis(finding("quadratic_damping", "r", c=-2.0), finding("current", "r", b=0.1),
                      finding("sensor_bias", "phi", b=0.005))
    outcome = score(case(DAMPING, BIAS), third, 1)
    assert not outcome.ranked_right and outcome.parameter_ok  # the matched one is right


@pytest.mark.parametrize(("factor", "ok"), [(1.29, True), (0.71, True), (1.31, False),
                                            (0.69, False)])
def test_parameter_within_30_percent(factor, ok):
    found = diagnosis(finding("quadratic_damping", "r", c=-2.0 * factor))
    assert score(case(DAMPING), found, 1).parameter_ok is ok


@pytest.mark.parametrize(("time", "ok"), [(174.0, True), (176.0, False), (154.0, False)])
def test_change_time_within_10_s(time, ok):
    found = diagnosis(finding("parameter_change", "r", time=time, c=-0.5))  # c is not checked
    assert score(case(CHANGE), found, 1).parameter_ok is ok


def test_improvement_below_30_percent_fails():
    found = diagnosis(finding("quadratic_damping", "r", c=-2.0), improvement=0.29)
    assert score(case(DAMPING), found, 1).improvement_ok is False


def test_effect_free_false_alarm_at_confidence_0_5():
    alarm = score(case(), diagnosis(finding("current", "r", 0.6, b=0.1)), 1)
    assert alarm.false_alarm and not alarm.ranked_right and alarm.improvement_ok is None
    quiet = score(case(), diagnosis(finding("current", "r", 0.4, b=0.1)), 1)
    assert not quiet.false_alarm and quiet.ranked_right and quiet.parameter_ok is None


def test_crashed_diagnosis_scores_as_nothing_found():
    outcome = score(case(DAMPING), Diagnosis("usv", None, "crashed: boom"), 2.0)
    assert not outcome.ranked_right and outcome.improvement is None
    assert outcome.improvement_ok is False and outcome.reason == "crashed: boom"


def test_confusion_and_summary():
    outcomes = [
        score(case(DAMPING), diagnosis(finding("quadratic_damping", "r", c=-2.0)), 1),
        score(case(DAMPING), diagnosis(finding("linear_damping", "r", c=-1.0)), 1),
        score(case(DAMPING), diagnosis(), 1),
        score(case(DAMPING, BIAS), diagnosis(finding("quadratic_damping", "r", c=-9.0),
                                             finding("current", "p", b=1.0),
                                             finding("sensor_bias", "phi", b=1.0)), 1),
        score(case(), diagnosis(finding("current", "r", 0.7, b=0.1)), 1),
        score(case(), diagnosis(finding("current", "r", 0.2, b=0.1)), 1),
    ]
    assert confusion(outcomes) == {
        "quadratic_damping": {"quadratic_damping": 2, "linear_damping": 1, "none": 1},
        "sensor_bias": {"current": 1}, "none": {"current": 1, "none": 1}}
    rates = summarize(outcomes)
    assert rates["ranked_right"]["rate"] == 0.25 and rates["ranked_right"]["n"] == 4
    assert rates["right"]["rate"] == 0.25  # the ranked-right one's parameter is within 30 %
    off = summarize([score(case(DAMPING), diagnosis(finding("quadratic_damping", "r", c=-9.0)),
                           1)])
    assert off["ranked_right"]["rate"] == 1.0 and off["right"]["rate"] == 0.0
    assert rates["parameter_ok"]["rate"] == 0.5 and rates["parameter_ok"]["n"] == 2
    assert rates["clean"]["rate"] == 0.5 and not rates["clean"]["passed"]


def test_targets_cover_the_catalogue_and_build_valid_effects():
    for model, entries in TARGETS.items():
        left_out = LEFT_OUT.get(model, {})
        assert sorted(e for e, _, _ in entries) == sorted(set(CATALOGUE) - set(left_out))
        vehicle = get_model(model)
        for entry in entries + [e for pair in PAIRS[model] for e in pair]:
            effect = build_effect(model, entry, seed=0, duration=60.0)
            effect.check(vehicle)
            assert (effect.effect, effect.target) == entry[:2]


def test_the_hydrofoil_s_input_effect_records_keep_it_flying():
    # on the front flap the same effects crashed it (heave 1e6 m was recorded as a test case)
    cases = [c for c in catalogue_cases(vehicles=("hydrofoil",), noises=(0.05,), effect_free=0,
                                        duration=120.0)
             if any(e.kind == "input" for e in c.effects)]
    assert len(cases) == 6  # five input effects and a pair
    for case in cases:
        heave = case.recording().measurements[:, 0]
        assert np.std(heave) < 1.0, case.name  # m


def test_catalogue_cases_counts_and_seeds():
    cases = catalogue_cases(vehicles=("usv",), noises=(0.05, 0.1), duration=60.0)
    free = [c for c in cases if not c.effects]
    assert len(cases) == 2 * (15 + 2 + 3) and len(free) == 6
    assert len({c.seed for c in free}) == 3 and len({c.name for c in cases}) == len(cases)
    assert all(c.duration == 60.0 for c in cases)


def test_odd_seeds_record_the_partial_channels_and_keep_every_target_observable():
    cases = catalogue_cases(vehicles=("usv",), noises=(0.05,), seeds=(0, 1), pairs=False,
                            effect_free=2, duration=60.0, partial=True)
    assert {c.seed % 2 for c in cases if c.measured} == {1}
    assert all(c.measured is None for c in cases if c.seed % 2 == 0)
    recording = next(c for c in cases if c.measured).recording()
    assert recording.measured_names == PARTIAL["usv"]
    assert next(c for c in cases if c.measured).name.endswith("/partial")
    for model, channels in PARTIAL.items():
        vehicle = get_model(model)
        observable = observable_states(vehicle, channels)
        for effect, target, _ in TARGETS[model]:
            if target in vehicle.state_names:
                assert observable[vehicle.state_names.index(target)], (model, effect, target)


@pytest.mark.parametrize(("term", "state", "expected"), [
    ("1", "r", ("current", "r", {})),
    ("r", "r", ("linear_damping", "r", {})),
    ("phi", "p", ("coupling", "p", {"source": "phi"})),
    ("p^3", "p", ("nonlinear_damping", "p", {})),
    ("phi^3", "p", ("nonlinear_restoring", "p", {"source": "phi"})),
    ("delta", "r", ("input_gain", "delta", {})),
    ("r phi", "r", ("unlisted", "r", {"expression": "r*phi"})),
    ("r^2", "r", ("unlisted", "r", {"expression": "r*r"})),
    ("r^2 delta", "p", ("unlisted", "p", {"expression": "r*r*delta"})),
    ("delta^3", "p", ("unlisted", "p", {"expression": "delta*delta*delta"})),
])
def test_sindy_term_to_effect(term, state, expected):
    usv = get_model("usv")
    assert sindy_term_to_effect(term, state, usv.state_names, usv.input_names) == expected


def test_sindy_term_names_with_underscores():
    foil = get_model("hydrofoil")
    mapped = sindy_term_to_effect("theta xi_dot", "xi_dot", foil.state_names, foil.input_names)
    assert mapped == ("unlisted", "xi_dot", {"expression": "theta*xi_dot"})
    Effect(mapped[0], mapped[1], {**mapped[2], "c": 1.0}).check(foil)
    with pytest.raises(ValueError, match="nope"):
        sindy_term_to_effect("nope", "xi", foil.state_names, foil.input_names)


def test_the_hydrofoils_state_terms_are_sized_against_its_models_own_forces():
    """Its pitch acceleration is a near balance of the foils' lift and the sea's: 30 % of the
    net would be a damping term of ~2 % of the model's own, which no record could show."""
    A, _, _ = get_model("hydrofoil").linearize()
    q = get_model("hydrofoil").state_names.index("theta_dot")
    entry = ("linear_damping", "theta_dot", {})
    sized = build_effect("hydrofoil", entry).parameters["c"] / A[q, q]
    net = typical_effect("hydrofoil", *entry[:2]).parameters["c"] / A[q, q]
    assert 0.1 < sized < 0.3 and 0 < net < 0.03
    with pytest.raises(ValueError, match="against='force'"):
        typical_effect("hydrofoil", *entry[:2], against="force")
