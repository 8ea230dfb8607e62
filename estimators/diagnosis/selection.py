"""Step 3: pick the hypotheses the data support, fit them jointly and say how sure we are.

Every family of candidate terms (:mod:`.hypotheses`) is scored by blocked cross-validation of
the nominal filter's whitened innovations (:mod:`.innovations`): the record is cut into
``folds`` contiguous blocks, and on each block the family's member and coefficient are chosen
on the *other* blocks, then the block's innovations are corrected by the term. Every sample is
thus predicted by a fit that never saw it, so a grid of delays or a library of products pays
for its freedom, and the whole record validates.

The held-out reduction of the squared innovations is tested over short blocks (a
self-normalised one-sided z-test, see :func:`gain_test`) and the p-value multiplied by the
number of families tried (Bonferroni). The significant family with the largest gain becomes
a finding, unless a rival with no more parameters explains what it leaves while it does not
explain the rival's leftovers (:func:`encompassing`); rivals neither explains are reported
beside it (:func:`rivals`). The search repeats with the finding in the model, until nothing
significant is left. The findings are then refitted jointly on the whole record (backfitting).

A finding's ``confidence`` is one minus its corrected p-value, times its share of the evidence
among the significant alternatives (Akaike weights from the held-out log-likelihood gains), so
two hypotheses that explain the same thing share it.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from marine_envs.models.effects import Effect

from . import changes
from .hypotheses import Family, all_families, bias_term
from .innovations import Innovations
from .residuals import Residuals

FloatArray = NDArray[np.float64]
BoolArray = NDArray[np.bool_]


@dataclass(frozen=True)
class DiagnosisConfig:
    """The one configuration every diagnosis uses (no per-vehicle or per-effect tuning).

    :param folds: contiguous cross-validation blocks.
    :param block: length of the significance test's blocks, s.
    :param alpha: significance level of a finding: family-wise in the search, and again on
        the held-out part (one pre-set hypothesis there).
    :param max_findings: at most this many effects are reported.
    :param fit_fraction: the reported validation fits on this first part of the record and
        predicts the rest.
    :param horizon, stride: that validation's prediction horizon and start spacing, s.
    :param confirm_block: block length of the held-out confirmation's test, s (shorter than
        ``block``: the held-out part is short and its innovations are whitened).
    """

    folds: int = 5
    block: float = 20.0
    alpha: float = 0.01
    max_findings: int = 3
    fit_fraction: float = 0.7
    horizon: float = 3.0
    stride: float = 0.5
    confirm_block: float = 5.0


@dataclass
class Fitted:
    """A fitted member of a family.

    :param effect: the catalogue effect with its parameters.
    :param contribution: its term in the state equations ``(T - 1, n)``, state units per s.
    :param response: its whitened innovation response ``(T, m)`` (for the joint fits).
    :param w, v: its term in the state equations ``(T, n)`` and on the channels ``(T, m)``.
    """

    effect: Effect
    contribution: FloatArray
    response: FloatArray
    free: bool
    w: FloatArray | None = None
    v: FloatArray | None = None
    std: dict[str, float] = field(default_factory=dict)
    n_parameters: int = 1
    multiplicity: int = 1
    details: dict[str, Any] = field(default_factory=dict)


@dataclass
class Scored:
    """A family's cross-validated score and its fit on the whole record."""

    family: Family
    fitted: Fitted
    improvement: float  # share of the held-out innovation sum of squares it removes
    gain: float  # held-out log-likelihood gain, less a BIC charge for extra parameters
    t: float
    p_value: float  # Bonferroni-corrected
    confidence: float = 0.0
    alone: float = 0.0  # validation improvement of this term alone (set by the api)
    held_out_p: float = 0.0  # does it, fitted on the first part, predict the rest? (by the api)
    #: the share of the held-out whitened innovations' sum of squares it removes so (by the api)
    innovation_gain: float = 0.0
    #: how many standard errors its held-out predictions improve (negative: worse; by the api)
    alone_z: float = 0.0
    #: whether its held-out improvement is that of the innovations, not of the predictions
    on_innovations: bool = False
    #: its held-out innovations ``(T, m)`` while its round is compared (significant ones)
    residual: FloatArray | None = field(default=None, repr=False)
    #: significant families of its round the record cannot tell from it (:func:`rivals`)
    rivals: list[Scored] = field(default_factory=list, repr=False)

    @property
    def effect(self) -> Effect:
        return self.fitted.effect


@dataclass
class Selection:
    """The findings, and every family of the first round ranked (for reports and tests)."""

    findings: list[Scored]
    ranking: list[Scored]
    tried: int
    combined_improvement: float = 0.0
    #: per-start weighted held-out prediction errors with the findings refitted on the first
    #: part (set by the api's validation)
    validated_errors: FloatArray | None = None


# -- least squares on the innovations -------------------------------------------------------------
@dataclass
class _Sums:
    """Sums over a set of rows of the products a joint fit needs: base columns ``B`` (free),
    target ``t``, family members ``G``."""

    tt: float
    Bt: FloatArray  # (A,)
    BB: FloatArray  # (A, A)
    Gt: FloatArray  # (R,)
    GG: FloatArray  # (R,)
    BG: FloatArray  # (A, R)


def _member_fits(s: _Sums, free: bool) -> tuple[FloatArray, FloatArray, FloatArray]:
    """For every member: the sum of squares left, its coefficient, and the base coefficients
    ``(R,), (R,), (A, R)`` (Frisch-Waugh: the member against the base's residual)."""
    BBinv = np.linalg.pinv(s.BB) if s.BB.size else s.BB
    if free:
        q = BBinv @ s.Bt
        tt = s.tt - s.Bt @ q
        Gt = s.Gt - s.BG.T @ q
        GG = s.GG - np.einsum("ar,ab,br->r", s.BG, BBinv, s.BG)
        ok = GG > 1e-12 * np.maximum(s.GG, 1e-300)
        coef = np.where(ok, Gt / np.where(ok, GG, 1.0), 0.0)
        sse = tt - coef * Gt
        return sse, coef, q[:, None] - BBinv @ s.BG * coef[None, :]
    Bt = s.Bt[:, None] - s.BG
    beta = BBinv @ Bt
    sse = s.tt - 2 * s.Gt + s.GG - np.einsum("ar,ar->r", Bt, beta)
    return sse, np.ones_like(sse), beta


class Evaluator:
    """Cross-validated fits of families on top of accepted columns."""

    def __init__(self, nu: FloatArray, folds: int) -> None:
        T = len(nu)
        self.nu = nu
        self.fold = (np.arange(T) * folds) // T
        self.bounds = np.searchsorted(self.fold, np.arange(folds))

    def _products(self, base: list[Fitted], G: FloatArray | None):
        t = self.nu - sum((f.response for f in base if not f.free), np.zeros_like(self.nu))
        B = np.stack([f.response for f in base if f.free], axis=-1) if any(
            f.free for f in base) else np.zeros(self.nu.shape + (0,))
        G = np.zeros(self.nu.shape + (0,)) if G is None else G
        per = {"tt": np.einsum("km,km->k", t, t), "Bt": np.einsum("kma,km->ka", B, t),
               "BB": np.einsum("kma,kmb->kab", B, B), "Gt": np.einsum("kmr,km->kr", G, t),
               "GG": np.einsum("kmr,kmr->kr", G, G), "BG": np.einsum("kma,kmr->kar", B, G)}
        return t, B, G, per

    def cross_validate(self, base: list[Fitted], G: FloatArray | None = None,
                       free: bool = True) -> FloatArray:
        """Held-out innovations left ``(T, m)`` by the base plus the family ``G`` ``(T, m, R)``
        (its member chosen on the other folds), or by the base alone."""
        t, B, G, per = self._products(base, G)
        totals = {k: v.sum(axis=0) for k, v in per.items()}
        folds = {k: np.add.reduceat(v, self.bounds, axis=0) for k, v in per.items()}
        errors = np.empty_like(t)
        for f in range(len(self.bounds)):
            train = _Sums(**{k: totals[k] - folds[k][f] for k in per})
            rows = self.fold == f
            residual = t[rows] - B[rows] @ _base_only(train)
            if G.shape[2]:
                sse, coef, beta = _member_fits(train, free)
                r = int(np.argmin(sse))
                residual = t[rows] - B[rows] @ beta[:, r] - coef[r] * G[rows][:, :, r]
            errors[rows] = residual
        return errors

    def fit(self, base: list[Fitted], G: FloatArray, free: bool,
            rows: BoolArray | None = None) -> tuple[FloatArray, FloatArray, FloatArray]:
        """Every member fitted on ``rows`` (default: all): sums of squares, coefficients and
        base coefficients, as :func:`_member_fits`."""
        _, _, _, per = self._products(base, G)
        sums = _Sums(**{k: (v if rows is None else v[rows]).sum(axis=0) for k, v in per.items()})
        return _member_fits(sums, free)


def _base_only(s: _Sums) -> FloatArray:
    return np.linalg.pinv(s.BB) @ s.Bt if s.BB.size else s.Bt


# -- the search -----------------------------------------------------------------------------------
def select(residuals: Residuals, config: DiagnosisConfig = DiagnosisConfig()) -> Selection:
    """Greedy cross-validated search for the effects the record supports (module doc)."""
    innovations = residuals.innovations
    assert innovations is not None
    evaluator = Evaluator(innovations.nu, config.folds)
    findings: list[Scored] = []
    ranking: list[Scored] = []
    tried = 0
    # a change in mid-record is detected and dated first (:mod:`.changes`), and only what it
    # detects is searched, at its time; the changes it tried count as tried
    detected = changes.detect(residuals, config.alpha)
    catalogue = list(all_families(residuals)) + list(changes.proposed_families(residuals,
                                                                               detected))
    untried_changes = changes.examined(residuals) - len(detected)
    response = _cached_responses(innovations)
    for round_ in range(config.max_findings):
        accepted = [s.fitted for s in findings]
        before = evaluator.cross_validate(accepted)
        families = [f for f in catalogue if f.key not in {s.family.key for s in findings}]
        tried = len(families) + untried_changes
        scored = [s for f in families if (s := _score(residuals, evaluator, accepted, before, f,
                                                      config, tried, response(f)))]
        scored.sort(key=lambda s: s.gain, reverse=True)
        _confidences(scored)
        if round_ == 0:
            ranking = scored
        # the best *significant* family: a lower-ranked one may be significant when the top
        # one is not (its gain is larger but spread over too few blocks)
        best = next((s for s in scored if s.p_value <= config.alpha and s.gain > 0), None)
        if best is not None:
            block = int(round(config.block / residuals.dt))
            best = encompassing(best, scored, block, config.alpha)
            best = yield_to_change(best, scored, block, config.alpha)
            best.rivals = rivals(best, scored, block, config.alpha)
        for s in scored:
            s.residual = None  # (T, m) each: kept only while the round is compared
        if best is None:
            break
        findings.append(best)
    if len(findings) > 1:
        _backfit(residuals, evaluator, findings)
    return Selection(findings, ranking, tried)


def _cached_responses(innovations: Innovations,
                      limit: float = 16e6) -> Callable[[Family], FloatArray]:
    """A family's innovation response, kept for the later rounds when it is small (the
    filter does not change between rounds; one response is a pass over the whole record)."""
    cache: dict[int, FloatArray] = {}

    def response(family: Family) -> FloatArray:
        if id(family) not in cache:
            G = innovations.response(family.w, family.v)
            if G.nbytes > limit:
                return G
            cache[id(family)] = G
        return cache[id(family)]

    return response


def _score(res: Residuals, evaluator: Evaluator, accepted: list[Fitted], before: FloatArray,
           family: Family, config: DiagnosisConfig, tried: int, G: FloatArray) -> Scored | None:
    if not np.any(np.abs(G) > 1e-9):
        return None  # the measured channels do not see this term
    after = evaluator.cross_validate(accepted, G, family.free)
    t, p = gain_test(before, after, int(round(config.block / res.dt)))
    sigma2 = float(np.mean(before**2))  # per channel and sample
    b, a = float(np.sum(before**2)), float(np.sum(after**2))
    fitted = fit_member(res, evaluator, accepted, family, G)
    # a simpler term that explains as much is preferred: a BIC charge per extra parameter and
    # the description length of the member chosen (which source, delay, time, library term)
    charge = 0.5 * math.log(before.size) * (family.n_parameters - 1) \
        + math.log(family.details.get("searched", len(family.members)))
    p = min(1.0, p * tried)
    return Scored(family, fitted, 1 - a / b, (b - a) / (2 * sigma2) - charge, t, p,
                  residual=after if p <= config.alpha else None)


def _explains(a: Scored, b: Scored, block: int, alpha: float) -> bool:
    """Whether ``a``'s held-out correction significantly predicts what ``b``'s leaves (the
    search's test, :func:`gain_test`, on ``b``'s held-out innovations)."""
    return gain_test(b.residual, a.residual, block)[1] <= alpha  # type: ignore[arg-type]


def encompassing(best: Scored, scored: list[Scored], block: int, alpha: float) -> Scored:
    """The significant family that explains what its rivals leave, starting from the largest
    gain: ``best`` yields to a rival that predicts what ``best`` leaves while ``best`` does not
    predict what it leaves (the encompassing principle). Gains of look-alike terms differ by
    less than their noise; which one accounts for the other's misses is the sharper test.
    Only rivals with no more parameters compete so: a richer family (a change point, which
    nests the constant term it changes) explains some of anything's leftovers, and the
    gain's charge for its parameters judges it instead."""
    for _ in range(len(scored)):
        challenger = next((s for s in scored if s is not best and s.residual is not None
                           and s.gain > 0 and s.family.n_parameters <= best.family.n_parameters
                           and _explains(s, best, block, alpha)
                           and not _explains(best, s, block, alpha)), None)
        if challenger is None:
            break
        best = challenger
    return best


def yield_to_change(best: Scored, scored: list[Scored], block: int, alpha: float) -> Scored:
    """A change the detector found (:mod:`.changes`) against a steady term: the term must fit
    both sides of the change, or it yields to the change, when the change predicts what the
    term leaves and the term does not predict what the change leaves. The encompassing test
    (:func:`encompassing`) leaves richer families out, since a change nests the steady term it
    changes; a detected change has already beaten its equation's steady terms on the whole
    record."""
    if best.family.effect == "parameter_change":
        return best
    return next((s for s in scored if s.family.effect == "parameter_change"
                 and s.residual is not None and s.gain > 0 and _explains(s, best, block, alpha)
                 and not _explains(best, s, block, alpha)), best)


def rivals(best: Scored, scored: list[Scored], block: int, alpha: float) -> list[Scored]:
    """The significant families of ``best``'s round that explain the record as well: neither
    predicts what the other leaves. Damping laws over one range of amplitudes, or a thrust
    delay and a surge damping, are often such pairs: the record cannot choose, and the user
    should know it."""
    return [s for s in scored if s is not best and s.residual is not None and s.gain > 0
            and not _explains(best, s, block, alpha) and not _explains(s, best, block, alpha)]


def fit_member(res: Residuals, evaluator: Evaluator, accepted: list[Fitted], family: Family,
               G: FloatArray, rows: BoolArray | None = None) -> Fitted:
    """The family's best member and coefficient on ``rows`` (default: the whole record) given
    the accepted terms, with standard deviations (a change's time: the detector's,
    :mod:`.changes`)."""
    sse, coef, _ = evaluator.fit(accepted, G, family.free, rows)
    r = int(np.argmin(sse))
    n_rows = int(rows.sum()) if rows is not None else len(evaluator.nu)
    sigma2 = max(float(sse[r]), 1e-300) / max(n_rows * evaluator.nu.shape[1], 1)
    std: dict[str, float] = {}
    if family.free:
        _, _, _, per = evaluator._products(accepted, G[:, :, r:r + 1])
        sums = {k: (v if rows is None else v[rows]).sum(axis=0) for k, v in per.items()}
        GG = float(sums["GG"][0] - sums["BG"][:, 0] @ np.linalg.pinv(sums["BB"])
                   @ sums["BG"][:, 0]) if sums["BB"].size else float(sums["GG"][0])
        std[family.coefficient] = math.sqrt(sigma2 / max(GG, 1e-300))  # type: ignore[index]
        if "change" in family.details:
            std["time"] = family.details["change"].time_std
    else:
        name = family.details["grid"]
        values = np.array([m[name] for m in family.members])
        value, std[name] = _parabola(values, sse, r, sigma2)
        family = _with_member(family, r, {name: value})
    return _fitted(res, family, r, float(coef[r]), G[:, :, r] * coef[r], std)


def _fitted(res: Residuals, family: Family, r: int, coefficient: float, response: FloatArray,
            std: dict[str, float]) -> Fitted:
    effect = family.effect_for(r, coefficient)
    details: dict[str, Any] = dict(family.details)
    if family.effect == "sensor_bias":
        contribution = bias_term(res, family.target, coefficient)[:-1]
    else:
        contribution = family.term(r, coefficient)[:-1]
    if family.effect == "wave_frequency":
        i = res.model.state_names.index(family.target)
        details["forcing"] = family.w[:, i, r] * coefficient  # type: ignore[index]
        effect = Effect(effect.effect, effect.target,
                        {k: v for k, v in effect.parameters.items() if k != "gain"})
        std.pop("gain", None)
        std.update({"omega": details["resolution"] / 2, "zeta": effect.parameters["zeta"] / 2})
    w = None if family.w is None else family.w[:, :, r] * coefficient
    v = None if family.v is None else family.v[:, :, r] * coefficient
    return Fitted(effect, contribution, response, family.free, w, v, std, family.n_parameters,
                  len(family.members), details)


def _with_member(family: Family, r: int, parameters: dict[str, Any]) -> Family:
    """The family with member ``r``'s parameters replaced (a refined grid value)."""
    members = list(family.members)
    members[r] = {**members[r], **parameters}
    return Family(family.effect, family.target, members, family.w, family.v,
                  family.coefficient, family.offset, family.n_parameters, family.details)


def _parabola(values: FloatArray, sse: FloatArray, r: int,
              sigma2: float) -> tuple[float, float]:
    """A grid parameter refined by a parabola through its neighbours' sums of squares (on the
    grid's own ordering), its std where the parabola rises by one residual variance."""
    order = np.argsort(values)
    v, s = values[order], sse[order]
    k = int(np.flatnonzero(order == r)[0])
    if 0 < k < len(v) - 1:
        a, b, _ = np.polyfit(v[k - 1:k + 2], s[k - 1:k + 2], 2)
        if a > 0:
            best = float(np.clip(-b / (2 * a), v[k - 1], v[k + 1]))
            return best, float(math.sqrt(sigma2 / a))
    return float(v[k]), float(abs(v[-1] - v[0]) / 2)


def gain_test(before: FloatArray, after: FloatArray, block: int) -> tuple[float, float]:
    """One-sided test that the held-out correction ``D = before - after`` ``(T, m)`` predicts
    the innovations ``before``: ``z = sum D.before / sqrt(sum_b (sum D.after)^2)`` over short
    contiguous blocks ``b``. Under the null the innovations are noise independent of ``D``
    (fitted on other folds), so ``z`` is standard normal; the blocks keep it so when the
    whitened innovations are not perfectly white, and the self-normalisation when a few
    excited stretches carry most of the evidence."""
    correction = before - after
    signal_ = np.sum(correction * before)
    noise = np.sum(correction * after, axis=1)
    blocks = np.add.reduceat(noise, np.arange(0, len(noise), max(block, 1)))
    scale = math.sqrt(float(np.sum(blocks**2)))
    z = float(signal_ / scale) if scale > 0 else 0.0
    return z, float(stats.t.sf(z, max(len(blocks) - 1, 1)))  # few blocks: heavier tails


def _confidences(scored: list[Scored]) -> None:
    """``(1 - p) *`` the family's Akaike weight among the significant ones (evidence: the
    held-out log-likelihood gain)."""
    significant = [s for s in scored if s.p_value < 0.5 and s.gain > 0]
    if not significant:
        return
    evidence = np.array([s.gain for s in significant])
    weights = np.exp(evidence - evidence.max())
    weights /= weights.sum()
    for s, w in zip(significant, weights, strict=True):
        s.confidence = float((1 - s.p_value) * w)


def _backfit(res: Residuals, evaluator: Evaluator, findings: list[Scored]) -> None:
    """Refit each finding given the others, on the whole record."""
    for finding, fitted in zip(findings, fit_findings(res, evaluator, findings), strict=True):
        finding.fitted = fitted


def fit_findings(res: Residuals, evaluator: Evaluator, findings: list[Scored],
                 rows: BoolArray | None = None) -> list[Fitted]:
    """The findings refitted jointly (backfitting) on ``rows`` (default: all; the first part
    only for an honest validation on the rest)."""
    fitted = [s.fitted for s in findings]
    for _ in range(2 if len(findings) > 1 else 1):
        for k, finding in enumerate(findings):
            others = [f for j, f in enumerate(fitted) if j != k]
            G = res.innovations.response(finding.family.w, finding.family.v)  # type: ignore
            fitted[k] = fit_member(res, evaluator, others, finding.family, G, rows)
    return fitted
