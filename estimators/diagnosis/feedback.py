"""Input effects under feedback: is a rudder's gain, delay or rate limit in the record, or in
the autopilot?

Under closed-loop control the command follows what the sensors saw, which the sea drove. The
smoother's equation errors keep the part of the sea its noise model does not describe (a
narrow-band sea at a resonance is in phase with the motion it rings, and the noise model's fit
gives most of it to the state terms), so a least-squares fit of an input effect takes the sea's
share of the command for the actuator: the direct prediction-error method is consistent only
with the right noise model (Ljung, *System Identification*, 1999, sec. 13.4). On the USV
environment's own records, with no effect hidden, that gave a rudder gain of -0.3, a 3-s delay
or a rate limit, each at confidence 1.00.

The part of the command the controller did not choose, what is left of it once a linear
controller on the measured channels (now and :data:`LAGS` samples back) is fitted to it
(:func:`unchosen_inputs`), is independent of the sea: a
dither, a reference step, a pilot's input. An input effect is confirmed only if it holds on
that part: its instrumental-variable estimate (Soderstrom and Stoica, *Instrumental Variable
Methods for System Identification*, 1983), with the effect's term computed from that part as
an instrument, must be significant with the least-squares estimate's sign, or at least half the
least-squares estimate. The sea colours the errors, so the standard error is a block
jackknife's. With the command open loop the
instrument is the command itself and the test is a plain significance test of the term.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numpy.typing import NDArray
from scipy import stats

from marine_envs.models.effects import INPUT_EFFECTS, Effect, applied_inputs

from .hypotheses import midpoint_states
from .residuals import Residuals

FloatArray = NDArray[np.float64]
#: Samples of the measured channels, now and back, a controller's command is regressed on.
LAGS = 2
#: An instrumental estimate this share of the least-squares one agrees with it.
AGREEMENT = 0.5
#: Blocks of the jackknife (30 s each on a 300-s record: longer than the sea's correlation).
BLOCKS = 10


@dataclass(frozen=True)
class FeedbackCheck:
    """An input effect's coefficient on its term (1: the effect as given; the gain's term is
    ``k = 2``'s, so its coefficient is ``k - 1``) by least squares and by instrumental
    variables, and the latter's standard error."""

    least_squares: float
    instrumental: float
    std: float

    @property
    def p_value(self) -> float:
        """Two-sided p-value of the instrumental estimate being zero (jackknife t, BLOCKS - 1
        degrees of freedom)."""
        t = abs(self.instrumental) / max(self.std, 1e-300)
        return float(2 * stats.t.sf(t, BLOCKS - 1))

    def holds(self, alpha: float) -> bool:
        """The effect holds on the input the controller did not choose: its instrumental
        estimate is significant at level ``alpha`` with the least-squares sign, or at least
        :data:`AGREEMENT` of the least-squares one (too little of that input to be
        significant alone, but no sign of the sea's share)."""
        same_sign = np.sign(self.instrumental) == np.sign(self.least_squares)
        agrees = self.least_squares != 0 and self.instrumental / self.least_squares >= AGREEMENT
        return bool(same_sign and self.p_value <= alpha or agrees)


def is_input_effect(effect: Effect) -> bool:
    return effect.effect in INPUT_EFFECTS


def unchosen_inputs(res: Residuals) -> FloatArray:
    """The inputs ``(T, n_u)`` less what a linear controller on the measured channels (now and
    :data:`LAGS` samples back) commanded, about the model's nominal inputs.

    The controller is fitted to the *increments*: an external command's (a dither's jump, a
    new reference) is new at its step and independent of what the sensors saw until then, so
    the fit is consistent, whereas the levels would take the vehicle's response to the
    external command for feedback and leave some of the sea in the rest."""
    y, u = res.y, res.u
    seen = np.stack([np.roll(y[:, j], lag) for lag in range(LAGS + 1)
                     for j in range(y.shape[1])], axis=1)[LAGS:]
    gain = np.linalg.lstsq(np.diff(seen, axis=0), np.diff(u[LAGS:], axis=0), rcond=None)[0]
    out = np.zeros_like(u)
    out[LAGS:] = u[LAGS:] - seen @ gain
    out[LAGS:] -= out[LAGS:].mean(axis=0)
    return out + res.model.u0


def check(res: Residuals, effect: Effect) -> FeedbackCheck | None:
    """:class:`FeedbackCheck` of input ``effect`` on the equations of the measured states it
    moves, each scaled by its equation error's spread; None when it moves none (the smoother
    makes an unmeasured state follow the model, so its equation error cannot tell).

    The instruments are the effect's term and the input's own (a gain's) term computed from
    the input the controller did not choose (two-stage least squares): a saturation or dead
    zone of the whole command may never act on that part alone, but is correlated with it."""
    model, x, u = res.model, midpoint_states(res), res.u
    measured = np.array([name in res.channels for name in model.state_names])
    gain = Effect("input_gain", effect.target, {"k": 2.0})
    effect = gain if effect.effect == "input_gain" else effect
    free = unchosen_inputs(res)
    term = _term(res, x, u, effect)
    rows = np.flatnonzero((np.std(term, axis=0) > 0) & measured)
    if not rows.size:
        return None
    scale = np.maximum(np.std(res.error[:, rows], axis=0), 1e-300)
    c, e = (term[:, rows] / scale).ravel(), (res.error[:, rows] / scale).ravel()
    Z = np.stack([(_term(res, x, free, e_)[:, rows] / scale).ravel() for e_ in (effect, gain)],
                 axis=1)
    per_block = len(rows)  # rows of the flattened arrays per sample

    def estimates(keep: NDArray[np.bool_]) -> tuple[float, float]:
        fitted = Z[keep] @ np.linalg.lstsq(Z[keep], c[keep], rcond=1e-10)[0]  # first stage
        cross = float(fitted @ c[keep])  # 0: no command the controller did not choose
        return (float(c[keep] @ e[keep]) / max(float(c[keep] @ c[keep]), 1e-300),
                float(fitted @ e[keep]) / cross if cross > 0 else 0.0)

    n = len(term)
    sample = np.repeat(np.arange(n), per_block)
    least_squares, instrumental = estimates(np.ones(len(c), bool))
    cuts = np.linspace(0, n, BLOCKS + 1).astype(int)
    left_out = np.array([estimates((sample < cuts[b]) | (sample >= cuts[b + 1]))[1]
                         for b in range(BLOCKS)])
    std = float(np.sqrt((BLOCKS - 1) / BLOCKS * np.sum((left_out - left_out.mean()) ** 2)))
    return FeedbackCheck(least_squares, instrumental, std)


def _term(res: Residuals, x: FloatArray, u: FloatArray, effect: Effect) -> FloatArray:
    """Input ``effect``'s term in the state equations ``(T - 1, n)`` with inputs ``u``."""
    model = res.model
    return (model.rhs(x, applied_inputs(effect, model, u, res.dt)) - model.rhs(x, u))[:-1]
