"""The hydrofoil AKF paper's adaptive Kalman filter: the process noise of each filter switches
between two covariances with the chi-square test of its innovation."""

from __future__ import annotations

from typing import Any

import numpy as np
from numpy.typing import ArrayLike, NDArray

from marine_envs.compiled import jit

from ..base import check_covariance
from .filter import FloatArray, KalmanFilter


class AdaptiveKalmanFilter(KalmanFilter):
    """The hydrofoil AKF paper's adaptive Kalman filter: the process noise switches with the
    innovation test.

    After each update the statistic ``phi = e' Ce^-1 e`` (``Ce = H P_pred H' + WR``), chi-square
    with ``m`` degrees of freedom when the filter's model is right, picks the process noise of the
    next prediction: ``Q_max`` above the ``upper_quantile`` (0.90) of chi2(m), ``Q_min`` below the
    ``lower_quantile`` (0.50), else unchanged. It starts at ``Q_min``.

    :param Q, Q_max: the two process-noise covariances ``Q_min`` and ``Q_max`` (the hydrofoil AKF
        paper: WQmin = diag(1, 1, 0.3, 0.3), WQmax = diag(10, 10, 3, 3)).
    :param upper_quantile, lower_quantile: the thresholds' chi-square probabilities.

    Other parameters as :class:`KalmanFilter`.

    ``fired`` ``(N,)`` says whose statistic exceeded the upper threshold at the last update, and
    ``high`` whose process noise is ``Q_max`` now.
    """

    def __init__(self, F: ArrayLike, G: ArrayLike, H: ArrayLike, Q: ArrayLike, R: ArrayLike, *,
                 Q_max: ArrayLike, upper_quantile: float = 0.90, lower_quantile: float = 0.50,
                 **kwargs: Any) -> None:
        import scipy.stats  # (here: `import estimators` need not load it)

        if not 0 < lower_quantile <= upper_quantile < 1:
            raise ValueError(f"quantiles lower={lower_quantile}, upper={upper_quantile} are "
                             "invalid: need 0 < lower <= upper < 1")
        self.upper_quantile, self.lower_quantile = upper_quantile, lower_quantile
        super().__init__(F, G, H, Q, R, **kwargs)
        self.Q_min, self.Q_max = self.Q, check_covariance("Q_max", Q_max, self._n)
        self._Q_pair = np.stack([self.Q_min, self.Q_max]).astype(self.dtype)
        dof = np.arange(self.H.shape[0] + 1)
        # thresholds by the number of channels measured at the update (0 measured: never fires)
        self._upper = np.r_[np.inf, scipy.stats.chi2.ppf(upper_quantile, dof[1:])]
        self._lower = np.r_[-np.inf, scipy.stats.chi2.ppf(lower_quantile, dof[1:])]

    def bind(self, batch_size: int) -> None:
        super().bind(batch_size)
        self.high = np.zeros(batch_size, dtype=bool)
        self.fired = np.zeros(batch_size, dtype=bool)

    def reset(self, x0: ArrayLike | None = None, P0: ArrayLike | None = None,
              idx: ArrayLike | None = None) -> None:
        super().reset(x0, P0, idx)
        rows = slice(None) if idx is None else np.atleast_1d(np.asarray(idx))
        self.high[rows], self.fired[rows] = False, False

    def _noise_varies(self) -> bool:
        return bool(self.high.any() and not self.high.all())

    def _noise_choices(self) -> tuple[FloatArray, NDArray[np.bool_]]:
        return self._Q_pair, self.high

    def _after_update(self, finite: NDArray[np.bool_]) -> None:
        self.high, self.fired = self.high.copy(), np.empty(self.batch_size, dtype=bool)
        _switch_noise(self.nis, self.dof, self._upper, self._lower, self.high, self.fired)
        super()._after_update(finite)


@jit
def _switch_noise(nis, dof, upper, lower, high, fired):
    """The adaptive filter's test: ``fired`` where the statistic exceeds the upper threshold for
    its degrees of freedom; ``high`` (in place) set there, cleared below the lower one."""
    for b in range(nis.size):
        fired[b] = nis[b] > upper[dof[b]]
        if fired[b]:
            high[b] = True
        elif nis[b] < lower[dof[b]]:
            high[b] = False
