"""Sea states and wave realisations that step cheaply and reproducibly.

Choice of realisation: **random-phase superposition evaluated with rotating phasors.** Each of N
wave components is a complex phasor ``Z_j = exp(i(omega_e,j t + eps_j))``, advanced by the
constant rotation ``exp(i omega_e,j dt)`` per step, and every disturbance channel is
``Re(sum_j Z_j G_jc)``, where
``G_jc = a_j H_c(omega_j)`` carries the component amplitude ``a_j`` and the vessel's response
``H_c`` (see :mod:`marine_envs.sea.coupling`). Why this and not the alternatives:

* unlike a fitted low-order shaping filter it reproduces *any* spectrum (PM, JONSWAP, a measured
  bimodal buoy spectrum) to the resolution of the frequency grid, with no fitting step;
* it has no episode-length limit and no periodicity (unlike an inverse-FFT record), and it is
  cheap: the disturbance of 256 steps of many boats is one real matrix product of precomputed
  ``cos/sin(omega_e t)`` with the boats' phasor weights (:mod:`marine_envs.blocks`), after which
  the phasors jump a block ahead by one complex multiply;
* it is exact at the moving vessel: the phase advances at the (signed) encounter frequency while
  the amplitude and the vessel response use the absolute wave frequency, so following seas fold
  correctly without binning;
* randomness is only the phases, drawn at reset from the boat's own generator: reproducible by
  seed, and a batch of boats equals the same boats simulated one by one.

Components split the band holding 99.8 % of the energy into bins of equal energy (so they crowd
where the spectrum is high, not on its long omega^-5 tail); each component's variance is its bin's
integrated energy, so the realised Hs is that of the band (0.1 % below the target's). Within its
bin a component sits at an energy fraction given by a golden-ratio sequence, so no two are
commensurate (a uniform grid would repeat the record every ``2 pi / d_omega`` seconds).

A significant wave height that varies in time (:class:`Schedule`) scales the amplitudes each step;
when the spectral shape itself follows Hs (the one-parameter PM, ``tp=None``) the amplitudes are
tabulated over Hs and interpolated, and boats whose blocks start at the same time share one
matrix product (a reset boat starts again at 0 s, where others have been).

A reset costs about a step: a boat reset alone (a single environment) sums its first block with
each component's gains interpolated once where Hs holds over the block (as it does at the start
of the schedules), the channels a coupling leaves at zero are not summed, and the products run
on one BLAS thread (:func:`~marine_envs.blas.one_blas_thread`: a split between threads costs
more than it saves, and rounds a row differently). The numbers are those of the plain sums.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Literal

import numpy as np
from numpy.typing import ArrayLike, NDArray

from ..blas import one_blas_thread
from ..blocks import BLOCK, BlockSource
from ..compiled import jit
from .shaping import (
    WAVE_SAMPLE_SEEDS,
    WAVE_SAMPLE_STEPS,
    DisturbanceModel,
    StateBlock,
    autocovariance,
    channel_names,
    combine,
    sample_blocks,
    second_order,
)
from .spectra import MeasuredSpectrum, jonswap, pierson_moskowitz

G = 9.81  #: gravity, m/s^2
#: Block start times whose Hs-shaped weights are kept (each ``2n x BLOCK x channels`` floats).
SHAPED_CACHE = 8
#: Boats sharing a block start from which their product with the weights goes to BLAS.
BLAS_FROM = 16
_GOLDEN = (math.sqrt(5) - 1) / 2
Coupling = Callable[[NDArray[np.float64]], NDArray[np.complex128]]


def encounter_frequency(omega: ArrayLike, speed: float, heading: float) -> NDArray[np.float64]:
    """Encounter frequency ``|omega - omega^2 U cos(beta) / g|`` (rad/s), deep water.

    :param omega: wave frequency, rad/s.
    :param speed: vessel speed U, m/s.
    :param heading: encounter angle beta, rad, Fossen's convention: pi = head seas, 0 = following.
    """
    omega = np.asarray(omega, dtype=float)
    return np.abs(omega - omega**2 * speed * math.cos(heading) / G)


@dataclasses.dataclass(frozen=True)
class Schedule:
    """A quantity that varies in time, piecewise linear through ``(time, value)`` points and held
    constant before the first and after the last point.

    :param times: strictly increasing times, s.
    :param values: values at those times (e.g. significant wave height, m; must be > 0).
    """

    times: tuple[float, ...]
    values: tuple[float, ...]

    def __post_init__(self) -> None:
        t, v = np.asarray(self.times, dtype=float), np.asarray(self.values, dtype=float)
        if t.ndim != 1 or t.shape != v.shape or t.size == 0:
            raise ValueError("schedule needs equal, non-empty lists of times and values")
        if not (np.all(np.isfinite(t)) and np.all(np.diff(t) > 0)):
            raise ValueError(f"schedule times {t.tolist()} must be finite and strictly increasing")
        if not np.all(np.isfinite(v) & (v > 0)):
            raise ValueError(f"schedule values {v.tolist()} must be finite and > 0")

    @classmethod
    def from_points(cls, points: Sequence[Sequence[float]]) -> Schedule:
        """From ``[(t0, v0), (t1, v1), ...]``."""
        if len(points) == 0 or any(len(p) != 2 for p in points):
            raise ValueError(f"schedule {points!r} is invalid: give (time, value) pairs")
        times, values = zip(*points, strict=True)
        return cls(tuple(map(float, times)), tuple(map(float, values)))

    def __call__(self, t: ArrayLike) -> NDArray[np.float64]:
        return np.interp(t, self.times, self.values)

    @property
    def low(self) -> float:
        return min(self.values)

    @property
    def high(self) -> float:
        return max(self.values)


@dataclasses.dataclass(frozen=True)
class SeaState:
    """A (possibly time-varying) sea state.

    :param hs: significant wave height, m: a number, a :class:`Schedule`, a list of
        ``(t, hs)`` points, or ``None`` to keep a measured spectrum's own level.
    :param tp: peak (modal) period, s. ``None`` with ``spectrum="pm"`` gives the one-parameter
        Pierson-Moskowitz spectrum whose peak follows Hs (omega_p = 1.2561/sqrt(Hs)).
    :param spectrum: ``"pm"``, ``"jonswap"`` or a :class:`MeasuredSpectrum` (e.g. an NDBC record).
    :param gamma: JONSWAP peak-enhancement factor.
    """

    hs: float | Schedule | Sequence[Sequence[float]] | None = 2.0
    tp: float | None = 8.0
    spectrum: Literal["pm", "jonswap"] | MeasuredSpectrum = "pm"
    gamma: float = 3.3

    def __post_init__(self) -> None:
        hs = self.hs
        if hs is not None and not isinstance(hs, Schedule):
            if isinstance(hs, Sequence):
                hs = Schedule.from_points(hs)
            elif not (math.isfinite(hs) and hs > 0):
                raise ValueError(f"hs={hs!r} is invalid: significant wave height must be > 0 m")
            object.__setattr__(self, "hs", hs)
        if self.tp is not None and not (math.isfinite(self.tp) and self.tp > 0):
            raise ValueError(f"tp={self.tp!r} is invalid: peak period must be > 0 s")
        measured = isinstance(self.spectrum, MeasuredSpectrum)
        if not measured and self.spectrum not in ("pm", "jonswap"):
            raise ValueError(f"spectrum={self.spectrum!r} is invalid: 'pm', 'jonswap' or a "
                             "MeasuredSpectrum")
        if self.hs is None and not measured:
            raise ValueError("hs=None is only meaningful with a measured spectrum")
        if self.tp is None and self.spectrum == "jonswap":
            raise ValueError("tp=None is invalid for a JONSWAP spectrum: give the peak period")

    @property
    def varying(self) -> bool:
        """True when the significant wave height follows a schedule."""
        return isinstance(self.hs, Schedule)

    @property
    def shape_follows_hs(self) -> bool:
        """True when the spectral shape (not only its level) changes with Hs."""
        return self.spectrum == "pm" and self.tp is None

    def hs_range(self) -> tuple[float, float]:
        """Lowest and highest significant wave height, m."""
        if self.hs is None:
            hs = self.spectrum.hs  # type: ignore[union-attr]
            return hs, hs
        if isinstance(self.hs, Schedule):
            return self.hs.low, self.hs.high
        return float(self.hs), float(self.hs)

    def density(self, omega: ArrayLike, hs: float | None = None) -> NDArray[np.float64]:
        """Spectral density S(omega), m^2 s/rad, at significant wave height ``hs`` (m)."""
        hs = self.hs_range()[1] if hs is None else hs
        if isinstance(self.spectrum, MeasuredSpectrum):
            return self.spectrum(omega) * (hs / self.spectrum.hs) ** 2
        if self.spectrum == "jonswap":
            return jonswap(omega, hs, self.tp, self.gamma)
        return pierson_moskowitz(omega, hs, self.tp)


def elevation_coupling(omega: NDArray[np.float64]) -> NDArray[np.complex128]:
    """The identity coupling: one channel, the wave elevation at the vessel (m)."""
    return np.ones((omega.size, 1), dtype=complex)


def _fine_grid(sea: SeaState) -> NDArray[np.float64]:
    if isinstance(sea.spectrum, MeasuredSpectrum):
        return np.linspace(sea.spectrum.omega[0], sea.spectrum.omega[-1], 4000)
    return np.linspace(0.01, 40.0, 20000)


def _cumulative_energy(sea: SeaState, grid: NDArray[np.float64], hs: float | None):
    """Energy (m^2) below each grid frequency, trapezoid rule."""
    s = sea.density(grid, hs)
    return np.concatenate([[0.0], np.cumsum(0.5 * (s[1:] + s[:-1]) * np.diff(grid))])


def energy_band(sea: SeaState, fraction: float = 0.998) -> tuple[float, float]:
    """Frequency band (rad/s) holding ``fraction`` of the wave energy at every Hs of ``sea``."""
    grid, tail = _fine_grid(sea), (1 - fraction) / 2
    lows, highs = [], []
    for hs in sea.hs_range():
        cumulative = _cumulative_energy(sea, grid, hs)
        cumulative /= cumulative[-1]
        lows.append(np.interp(tail, cumulative, grid))
        highs.append(np.interp(1 - tail, cumulative, grid))
    return min(lows), max(highs)


class WaveRealisation(BlockSource):
    """Batched, seedable wave disturbance at a moving vessel (see the module docstring).

    :param sea: the sea state.
    :param coupling: maps wave frequencies (rad/s, shape (N,)) to complex responses (N, C): the
        amplitude and phase of each disturbance channel per metre of wave amplitude.
    :param dt: time step, s.
    :param speed: vessel speed, m/s.
    :param heading: encounter angle beta, rad (pi = head seas).
    :param n_components: number of wave components N.
    """

    def __init__(self, sea: SeaState, coupling: Coupling = elevation_coupling, *, dt: float,
                 speed: float = 0.0, heading: float = math.pi, n_components: int = 64) -> None:
        if not (isinstance(n_components, int) and n_components >= 1):
            raise ValueError(f"n_components={n_components!r} is invalid: an integer >= 1")
        if not (math.isfinite(dt) and dt > 0):
            raise ValueError(f"dt={dt!r} is invalid: must be > 0 s")
        if not (math.isfinite(speed) and speed >= 0):
            raise ValueError(f"speed={speed!r} is invalid: must be >= 0 m/s")
        self.sea, self.dt = sea, dt
        grid = _fine_grid(sea)
        # equal-energy bins of the most energetic sea, between the 0.1 % and 99.9 % fractions
        cumulative = _cumulative_energy(sea, grid, sea.hs_range()[1])
        fraction = cumulative / cumulative[-1]
        edges = np.linspace(0.001, 0.999, n_components + 1)
        jitter = (0.5 + _GOLDEN * np.arange(n_components)) % 1.0
        #: wave frequencies (rad/s) and signed encounter frequencies (rad/s)
        self.omega = np.interp(edges[:-1] + jitter * np.diff(edges), fraction, grid)
        self._grid, self._edges = grid, np.interp(edges, fraction, grid)
        self.omega_e = self.omega - self.omega**2 * speed * math.cos(heading) / G
        # phasor rotations over the steps of a block, and over a whole block
        self._step_times = np.arange(BLOCK) * dt
        self._rotations = np.exp(1j * np.outer(self._step_times, self.omega_e))  # (BLOCK, n)
        self._cos_sin = np.hstack([self._rotations.real, self._rotations.imag])
        self._block_rotation = np.exp(1j * self.omega_e * BLOCK * dt)
        response = np.asarray(coupling(self.omega), dtype=complex)
        self.n_channels = response.shape[1]
        super().__init__(self.n_channels)
        # the channels the sea moves: the others (a coupling's unused columns) are 0 at every
        # step, so the sums are made for these alone (the same numbers, a third of the work
        # for the hydrofoil's paper model)
        moved = np.flatnonzero(np.any(response != 0, axis=0))
        self._moved: slice | NDArray[np.intp] | None = None
        if moved.size < self.n_channels:  # (a range as a slice: basic indexing is cheaper)
            contiguous = moved.size and moved[-1] - moved[0] + 1 == moved.size
            self._moved = slice(moved[0], moved[-1] + 1) if contiguous else moved
        response = response[:, moved]
        self._hs_grid: NDArray[np.float64] | None = None
        self._shaped_cache: dict[float, NDArray[np.float64]] = {}
        self._rows_cache: dict[float, tuple] = {}
        if sea.varying and sea.shape_follows_hs:
            # amplitudes tabulated over Hs (2 % steps) and interpolated in between
            lo, hi = sea.hs_range()
            self._hs_grid = np.geomspace(lo, hi, max(2, int(np.log(hi / lo) / 0.02) + 2))
            table = np.stack([self._amplitude(hs)[:, None] * response for hs in self._hs_grid])
            # component-major real and imaginary parts, as _shaped_weights reads them
            table = table.transpose(1, 0, 2)  # (n, Hs, c)
            rotations = self._rotations.T  # (n, BLOCK)
            self._shaping = tuple(np.ascontiguousarray(a) for a in (
                rotations.real, rotations.imag, table.real, table.imag))
        elif sea.varying:
            self._gain = self._amplitude(1.0)[:, None] * response  # amplitude scales with Hs
        else:
            self._gain = self._amplitude(None)[:, None] * response

    def _amplitude(self, hs: float | None) -> NDArray[np.float64]:
        """Component amplitudes (m): sqrt(2 x energy of each bin) at significant height hs."""
        energy = np.interp(self._edges, self._grid, _cumulative_energy(self.sea, self._grid, hs))
        return np.sqrt(2 * np.diff(energy))

    # -- batched state ---------------------------------------------------------------------------
    def bind_state(self, batch_size: int) -> None:
        #: each boat's phasors exp(i(omega_e t + eps)) and time t (s) at the start of its next block
        self.phasor = np.ones((batch_size, self.omega.size), dtype=complex)
        self.block_time = np.zeros(batch_size)

    def start(self, idx: NDArray[np.intp], rngs: Sequence[np.random.Generator]) -> None:
        """New random phases for boats ``idx`` from their generators; their time restarts at 0."""
        # each boat's phases from its own generator, in order; their phasors in one operation
        # (np.exp on a row or on the stack of rows: the same numbers)
        phases = np.empty((len(idx), self.omega.size))
        for row, rng in zip(phases, rngs, strict=True):
            row[:] = rng.uniform(0.0, 2 * math.pi, self.omega.size)
        boats = _boats(idx)
        self.phasor[boats] = np.exp(1j * phases)
        self.block_time[boats] = 0.0

    def blocks(self, idx: NDArray[np.intp]) -> NDArray[np.float64]:
        """The next ``BLOCK`` steps of boats ``idx`` (boats x BLOCK x channels)."""
        if self._hs_grid is None:
            values = self._gain_values(idx)
        else:
            values = self._shaped_values(idx).reshape(idx.size, BLOCK, -1)
        if self._moved is not None:  # the channels the sea does not move: 0
            every = np.zeros((idx.size, BLOCK, self.n_channels))
            every[:, :, self._moved] = values
            values = every
        boats = _boats(idx)
        self.phasor[boats] *= self._block_rotation
        self.block_time[boats] += BLOCK * self.dt
        return values

    def _gain_values(self, idx: NDArray[np.intp]) -> NDArray[np.float64]:
        """The next block of boats ``idx`` (boats x BLOCK x the channels the sea moves) when
        the spectral shape holds:
        ``Re(sum_j Z_j(t) G_jc)`` for all steps at once, one real matrix product (on one BLAS
        thread), scaled by Hs(t) when only the level varies."""
        k, n, c = idx.size, self.omega.size, self._gain.shape[1]
        weights = self.phasor[idx, :, None] * self._gain  # (k, n, c)
        stacked = np.concatenate([weights.real, -weights.imag], axis=1)  # (k, 2n, c)
        with one_blas_thread():
            values = self._cos_sin @ stacked.transpose(1, 0, 2).reshape(2 * n, k * c)
        values = values.reshape(BLOCK, k, c).transpose(1, 0, 2)
        if self.sea.varying:
            times = self.block_time[idx, None] + self._step_times  # (k, BLOCK)
            values = values * self.sea.hs(times)[:, :, None]  # type: ignore[operator]
        return values

    def _shaped_values(self, idx: NDArray[np.intp]) -> NDArray[np.float64]:
        """The next block of boats ``idx`` (boats x BLOCK times the channels the sea moves)
        when the spectral shape follows Hs. Boats whose blocks start at the same time (boats
        reset together: at 0 s) share the Hs-shaped weights: one real matrix product per start
        time (compiled for a few boats; BLAS, on one thread, from :data:`BLAS_FROM`); a boat
        alone is summed directly (making the weights costs three times more)."""
        values = np.empty((idx.size, BLOCK * self._shaping[2].shape[2]))
        if idx.size == 1:  # a single environment: one boat, nothing to group
            boat, start = int(idx[0]), float(self.block_time[idx[0]])
            if start not in self._shaped_cache:
                self._lone_block(self.phasor[boat], start, values[0])
                return values
        unique, group = np.unique(self.block_time[idx], return_inverse=True)
        groups = [(float(start), np.flatnonzero(group == g) if unique.size > 1 else slice(None))
                  for g, start in enumerate(unique)]
        for start, members in groups:
            phasors = self.phasor[idx[members]]
            # the group's rows of `values` itself when it is every boat (no copy)
            block = values if isinstance(members, slice) else np.empty((phasors.shape[0],
                                                                        values.shape[1]))
            if phasors.shape[0] == 1 and start not in self._shaped_cache:
                self._lone_block(phasors[0], start, block[0])
            elif phasors.shape[0] < BLAS_FROM:
                _weighted(np.hstack([phasors.real, phasors.imag]),
                          self._shaped_weights(start), block)
            else:
                with one_blas_thread():
                    np.dot(np.hstack([phasors.real, phasors.imag]),
                           self._shaped_weights(start), out=block)
            if block is not values:
                values[members] = block
        return values

    def _shaped_weights(self, start: float) -> NDArray[np.float64]:
        """The weights ``(2n, BLOCK * c)`` of a block starting at ``start`` (s) when the spectral
        shape follows a time-varying Hs: ``[Re Z, Im Z] @ weights`` is ``Re(sum_j Z_j(t)
        G_jc(Hs(t)))`` for phasors ``Z`` at the block's start. A few recent start times are
        kept (boats reset together share them)."""
        if start not in self._shaped_cache:
            n, c = self.omega.size, self._shaping[2].shape[2]
            weights = np.empty((2 * n, BLOCK * c))
            _shaped_weights(*self._shaping, *self._block_rows(start)[0], weights)
            if len(self._shaped_cache) >= SHAPED_CACHE:
                del self._shaped_cache[next(iter(self._shaped_cache))]  # the oldest
            self._shaped_cache[start] = weights
        return self._shaped_cache[start]

    def _lone_block(self, phasor: NDArray[np.complex128], start: float,
                    out: NDArray[np.float64]) -> None:
        """One boat's block starting at ``start`` (s) into ``out`` (``BLOCK * c``), summed
        directly: where Hs holds over the whole block (every block of a steady stretch of the
        schedule, such as the first, where each episode starts) with gains interpolated once
        per component, else step by step (the same numbers either way)."""
        rows, steady = self._block_rows(start)
        if steady is not None:
            _steady_block(phasor, *self._shaping[:2], *steady, out)
        else:
            _shaped_block(phasor.real.copy(), phasor.imag.copy(), *self._shaping, *rows, out)

    def _block_rows(self, start: float) -> tuple[tuple[NDArray[np.intp], NDArray[np.float64]],
                                                 tuple[NDArray[np.float64], ...] | None]:
        """:meth:`_hs_rows` of a block starting at ``start`` (s), and, when they are the same at
        every step of it, each component's gains ``(re, im)`` (n x c) there; kept for the
        last few start times (a reset boat starts every episode at 0 s)."""
        if start not in self._rows_cache:
            j, w = rows = self._hs_rows(start)
            steady = None
            if np.all(j == j[0]) and np.all(w == w[0]):
                row, weight = int(j[0]), float(w[0])
                keep = 1 - weight  # as _shaped_block interpolates, so the same numbers
                steady = tuple(keep * table[:, row, :] + weight * table[:, row + 1, :]
                               for table in self._shaping[2:])
            if len(self._rows_cache) >= SHAPED_CACHE:
                del self._rows_cache[next(iter(self._rows_cache))]  # the oldest
            self._rows_cache[start] = rows, steady
        return self._rows_cache[start]

    def _hs_rows(self, start: float) -> tuple[NDArray[np.intp], NDArray[np.float64]]:
        """The rows ``j`` of the gain table below each step's Hs in a block starting at
        ``start`` (s), and the weight of row ``j + 1`` (linear interpolation)."""
        hs = self.sea.hs(start + self._step_times)  # type: ignore[operator]
        pos = np.interp(hs, self._hs_grid, np.arange(self._hs_grid.size))
        j = np.minimum(pos.astype(np.intp), self._hs_grid.size - 2)
        return j, pos - j

    def linear_model(self, dt: float, names: Sequence[str] | None = None) -> DisturbanceModel:
        """Each channel's second-order shaping filter: the AR(2) ``xi_{k+1} = phi_1 xi_k +
        phi_2 xi_{k-1} + w_k`` whose autocovariance at lags 0, 1, 2 is this sea's own
        (Yule-Walker on :data:`~marine_envs.sea.shaping.WAVE_SAMPLE_STEPS` steps from each of
        :data:`~marine_envs.sea.shaping.WAVE_SAMPLE_SEEDS`, so a sea whose height varies in time
        is averaged over its schedule); its poles as a continuous second-order system are the
        model's ``wave_peaks``. A channel this sea does not move is its mean.

        :param dt: the period the sea is sampled at, s (this realisation's ``dt``).
        :param names: the channels' names (default ``d0, d1, ...``).
        :raises ValueError: ``dt`` is not this realisation's period.
        """
        if dt != self.dt:
            raise ValueError(f"dt={dt!r} is invalid: this sea is sampled every {self.dt} s")
        names = channel_names(names, self.n_channels)
        samples = [sample_blocks(self, WAVE_SAMPLE_STEPS, seed) for seed in WAVE_SAMPLE_SEEDS]
        mean = np.mean([s.mean(axis=0) for s in samples], axis=0)
        states: list[StateBlock] = []
        peaks: dict[str, tuple[float, float]] = {}
        for c, name in enumerate(names):
            r0, r1, r2 = np.mean([autocovariance(s[:, c], 3) for s in samples], axis=0)
            if not r0 > 1e-12 * max(1.0, abs(mean[c])) ** 2:
                continue  # a channel this sea does not move
            det = r0 * r0 - r1 * r1
            phi1, phi2 = r1 * (r0 - r2) / det, (r0 * r2 - r1 * r1) / det
            innovation = max(r0 - phi1 * r1 - phi2 * r2, 1e-12 * r0)
            states.append(((name, f"{name}_prev"), np.array([[phi1, phi2], [1.0, 0.0]]), c,
                           np.diag([innovation, 0.0]), np.array([[r0, r1], [r1, r0]])))
            peaks[name] = second_order(phi1, phi2, dt)
        model = combine(states, len(names), mean, np.zeros((len(names), len(names))))
        return dataclasses.replace(model, wave_peaks=peaks)

    def sample(self, n_steps: int, rng: np.random.Generator) -> NDArray[np.float64]:
        """One boat's realisation over ``n_steps`` steps (n_steps x channels), for analysis."""
        self.bind(1)
        self.reset(np.array([0]), [rng])
        return np.concatenate([self.step() for _ in range(n_steps)])


def _boats(idx: NDArray[np.intp]) -> slice | NDArray[np.intp]:
    """Boats ``idx`` as an index: a slice for one boat (a single environment's every reset and
    refill; basic indexing costs a fraction of an index array's)."""
    return slice(int(idx[0]), int(idx[0]) + 1) if idx.size == 1 else idx


@jit
def _shaped_weights(rotation_re, rotation_im, table_re, table_im, j, w, out):
    """The weights of :meth:`WaveRealisation._shaped_weights`: ``out[i, t c + k]`` is the real
    part (``i < n``) or minus the imaginary part (row ``n + i``) of ``rotation[i, t] G_ik(Hs(t))``,
    the gains interpolated between rows ``j[t]`` and ``j[t] + 1`` of ``table[i]`` with weight
    ``w[t]``. Compiled (a block per boat of a single environment would otherwise cost more than
    its 256 steps of physics), component by component (contiguous writes), on real and imaginary
    parts (numba's complex product guards infinities in a call of its own)."""
    n, steps = rotation_re.shape
    c = table_re.shape[2]
    for i in range(n):
        for t in range(steps):
            row, weight = j[t], w[t]
            keep = 1 - weight
            r_re, r_im = rotation_re[i, t], rotation_im[i, t]
            for k in range(c):
                g_re = keep * table_re[i, row, k] + weight * table_re[i, row + 1, k]
                g_im = keep * table_im[i, row, k] + weight * table_im[i, row + 1, k]
                out[i, t * c + k] = r_re * g_re - r_im * g_im
                out[n + i, t * c + k] = -(r_re * g_im + r_im * g_re)


@jit
def _weighted(phasors, weights, out):
    """``out = phasors @ weights`` row by row, each sum in the order of the components (the
    inner loop runs along a row of ``weights``: it vectorises)."""
    for r in range(phasors.shape[0]):
        for col in range(out.shape[1]):
            out[r, col] = 0.0
        for i in range(phasors.shape[1]):
            a = phasors[r, i]
            for col in range(out.shape[1]):
                out[r, col] += a * weights[i, col]


@jit
def _shaped_block(phasor_re, phasor_im, rotation_re, rotation_im, table_re, table_im, j, w, out):
    """One boat's block (``BLOCK * c`` values, step by step) of the Hs-shaped sea summed
    directly: ``Re(sum_i Z_i rotation[i, t] G_ik(Hs(t)))`` with the gains interpolated as in
    :func:`_shaped_weights` (the same sum, without the weights matrix)."""
    n, steps = rotation_re.shape
    c = table_re.shape[2]
    for col in range(out.size):
        out[col] = 0.0
    for i in range(n):
        for t in range(steps):
            r_re, r_im = rotation_re[i, t], rotation_im[i, t]
            z_re = phasor_re[i] * r_re - phasor_im[i] * r_im
            z_im = phasor_re[i] * r_im + phasor_im[i] * r_re
            row, weight = j[t], w[t]
            keep = 1 - weight
            for k in range(c):
                g_re = keep * table_re[i, row, k] + weight * table_re[i, row + 1, k]
                g_im = keep * table_im[i, row, k] + weight * table_im[i, row + 1, k]
                out[t * c + k] += z_re * g_re - z_im * g_im


@jit
def _steady_block(phasor, rotation_re, rotation_im, gain_re, gain_im, out):
    """One boat's block (``BLOCK * c`` values, step by step) where Hs holds: what
    :func:`_shaped_block` sums, ``Re(sum_i Z_i rotation[i, t] G_ik)``, with each component's
    gains ``G_ik`` (n x c) the same at every step. The same operations on the same numbers in
    the same order, but a component's phasors over the block first, then each channel along
    the steps (contiguous loops that vectorise: ten times faster than step by step)."""
    n, steps = rotation_re.shape
    c = gain_re.shape[1]
    sums = np.zeros((c, steps))
    z_re, z_im = np.empty(steps), np.empty(steps)
    for i in range(n):
        p_re, p_im = phasor[i].real, phasor[i].imag
        r_re, r_im = rotation_re[i], rotation_im[i]
        for t in range(steps):
            z_re[t] = p_re * r_re[t] - p_im * r_im[t]
            z_im[t] = p_re * r_im[t] + p_im * r_re[t]
        for k in range(c):
            g_re, g_im = gain_re[i, k], gain_im[i, k]
            total = sums[k]
            for t in range(steps):
                total[t] += z_re[t] * g_re - z_im[t] * g_im
    for t in range(steps):
        for k in range(c):
            out[t * c + k] = sums[k, t]
