"""Events in mid-record: whether, when and how the dynamics changed.

A parameter that changes during a record (a mass or drag after a payload drop, added mass after
a morph) is not a steady term: fitted as one, it is right on neither side of the change, and a
search over steady terms names whatever imitates it best (a wave-frequency forcing, an unlisted
product) or nothing. So the change is tested first, as a change, by a generalized likelihood
ratio (GLR) on the nominal filter's whitened innovations:

* for each force equation and each kind of change (its damping ``c x`` or a constant force
  ``c`` from a time ``s`` on), the innovations' response to the step term (:mod:`.innovations`)
  at each of :data:`CHANGE_TIMES` times over the record;
* the steady terms of the same equation (a constant force, linear, quadratic and cubic damping)
  are fitted first, over the whole record, as nuisance: a change must be what no steady term of
  its equation explains, i.e. a steady term that does not fit both sides of it;
* the GLR of a change at ``s``, ``S_s^2 / I_s`` (score and information of the step's
  coefficient, orthogonal to the steady terms), is largest at the change; it is tested by the
  self-normalised score over blocks of :data:`BLOCK` seconds (the sea colours the innovations;
  blocks keep the test honest) with as many degrees of freedom as the blocks that see the step,
  Bonferroni over the equations and over the times a block apart;
* the time is refined to a sample about the best grid time, with its posterior (flat prior,
  the GLR's likelihood) giving the median time and its std.

:func:`detect` returns the significant changes, strongest first; :func:`proposed_families`
offers them to the search (:mod:`.selection`) as one-member ``parameter_change`` families
dated by the detector, in place of a grid of times that pays for its freedom.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats
from scipy.integrate import cumulative_trapezoid

from .hypotheses import (
    CHANGE_TIMES,
    Family,
    _in_equation,
    _moving,
    _targets,
    change_families,
    midpoint_states,
)
from .residuals import Residuals, displacements

FloatArray = NDArray[np.float64]
#: The change's time is sought from this share of the record to one minus it: each side must
#: hold enough of it to fit the step against the steady terms, and the filter's start-up lies
#: before (a USV force change at 6 % of a record, z = 18, was the filter settling).
MARGIN = 0.1
#: Times tried in each pass of a change time's refinement (one sample apart when they span
#: no more than this many samples).
FINE_TIMES = 300
#: Blocks of the self-normalised score test, s (the search's own block, DiagnosisConfig.block).
BLOCK = 20.0
#: Family-wise level of the detection (the search's alpha).
ALPHA = 0.01


@dataclass(frozen=True)
class ChangePoint:
    """A change of one equation's dynamics detected in mid-record.

    :param target: the state whose equation changes.  :param what: ``"damping"`` (``+ c x``
        from ``time`` on) or ``"force"`` (``+ c``).
    :param time, time_std: when, s (the median of its posterior and half its central 68 %).
    :param c, c_std: the size of the change (state units per s per unit of the state, or per s).
    :param before, after: for a damping change the equation's damping derivative
        ``d(x_dot)/dx`` (1/s) averaged over the record, before and after; for a force, the mean
        equation error before and after (state units per s).
    :param z: the self-normalised score of the change; ``p_value`` its Bonferroni-corrected
        p-value (over the equations and the times a block apart).
    """

    target: str
    what: str
    time: float
    time_std: float
    c: float
    c_std: float
    before: float
    after: float
    z: float
    p_value: float


@dataclass
class _Profile:
    """GLR, coefficient, information and score of a change at each of ``times``."""

    times: FloatArray
    glr: FloatArray
    c: FloatArray
    info: FloatArray
    z: FloatArray
    dof: FloatArray
    sigma2: float


def detect(res: Residuals, alpha: float = ALPHA) -> list[ChangePoint]:
    """The significant changes of the record (one per equation and kind at most), strongest
    (largest GLR) first; ``[]`` when nothing changed."""
    if res.innovations is None:
        return []
    candidates = list(_candidates(res))
    found = []
    for target, what in candidates:
        profile = _profile(res, target, what, _grid(res))
        k = int(np.argmax(profile.glr))
        p = 2 * stats.t.sf(abs(profile.z[k]), profile.dof[k]) * _independent_times(res) \
            * len(candidates)
        if p <= alpha:
            found.append((profile.glr[k], _dated(res, target, what, profile, min(p, 1.0))))
    found.sort(key=lambda item: -item[0])
    return [change for _, change in found]


def _independent_times(res: Residuals) -> int:
    """How many independent tests the grid of times makes: change times closer than a block
    are one test (the score is summed block by block). Bonferroni over the 60 grid times missed
    the acceptance set's hovercraft yaw damping change (z = -37 over 3 effective blocks: p =
    0.015); over the blocks it is 0.004, while on 8 tuning records without a change (effect-free
    or with a steady term; USV, hovercraft, ROV) the smallest p was 0.04."""
    return max(min(CHANGE_TIMES, int((res.time[-1] - res.time[0]) / BLOCK)), 1)


def examined(res: Residuals) -> int:
    """How many change families :func:`detect` tries (the search counts them as tried)."""
    return len(list(_candidates(res)))


def proposed_families(res: Residuals, changes: list[ChangePoint]) -> Iterator[Family]:
    """The detected ``changes`` as one-member ``parameter_change`` families at their times
    (``details["change"]``: the :class:`ChangePoint`; ``details["searched"]``: the times the
    detector tried, which the search's description length charges)."""
    for change in changes:
        family = next(change_families(res, times=np.array([change.time]), target=change.target,
                                      what=change.what))
        family.details.update(change=change, searched=CHANGE_TIMES)
        yield family


# -- the GLR profile ------------------------------------------------------------------------------
def _candidates(res: Residuals) -> Iterator[tuple[str, str]]:
    """``(target, what)`` of every change :func:`detect` tries: a damping change in each moving
    force equation, a force change in each force equation."""
    kinematic, moving = displacements(res.model), _moving(res)
    for i in _targets(res):
        if i in kinematic:
            continue
        name = res.model.state_names[i]
        if i in moving:
            yield name, "damping"
        yield name, "force"


def _grid(res: Residuals) -> FloatArray:
    t = res.time
    span = t[-1] - t[0]
    return np.linspace(t[0] + MARGIN * span, t[-1] - MARGIN * span, CHANGE_TIMES)


def _steady(res: Residuals, target: str) -> FloatArray:
    """``(T, n, a)`` the steady terms of ``target``'s equation: a constant force, and for a
    moving state linear, quadratic and cubic damping."""
    x, names = midpoint_states(res), res.model.state_names
    i = names.index(target)
    columns = [np.ones(len(x))]
    if i in _moving(res):
        xi = x[:, i]
        columns += [xi, xi * np.abs(xi), xi**3]
    return _in_equation(i, np.column_stack(columns), len(names))


def _profile(res: Residuals, target: str, what: str, times: FloatArray) -> _Profile:
    """The change's GLR at each of ``times``, its steady terms fitted as nuisance."""
    innovations = res.innovations
    assert innovations is not None
    nu = innovations.nu
    T, m = nu.shape
    B = innovations.response(_steady(res, target)).reshape(T * m, -1)
    family = next(change_families(res, times=times, target=target, what=what))
    G = innovations.response(family.w, family.v).reshape(T * m, -1)
    # everything orthogonal to the steady terms (scaled: a cubic's column is tiny or huge)
    scale = np.maximum(np.linalg.norm(B, axis=0), 1e-300)
    Bq, _ = np.linalg.qr(B / scale)
    r = nu.ravel() - Bq @ (Bq.T @ nu.ravel())
    g = G - Bq @ (Bq.T @ G)
    info = np.einsum("kr,kr->r", g, g)
    score = g.T @ r
    usable = info > 1e-12 * max(float(info.max()), 1e-300)
    c = np.where(usable, score / np.where(usable, info, 1.0), 0.0)
    glr = np.where(usable, score * c, 0.0)
    # the score's noise, block by block, from what the change leaves
    left = (r[:, None] - g * c[None, :]) * g  # (T m, R)
    per_sample = left.reshape(T, m, -1).sum(axis=1)
    block = max(int(round(BLOCK / res.dt)), 1)
    starts = np.arange(0, T, block)
    sums = np.add.reduceat(per_sample, starts, axis=0)
    noise = np.sqrt(np.sum(sums**2, axis=0))
    z = np.where(usable & (noise > 0), score / np.where(noise > 0, noise, 1.0), 0.0)
    # the blocks that carry the information: a change near an end is seen by few of them, and
    # its self-normalised score is only as sure as their number
    held = np.add.reduceat((g**2).reshape(T, m, -1).sum(axis=1), starts, axis=0)
    effective = held.sum(axis=0) ** 2 / np.maximum(np.sum(held**2, axis=0), 1e-300)
    sigma2 = max(float(r @ r - glr.max()) / max(T * m - B.shape[1] - 2, 1), 1e-300)
    return _Profile(times, glr, c, info, z, np.maximum(effective - 1, 1.0), sigma2)


def _dated(res: Residuals, target: str, what: str, coarse: _Profile, p: float) -> ChangePoint:
    """The change refined to one sample over the grid's whole span, :data:`FINE_TIMES` times a
    pass, each pass about the last one's best (where the state a damping change acts through
    falls quiet, the grid times fit alike and the truth may be a dip narrower than the grid's
    spacing beside them); dated by its posterior over every time tried
    (:func:`time_posterior`)."""
    low, high = float(coarse.times[0]), float(coarse.times[-1])
    profiles = [coarse]
    while True:
        step = max(res.dt, (high - low) / FINE_TIMES)
        fine = np.arange(low, high + step / 2, step)
        profile = _profile(res, target, what, fine[(fine > res.time[0]) & (fine < res.time[-1])])
        profiles.append(profile)
        if step <= res.dt * 1.001:
            break
        best = float(profile.times[int(np.argmax(profile.glr))])
        low, high = best - step, best + step
    times = np.concatenate([q.times for q in profiles])
    glr = np.concatenate([q.glr for q in profiles])
    sigma2 = min(q.sigma2 for q in profiles)
    low, median, high = time_posterior(times, -glr, sigma2)
    final = _profile(res, target, what, np.array([res.time[int(np.argmin(np.abs(res.time
                                                                                 - median)))]]))
    c = float(final.c[0])
    c_std = math.sqrt(final.sigma2 / max(float(final.info[0]), 1e-300))
    time = float(final.times[0])
    before, after = _levels(res, target, what, time, c)
    k = int(np.argmax(coarse.glr))
    return ChangePoint(target, what, time, float(max((high - low) / 2, res.dt)), c, c_std,
                       before, after, float(coarse.z[k]), p)


def time_posterior(times: FloatArray, sse: FloatArray, sigma2: float
                   ) -> tuple[float, float, float]:
    """The 16 %, 50 % and 84 % points of a change time's posterior: a flat prior over the
    times tried, the Gaussian likelihood ``exp(-(SSE - min) / 2 sigma2)`` between them.
    Where the state the change acts through is quiet, the times across the quiet stretch fit
    alike and the best of them is a guess; the median is the estimate of least expected
    absolute error."""
    t, first = np.unique(times, return_index=True)
    density = np.exp(-(sse[first] - sse.min()) / (2 * sigma2))
    mass = cumulative_trapezoid(density, t, initial=0.0)
    if mass[-1] <= 0:  # one time tried
        return float(t[0]), float(t[0]), float(t[0])
    low, median, high = np.interp(np.array([0.16, 0.5, 0.84]) * mass[-1], mass, t)
    return float(low), float(median), float(high)


def _levels(res: Residuals, target: str, what: str, time: float, c: float) -> tuple[float, float]:
    """Before and after the change: the damping derivative ``d(x_dot)/dx`` of the nominal
    model averaged over the record (1/s), or the mean equation error (a force)."""
    i = res.model.state_names.index(target)
    if what == "force":
        after = res.time[:-1] >= time
        error = res.error[:, i]
        return float(np.mean(error[~after])), float(np.mean(error[~after]) + c)
    x, u = res.midpoint, res.u[:-1]
    step = 1e-6 * max(float(np.std(x[:, i])), 1e-6)
    shifted = x.copy()
    shifted[:, i] += step
    derivative = float(np.mean((res.model.rhs(shifted, u)[:, i] - res.model.rhs(x, u)[:, i])
                               / step))
    return derivative, derivative + c
