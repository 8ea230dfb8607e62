"""Multi-step predictions: the test every hypothesis must finally pass.

From the smoothed state at many start times, the model (with the hypothesised effects) predicts
the measured channels a few seconds ahead with the recorded inputs. A missing term accumulates
over the horizon while sensor noise does not, and a term in an unmeasured state's equation shows
in the channels it drives, so these predictions both fit the candidates' parameters (free of the
smoothing bias of the equation errors) and score them on held-out start times.

A term that reads states the nominal model cannot predict over the horizon (a ROV's sway and
yaw rates, whose 3-s prediction errors are 4x their spread) would carry their prediction
errors, not itself, into the test: the true ``35 v r`` in a ROV's surge made its surge
predictions 6 times worse. Each state term is therefore either predicted in the loop or
evaluated on the smoothed states (what it adds along the record, as the innovations see it),
whichever predicts the first part of the record, where the findings are fitted, better.

A sea the noise model carries as one narrow-band process (:class:`~.residuals.Sea`) is
predicted too: its oscillator runs free from its smoothed state at the start. Such a sea is
predictable for several seconds, and predictions without it were improved by any term that
keeps the roll ringing (a negative roll damping on an effect-free USV record: 64 % held out).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np
from numpy.typing import NDArray
from scipy import linalg

from marine_envs.models.effects import Effect, EffectModel, state_term
from marine_envs.models.integrate import rk4

from .residuals import Residuals, model_noise_spread

FloatArray = NDArray[np.float64]
#: A prediction that runs off (a wild trial value) is pinned here, in channel units, so that
#: its squared error stays finite.
DIVERGED = 1e6


class Rollouts:
    """Predictions ``horizon`` seconds ahead from start times every ``stride`` seconds.

    :param residuals: the nominal model's smoothed states and the data.
    :param fit_fraction: starts whose horizon ends in the first part fit; the others validate.
    :param horizon: prediction horizon, s.  :param stride: time between starts, s.
    """

    def __init__(self, residuals: Residuals, fit_fraction: float, horizon: float = 3.0,
                 stride: float = 0.5) -> None:
        self.res, self.fit_fraction = residuals, fit_fraction
        dt, T = residuals.dt, len(residuals.time)
        self.steps = max(2, int(round(horizon / dt)))
        starts = np.arange(0, T - self.steps - 1, max(1, int(round(stride / dt))))
        boundary = int(fit_fraction * T)
        self.fit = starts + self.steps < boundary
        self.held = starts >= boundary
        self.starts = starts
        model = residuals.model
        self.channel_index = [model.output_names.index(c) for c in residuals.channels]
        self._outputs_are_states = model.output_names == model.state_names
        self.target = residuals.y[starts[:, None] + np.arange(1, self.steps + 1)]  # (S, H, m)
        self._carried: dict[str, bool] = {}
        if residuals.sea is not None:  # the sea's own prediction: its oscillator runs free
            h = residuals.dt / residuals.substeps
            self._sea_gains = residuals.sea.gains(len(model.state_names))
            self._sea_step = linalg.expm(residuals.sea.dynamics() * h)
        nominal = self.predict([])
        self.weights = 1 / np.maximum(np.var((self.target - nominal)[self.fit], axis=(0, 1)),
                                      1e-300)
        self.nominal_error = self.target - nominal
        # what no model can remove: the sensor noise in the predicted samples, per start
        self.noise_floor = self.steps * float(np.sum(self.weights * residuals.noise**2))
        # and what the model's own disturbance model (a DP vessel's sea) expects on top
        self.sea_floor = float(np.sum(self.weights * model_noise_spread(
            model, residuals.channels, residuals.dt, self.steps)))

    def predict(self, effects: Sequence[Effect],
                forcing: Mapping[int, FloatArray] | None = None,
                shift: FloatArray | None = None) -> FloatArray:
        """Predicted channels ``(S, H, m)`` of the model with ``effects``; ``forcing`` maps the
        index of a ``wave_frequency`` effect to its process ``(T,)`` (equation units);
        ``shift`` ``(T, n)`` moves the smoothed states to where the smoother of the model with
        the effects would have put them (the nominal smoother bent them to fit the data)."""
        with np.errstate(over="ignore", invalid="ignore"):  # a wild trial value may overflow
            return self._predict(effects, forcing, shift)

    def carries(self, effect: Effect) -> bool:
        """Whether ``effect``'s state term is predicted in the loop (the model with it) or
        evaluated on the smoothed states: whichever predicts the first part's channels better
        (module doc; a damping mends the very drift it reads, a product of two drifting states
        multiplies it). Input and sensor effects read no state."""
        if effect.kind != "state" or effect.effect in ("current", "wave_frequency"):
            return True
        key = repr(effect)
        if key not in self._carried:
            model = self.res.model
            with np.errstate(over="ignore", invalid="ignore"):
                looped = self._run(EffectModel(model, [effect]), {}, None, None)
                frozen = self._run(EffectModel(model, []), {}, self._frozen([effect], None),
                                   None)
            self._carried[key] = bool(self._fit_error(looped) <= self._fit_error(frozen))
        return self._carried[key]

    def _fit_error(self, predicted: FloatArray) -> float:
        r = (self.target - predicted)[self.fit]
        return float(np.sum(r * r * self.weights))

    def _predict(self, effects: Sequence[Effect], forcing: Mapping[int, FloatArray] | None,
                 shift: FloatArray | None) -> FloatArray:
        kept = [k for k, e in enumerate(effects) if self.carries(e)]
        truth = EffectModel(self.res.model, [effects[k] for k in kept])
        forcing = {kept.index(k): f for k, f in (forcing or {}).items()}  # never frozen
        frozen = self._frozen([e for k, e in enumerate(effects) if k not in kept], shift)
        return self._run(truth, forcing, frozen, shift)

    def _run(self, truth: EffectModel, forcing: Mapping[int, FloatArray],
             frozen: FloatArray | None, shift: FloatArray | None) -> FloatArray:
        """Predicted channels ``(S, H, m)`` of ``truth`` plus the ``frozen`` terms
        ``(T, n)``."""
        res, model = self.res, self.res.model
        u = truth.applied_inputs(res.u, res.dt)
        x = res.x[self.starts] + (0.0 if shift is None else shift[self.starts])
        out = np.empty((len(self.starts), self.steps, len(res.channels)))
        h = res.dt / res.substeps
        sea = None if res.sea is None else res.sea_state[self.starts]  # type: ignore[index]
        for j in range(self.steps):
            k = self.starts + j
            w = {i: f[k] for i, f in forcing.items()}
            uk, added = u[k], 0.0 if frozen is None else frozen[k]
            for m in range(res.substeps):
                waves = 0.0 if sea is None else sea @ self._sea_gains.T
                def f(z, s, uk=uk, w=w, added=added + waves):
                    return truth.rhs(z, uk, None, s, w) + added

                x = rk4(f, x, h, t=res.time[k] + m * h)
                if sea is not None:
                    sea = sea @ self._sea_step.T
            outputs = x if self._outputs_are_states else model.output(x)
            out[:, j] = truth.measure(outputs[:, self.channel_index], res.channels)
        return np.clip(np.nan_to_num(out, nan=DIVERGED), -DIVERGED, DIVERGED)

    def _frozen(self, effects: Sequence[Effect], shift: FloatArray | None) -> FloatArray | None:
        """The state terms of ``effects`` on the (shifted) smoothed states ``(T, n)``."""
        if not effects:
            return None
        res, model = self.res, self.res.model
        x = res.x + (0.0 if shift is None else shift)
        added = np.zeros_like(res.x)
        for effect in effects:
            added[:, model.state_names.index(effect.target)] += state_term(
                effect, model, x, res.u, res.time)
        return added

    def errors(self, effects: Sequence[Effect],
               forcing: Mapping[int, FloatArray] | None = None,
               shift: FloatArray | None = None) -> FloatArray:
        """Weighted squared prediction error per start ``(S,)``."""
        with np.errstate(over="ignore", invalid="ignore"):  # a wild trial value may overflow
            r = self.target - self.predict(effects, forcing, shift)
            return np.minimum(np.sum(r * r * self.weights, axis=(1, 2)), 1e30)

    def improvement(self, before: FloatArray, after: FloatArray) -> float:
        """The share of the held-out error in excess of the sensor noise that ``after`` removes
        (per-start weighted errors as from :meth:`errors`)."""
        floor = self.noise_floor * int(self.held.sum())
        b, a = float(before[self.held].sum()), float(after[self.held].sum())
        excess = max(b - floor, 0.05 * b)
        return min((b - a) / excess, 1.0) if excess > 0 else 0.0

    def improvement_z(self, before: FloatArray, after: FloatArray, block: float) -> float:
        """How many standard errors ``after`` improves the held-out predictions over ``before``
        (per-start errors as from :meth:`errors`; negative: worse): the summed error
        difference over its spread across ``block``-s blocks of starts, which the overlapping
        horizons and the sea make dependent."""
        d = (before - after)[self.held]
        if not d.size:
            return 0.0
        stride = float(self.res.time[self.starts[1]] - self.res.time[self.starts[0]]) \
            if len(self.starts) > 1 else self.res.dt
        size = max(1, int(round(block / stride)))
        blocks = np.add.reduceat(d, np.arange(0, len(d), size))
        scale = float(np.sqrt(np.sum(blocks**2)))
        return float(d.sum() / scale) if scale > 0 else 0.0

    def sea_share(self, before: FloatArray) -> float:
        """The share of the held-out error in excess of the sensor noise that the model's own
        disturbance model expects (0 for a model without one)."""
        b = float(before[self.held].mean())
        return min(self.sea_floor / max(b - self.noise_floor, 1e-300), 1.0) \
            if self.sea_floor else 0.0

    def rmse(self, effects: Sequence[Effect], forcing: Mapping[int, FloatArray] | None = None,
             shift: FloatArray | None = None, held: bool = True) -> dict[str, float]:
        """Root-mean-square prediction error per channel over the held-out (or fit) starts."""
        rows = self.held if held else self.fit
        r = (self.target - self.predict(effects, forcing, shift))[rows]
        return {c: float(np.sqrt(np.mean(r[..., j] ** 2)))
                for j, c in enumerate(self.res.channels)}
