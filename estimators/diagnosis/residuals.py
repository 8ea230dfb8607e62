"""Step 1 of a diagnosis: the state the nominal model believes, and what it cannot explain.

The nominal model's extended Kalman filter and Rauch-Tung-Striebel smoother estimate every state,
measured or not, over the whole record. Their process noise is first guessed from the data, then
set to what the model actually fails to explain (one expectation-maximisation-like pass), so the
smoothed states follow the recording and the model's mistakes land in the *equation errors*:

    e_k = (x_{k+1} - Phi(x_k, u_k)) / dt

(``Phi``: one RK4 step of the nominal model). A term the model leaves out shows up in ``e`` as a
function of the smoothed states and inputs, which is what the hypotheses are fitted to.

The unmodelled sea or wind is coloured, and under closed-loop control a coloured forcing the
filter takes for white biases every fit of a term that the controller correlates with it (the
direct prediction-error method is consistent only with the right noise model). So the last pass
gives each measured force equation a first-order Gauss-Markov forcing state, its correlation
time and variance read off the part of the first pass's equation errors that is not a function
of the state and input (:func:`forcing_model`). A seaway that drives several equations
through the model's wave channels as one narrow-band process is one sea (:func:`sea_model`): a
second-order oscillator added to each at its own amplitude and phase. Where the model names
its environment (a hovercraft's wind, a ROV's current: ``VehicleModel.environment_disturbances``)
and the measured equations determine it, that forcing is the environment itself, estimated as
Gauss-Markov states, each with a steady part (a mean wind or current, a constant state), that
enter through the model's own equations: a wind or current acts on the relative velocity, so
its effect depends on the state, which an additive forcing cannot mimic.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import linalg, ndimage, signal

from marine_envs import compiled
from marine_envs.compiled import first_use, jit, local_array
from marine_envs.models import MeasuredDisturbances, VehicleModel
from marine_envs.models.integrate import rk4
from marine_envs.recording import Recording

from ..ekf import ExtendedKalmanFilter
from ..ekf.dynamics import CompiledDynamics, no_parameters, same_constants
from .innovations import Innovations, c_array

FloatArray = NDArray[np.float64]
#: Channels that are angles: unwrapped before smoothing.
ANGLES = ("psi", "phi", "theta", "psi_lf")
#: Unmeasured states get this share of their guessed process noise: they follow the model, so a
#: model error cannot hide in them and shows in the equations of the measured states instead.
FOLLOW_MODEL = 1e-3
#: Share of a force equation's error variance left to white process noise once it has a
#: Gauss-Markov forcing state, and taken from the forcing's (keeps the filter from trusting the
#: forcing model blindly).
WHITE_SHARE = 0.1
#: An equation keeps a forcing of its own only if the environment leaves at least this share
#: of its error variance.
MINOR = 0.01
#: The environment's prior before its statistics are known: a Gauss-Markov process with this
#: share of the record as correlation time, and this many times the spread of its estimate
#: from the equation errors (which misses its slow part).
BROAD_TAU, BROAD = 0.25, 2.0
#: Prior spread of a steady environment (a mean wind or current), in units of that estimate's
#: spread: broad, since the equation errors cannot show a steady part (the fit removes it).
STEADY = 5.0
#: Passes that re-estimate the environment's statistics, each under the last one's (an EM
#: iteration: the first, under the broad prior, smooths a fast sea into a slower one).
ENVIRONMENT_PASSES = 2
#: Finite-difference step of the sensitivity to a disturbance channel, in its units.
STEP = 1e-3
#: The equations a model's waves reach take one sea (:func:`sea_model`) when this share of
#: their normalised error power in the sea's band is one process.
COHERENT = 0.9
#: Welch segment of the equations' cross-spectra, s (0.063 rad/s; at most a third of the
#: record): the USV environment's sea piles up below the 0.64 rad/s its encounter frequency
#: cannot pass, and 60-s segments made it twice as broad as it is.
SEA_SEGMENT = 100.0
#: Bounds of the sea oscillator's damping ratio: a narrow sea at one frequency; above the
#: upper one the shared forcing is no narrow-band sea (the USV environment's: 0.05-0.13; the
#: generator's independent 2-s Gauss-Markov moments, shared at low frequency through the
#: unmeasured sway: 0.63-0.65), and each equation keeps a forcing of its own.
SEA_ZETA = (0.02, 0.4)


class SmootherDiverged(ValueError):
    """The model's filter ran off on the record: non-finite states, innovations, equation-error
    variances or forcing statistics."""


@dataclass
class Residuals:
    """The nominal model's view of a recording.

    :param time: ``(T,)`` s.  :param dt: sample period, s.
    :param u: commanded inputs ``(T, n_u)``.  :param y: measurements ``(T, m)`` (angles unwrapped).
    :param channels: measured channel names; ``channel_index`` their indices among the outputs.
    :param x: smoothed states ``(T, n)``.  :param x_std: their standard deviations.
    :param error: equation errors ``(T - 1, n)``, state units per second.
    :param noise: white-noise standard deviation of each channel, estimated from the data.
    :param observable: per state, whether the measured channels see it.
    :param innovations: the last pass's filter innovations and their sensitivities.
    :param forcing: the last pass's coloured forcing of the force equations (noise model).
    :param sensed: the inputs whose actuator position was recorded (``u`` holds the position;
        their input effects are judged on that sensor, :mod:`.actuators`, not searched here).
    :param sea: the last pass's sea, one process driving the equations its waves reach, or None.
    :param sea_state: its smoothed states ``(T, 2)`` (predictions carry them on).
    """

    model: VehicleModel
    time: FloatArray
    dt: float
    u: FloatArray
    y: FloatArray
    channels: tuple[str, ...]
    x: FloatArray
    x_std: FloatArray
    error: FloatArray
    noise: FloatArray
    observable: NDArray[np.bool_]
    substeps: int = 1
    innovations: Innovations | None = None
    forcing: tuple[Forcing, ...] = ()
    sensed: tuple[str, ...] = ()
    sea: Sea | None = None
    sea_state: FloatArray | None = None

    @property
    def midpoint(self) -> FloatArray:
        """The state halfway through each step ``(T - 1, n)``: where equation errors are
        evaluated (a first-order-accurate match of the RK4 step)."""
        return 0.5 * (self.x[1:] + self.x[:-1])


def rk4_step(model: VehicleModel, x: FloatArray, u: FloatArray, dt: float,
             substeps: int = 1) -> FloatArray:
    """One step of ``dt`` for every row of ``x`` with inputs ``u`` held (no disturbance)."""
    return rk4(lambda z, _t: model.rhs(z, u), x, dt / substeps, substeps)


def substeps_for(model: VehicleModel, dt: float) -> int:
    """RK4 steps per sample that keep the fastest mode of the linearised model accurate
    (``|lambda| h <= 0.5``; one step of 0.1 s is unstable for the hydrofoil's 38 1/s mode)."""
    A, _, _ = model.linearize()
    fastest = float(np.max(np.abs(np.linalg.eigvals(A)))) if A.size else 0.0
    return max(1, math.ceil(fastest * dt / 0.5))


def equation_error(model: VehicleModel, x: FloatArray, u: FloatArray, dt: float,
                   substeps: int = 1) -> FloatArray:
    """``(x_{k+1} - Phi(x_k, u_k)) / dt``, shape ``(T - 1, n)``."""
    return (x[1:] - rk4_step(model, x[:-1], u[:-1], dt, substeps)) / dt


def model_inputs(recording: Recording, model: VehicleModel) -> FloatArray:
    """The record's inputs to ``model`` ``(T, n_u)``: each actuator's position where a sensor
    on it was recorded (``<input>_applied``: what reached the hull, after any actuator effect,
    which :mod:`.actuators` judges from command and position), else its command; and any
    measured disturbance (:class:`~marine_envs.models.MeasuredDisturbances`). Both kinds of
    sensor are cleared of their white noise, which the model would otherwise take for a
    real input, wind or current (:func:`denoised`)."""
    u = recording.inputs_for(model).copy()
    actuators = len(model.actuator_names)  # the measured disturbances follow them
    sensed = [j for j, name in enumerate(model.input_names[:actuators])
              if name in recording.actuator_names]
    for j in sensed:
        u[:, j] = recording.applied(model.input_names[j])
    sensed += list(range(actuators, u.shape[1]))
    u[:, sensed] = denoised(u[:, sensed])
    return u


def denoised(y: FloatArray, bins: int = 9) -> FloatArray:
    """Columns of ``y`` cleared of white noise by a zero-phase Wiener low-pass: each frequency
    kept in the share its signal has of the (smoothed) power there, the noise floor from
    :func:`white_noise_std`, the gain never rising with frequency (isolated passbands in the
    noise left narrow-band remnants that the ROV's moments took for waves)."""
    if not y.size:
        return y
    mean = y.mean(axis=0)
    spectrum = np.fft.rfft(y - mean, axis=0)
    power = ndimage.uniform_filter1d(np.abs(spectrum) ** 2, bins, axis=0, mode="nearest")
    floor = len(y) * white_noise_std(y) ** 2
    gain = np.clip(1 - floor / np.maximum(power, 1e-300), 0.0, 1.0)
    gain = np.minimum.accumulate(gain, axis=0)
    return np.fft.irfft(gain * spectrum, n=len(y), axis=0) + mean


def white_noise_std(y: FloatArray) -> FloatArray:
    """Per column, the standard deviation of white noise on a smooth signal: from the fourth
    differences (a white sequence's have variance 70 sigma^2; a signal sampled well above its
    bandwidth contributes almost nothing), with a robust (median) scale."""
    d4 = np.diff(y, n=4, axis=0)
    mad = np.median(np.abs(d4 - np.median(d4, axis=0)), axis=0) / 0.6745
    return np.maximum(mad / np.sqrt(70.0), 1e-6 * (np.std(y, axis=0) + 1e-12))


def displacements(model: VehicleModel) -> set[int]:
    """The states whose equations are kinematic (nothing damps them, no input or disturbance
    drives them): positions and angles. Only they can carry a restoring force, and their
    equations take no force (``hypotheses``) and no sea forcing (:func:`forcing_model`)."""
    A, B, E = model.linearize()
    return {i for i in range(A.shape[0])
            if A[i, i] == 0 and not B[i].any() and not E[i].any()}


def observable_states(model: VehicleModel, channels: tuple[str, ...]) -> NDArray[np.bool_]:
    """Per state, whether it lies in the observable subspace of the model linearised at its
    nominal point, measured through ``channels``."""
    A, _, _ = model.linearize()
    C = _output_matrix(model, channels)
    n = A.shape[0]
    blocks, M = [], C
    for _ in range(n):
        blocks.append(M)
        M = M @ A
    observability = np.vstack(blocks)
    scale = np.abs(observability).max(axis=1, keepdims=True) + 1e-300
    _, s, vt = np.linalg.svd(observability / scale)
    basis = vt[: int(np.sum(s > 1e-9 * s[0]))]
    return np.linalg.norm(basis, axis=0) > 0.99  # unit vector e_i inside the row space


def _output_matrix(model: VehicleModel, channels: tuple[str, ...]) -> FloatArray:
    """``d outputs / d x`` at the nominal state for the measured channels."""
    x0 = model.x0
    idx = [model.output_names.index(c) for c in channels]
    eps = 1e-6 * np.maximum(1.0, np.abs(x0))
    C = np.empty((len(idx), x0.size))
    for j in range(x0.size):
        step = np.zeros_like(x0)
        step[j] = eps[j]
        C[:, j] = (model.output(x0 + step)[idx] - model.output(x0 - step)[idx]) / (2 * eps[j])
    return C


def estimate(recording: Recording, model: VehicleModel, passes: int = 2) -> Residuals:
    """Smooth the record with the nominal model and compute the equation errors.

    The process noise of each later pass is fitted to the previous pass's equation errors, so
    the smoother follows the data wherever the model is wrong; the last pass models the
    forcing of the measured force equations as coloured (module doc). Samples a logger dropped
    (:attr:`~marine_envs.recording.Recording.gaps` of a filled recording) are missing
    measurements to the filter: it predicts through them.
    """
    channels = recording.measured_names
    y = recording.measurements.copy()
    mask = None if recording.gaps is None else ~recording.gaps
    for j, name in enumerate(channels):
        if name in ANGLES:
            y[:, j] = np.unwrap(y[:, j])
    u, dt = model_inputs(recording, model), recording.dt
    noise = white_noise_std(y)
    n = len(model.state_names)
    substeps = substeps_for(model, dt)
    measured = np.array([name in channels for name in model.state_names])
    own, own_q = _model_process_noise(model, dt)
    q = _initial_process_noise(model, y, u, channels, dt)
    q = np.where(own, own_q, np.where(measured, q, q * FOLLOW_MODEL))
    x0, P0 = _initial_state(model, y, channels, noise)
    forcing: list[Forcing] = []
    forces = [int(i) for i in np.flatnonzero(measured) if i not in displacements(model)]
    sea = sea_model(model, crude_errors(model, y, u, channels, dt), forces, dt)
    for k in range(passes):
        ekf = _filter(model, dt, channels, q, noise, x0, P0, substeps, forcing, sea)
        with np.errstate(over="ignore", invalid="ignore"):  # checked just below
            smoothed = ekf.smooth(u, y, mask)
            x = smoothed.x[:, 0, :n]
            error = equation_error(model, x, u, dt, substeps)
            variance = np.maximum(np.var(error, axis=0), 1e-12 * (np.var(x, axis=0) + 1e-12))
        _check_finite(model, smoothed.x, smoothed.filtered.innovation, variance)
        if k == passes - 1:
            break
        q = np.where(own, own_q, np.where(measured, variance * dt**2, q * FOLLOW_MODEL))
        if k == passes - 2:
            forcing, sea = forcing_model(model, x, u, error, measured, dt, sea is not None)
            _check_finite(model, _statistics(forcing, sea))
            forced = sorted({i for f in forcing for i in f.equations}
                            | set(() if sea is None else sea.equations))
            q[forced] *= WHITE_SHARE
            for _ in range(ENVIRONMENT_PASSES if _split(forcing)[1] else 0):
                with np.errstate(over="ignore", invalid="ignore"):
                    forcing = environment_statistics(model, dt, channels, q, noise, x0, P0,
                                                     substeps, forcing, u, y, mask, sea)
            _check_finite(model, _statistics(forcing, sea))
    return Residuals(model, recording.time, dt, u, y, channels, x, smoothed.std[:, 0, :n],
                     error, noise, observable_states(model, channels), substeps,
                     Innovations.from_filter(ekf, smoothed.filtered, u, n),
                     _with_levels(forcing, smoothed.x[:, 0, n + len(forcing) + _width(sea):]),
                     recording.actuator_names, sea, None if sea is None else
                     smoothed.x[:, 0, n + len(forcing):n + len(forcing) + _width(sea)])


def _statistics(forcing: Sequence[Forcing], sea: Sea | None = None) -> FloatArray:
    """Each forcing's ``(tau, variance)``, and the sea's ``(omega, zeta)`` and loadings."""
    rows = [(f.tau, f.variance) for f in forcing]
    if sea is not None:
        rows += [(sea.omega, sea.zeta), *((a, c) for _, a, c in sea.loading)]
    return np.array(rows)


def _check_finite(model: VehicleModel, *arrays: FloatArray) -> None:
    """:raises SmootherDiverged: if any of ``arrays`` (a smoothing's results) is not finite."""
    if not all(np.isfinite(a).all() for a in arrays):
        raise SmootherDiverged(f"the {model.name} model's smoother diverged on this record")


@dataclass(frozen=True)
class Forcing:
    """A first-order Gauss-Markov forcing ``zeta' = -zeta / tau + white``, stationary
    ``variance``: added to state ``state``'s equation (state units per s), or, with
    ``disturbance`` set, the model's disturbance channel of that index (its own units), which
    enters through the model's equations ``equations``. Such a channel may also have a steady
    part (a mean wind or current): a constant the filter estimates, ``level`` (the channel's
    units), under the prior variance ``steady`` (0: none)."""

    state: int | None
    tau: float
    variance: float
    disturbance: int | None = None
    equations: tuple[int, ...] = ()
    steady: float = 0.0
    level: float = 0.0

    def __post_init__(self) -> None:
        if not self.equations and self.state is not None:
            object.__setattr__(self, "equations", (self.state,))


@dataclass(frozen=True)
class Sea:
    """One narrow-band wave process driving several equations: a second-order oscillator

        s1' = omega s2,    s2' = -omega s1 - 2 zeta omega s2 + white

    (``s2 = s1' / omega``: ``s1`` in quadrature; both of unit stationary variance), added to
    equation ``i`` as ``a s1 + c s2`` for each ``(i, a, c)`` of ``loading`` (state units per
    s): each equation at its own amplitude and phase, as one wave elevation drives them
    through the model's wave coupling. A first-order Gauss-Markov forcing cannot represent
    such a sea: its spectrum is flat below its corner, so at a resonance beside the sea's peak
    the filter under-tracks it and the search takes the motion it drives for damping.

    :param omega: peak frequency, rad/s.  :param zeta: damping ratio of the oscillator, -.
    :param loading: ``(equation, a, c)`` per equation the sea reaches.
    :param coherence: the share of the equations' error power in the sea's band that is one
        process (the rank-one share of their normalised cross-spectral matrix).
    """

    omega: float
    zeta: float
    loading: tuple[tuple[int, float, float], ...]
    coherence: float = 1.0

    @property
    def equations(self) -> tuple[int, ...]:
        return tuple(i for i, _, _ in self.loading)

    def dynamics(self) -> FloatArray:
        """``F`` ``(2, 2)`` of ``s' = F s``."""
        return self.omega * np.array([[0.0, 1.0], [-1.0, -2 * self.zeta]])

    def gains(self, n: int) -> FloatArray:
        """``G`` ``(n, 2)``: what ``s`` adds to the ``n`` state derivatives."""
        G = np.zeros((n, 2))
        for i, a, c in self.loading:
            G[i] = (a, c)
        return G

    def spectrum(self, omega: FloatArray) -> FloatArray:
        """One-sided spectral density of ``s1`` per Hz at ``omega`` (rad/s): unit variance."""
        w0, z = self.omega, self.zeta
        return 8 * z * w0**3 / ((w0**2 - omega**2) ** 2 + (2 * z * w0 * omega) ** 2)

    def step_noise(self, dt: float) -> FloatArray:
        """Per-step process noise ``(2, 2)`` that keeps ``s`` at unit variance:
        ``I - Phi Phi'`` (the stationary covariance of the scaled oscillator is ``I``)."""
        Phi = linalg.expm(self.dynamics() * dt)
        return np.eye(2) - Phi @ Phi.T


def _width(sea: Sea | None) -> int:
    """The filter states the sea takes."""
    return 0 if sea is None else 2


def sea_model(model: VehicleModel, error: FloatArray, rows: Sequence[int], dt: float
              ) -> Sea | None:
    """The sea as one process (:class:`Sea`) in the ``rows``' equations that the model's
    wave channels (:attr:`~marine_envs.models.VehicleModel.wave_disturbances`) reach, read off
    the cross-spectra of their equation errors ``error`` ``(T - 1, n)``, or None: fewer than
    two such equations, errors that are not one process in the sea's band (share below
    :data:`COHERENT`), or a band that is no narrow one (it reaches zero frequency, or is
    broader than :data:`SEA_ZETA` allows).

    The errors as they are, not the part that is no function of the state: at a resonance the
    sea and the motion it drives are in phase, and a regression on the state would hand the
    sea to the search as damping. What the cross-spectra keep is what the equations share; a
    missing term in one equation is mostly not in it. The band is where the shared (first
    eigenvalue's) spectrum stays above half its peak; its peak (a parabola through the log
    spectrum) and half-power width set the oscillator's frequency and damping; each equation's
    loading is its shared power in the band (the first eigenvalue less the second, the
    incoherent floor), divided by the oscillator's share of its power there, at the phase of
    its cross-spectrum with the strongest equation.
    """
    if not model.wave_disturbances:
        return None
    _, _, E = model.linearize()
    waves = [model.disturbance_names.index(c) for c in model.wave_disturbances]
    reached = [i for i in rows if np.any(E[i, waves] != 0)]
    if len(reached) < 2:
        return None
    e = error[:, reached] - error[:, reached].mean(axis=0)
    scale = np.maximum(e.std(axis=0), 1e-300)
    z = e / scale
    m, segment = len(reached), min(len(z) // 3, int(round(SEA_SEGMENT / dt)))
    S = np.empty((segment // 2 + 1, m, m), dtype=complex)
    for a in range(m):
        for b in range(m):
            f, S[:, a, b] = signal.csd(z[:, a], z[:, b], fs=1 / dt, nperseg=segment)
    omega, df = 2 * np.pi * f, f[1] - f[0]
    S = 0.5 * (S + np.conj(S.transpose(0, 2, 1)))  # Hermitian to rounding
    lam, vec = np.linalg.eigh(S)
    first, shared = lam[:, -1], np.maximum(lam[:, -1] - lam[:, -2], 0.0)
    peak = 1 + int(np.argmax(first[1:]))
    low, high = peak, peak
    while low > 1 and first[low - 1] >= first[peak] / 2:
        low -= 1
    while high < len(first) - 1 and first[high + 1] >= first[peak] / 2:
        high += 1
    band = slice(low, high + 1)
    coherence = float(first[band].sum() / np.trace(S[band].real, axis1=1, axis2=2).sum())
    if coherence < COHERENT or low <= 1:  # not one process, or low-pass: no sea
        return None
    resolution = omega[1] - omega[0]
    a, b, c = np.log(first[peak - 1:peak + 2]) if peak + 1 < len(first) else (0.0, 1.0, 0.0)
    centre = float(omega[peak] + resolution * 0.5 * (a - c) / (a - 2 * b + c))  # parabola
    edges = [_half_power(omega, first, peak, -1), _half_power(omega, first, peak, 1)]
    width = max(edges[1] - edges[0], resolution)
    zeta = max(width / (2 * centre), SEA_ZETA[0])
    if zeta > SEA_ZETA[1]:
        return None
    sea = Sea(centre, zeta, ())
    # loaded to the shared power in the band, which the oscillator spreads wider than a sea
    fine = np.linspace(omega[low] - resolution / 2, omega[high] + resolution / 2, 200)
    share = float(np.mean(sea.spectrum(fine))) * (fine[-1] - fine[0]) / (2 * np.pi)
    power = np.sum(shared[band, None] * np.abs(vec[band, :, -1]) ** 2, axis=0) * df \
        * scale**2 / share
    reference = int(np.argmax(power))
    phase = np.angle(S[band, reference, :].sum(axis=0))  # of each equation against it
    amplitude = np.sqrt(power)
    loading = tuple((i, float(amp * np.cos(ph)), float(amp * np.sin(ph)))
                    for i, amp, ph in zip(reached, amplitude, phase, strict=True))
    return replace(sea, loading=loading, coherence=coherence)


def _half_power(omega: FloatArray, level: FloatArray, peak: int, side: int) -> float:
    """The frequency on ``side`` (-1 below, +1 above) of ``peak`` where ``level`` first falls
    to half its peak, interpolated between bins (the last bin's frequency if it never does)."""
    k = peak
    while 0 < k + side < len(level) and level[k + side] >= level[peak] / 2:
        k += side
    if not 0 < k + side < len(level):
        return float(omega[k])
    a, b = level[k], level[k + side]
    return float(omega[k] + side * (omega[1] - omega[0]) * (a - level[peak] / 2) / (a - b))


def forcing_model(model: VehicleModel, x: FloatArray, u: FloatArray, error: FloatArray,
                  measured: NDArray[np.bool_], dt: float, seaway: bool = True
                  ) -> tuple[list[Forcing], Sea | None]:
    """The coloured forcing of the measured force equations (not the kinematics), fitted to
    what of their equation errors is not a function of the present state and input (a missing
    term is; it must stay a model error, not become forcing), and the sea where the model's
    waves drive several of them (:func:`sea_model`: those equations get no forcing of their
    own) and ``seaway`` says the crude errors held one: a smoother without a sea model mixes a
    missing roll term into the yaw equation's errors too, where it passed for a sea (the
    generator's independent moments with a missing roll damping: 0.94 one process).

    The model's environment channels come first, where these equations determine them: here
    only a broad prior for :func:`environment_statistics` (least squares through the model's
    sensitivity to them, sample by sample). Each equation then gets a Gauss-Markov forcing for
    what the environment leaves: its variance, and its correlation time ``1 / omega_c`` where
    its spectrum falls to half its peak (a sea's forcing is low-pass).
    """
    regressors = _state_functions(x[:-1], u[:-1])
    exogenous = error - regressors @ np.linalg.lstsq(regressors, error, rcond=None)[0]
    kinematic = displacements(model)
    rows = [int(i) for i in np.flatnonzero(measured) if i not in kinematic]
    sea = sea_model(model, error, rows, dt) if seaway else None
    if sea is not None:
        rows = [i for i in rows if i not in sea.equations]
    out, explained = _environment_prior(model, x[:-1], u[:-1], exogenous, rows, dt)
    exogenous[:, rows] -= explained
    for i in rows:
        e = exogenous[:, i]
        if out and np.var(e) < MINOR * np.var(error[:, i]):
            continue  # the environment is all of it
        f, psd = signal.welch(e, fs=1 / dt, nperseg=max(len(e) // 4, 8))
        omega, level = 2 * np.pi * f[1:], psd[1:]
        peak = int(np.argmax(level))
        below = np.flatnonzero(level[peak:] < level[peak] / 2)
        corner = omega[peak + below[0]] if below.size else omega[-1]
        out.append(Forcing(i, float(1 / corner), float((1 - WHITE_SHARE) * np.var(e))))
    return out, sea


def _environment_prior(model: VehicleModel, x: FloatArray, u: FloatArray,
                       exogenous: FloatArray, rows: list[int], dt: float
                       ) -> tuple[list[Forcing], FloatArray]:
    """Broad Gauss-Markov priors of the environment channels (:data:`BROAD_TAU` of the record,
    :data:`BROAD` times the spread their least-squares estimate from the ``rows``' equation
    errors has) and what that estimate explains of these errors ``(T, len(rows))``. None when
    the rows do not determine the channels, or when the channels act the same whatever the
    state (then they are the equations' own forcings)."""
    channels = [model.disturbance_names.index(c) for c in model.environment_disturbances]
    none = ([], np.zeros((len(x), len(rows))))
    if not channels or len(channels) > len(rows):
        return none
    base = model.rhs(x, u)
    D = np.empty((len(x), len(rows), len(channels)))  # sensitivity to each channel
    for j, c in enumerate(channels):
        d = np.zeros((len(x), len(model.disturbance_names)))
        d[:, c] = STEP
        D[:, :, j] = (model.rhs(x, u, d) - base)[:, rows] / STEP
    if np.linalg.matrix_rank(D.reshape(-1, len(channels))) < len(channels):
        return none  # a channel moves no measured equation
    if np.ptp(D, axis=0).max() <= 1e-6 * np.abs(D).max():
        return none  # additive (the USV's wave moments): each equation's own forcing is it
    values = (np.linalg.pinv(D) @ exogenous[:, rows, None])[..., 0]  # (T, channels)
    reaches = np.abs(D).max(axis=0) > 0  # (rows, channels)
    tau = BROAD_TAU * len(x) * dt
    out = [Forcing(None, tau, BROAD**2 * float(np.var(v)), c,
                   tuple(rows[i] for i in np.flatnonzero(reaches[:, j])),
                   STEADY**2 * float(np.var(v)))
           for j, (c, v) in enumerate(zip(channels, values.T, strict=True))]
    return out, np.einsum("trc,tc->tr", D, values)


def environment_statistics(model: VehicleModel, dt: float, channels: tuple[str, ...],
                           q: FloatArray, noise: FloatArray, x0: FloatArray, P0: FloatArray,
                           substeps: int, forcing: list[Forcing], u: FloatArray, y: FloatArray,
                           mask: NDArray[np.bool_] | None = None, sea: Sea | None = None
                           ) -> list[Forcing]:
    """The environment channels' Gauss-Markov statistics from the filter itself: smoothed as
    states under their present statistics, then each series' decorrelation time and variance,
    the latter at most the present one (the first is the broad prior of
    :func:`forcing_model`: a smoother free to move the environment would take a missing term
    for it). The equation errors alone cannot show a slow current or wind: under control the
    thrust that holds against it is a function of the input, which their fit removes.
    ``mask``: the valid measurements ``(T, m)`` (None: all); ``sea``: the sea, if any."""
    own, environment = _split(forcing)
    start = len(model.state_names) + len(own)
    z = _filter(model, dt, channels, q, noise, x0, P0, substeps, own + environment, sea
                ).smooth(u, y, mask).x[:, 0, start:start + len(environment)]
    return own + [replace(f, tau=_decorrelation_time(e, dt, f.tau),
                          variance=min(float(np.var(e)), f.variance))
                  for f, e in zip(environment, z.T, strict=True)]


def _split(forcing: Sequence[Forcing]) -> tuple[list[Forcing], list[Forcing]]:
    """The equations' own forcings and the environment's channels, in the filter's order."""
    return ([f for f in forcing if f.disturbance is None],
            [f for f in forcing if f.disturbance is not None])


def _with_levels(forcing: list[Forcing], z: FloatArray) -> tuple[Forcing, ...]:
    """``forcing`` with the smoothed steady parts (the filter's states after the forcings,
    ``z``) as their ``level``."""
    steady = iter(z.mean(axis=0))
    return tuple(replace(f, level=float(next(steady))) if f.steady > 0 else f for f in forcing)


def _decorrelation_time(series: FloatArray, dt: float, longest: float) -> float:
    """Lag, s, at which the autocorrelation of ``series`` first falls below ``1/e`` (a
    Gauss-Markov process's correlation time; a smoothed series has lost its fast part, so the
    shape of its spectrum would not tell), at most ``longest``."""
    e = series - series.mean()
    spectrum = np.fft.rfft(e, 2 * len(e))
    acf = np.fft.irfft(spectrum * np.conj(spectrum))[:len(e)]
    below = np.flatnonzero(acf < acf[0] / math.e)
    return float(min(below[0] * dt, longest)) if below.size and acf[0] > 0 else longest


def _state_functions(x: FloatArray, u: FloatArray) -> FloatArray:
    """Regressors ``(T, k)``: a constant, and each state and input, its ``|.| .`` and cube
    (scaled to unit spread so that the least squares is well conditioned)."""
    z = np.concatenate([x, u], axis=1)
    z = (z - z.mean(axis=0)) / np.maximum(z.std(axis=0), 1e-12)
    return np.concatenate([np.ones((len(z), 1)), z, z * np.abs(z), z**3], axis=1)


def _filter(model: VehicleModel, dt: float, channels: tuple[str, ...], q: FloatArray,
            noise: FloatArray, x0: FloatArray, P0: FloatArray, substeps: int,
            forcing: Sequence[Forcing], sea: Sea | None = None) -> ExtendedKalmanFilter:
    """The nominal model's filter with per-step process noise ``q`` on the states and, after
    them, the ``forcing`` states (zero mean, their stationary variance as prior): the
    equations' own forcings, the environment's channels, the ``sea``'s two states, then the
    steady parts of those that have one (constants)."""
    n = len(model.state_names)
    own, environment = _split(forcing)
    forcing = own + environment
    steady = [f for f in environment if f.steady > 0]
    tau = np.array([f.tau for f in forcing])
    variance = np.array([f.variance for f in forcing])
    outputs = [model.output_names.index(c) for c in channels]
    dynamics = AugmentedDynamics(model, own, environment, sea)
    if model.output_names == model.state_names:
        h: Any = np.eye(dynamics.width)[outputs]  # a matrix: the compiled filter's update
        fast = compiled_augmented(dynamics)
    else:
        def h(z: FloatArray) -> FloatArray:
            return model.output(z[:, :n])[:, outputs]
        fast = None

    decay = np.exp(-2 * dt / tau)
    waves = np.zeros((0, 0)) if sea is None else sea.step_noise(dt)
    Q = linalg.block_diag(np.diag(np.concatenate([q, variance * (1 - decay)])), waves,
                          np.zeros((len(steady), len(steady))))
    names = ([f"forcing_{model.state_names[i]}" for i in dynamics.rows]
             + [model.disturbance_names[c] for c in dynamics.channels]
             + ["sea", "sea_quadrature"][:_width(sea)]
             + [f"steady_{model.disturbance_names[c]}" for c in dynamics.steady])
    prior = np.concatenate([variance, np.ones(_width(sea)), [f.steady for f in steady]])
    with first_use(f"{model.name} diagnosis"):  # compiled as the filter is made
        return ExtendedKalmanFilter(
            dynamics, h, dt=dt, Q=Q, R=np.diag(noise**2), n_inputs=len(model.input_names),
            state_names=(*model.state_names, *names),
            measurement_names=channels, x0=np.concatenate([x0, np.zeros(len(prior))]),
            P0=linalg.block_diag(P0, np.diag(prior)), substeps=substeps,
            compiled=fast)


class AugmentedDynamics:
    """The filter's dynamics ``f(z, u, theta) -> z_dot`` (rows of ``z``: the model's states,
    then its forcing states, :func:`_filter`): the model's equations with the equations' own
    forcings added and the environment's channels (plus their steady parts) as its
    disturbances; each forcing a first-order Gauss-Markov process, a steady part constant;
    the sea's two states (:class:`Sea`) an oscillator added to the equations it reaches.

    Compiled (:func:`augmented_rows`) for a model with compiled equations (the filter calls it
    at every RK4 stage and for every Jacobian, on a few rows, where a numpy call costs mostly
    its overhead); numpy (:meth:`reference`) for any other.

    :param own: the equations' own forcings (``Forcing.state`` set), in the filter's order.
    :param environment: the environment's channels (``Forcing.disturbance`` set).
    :param sea: the sea, or None.
    """

    def __init__(self, model: VehicleModel, own: Sequence[Forcing],
                 environment: Sequence[Forcing], sea: Sea | None = None) -> None:
        self.model, self.n, self.n_d = model, len(model.state_names), len(model.disturbance_names)
        self.rows = np.array([f.state for f in own], dtype=np.int64)
        self.channels = np.array([f.disturbance for f in environment], dtype=np.int64)
        self.steady = np.array([f.disturbance for f in environment if f.steady > 0],
                               dtype=np.int64)
        self.tau = np.array([f.tau for f in (*own, *environment)], dtype=np.float64)
        self.sea_F = np.zeros((0, 0)) if sea is None else sea.dynamics()
        self.sea_G = np.zeros((self.n, 0)) if sea is None else sea.gains(self.n)
        self.width = self.n + self.tau.size + _width(sea) + self.steady.size
        compiled = type(model).equations is not None and type(model).rhs is VehicleModel.rhs \
            and model.constants.ndim == 1
        self._kernel = augmented_rows(type(model).equations.core) if compiled else None
        self._p = c_array(model.constants) if compiled else None

    def __call__(self, z: FloatArray, u: FloatArray, _theta: FloatArray) -> FloatArray:
        """``z_dot`` ``(R, width)`` of states ``z`` ``(R, width)`` with inputs ``u``
        ``(R, n_u)``."""
        if self._kernel is None:
            return self.reference(z, u)
        out = np.empty((z.shape[0], self.width))
        self._kernel(c_array(z), c_array(u), self._p, self.rows, self.channels, self.steady,
                     self.tau, self.sea_F, self.sea_G, self.n, self.n_d, out)
        return out

    def reference(self, z: FloatArray, u: FloatArray) -> FloatArray:
        """:meth:`__call__` in numpy, through ``model.rhs``."""
        n, n_own, n_gm = self.n, self.rows.size, self.n + self.tau.size
        n_f = n_gm + self.sea_F.shape[0]
        d = np.zeros((len(z), self.n_d))
        d[:, self.channels] = z[:, n + n_own:n_gm]
        d[:, self.steady] += z[:, n_f:]
        x_dot = self.model.rhs(z[:, :n], u, d)
        x_dot[:, self.rows] += z[:, n:n + n_own]
        sea = z[:, n_gm:n_f]
        return np.concatenate([x_dot + sea @ self.sea_G.T, -z[:, n:n_gm] / self.tau,
                               sea @ self.sea_F.T, np.zeros((len(z), self.steady.size))],
                              axis=1)


@functools.cache
def augmented_rows(core: Callable[..., None]) -> Callable[..., None]:
    """The compiled :class:`AugmentedDynamics` of a model's equations ``core(x, u, d, p,
    out)`` (:mod:`marine_envs.compiled`): ``f(Z, U, p, rows, channels, steady, tau, sea_F,
    sea_G, n, n_d, OUT)`` on every row of ``Z``; made once per process, compiled once per
    machine."""

    @jit
    def augmented(Z, U, p, rows, channels, steady, tau, sea_F, sea_G, n, n_d, OUT):
        n_own, n_gm = rows.size, n + tau.size
        n_sea = sea_F.shape[0]
        n_f = n_gm + n_sea
        d = np.empty(n_d)
        for b in range(Z.shape[0]):
            z, out = Z[b], OUT[b]
            d[:] = 0.0
            for j in range(channels.size):
                d[channels[j]] = z[n + n_own + j]
            for j in range(steady.size):
                d[steady[j]] += z[n_f + j]
            core(z[:n], U[b], d, p, out[:n])
            for j in range(n_own):
                out[rows[j]] += z[n + j]
            for i in range(n_sea):
                for j in range(n):
                    out[j] += sea_G[j, i] * z[n_gm + i]
                total = 0.0
                for j in range(n_sea):
                    total += sea_F[i, j] * z[n_gm + j]
                out[n_gm + i] = total
            for j in range(n, n_gm):
                out[j] = -z[j] / tau[j - n]
            for j in range(n_f, out.size):
                out[j] = 0.0

    return augmented


#: Largest relative difference between the compiled filter's dynamics and
#: :class:`AugmentedDynamics` on trial states (rounding only: the same equations, in the same
#: order); beyond it the filter keeps the numpy path.
SAME_DYNAMICS = 1e-12


def compiled_augmented(dynamics: AugmentedDynamics) -> CompiledDynamics | None:
    """``dynamics`` as the compiled filter's kernels take them (:mod:`estimators.ekf.kernels`:
    one boat's ``f(z, u, d, q, out)`` and its constants ``q``), so that the diagnosis's filter
    predicts and updates compiled; None for a model without compiled equations, or when the
    kernel does not reproduce ``dynamics`` on trial states (a filter the kernel was not written
    for keeps the numpy path). A model with measured disturbances
    (:class:`~marine_envs.models.MeasuredDisturbances`, a ROV's logged morph command) takes
    them from the inputs after its actuators'.

    ``q``: the numbers of own forcings, environment channels, steady parts, measured
    disturbances and sea states, the model's packed constants, the forcings' correlation
    times, then (as floats) the equations of the own forcings and the model's disturbance
    channels of the environment, of their steady parts and of the measured disturbances, then
    the sea's dynamics and gains (row-major): read as the kernel runs, so that one kernel per
    vehicle serves every forcing model (compiled once)."""
    model = dynamics.model
    base = model.model if isinstance(model, MeasuredDisturbances) else model
    if type(base).equations is None or type(base).rhs is not VehicleModel.rhs \
            or base.constants.ndim != 1:
        return None
    names = base.disturbance_names
    rest = np.array([names.index(c) for c in model.disturbance_names], dtype=np.int64)
    measured = [names.index(c) for c in getattr(model, "measured_disturbances", ())]
    constants = np.asarray(base.constants, dtype=float)
    counts = [dynamics.rows.size, dynamics.channels.size, dynamics.steady.size, len(measured),
              dynamics.sea_F.shape[0]]
    q = np.concatenate([counts, constants, dynamics.tau, dynamics.rows,
                        rest[dynamics.channels], rest[dynamics.steady], measured,
                        dynamics.sea_F.ravel(), dynamics.sea_G.ravel()]).astype(float)
    f = augmented_core(type(base).equations.core, dynamics.n, constants.size,
                       len(base.input_names), len(names))
    made = CompiledDynamics(f, compiled.rk4(f), same_constants, no_parameters, q,
                            (np.zeros(0), np.zeros(0, dtype=np.int64)), dynamics.width, 0)
    return made if _reproduces(made, dynamics) else None


def _reproduces(made: CompiledDynamics, dynamics: AugmentedDynamics) -> bool:
    """Whether ``made.f`` gives ``dynamics``'s derivatives on a few random states and inputs."""
    rng = np.random.default_rng(0)
    model = dynamics.model
    z = np.concatenate([model.x0, np.zeros(made.n - dynamics.n)]) \
        + 0.1 * rng.standard_normal((4, made.n))
    u = model.u0 + 0.1 * rng.standard_normal((4, len(model.input_names)))
    expected = dynamics(z, u, np.zeros((4, 0)))
    got = np.empty_like(expected)
    for b in range(len(z)):
        made.f(z[b], u[b], np.zeros(0), made.constants, got[b])
    scale = np.maximum(np.abs(expected), 1.0)
    return bool(np.all(np.abs(got - expected) <= SAME_DYNAMICS * scale))


@functools.cache
def augmented_core(core: Callable[..., None], n: int, n_p: int, n_act: int,
                   n_d: int) -> Callable[..., None]:
    """One boat's :class:`AugmentedDynamics` ``f(z, u, d, q, out)`` (``d`` unused: the
    environment is in ``z``) of a model's equations ``core(x, u, d, p, out)`` with ``n``
    states, ``n_p`` constants, ``n_act`` actuator inputs (then any measured disturbances) and
    ``n_d`` disturbance channels; ``q`` as :func:`compiled_augmented` packs it. Made once per
    process, compiled once per machine."""
    width = max(n_d, 1)  # (a literal size for the scratch on the stack)

    @jit
    def augmented(z, u, d, q, out):
        n_own, n_env, n_steady = int(q[0]), int(q[1]), int(q[2])
        n_measured, n_sea = int(q[3]), int(q[4])
        n_gm = n + n_own + n_env
        n_f = n_gm + n_sea
        at_tau = 5 + n_p
        at_rows = at_tau + n_own + n_env
        at_channels = at_rows + n_own
        at_steady = at_channels + n_env
        at_measured = at_steady + n_steady
        at_sea_F = at_measured + n_measured
        at_sea_G = at_sea_F + n_sea * n_sea
        full = local_array(width)
        for j in range(n_d):
            full[j] = 0.0
        for j in range(n_env):
            full[int(q[at_channels + j])] = z[n + n_own + j]
        for j in range(n_steady):
            full[int(q[at_steady + j])] += z[n_f + j]
        for j in range(n_measured):
            full[int(q[at_measured + j])] = u[n_act + j]
        core(z[:n], u[:n_act], full[:n_d], q[5:5 + n_p], out[:n])
        for j in range(n_own):
            out[int(q[at_rows + j])] += z[n + j]
        for j in range(n, n_gm):
            out[j] = -z[j] / q[at_tau + j - n]
        for i in range(n_sea):
            for j in range(n):
                out[j] += q[at_sea_G + j * n_sea + i] * z[n_gm + i]
            total = 0.0
            for j in range(n_sea):
                total += q[at_sea_F + i * n_sea + j] * z[n_gm + j]
            out[n_gm + i] = total
        for j in range(n_f, out.size):
            out[j] = 0.0

    return augmented


def _initial_state(model: VehicleModel, y: FloatArray, channels: tuple[str, ...],
                   noise: FloatArray) -> tuple[FloatArray, FloatArray]:
    """The nominal state with measured states set to the first samples; a wide prior."""
    x0 = model.x0.copy()
    spread = np.ones_like(x0)
    for j, name in enumerate(channels):
        if name in model.state_names:
            i = model.state_names.index(name)
            x0[i] = y[0, j]
            spread[i] = 10 * noise[j] + 1e-6
    scale = np.maximum(np.abs(x0), 1.0)
    for i, name in enumerate(model.state_names):
        if name not in channels:
            spread[i] = scale[i]
    return x0, np.diag(spread**2)


def _model_process_noise(model: VehicleModel, dt: float, E: FloatArray | None = None
                         ) -> tuple[NDArray[np.bool_], FloatArray]:
    """Which states belong to the model's own disturbance model, and their per-step process
    noise variance ``diag(E E') dt`` from its unit-intensity white disturbances (``E`` from
    :meth:`~marine_envs.models.VehicleModel.linearize` when not given)."""
    own = np.array([name in model.noise_model_states for name in model.state_names])
    if not own.any():
        return own, np.zeros(len(own))
    if E is None:
        _, _, E = model.linearize()
    return own, np.sum(E * E, axis=1) * dt


def model_noise_spread(model: VehicleModel, channels: tuple[str, ...], dt: float,
                       steps: int) -> FloatArray:
    """Variance ``(steps, m)`` that the model's own white disturbances (of its
    :attr:`~marine_envs.models.VehicleModel.noise_model_states`) add to a prediction of the
    ``channels`` 1..``steps`` samples ahead (linearised at the nominal point): what no
    prediction can remove, however right the model. Zero for a model without them."""
    out = np.zeros((steps, len(channels)))
    if not model.noise_model_states:
        return out
    A, _, E = model.linearize()
    own, q = _model_process_noise(model, dt, E)
    C = _output_matrix(model, channels)
    Phi, Q = linalg.expm(A * dt), np.diag(np.where(own, q, 0.0))
    P = np.zeros_like(Q)
    for k in range(steps):
        P = Phi @ P @ Phi.T + Q
        out[k] = np.einsum("ij,jk,ik->i", C, P, C)
    return out


def _initial_process_noise(model: VehicleModel, y: FloatArray, u: FloatArray,
                           channels: tuple[str, ...], dt: float) -> FloatArray:
    """A first guess of the per-step process noise variance of each state: a tenth of the
    spread of its derivative along a crude trajectory (:func:`_crude`)."""
    rates = np.std(model.rhs(_crude(model, y, channels, dt), u), axis=0)
    floor = 1e-6 * (np.abs(model.x0) + 1.0)
    return (np.maximum(0.1 * rates, floor) * dt) ** 2


def _crude(model: VehicleModel, y: FloatArray, channels: tuple[str, ...], dt: float,
           deriv: int = 0) -> FloatArray:
    """A crude trajectory ``(T, n)`` (``deriv=1``: its rates): the measured states from the
    data smoothed over 2 s (Savitzky-Golay, cubic), the others at their nominal values (rate
    0)."""
    window = min(len(y) // 2 * 2 - 1, 2 * int(1.0 / dt) + 1)
    smooth = signal.savgol_filter(y, max(window, 5), 3, deriv, delta=dt, axis=0) \
        if len(y) > 5 else (y if deriv == 0 else np.gradient(y, dt, axis=0))
    crude = np.tile(model.x0 * (deriv == 0), (len(y), 1))
    for j, name in enumerate(channels):
        if name in model.state_names:
            crude[:, model.state_names.index(name)] = smooth[:, j]
    return crude


def crude_errors(model: VehicleModel, y: FloatArray, u: FloatArray,
                 channels: tuple[str, ...], dt: float) -> FloatArray:
    """Equation errors ``(T, n)`` along the crude trajectory (:func:`_crude`): the data's
    rates less the model's (meaningful in the measured states' equations). Before any
    smoothing they hold the sea at its full strength: a first smoother, its process noise
    guessed, keeps to the model and leaves most of it in the measurement residuals (the USV
    environment's yaw moment came out at a 60th of its variance)."""
    crude = _crude(model, y, channels, dt)
    return _crude(model, y, channels, dt, deriv=1) - model.rhs(crude, u)
