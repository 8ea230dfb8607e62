"""Whole-model comparison in free simulation: nested models, each refitted whole, judged on
data no fit has seen.

The nominal model (its ``--calibrate`` parameters and initial states fitted) is the first model.
Each candidate adds one catalogue term and is refitted *together with* the calibrated parameters,
the initial states, the terms accepted before it and, where no calibrated parameter plays that
part, the linear term it extends (quadratic damping is judged as linear + quadratic, cubic
restoring as linear + cubic). Models are compared on held-out data in free simulation:

* one recording: its last ``1 - fit_fraction``, predicted by continuing the simulation fitted on
  the rest (for a decay, the small amplitudes the fit did not see);
* a series: each recording in turn, predicted by the model fitted on the others (only its own
  initial state fitted to it; a recording cut into windows is held out whole).

The best candidate whose coefficient is at least two standard deviations from zero is accepted
when it removes at least ``min_gain`` of the held-out error in excess of the sensor noise; the
search repeats on top of it. Actuator effects (rate limit, delay, saturation) are grids over
their physical ranges, each screened by its best member, refined between its neighbours.
Candidates act only where the data can see them: the force equations of states an input or a
measured state moves.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

from marine_envs.models.effects import Effect

from .hypotheses import rate_limit_grid
from .output_error import Fit, Series, Structure, basis, fit, jacobian, term_label
from .ranges import nonphysical

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]
#: Points of each actuator effect's grid.
GRID = 12
#: Unknowns correlated beyond this cannot be told apart by the records.
MAX_CORRELATION = 0.98


@dataclass(frozen=True)
class ComparisonConfig:
    """The one configuration of the free-simulation comparison (no per-vehicle tuning).

    :param fit_fraction: a single recording fits on this first part and predicts the rest.
    :param min_gain: share of the remaining held-out excess error a term must remove.
    :param screen: candidates per round that get a full held-out refit (the rest are ranked
        by a linearised refit and dropped).
    :param max_findings: at most this many terms.
    :param tie: candidates whose held-out errors differ by less than this share explain the
        data equally.
    :param noise_factor: the model explains the record when its held-out RMS error is within
        this factor of the sensor noise.
    """

    fit_fraction: float = 0.7
    min_gain: float = 0.2
    screen: int = 4
    max_findings: int = 3
    tie: float = 0.1
    noise_factor: float = 2.0


@dataclass(frozen=True)
class Candidate:
    """A catalogue term (unit coefficient) and the linear terms refitted with it."""

    term: Effect
    companions: tuple[Effect, ...] = ()
    #: an actuator effect's grid neighbours (its value is refined between them)
    neighbours: tuple[Effect, ...] = ()

    @property
    def label(self) -> str:
        return term_label(self.term)


@dataclass
class HeldOut:
    """A model's held-out free-simulation error.

    :param mean_square: in signal scales, mean over channels (and runs).
    :param rmse: per channel, in the channel's units.  :param per_run: mean square per run.
    :param diverged: its simulation left every sane range.
    :param theta: of a single record, the unknowns fitted on its first part (what predicted
        the rest); None for a series.
    """

    mean_square: float
    rmse: dict[str, float]
    per_run: list[float]
    diverged: bool = False
    theta: FloatArray | None = field(default=None, repr=False)


@dataclass
class Scored:
    """A candidate's refit on all data and its held-out error."""

    candidate: Candidate
    fit: Fit
    held_out: HeldOut


@dataclass
class Comparison:
    """The outcome: the nominal fit, the accepted terms, the final fit and each round's
    candidates (best first)."""

    series: Series
    config: ComparisonConfig
    nominal: Fit
    nominal_held_out: HeldOut
    accepted: list[Scored] = field(default_factory=list)
    rounds: list[list[Scored]] = field(default_factory=list)

    @property
    def final(self) -> Fit:
        return self.accepted[-1].fit if self.accepted else self.nominal

    @property
    def final_held_out(self) -> HeldOut:
        return self.accepted[-1].held_out if self.accepted else self.nominal_held_out

    @property
    def noise_floor(self) -> float:
        """Mean square of the sensor noise in signal scales (what no model removes)."""
        s = self.series
        return float(np.mean([np.mean((r.noise / s.scale) ** 2) for r in s.runs]))

    def improvement(self, before: HeldOut, after: HeldOut) -> float | None:
        """Share of the held-out error in excess of the noise that ``after`` removes (at most
        1), or None when ``after`` diverged."""
        if after.diverged:
            return None
        excess = max(before.mean_square - self.noise_floor, 1e-3 * before.mean_square, 1e-300)
        return min((before.mean_square - after.mean_square) / excess, 1.0)

    def refusal(self, scored: Scored, before: HeldOut) -> str | None:
        """Why ``scored`` is not accepted over a model whose held-out error is ``before``
        (None: it is acceptable): it diverges, its coefficient is not significant, its sign
        makes the motion less stable than the linear model (:func:`.ranges.nonphysical`), or
        it removes less than ``min_gain`` of the held-out error in excess of the noise."""
        if scored.held_out.diverged:
            return "its free simulation diverges on the held-out data"
        if not _significant(scored):
            return _insignificant(scored)
        unstable = nonphysical(scored.fit, scored.candidate.term)
        if unstable:
            return unstable
        gain = self.improvement(before, scored.held_out)
        if before.mean_square - scored.held_out.mean_square < self.config.min_gain * max(
                before.mean_square - self.noise_floor, 0.0):
            return (f"it removes {max(gain or 0.0, 0.0):.0%} of the held-out error beyond the "
                    f"noise, less than the {self.config.min_gain:.0%} a term must")
        return None

    def not_kept(self) -> list[tuple[Scored, str]]:
        """The candidates of the round that ended the search without a term, best first,
        each with its :meth:`refusal` (empty when the search ended for another reason)."""
        if len(self.rounds) == len(self.accepted):
            return []
        before = self.final_held_out
        return [(s, self.refusal(s, before) or "") for s in self.rounds[-1]]

    def explained(self) -> bool:
        """The final model's held-out error is within ``noise_factor`` of the sensor noise."""
        return self.final_held_out.mean_square <= self.config.noise_factor**2 * self.noise_floor

    def validation(self) -> str:
        if len(self.series.runs) > 1:
            return ("free simulation of each recording by the model fitted on the others "
                    "(leave one recording out), error in the measured channels")
        return (f"free simulation from the start: fitted on the first "
                f"{self.config.fit_fraction:.0%} of the record, error on the last "
                f"{1 - self.config.fit_fraction:.0%}")


# -- candidates -----------------------------------------------------------------------------------
def candidates(series: Series, names: Sequence[str]) -> list[Candidate]:
    """Damping forms and cubic restoring in the force equations of excited states, a constant
    force there, and a bias on each measured channel."""
    model = series.model
    A = model.linearize()[0]
    covered = _covered(series, names)
    excited = series.excited()
    out: list[Candidate] = []
    for i in series.force_states():
        target = model.state_names[i]
        linear = () if covered[i, i] else (basis("linear_damping", target),)
        out.append(Candidate(basis("quadratic_damping", target), linear))
        out.append(Candidate(basis("nonlinear_damping", target, form="cubic"), linear))
        for q in np.flatnonzero(excited & (A[i] != 0)):
            if q == i or q in series.force_states():
                continue
            source = model.state_names[q]
            coupling = () if covered[i, q] else (basis("coupling", target, source=source),)
            out.append(Candidate(basis("nonlinear_restoring", target, source=source), coupling))
        out.append(Candidate(basis("current", target)))
    out += [Candidate(basis("sensor_bias", c)) for c in series.channels]
    return out


def input_candidates(series: Series) -> list[list[Candidate]]:
    """Per moving input and actuator effect, a grid of candidates spanning the physical range:
    rate limits of 1-30 deg/s for an angle (else 3-100 % of the fastest commanded slew),
    delays of one step to 3 s, saturations at 30-100 % of the largest command."""
    model, dt = series.model, series.dt
    grids = []
    for j, name in enumerate(model.input_names):
        if not series.moving[j] or name not in model.actuator_names:  # not a measured wind
            continue
        c = np.concatenate([r.u[:, j] for r in series.runs]) - model.u0[j]
        slew = max(float(np.max(np.abs(np.diff(r.u[:, j])))) for r in series.runs) / dt
        for effect, key, values in (
                ("input_rate_limit", "rate", rate_limit_grid(model.input_units[j], slew, GRID)),
                ("input_delay", "tau", np.unique(np.round(np.geomspace(dt, 3.0, GRID) / dt)) * dt),
                ("input_saturation", "limit", np.linspace(0.3, 0.97, GRID) * np.abs(c).max())):
            if values.size:
                grids.append([Candidate(Effect(effect, name, {key: float(v)})) for v in values])
    return grids


def _covered(series: Series, names: Sequence[str]) -> BoolArray:
    """Which entries of the linearised state matrix a calibrated parameter moves (a linear
    companion there would duplicate it)."""
    model = series.model
    A = model.linearize()[0]
    covered = np.zeros(A.shape, dtype=bool)
    for name in names:
        value = float(getattr(model.params, name))
        moved = model.with_params(**{name: value * 1.01 if value else 1e-3}).linearize()[0]
        covered |= moved != A
    return covered


# -- held-out scores ------------------------------------------------------------------------------
def all_rows(series: Series) -> list[BoolArray | None]:
    return [np.ones(len(r.time), dtype=bool) for r in series.runs]


def fit_part(time: FloatArray, config: ComparisonConfig) -> BoolArray:
    """The samples of a single record its held-out score fits on (the rest is predicted)."""
    return time < time[0] + config.fit_fraction * (time[-1] - time[0])


def held_out(structure: Structure, theta: FloatArray, config: ComparisonConfig) -> HeldOut:
    """The structure's held-out error, its fits warm-started from ``theta`` (module doc)."""
    series = structure.series
    fitted = None
    if len(series.runs) == 1:
        run = series.runs[0]
        split = fit_part(run.time, config)
        fitted = fit(structure, [split], theta).theta
        errors = [(structure.simulate(fitted, 0)[0][~split] - run.y[~split]) / series.scale]
    else:
        errors = []
        per_state = len(structure.free_states)
        first = len(structure.names) + len(structure.terms)
        for fold in series.folds():  # a recording (or all the windows cut from it)
            own = np.concatenate([np.arange(first + r * per_state, first + (r + 1) * per_state)
                                  for r in fold])
            rows: list[BoolArray | None] = all_rows(series)
            alone: list[BoolArray | None] = [None] * len(series.runs)
            for r in fold:
                rows[r], alone[r] = None, np.ones(len(series.runs[r].time), dtype=bool)
            others = fit(structure, rows, theta, fixed=own).theta
            rest = np.setdiff1d(np.arange(structure.size), own)
            fitted = fit(structure, alone, others, fixed=rest).theta
            errors += [(structure.simulate(fitted, r)[0] - series.runs[r].y) / series.scale
                       for r in fold]
    diverged = any(not np.all(np.abs(e) <= 1e2) for e in errors)  # NaN too
    errors = [np.clip(np.nan_to_num(e, nan=1e2), -1e2, 1e2) for e in errors]
    per_run = [float(np.mean(e**2)) for e in errors]
    stacked = np.concatenate(errors)
    rmse = {c: float(np.sqrt(np.mean(stacked[:, j] ** 2)) * series.scale[j])
            for j, c in enumerate(series.channels)}
    return HeldOut(float(np.mean(per_run)) if not diverged else math.inf, rmse,
                   per_run, diverged, fitted)


# -- the search -----------------------------------------------------------------------------------
def compare(series: Series, names: Sequence[str] = (),
            start: Mapping[str, float] | None = None,
            config: ComparisonConfig = ComparisonConfig()) -> Comparison:
    """Nominal model, then the nested models the held-out data support (module doc).

    :param names: model parameters refitted in every model (``--calibrate``).
    :param start: start values of unknowns by label (e.g. from :func:`.modes.mode_start`).
    """
    nominal = Structure(series, tuple(names))
    nominal_fit = fit(nominal, all_rows(series), nominal.start(start))
    comparison = Comparison(series, config, nominal_fit,
                            held_out(nominal, nominal_fit.theta, config))
    pool = candidates(series, names)
    grids = input_candidates(series)
    current, current_fit, score = nominal, nominal_fit, comparison.nominal_held_out
    for _ in range(config.max_findings):
        if score.mean_square <= config.noise_factor**2 * comparison.noise_floor:
            break
        pool = [c for c in pool if not _present(current, c)]
        grids = [g for g in grids if not _present(current, g[0])]
        ranked = [c for _, c in sorted(_screen(current, current_fit, pool)
                                       + _screen_grids(current, current_fit, grids),
                                       key=lambda item: item[0])][:config.screen]
        scored = sorted((_score(current, current_fit, c, config) for c in ranked),
                        key=lambda s: s.held_out.mean_square)
        comparison.rounds.append(scored)
        best = next((s for s in scored if comparison.refusal(s, score) is None), None)
        if best is None:
            break
        comparison.accepted.append(best)
        current, current_fit, score = best.fit.structure, best.fit, best.held_out
    return comparison


def _significant(scored: Scored, t: float = 2.0) -> bool:
    """The term's fitted coefficient is at least ``t`` standard deviations from zero (a grid
    member of an actuator effect has no coefficient: its held-out gain is its test)."""
    if scored.candidate.term.kind == "input":
        return True
    k = scored.fit.structure.labels().index(scored.candidate.label)
    return abs(float(scored.fit.theta[k])) >= t * float(scored.fit.std[k])


def _insignificant(scored: Scored) -> str:
    """Why a term's coefficient is not significant: its value and std, and the unknown it is
    most correlated with when the records cannot tell the two apart."""
    fit, labels = scored.fit, scored.fit.structure.labels()
    k = labels.index(scored.candidate.label)
    if not math.isfinite(fit.std[k]):
        return "its coefficient is not identifiable: the records hold it only together with " \
            "other unknowns"
    text = f"its coefficient is not significant ({fit.theta[k]:.3g} ± {fit.std[k]:.2g})"
    others = [j for j in range(len(labels)) if j != k]
    j = max(others, key=lambda j: abs(fit.correlation[k, j]), default=None)
    if j is not None and abs(fit.correlation[k, j]) > MAX_CORRELATION:
        text += (f": correlated {fit.correlation[k, j]:+.2f} with {labels[j]}, which the "
                 "records cannot tell it from")
    return text


def extend(structure: Structure, candidate: Candidate) -> Structure:
    """``structure`` with the candidate's term and its companions (not already there)."""
    if candidate.term.kind == "input":
        return Structure(structure.series, structure.names, structure.terms,
                         structure.inputs + (candidate.term,))
    new = tuple(t for t in (*candidate.companions, candidate.term) if t not in structure.terms)
    return Structure(structure.series, structure.names, structure.terms + new, structure.inputs)


def _present(structure: Structure, candidate: Candidate) -> bool:
    term = candidate.term
    if term.kind == "input":
        return any((e.effect, e.target) == (term.effect, term.target) for e in structure.inputs)
    return term in structure.terms


def _warm(structure: Structure, theta: FloatArray, wider: Structure) -> FloatArray:
    """``theta`` of ``structure`` placed in the unknowns of ``wider`` (new terms at zero)."""
    old, new = structure.labels(), wider.labels()
    out = wider.start()
    for k, label in enumerate(old):
        out[new.index(label)] = theta[k]
    return out


def _score(current: Structure, current_fit: Fit, candidate: Candidate,
           config: ComparisonConfig) -> Scored:
    if candidate.term.kind == "input":
        candidate = _refined(current, current_fit.theta, candidate)
    wider = extend(current, candidate)
    refit = fit(wider, all_rows(current.series), _warm(current, current_fit.theta, wider))
    return Scored(candidate, refit, held_out(wider, refit.theta, config))


def _screen(current: Structure, current_fit: Fit,
            pool: Sequence[Candidate]) -> list[tuple[float, Candidate]]:
    """Each candidate with the sum of squares a linearised (one Gauss-Newton step) refit with
    it would leave: one batched simulation for all of them."""
    if not pool:
        return []
    wider = current
    for candidate in pool:
        wider = extend(wider, candidate)
    theta = _warm(current, current_fit.theta, wider)
    r, J = jacobian(wider, theta, all_rows(current.series))
    labels = wider.labels()
    base = [labels.index(label) for label in current.labels()]
    out = []
    for candidate in pool:
        own = [labels.index(term_label(t)) for t in (*candidate.companions, candidate.term)]
        columns = J[:, sorted(set(base + own))]
        step, *_ = np.linalg.lstsq(columns, r, rcond=None)
        out.append((float(np.sum((r - columns @ step) ** 2)), candidate))
    return out


def _screen_grids(current: Structure, current_fit: Fit,
                  grids: Sequence[Sequence[Candidate]]) -> list[tuple[float, Candidate]]:
    """The best member of each actuator grid with the sum of squares left after a linearised
    refit of the current unknowns (the current model's Jacobian, the member's residuals)."""
    if not grids:
        return []
    rows = all_rows(current.series)
    _, J = jacobian(current, current_fit.theta, rows)
    out = []
    for grid in grids:
        theta = np.tile(current_fit.theta, (len(grid), 1))
        r = current.residuals(theta, rows, [[c.term] for c in grid])
        step, *_ = np.linalg.lstsq(J, r.T, rcond=None)
        left = np.sum((r.T - J @ step) ** 2, axis=0)
        k = int(np.argmin(left))
        near = tuple(grid[j].term for j in (k - 1, k + 1) if 0 <= j < len(grid))
        out.append((left[k], Candidate(grid[k].term, neighbours=near)))
    return out


def _refined(current: Structure, theta: FloatArray, candidate: Candidate) -> Candidate:
    """An actuator effect's value moved to the vertex of the parabola through the refitted
    costs at it and its grid neighbours (in the logarithm of the value)."""
    if len(candidate.neighbours) < 2:
        return candidate
    key = next(iter(candidate.term.parameters))
    members = sorted((candidate.neighbours[0], candidate.term, candidate.neighbours[1]),
                     key=lambda e: e.parameters[key])
    x = np.log([e.parameters[key] for e in members])
    costs = [fit(extend(current, Candidate(e)), all_rows(current.series), theta).cost
             for e in members]
    a, b, _ = np.polyfit(x, costs, 2)
    if a <= 0:
        return candidate
    value = float(np.exp(np.clip(-b / (2 * a), x[0], x[2])))
    return Candidate(Effect(candidate.term.effect, candidate.term.target, {key: value}))
