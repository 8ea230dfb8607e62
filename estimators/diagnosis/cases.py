"""The seeded acceptance set of the mismatch diagnosis (:mod:`estimators.diagnosis`).

Every catalogue effect once per vehicle (:data:`TARGETS`), a few two-effect combinations
(:data:`PAIRS`) and effect-free records, synthesized by :func:`.synthetic.synthesize` at given
sensor noise levels and seeds (:func:`catalogue_cases`). :func:`score` grades one
diagnosis against the truth the way the acceptance criteria read; :func:`summarize` and
:func:`confusion` aggregate. The test suite and ``benchmarks/diagnosis.py`` share them::

    outcomes = [run_case(case) for case in catalogue_cases(vehicles=("usv",), pairs=False)]
    print(summarize(outcomes))
"""

from __future__ import annotations

import functools
import time
from collections import Counter
from collections.abc import Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

from marine_envs.models.effects import KEY_PARAMETER, Effect
from marine_envs.recording import Recording

from .api import diagnose
from .result import Diagnosis, Finding
from .synthetic import synthesize, typical_effect

#: One catalogue entry on one vehicle: (effect, target, extra arguments of ``typical_effect``).
Entry = tuple[str, str, dict[str, str]]
_INPUT_EFFECTS = ("input_gain", "input_delay", "input_saturation", "input_deadzone",
                  "input_rate_limit")
#: Per vehicle, each of the 15 catalogue effects once, on a target where it matters and where
#: a record can tell it from the others: on the USV's linear roll model a roll-angle bias and
#: a steady heel moment make the same record (the diagnosis reports both at confidence ~0.5),
#: so the USV's sensor bias is on the yaw-rate gyro. The hydrofoil's input effects are on its
#: rear flap: its autopilot loses the craft with 5 % less gain on the front one.
TARGETS: dict[str, list[Entry]] = {
    "usv": [("current", "r", {}), ("linear_damping", "p", {}), ("quadratic_damping", "r", {}),
            ("coupling", "p", {"source": "r"}),
            *[(e, "delta", {}) for e in _INPUT_EFFECTS],
            ("wave_frequency", "p", {}), ("parameter_change", "r", {}),
            ("sensor_bias", "r", {}), ("nonlinear_damping", "p", {}),
            ("nonlinear_restoring", "p", {"source": "phi"}),
            ("unlisted", "r", {"expression": "phi*r"})],
    "hydrofoil": [("current", "xi_dot", {}), ("linear_damping", "theta_dot", {}),
                  ("quadratic_damping", "xi_dot", {}),
                  ("coupling", "theta_dot", {"source": "xi_dot"}),
                  *[(e, "alpha_s2", {}) for e in _INPUT_EFFECTS],
                  ("wave_frequency", "xi_dot", {}), ("parameter_change", "theta_dot", {}),
                  ("sensor_bias", "theta", {}), ("nonlinear_damping", "xi_dot", {}),
                  ("nonlinear_restoring", "theta_dot", {"source": "theta"}),
                  ("unlisted", "xi_dot", {"expression": "theta*xi_dot"})],
    "hovercraft": [("current", "r", {}), ("linear_damping", "v", {}),
                   ("quadratic_damping", "u", {}), ("coupling", "r", {"source": "v"}),
                   *[(e, "delta", {}) for e in _INPUT_EFFECTS],
                   ("wave_frequency", "r", {}), ("parameter_change", "r", {}),
                   ("sensor_bias", "psi", {}), ("nonlinear_damping", "r", {}),
                   ("nonlinear_restoring", "v", {"source": "psi"}),
                   ("unlisted", "u", {"expression": "v*r"})],
    "rov": [("current", "w", {}), ("linear_damping", "r", {}), ("quadratic_damping", "u", {}),
            ("coupling", "q", {"source": "w"}), *[(e, "X", {}) for e in _INPUT_EFFECTS],
            ("wave_frequency", "w", {}), ("parameter_change", "r", {}),
            ("sensor_bias", "psi", {}), ("nonlinear_damping", "u", {}),
            ("nonlinear_restoring", "p", {"source": "phi"}),
            ("unlisted", "u", {"expression": "v*r"})],
    # not a current, a wave-frequency forcing, a sensor offset or a restoring force: see
    # LEFT_OUT
    "dp_vessel": [("linear_damping", "v", {}), ("quadratic_damping", "u", {}),
                  ("coupling", "r", {"source": "v"}), *[(e, "X", {}) for e in _INPUT_EFFECTS],
                  ("parameter_change", "r", {}), ("nonlinear_damping", "v", {}),
                  ("unlisted", "u", {"expression": "v*r"})],
}
#: Catalogue effects left out of a vehicle's :data:`TARGETS`, and why.
LEFT_OUT: dict[str, dict[str, str]] = {
    "dp_vessel": {
        "nonlinear_restoring": "nothing restores a position or heading in the horizontal "
                               "plane",
        "current": "the model's slowly varying bias force is a current",
        "wave_frequency": "the model's wave-frequency motion is a narrow-band sea",
        "sensor_bias": "a position or heading offset moves only where the controller holds "
                       "the vessel"},
}
#: The vehicles of the acceptance set: all five.
ACCEPTANCE_VEHICLES = ("usv", "hovercraft", "hydrofoil", "rov", "dp_vessel")
#: The vehicles and seeds the thresholds and settings of the diagnosis were chosen on (issues 6
#: to 22; the ROV's and DP vessel's seed 0 too, in issue 22); the held-out seeds were run only
#: after the code was frozen, to report the rates.
TUNED_VEHICLES, TUNED_SEEDS, HELD_OUT_SEEDS = ("usv", "hovercraft"), (0, 1), (2, 3)
#: Odd seeds record only these channels (partial measurements): no USV roll rate, no hovercraft
#: sway speed, no hydrofoil rates, no ROV sway and heave speeds; the DP vessel measures its
#: position and heading only, as always.
PARTIAL: dict[str, tuple[str, ...]] = {
    "usv": ("r", "psi", "phi"),
    "hovercraft": ("u", "r", "north", "east", "psi"),
    "hydrofoil": ("xi", "theta"),
    "rov": ("u", "p", "q", "r", "x", "y", "z", "phi", "theta", "psi", "s"),
    "dp_vessel": ("north", "east", "psi"),
}
#: Per vehicle, two-effect combinations.
PAIRS: dict[str, list[tuple[Entry, Entry]]] = {
    "usv": [(("quadratic_damping", "r", {}), ("sensor_bias", "r", {})),
            (("input_delay", "delta", {}), ("current", "r", {}))],
    "hydrofoil": [(("input_delay", "alpha_s2", {}), ("current", "xi_dot", {})),
                  (("quadratic_damping", "xi_dot", {}), ("sensor_bias", "theta", {}))],
    "hovercraft": [(("input_gain", "delta", {}), ("linear_damping", "v", {})),
                   (("quadratic_damping", "u", {}), ("sensor_bias", "psi", {}))],
    "rov": [(("input_gain", "X", {}), ("current", "w", {})),
            (("quadratic_damping", "u", {}), ("sensor_bias", "psi", {}))],
    "dp_vessel": [(("input_gain", "X", {}), ("linear_damping", "v", {})),
                  (("quadratic_damping", "u", {}), ("coupling", "r", {"source": "v"}))],
}
#: What each vehicle's state terms are sized against (``typical_effect``'s ``against``). The
#: hydrofoil's accelerations are a near balance of its foils' lift and the sea's (the spread of
#: its sea-free pitch acceleration is 8x that of the net one), so 30 % of the net would be 1.6 %
#: of its pitch damping: below any model's accuracy, and not what a model gets wrong.
SIZED_AGAINST: dict[str, str] = {"hydrofoil": "model"}
#: Effect-free cases use seeds from here on, apart from the effect cases' seeds.
EFFECT_FREE_SEED = 100
#: A finding at or above this confidence is a claim (a false alarm on an effect-free record).
CONFIDENT = 0.5
#: Key parameter tolerance: relative, and absolute for a parameter change's time, s.
PARAMETER_TOLERANCE, CHANGE_TIME_TOLERANCE = 0.30, 10.0
#: The held-out fractional improvement a diagnosis of a record with effects must reach.
MIN_IMPROVEMENT = 0.30
#: Acceptance: the share of cases that must pass each check.
ACCEPTANCE = {"right": 0.90, "ranked_right": 0.90, "parameter_ok": 0.90, "improvement_ok": 0.90,
              "clean": 0.95}


@dataclass(frozen=True)
class Case:
    """One synthetic record to diagnose.

    :param model: vehicle model name.  :param effects: the truth's effects (0, 1 or 2).
    :param noise: sensor noise, a fraction of each channel's standard deviation.
    :param seed: seeds the record (sea, references, dither, sensors).
    :param duration: record length, s (sampled at 10 Hz).
    """

    model: str
    effects: tuple[Effect, ...]
    noise: float
    seed: int
    duration: float = 300.0
    measured: tuple[str, ...] | None = None

    @property
    def name(self) -> str:
        """E.g. ``"usv/quadratic_damping:r/noise=0.10/seed=0"`` (``/partial`` when only some
        channels are recorded)."""
        truth = "+".join(label(e.effect, e.target) for e in self.effects) or "none"
        partial = "/partial" if self.measured else ""
        return f"{self.model}/{truth}/noise={self.noise:.2f}/seed={self.seed}{partial}"

    def recording(self) -> Recording:
        """The closed-loop record, default sea and 0.1 s sampling."""
        return synthesize(self.model, self.effects, duration=self.duration, noise=self.noise,
                          seed=self.seed, measured=self.measured)


@dataclass
class Outcome:
    """How one diagnosis scored (see :func:`score`); plain data, picklable and JSON-ready.

    :param true: the truth's effects as ``"effect:target"``.
    :param found: the findings as ``"effect:target"``, in rank order; ``confidences`` theirs.
    :param improvement: the held-out fractional improvement of the combined findings.
    :param seconds: wall time of the diagnosis, s.
    :param parameters: each finding's fitted parameters, in rank order (SI units).
    :param alternatives: terms the record supports as well as a finding, ``"effect:target"``.
    :param withdrawn: the withdrawn candidates, ``"effect:target: why"``.
    """

    case: str
    model: str
    true: list[str]
    found: list[str]
    confidences: list[float]
    ranked_right: bool
    parameter_ok: bool | None
    improvement: float | None
    improvement_ok: bool | None
    false_alarm: bool | None
    seconds: float
    reason: str = ""
    parameters: list[dict[str, Any]] = field(default_factory=list)
    alternatives: list[str] = field(default_factory=list)
    withdrawn: list[str] = field(default_factory=list)


def label(effect: str, target: str) -> str:
    return f"{effect}:{target}"


# -- the cases ------------------------------------------------------------------------------------
@functools.lru_cache(maxsize=1024)
def _sized(model: str, effect: str, target: str, extra: tuple[tuple[str, str], ...],
           strength: float, seed: int, duration: float) -> Effect:
    """``typical_effect`` (a pilot simulation, ~2 s), cached on hashable arguments."""
    return typical_effect(model, effect, target, strength=strength, seed=seed,
                          duration=duration, against=SIZED_AGAINST.get(model, "acceleration"),
                          **dict(extra))


def build_effect(model: str, entry: Entry, strength: float = 0.3, seed: int = 0,
                 duration: float = 300.0) -> Effect:
    """The effect of a :data:`TARGETS` entry sized by ``typical_effect`` (``strength``: its
    term's share of the natural spread of what it disturbs; ``duration`` of the pilot, s)."""
    effect, target, extra = entry
    return _sized(model, effect, target, tuple(sorted(extra.items())), strength, seed, duration)


def catalogue_cases(vehicles: Sequence[str] = ACCEPTANCE_VEHICLES,
                    noises: Sequence[float] = (0.05, 0.10), seeds: Sequence[int] = (0,),
                    strength: float = 0.3, pairs: bool = True, effect_free: int = 3,
                    duration: float = 300.0, effect_free_seed: int = EFFECT_FREE_SEED,
                    partial: bool = False) -> list[Case]:
    """Every :data:`TARGETS` entry (and :data:`PAIRS` pair) at every noise and seed, plus
    ``effect_free`` effect-free cases per vehicle and noise (seeds from ``effect_free_seed``).
    With ``partial``, odd seeds record only the :data:`PARTIAL` channels. ``noises`` are
    fractions; ``duration`` s."""
    def measured(model: str, seed: int) -> tuple[str, ...] | None:
        return PARTIAL[model] if partial and seed % 2 else None

    cases = []
    for model in vehicles:
        groups = [(e,) for e in TARGETS[model]] + (list(PAIRS[model]) if pairs else [])
        for noise in noises:
            for seed in seeds:
                cases += [Case(model, tuple(build_effect(model, e, strength, seed, duration)
                                            for e in group), noise, seed, duration,
                               measured(model, seed))
                          for group in groups]
            cases += [Case(model, (), noise, effect_free_seed + k, duration,
                           measured(model, effect_free_seed + k))
                      for k in range(effect_free)]
    return cases


# -- scoring --------------------------------------------------------------------------------------
def _parameter_ok(truth: Effect, finding: Finding) -> bool:
    """The finding's key parameter within tolerance of the truth's."""
    key = KEY_PARAMETER[truth.effect]
    value = finding.parameters.get(key)
    if not isinstance(value, int | float):
        return False
    expected = float(truth.parameters[key])
    if truth.effect == "parameter_change":
        return abs(value - expected) <= CHANGE_TIME_TOLERANCE
    return abs(value - expected) <= PARAMETER_TOLERANCE * abs(expected)


def matches(case: Case, findings: Sequence[Finding]) -> list[tuple[Effect, Finding | None]]:
    """Each true effect with the finding of the same effect and target among the first
    ``len(case.effects)`` findings (None if there is none)."""
    window = list(findings[:len(case.effects)])
    out: list[tuple[Effect, Finding | None]] = []
    for truth in case.effects:
        hit = next((f for f in window if (f.effect, f.target) == (truth.effect, truth.target)),
                   None)
        if hit is not None:
            window.remove(hit)
        out.append((truth, hit))
    return out


def score(case: Case, diagnosis: Diagnosis, seconds: float) -> Outcome:
    """Grade ``diagnosis`` of ``case`` (``seconds``: its wall time).

    With effects: ``ranked_right`` when every true effect is among the first
    ``len(case.effects)`` findings (effect and target); ``parameter_ok`` when every matched
    finding's key parameter is within 30 % (a change time within 10 s), None when none matched;
    ``improvement_ok`` when the held-out improvement is >= 0.30. Effect-free: ``false_alarm``
    when a finding has confidence >= 0.5, ``ranked_right`` otherwise.
    """
    findings = list(diagnosis.findings)
    confidences = [float(f.confidence) for f in findings]
    improvement = diagnosis.fit.get("improvement") if diagnosis.fit else None
    improvement = None if improvement is None else float(improvement)
    base = dict(case=case.name, model=case.model,
                true=[label(e.effect, e.target) for e in case.effects],
                found=[label(f.effect, f.target) for f in findings], confidences=confidences,
                improvement=improvement, seconds=seconds, reason=diagnosis.reason,
                parameters=[dict(f.parameters) for f in findings],
                alternatives=[label(a["effect"], a["target"]) for a in diagnosis.alternatives],
                withdrawn=[f"{label(f.effect, f.target)}: {f.withdrawn}"
                           for f in diagnosis.unconfirmed])
    if not case.effects:
        alarm = any(c >= CONFIDENT for c in confidences)
        return Outcome(**base, ranked_right=not alarm, parameter_ok=None, improvement_ok=None,
                       false_alarm=alarm)
    pairs = matches(case, findings)
    checked = [_parameter_ok(t, f) for t, f in pairs if f is not None]
    return Outcome(**base, ranked_right=all(f is not None for _, f in pairs),
                   parameter_ok=all(checked) if checked else None,
                   improvement_ok=improvement is not None and improvement >= MIN_IMPROVEMENT,
                   false_alarm=None)


def run_case(case: Case, recording: Recording | None = None) -> Outcome:
    """Synthesize ``case`` (unless its ``recording`` is given), diagnose it against its model
    and score it. A diagnosis that raises scores as a diagnosis without findings whose reason
    names the exception."""
    recording = case.recording() if recording is None else recording
    start = time.perf_counter()
    try:
        diagnosis = diagnose(recording, case.model)
    except Exception as exc:  # a benchmark goes on past one crash
        diagnosis = Diagnosis(case.model, None, f"crashed: {type(exc).__name__}: {exc}")
    return score(case, diagnosis, time.perf_counter() - start)


# -- aggregates -----------------------------------------------------------------------------------
def _rate(flags: Iterable[bool | None]) -> tuple[float | None, int]:
    values = [bool(f) for f in flags if f is not None]
    return (sum(values) / len(values) if values else None), len(values)


def summarize(outcomes: Sequence[Outcome]) -> dict[str, dict[str, Any]]:
    """The acceptance rates, each ``{"rate", "n", "target", "passed"}`` (rate None and passed
    True when no case applies): among cases with effects, *right* (ranked right with the key
    parameter within tolerance: the issue's criterion), ranked right and improvement >= 0.30;
    key parameter within tolerance among matched findings; the share of effect-free cases
    without a false alarm."""
    effects = [o for o in outcomes if o.true]
    free = [o for o in outcomes if not o.true]
    flags = {"right": [o.ranked_right and bool(o.parameter_ok) for o in effects],
             "ranked_right": [o.ranked_right for o in effects],
             "parameter_ok": [o.parameter_ok for o in effects],
             "improvement_ok": [o.improvement_ok for o in effects],
             "clean": [not o.false_alarm for o in free]}
    out = {}
    for key, values in flags.items():
        rate, n = _rate(values)
        out[key] = {"rate": rate, "n": n, "target": ACCEPTANCE[key],
                    "passed": rate is None or rate >= ACCEPTANCE[key]}
    return out


def _confused(outcome: Outcome) -> list[tuple[str, str]]:
    """(true effect name, found effect name or "none") pairs of one outcome."""
    name = [f.split(":")[0] for f in outcome.found]
    if not outcome.true:
        claimed = [n for n, c in zip(name, outcome.confidences, strict=True) if c >= CONFIDENT]
        return [("none", claimed[0] if claimed else "none")]
    window = outcome.found[:len(outcome.true)]
    spare = [f for f in outcome.found if f not in outcome.true]
    out = []
    for truth in outcome.true:
        if truth in window:
            out.append((truth.split(":")[0], truth.split(":")[0]))
        else:
            out.append((truth.split(":")[0], spare.pop(0).split(":")[0] if spare else "none"))
    return out


def confusion(outcomes: Sequence[Outcome]) -> dict[str, dict[str, int]]:
    """True effect name -> found effect name (or "none") -> count. A single effect counts
    against the top finding; each effect of a pair against the finding matched to it in the
    first two, or else the best-ranked finding matched to no true effect. Effect-free records
    count as true "none" against their top finding of confidence >= 0.5."""
    counts: dict[str, Counter[str]] = {}
    for outcome in outcomes:
        for truth, found in _confused(outcome):
            counts.setdefault(truth, Counter())[found] += 1
    return {truth: dict(c) for truth, c in counts.items()}


# -- the SINDy baseline's vocabulary --------------------------------------------------------------
def term_factors(term_name: str, names: Sequence[str]) -> list[str]:
    """``"r^2 delta"`` -> ``["r", "r", "delta"]`` (a pysindy polynomial feature name)."""
    out = []
    for factor in term_name.split():
        base, _, power = factor.partition("^")
        if base not in names:
            raise ValueError(f"{base!r} in term {term_name!r} is not one of {list(names)}")
        out += [base] * (int(power) if power else 1)
    return out


def sindy_term_to_effect(term_name: str, equation_state: str, state_names: Sequence[str],
                         input_names: Sequence[str]) -> tuple[str, str, dict[str, str]]:
    """The catalogue entry ``(effect, target, extra)`` a SINDy term of the residual of
    ``equation_state``'s equation stands for.

    ``"1"`` -> current; the state itself -> linear_damping; another state -> coupling (its
    source); the state cubed -> nonlinear_damping; another state cubed -> nonlinear_restoring;
    an input alone -> input_gain on that input; any other product -> unlisted (expression).
    """
    if term_name.strip() == "1":
        return "current", equation_state, {}
    factors = term_factors(term_name, [*state_names, *input_names])
    one = len(set(factors)) == 1
    if one and factors[0] in input_names and len(factors) == 1:
        return "input_gain", factors[0], {}
    if one and factors[0] in state_names and len(factors) in (1, 3):
        source = factors[0]
        own = source == equation_state
        kind = {(1, True): "linear_damping", (1, False): "coupling",
                (3, True): "nonlinear_damping", (3, False): "nonlinear_restoring"}
        return kind[len(factors), own], equation_state, {} if own else {"source": source}
    return "unlisted", equation_state, {"expression": "*".join(factors)}
