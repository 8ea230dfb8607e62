"""Step 3: pick the hypotheses the held-out data support, fit them jointly and say what they mean.

Selection is greedy and validated: every hypothesis is fitted on the first 70 % of the record
and scored by how much it reduces the weighted equation errors of the last 30 %. The held-out
reduction is tested batch by batch (ten contiguous batches, a one-sided t-test, robust to the
errors' autocorrelation) and the p-value multiplied by the number of hypotheses tried
(Bonferroni), so a search over hundreds of terms does not find one by chance. The best
significant hypothesis becomes a finding, its contribution is removed, and the search repeats
until nothing significant is left. The findings are then refitted jointly (backfitting).

A finding's ``confidence`` is the probability that it is real (one minus the corrected p-value)
times its share of the evidence among the significant alternatives (Akaike-style weights from the
t statistics), so two hypotheses that explain the same thing share it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from marine_envs.effects import Effect

from .hypotheses import Fitted, Problem, all_hypotheses
from .residuals import Residuals
from .rollout import Rollouts

FloatArray = NDArray[np.float64]


@dataclass(frozen=True)
class DiagnosisConfig:
    """The one configuration every diagnosis uses (no per-vehicle or per-effect tuning).

    :param fit_fraction: the first part of the record used for fitting; the rest validates.
    :param batches: contiguous validation batches of the significance test.
    :param alpha: family-wise significance level of a finding.
    :param max_findings: at most this many effects are reported.
    :param min_improvement: a finding must remove at least this share of the held-out error.
    :param shortlist: hypotheses ranked best by the equation errors go on to the multi-step test.
    :param horizon, stride: multi-step prediction horizon and spacing of its start times, s.
    """

    fit_fraction: float = 0.7
    batches: int = 20
    alpha: float = 0.01
    max_findings: int = 3
    min_improvement: float = 0.02
    shortlist: int = 24
    horizon: float = 3.0
    stride: float = 0.5


@dataclass
class Scored:
    """A fitted hypothesis with its held-out score."""

    fitted: Fitted
    improvement: float  # share of the held-out weighted error it removes
    t: float
    p_value: float  # Bonferroni-corrected
    confidence: float = 0.0
    alone: float = 0.0  # held-out improvement of this term alone (after the joint fit)

    @property
    def effect(self) -> Effect:
        return self.fitted.effect


@dataclass
class Selection:
    """The outcome of the search: the findings, and every hypothesis of the first round ranked
    (for reports and the confusion tables of the tests)."""

    findings: list[Scored]
    ranking: list[Scored]
    tried: int
    combined_improvement: float = 0.0


def in_sample(problem: Problem, fitted: Fitted) -> Scored:
    """The share of the fit rows' weighted equation error a hypothesis removes (no test)."""
    before = problem.sse(np.zeros_like(fitted.contribution))
    after = problem.sse(fitted.contribution)
    return Scored(fitted, 1 - after / before if before > 0 else 0.0, 1.0, 1.0)


def select(residuals: Residuals, config: DiagnosisConfig = DiagnosisConfig()) -> Selection:
    """Greedy validated search for the effects the residuals support (see the module doc)."""
    rollouts = Rollouts(residuals, config.fit_fraction, config.horizon, config.stride)
    error = residuals.error.copy()
    findings: list[Scored] = []
    ranking: list[Scored] = []
    tried = 0
    for round_ in range(config.max_findings):
        problem = Problem.build(residuals, error, config.fit_fraction)
        candidates = [h for h in all_hypotheses(problem) if not _already(h, findings)]
        # the shortlist is chosen on the fit rows alone, so the held-out test corrects for it
        screened = sorted((in_sample(problem, h) for h in candidates),
                          key=_rank_key, reverse=True)[: config.shortlist]
        tried = len(screened)
        scored = sorted((rollout_score(rollouts, findings, refine(rollouts, findings, s.fitted),
                                       config, tried) for s in screened),
                        key=_rank_key, reverse=True)
        _confidences(scored, config)
        if round_ == 0:
            ranking = scored
        best = next(iter(scored), None)
        if best is None or best.p_value > config.alpha \
                or best.improvement < config.min_improvement:
            break
        findings.append(best)
        error = error - best.fitted.contribution
    selection = Selection(findings, ranking, tried)
    if findings:
        _backfit(rollouts, selection, config)
    return selection


def rollout_score(rollouts: Rollouts, accepted: list[Scored], fitted: Fitted,
                  config: DiagnosisConfig, tried: int) -> Scored:
    """Held-out multi-step improvement of ``fitted`` over the accepted findings, tested over
    contiguous batches of start times."""
    base = rollouts.errors(*_model(accepted))
    new = rollouts.errors(*_model(accepted, fitted))
    held = rollouts.held
    t, p = _batch_test(base[held], new[held], config.batches)
    improvement = rollouts.improvement(base, new)
    return Scored(fitted, improvement, t, min(1.0, p * tried))


def _batch_test(before: FloatArray, after: FloatArray, batches: int) -> tuple[float, float]:
    """One-sided t-test that the errors shrink, on the log-ratios of contiguous batches' sums of
    squares (a batch's ratio hardly depends on how much excitation it happened to contain, and
    the batches are nearly independent even when the errors within one are not)."""
    pairs = [(b.sum(), a.sum()) for b, a in zip(np.array_split(before, batches),
                                                 np.array_split(after, batches), strict=True)
             if b.size]
    ratios = np.array([math.log(b / a) for b, a in pairs
                       if 0 < b < math.inf and 0 < a < math.inf])
    if ratios.size < 3:
        return 0.0, 1.0
    spread = ratios.std(ddof=1)
    t = float(ratios.mean() / (spread / math.sqrt(len(ratios)))) if spread > 0 else 0.0
    return t, float(stats.t.sf(t, len(ratios) - 1))


def _model(accepted: list[Scored], extra: Fitted | None = None):
    """Effects and wave forcings of the accepted findings (plus one more)."""
    fitted = [s.fitted for s in accepted] + ([extra] if extra is not None else [])
    forcing = {k: f.details["forcing"] for k, f in enumerate(fitted) if "forcing" in f.details}
    return [f.effect for f in fitted], forcing


#: Parameters refined by Gauss-Newton (they enter almost linearly) or on a grid (they do not).
LINEAR = {"current": "b", "linear_damping": "c", "quadratic_damping": "c", "coupling": "c",
          "nonlinear_damping": "c", "nonlinear_restoring": "c", "parameter_change": "c",
          "unlisted": "c", "input_gain": "k", "sensor_bias": "b", "wave_frequency": "gain"}
GRID = {"input_delay": "tau", "input_saturation": "limit", "input_deadzone": "width",
        "input_rate_limit": "rate"}


def refine(rollouts: Rollouts, accepted: list[Scored], fitted: Fitted) -> Fitted:
    """Refit the hypothesis's free parameter on the fit starts' multi-step predictions (the
    equation errors' estimate is the starting point)."""
    effect = fitted.effect
    if effect.effect == "wave_frequency" and "forcing" not in fitted.details:
        i = rollouts.res.model.state_names.index(effect.target)
        column = fitted.contribution[:, i]
        fitted.details["forcing"] = np.append(column, column[-1])
        effect = Effect(effect.effect, effect.target, {**effect.parameters, "gain": 1.0})
    name = LINEAR.get(effect.effect) or GRID[effect.effect]
    effects, forcing = _model(accepted)

    def cost(value: float) -> float:
        if not math.isfinite(value):
            return math.inf
        trial = _with(effect, name, value, fitted)
        f = dict(forcing)
        if "forcing" in fitted.details:
            f[len(effects)] = fitted.details["forcing"] * trial.parameters.get("gain", 1.0)
        total = float(rollouts.errors([*effects, trial], f)[rollouts.fit].sum())
        return total if math.isfinite(total) else math.inf

    value = float(effect.parameters[name])
    if name in LINEAR.values() and effect.effect in LINEAR:
        value, std = _gauss_newton(cost, value)
    else:
        value, std = _log_grid(cost, value)
    refined = _with(effect, name, value, fitted)
    if "forcing" in fitted.details:
        fitted.details["forcing"] = fitted.details["forcing"] * refined.parameters["gain"]
        refined = Effect(refined.effect, refined.target,
                         {k: v for k, v in refined.parameters.items() if k != "gain"})
    scale = value / effect.parameters[name] if name in LINEAR.values() \
        and effect.parameters[name] and effect.effect not in ("input_gain",) else 1.0
    out = Fitted(refined, fitted.contribution * scale, dict(fitted.std), fitted.n_parameters,
                 fitted.multiplicity, fitted.details)
    if name != "gain" and np.isfinite(std):
        out.std[name] = std
    return out


def _with(effect: Effect, name: str, value: float, fitted: Fitted) -> Effect:
    return Effect(effect.effect, effect.target, {**effect.parameters, name: value})


def _gauss_newton(cost, value: float, iterations: int = 3) -> tuple[float, float]:
    """Minimise a cost that is nearly quadratic in one parameter: Newton steps on a
    three-point parabola; the std is the parameter change that raises the cost by one unit
    of its per-start residual variance."""
    step = max(abs(value) * 0.2, 1e-9)
    for _ in range(iterations):
        c0, cp, cm = cost(value), cost(value + step), cost(value - step)
        curvature = (cp - 2 * c0 + cm) / step**2
        if not (math.isfinite(curvature) and curvature > 0):
            break
        move = -(cp - cm) / (2 * step) / curvature
        value += float(np.clip(move, -5 * step, 5 * step))
        step = max(min(abs(move), step), abs(value) * 0.02, 1e-12)
    c0, cp, cm = cost(value), cost(value + step), cost(value - step)
    curvature = (cp - 2 * c0 + cm) / step**2
    if not (math.isfinite(curvature) and curvature > 0):
        return value, math.inf
    return value, float(np.sqrt(2 / curvature))


def _log_grid(cost, value: float, span: float = 2.0, points: int = 9) -> tuple[float, float]:
    """Minimise over a log-spaced grid around ``value`` (a positive parameter)."""
    grid = value * np.geomspace(1 / span, span, points)
    costs = np.array([cost(v) for v in grid])
    k = int(np.argmin(costs))
    best = float(grid[k])
    if 0 < k < points - 1:
        lg = np.log(grid[k - 1:k + 2])
        a, b, _ = np.polyfit(lg, costs[k - 1:k + 2], 2)
        if a > 0:
            best = float(np.exp(np.clip(-b / (2 * a), lg[0], lg[-1])))
    return best, float(best * (np.log(span) / (points - 1)))


def _rank_key(s: Scored) -> float:
    # a significant improvement ranks by its size; extra parameters must pay for themselves
    return s.improvement * (1 - 0.05 * (s.fitted.n_parameters - 1)) if s.t > 0 else -1.0


def _confidences(scored: list[Scored], config: DiagnosisConfig) -> None:
    """``(1 - p) *`` the hypothesis's Akaike-style weight among the significant ones; the
    evidence is half the held-out log-ratio of error sums over the batches, so the weights
    rank hypotheses as their improvements do."""
    significant = [s for s in scored if s.p_value < 0.5 and s.improvement > 0]
    if not significant:
        return
    evidence = np.array([config.batches / 2 * -math.log(max(1 - s.improvement, 1e-12))
                         for s in significant])
    weights = np.exp(evidence - evidence.max())
    weights /= weights.sum()
    for s, w in zip(significant, weights, strict=True):
        s.confidence = float((1 - s.p_value) * w)


def _already(fitted: Fitted, findings: list[Scored]) -> bool:
    return any(f.effect.effect == fitted.effect.effect and f.effect.target == fitted.effect.target
               for f in findings)


def _backfit(rollouts: Rollouts, selection: Selection, config: DiagnosisConfig,
             rounds: int = 2) -> None:
    """Refit each finding given the others, then score each alone and all together."""
    findings = selection.findings
    for _ in range(rounds if len(findings) > 1 else 0):
        for k, finding in enumerate(findings):
            others = [f for j, f in enumerate(findings) if j != k]
            refit = rollout_score(rollouts, others, refine(rollouts, others, finding.fitted),
                                  config, selection.tried)
            refit.confidence = finding.confidence
            findings[k] = refit
    for finding in findings:  # the improvement of each term alone
        alone = rollout_score(rollouts, [], finding.fitted, config, selection.tried)
        finding.alone = alone.improvement
    selection.combined_improvement = rollouts.improvement(rollouts.errors([]),
                                                          rollouts.errors(*_model(findings)))
