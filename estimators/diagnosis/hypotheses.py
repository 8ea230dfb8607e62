"""Step 2: every catalogue entry as a family of candidate terms.

A :class:`Family` is one catalogue entry on one target, with the members among which the data
must choose: the grid of delays of an input, the source state of a coupling, the product of an
``unlisted`` term, the time of a parameter change. Each member is a term per unit coefficient,
``w`` ``(T, n)`` added to the state derivatives or ``v`` ``(T, m)`` added to the measured
channels, evaluated on the smoothed states. A *free* family fits the coefficient (a damping's
``c``, a current's ``b``, a gain's ``k - 1``); a fixed one has it at 1 (a delay, a limit, a dead
zone and a rate limit change the applied input exactly as they say).
"""

from __future__ import annotations

import itertools
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import NDArray
from scipy import signal, stats

from marine_envs.models import VehicleModel
from marine_envs.models.effects import Effect, applied_inputs

from .modes import model_modes
from .residuals import Residuals, _output_matrix, displacements

FloatArray = NDArray[np.float64]
#: Parameter-change times tried: this many over the record (then refined to one sample about
#: the best, :mod:`.changes`).
CHANGE_TIMES = 60
#: Narrow-band motion is looked for below this frequency, rad/s (sea waves and the slow modes
#: they excite; above it a peak is far more likely a numerical artefact than physics).
MAX_WAVE_FREQUENCY = 6.0
#: The level at which each half of the record must confirm a line found in the whole record's
#: innovations (their whitening leaves a half's line weaker against its coarser bins: a USV roll
#: wave at 10 % sensor noise is confirmed at p = 5e-4 and 4e-14).
CONFIRMATION_ALPHA = 0.01
#: Grid points of a delay (in samples up to 3 s), a limit, a dead zone or a rate limit.
GRID_POINTS = 25
#: The physical span of an actuator's rate limit: 1-30 deg/s for a rudder or other angle, else
#: 3-100 % of the fastest commanded slew (quantiles of the commanded rates, heavy-tailed where
#: the command steps, left a gap from 3 to 64 deg/s about a USV's limit; a square wave's
#: commands have a single rate).
ANGLE_RATES = np.radians((1.0, 30.0))
SLEW_FRACTIONS = (0.03, 1.0)
#: The span of a dead zone's width, as shares of the commands it swallows: up to nearly all (a
#: wide dead zone under a controller that keeps its commands small holds most of them; at 60 %
#: the hydrofoil's flap, 84 % inside, was fitted as a lower gain).
DEADZONE_SHARES = (0.02, 0.95)


def rate_limit_grid(unit: str, slew: float, points: int) -> FloatArray:
    """Rate limits to try on an input in ``unit`` whose fastest commanded slew is ``slew``
    [unit/s]: ``points`` geometrically spaced over the physical span, those below ``slew``
    (a limit above it never acts)."""
    low, high = ANGLE_RATES if unit == "rad" else np.multiply(SLEW_FRACTIONS, slew)
    rates = np.geomspace(low, high, points)
    return rates[rates < slew]


@dataclass
class Family:
    """Candidate terms of one effect on one target.

    :param members: the parameters that tell the members apart (``{"tau": 0.4}``, ...).
    :param w: ``(T, n, R)`` state-derivative terms per unit coefficient, or None.
    :param v: ``(T, m, R)`` channel offsets per unit coefficient, or None.
    :param coefficient: name of the fitted parameter (None: fixed at 1).
    :param offset: the parameter is ``offset + coefficient`` (an input gain: ``1 + a``).
    :param n_parameters: parameters a member has (penalised in the ranking).
    """

    effect: str
    target: str
    members: list[dict[str, Any]]
    w: FloatArray | None = None
    v: FloatArray | None = None
    coefficient: str | None = "c"
    offset: float = 0.0
    n_parameters: int = 1
    details: dict[str, Any] = field(default_factory=dict)

    @property
    def free(self) -> bool:
        return self.coefficient is not None

    @property
    def key(self) -> tuple[str, str]:
        return self.effect, self.target

    def effect_for(self, member: int, coefficient: float = 1.0) -> Effect:
        """The catalogue effect of one member with its coefficient."""
        parameters = dict(self.members[member])
        if self.coefficient is not None:
            parameters[self.coefficient] = self.offset + coefficient
        return Effect(self.effect, self.target, parameters)

    def term(self, member: int, coefficient: float = 1.0) -> FloatArray:
        """The state-derivative term ``(T, n)`` of one member of a state-equation family."""
        assert self.w is not None, "a channel offset has no state-derivative term"
        return self.w[:, :, member] * coefficient


def all_families(res: Residuals) -> Iterator[Family]:
    """Every family the catalogue allows for this model and these channels, but the changes
    in mid-record: those are detected and dated first (:mod:`.changes`), and only what is
    detected is searched."""
    yield from state_families(res)
    yield from input_families(res)
    yield from bias_families(res)
    yield from wave_families(res)
    yield from unlisted_families(res)


# -- state terms ----------------------------------------------------------------------------------
def midpoint_states(res: Residuals) -> FloatArray:
    """The smoothed states at the middle of each step ``(T, n)`` (the last one repeated)."""
    x = res.midpoint
    return np.vstack([x, x[-1:]])


def _targets(res: Residuals) -> list[int]:
    """Observable states of the vehicle (not of its disturbance model)."""
    noise = res.model.noise_model_states
    return [i for i, name in enumerate(res.model.state_names)
            if res.observable[i] and name not in noise]


def _moving(res: Residuals) -> list[int]:
    """Targets whose smoothed state moves well beyond its own uncertainty: only a moving state
    can carry a damping, drive a coupling or enter a product (a morphing fraction held
    constant, known to 1e-18, would fit any coefficient, 1e32 included)."""
    spread = np.std(res.x, axis=0)
    uncertainty = np.median(res.x_std, axis=0)
    return [i for i in _targets(res) if spread[i] > 3 * uncertainty[i]]


def _dynamic_targets(res: Residuals) -> list[int]:
    """Observable states whose equations carry forces (not kinematics)."""
    kinematic = displacements(res.model)
    return [i for i in _targets(res) if i not in kinematic]


def _in_equation(i: int, columns: FloatArray, n: int) -> FloatArray:
    """``(T, R)`` regressors placed in equation ``i``: ``(T, n, R)``."""
    w = np.zeros((columns.shape[0], n, columns.shape[1]))
    w[:, i, :] = columns
    return w


def state_families(res: Residuals) -> Iterator[Family]:
    """A current in every observable state's equation; linear/quadratic/cubic damping,
    coupling and cubic restoring in the force (non-kinematic) equations."""
    x, names = midpoint_states(res), res.model.state_names
    n = len(names)
    kinematic = displacements(res.model)
    moving = _moving(res)
    for i in _targets(res):
        xi = x[:, i]
        singles = [("current", np.ones_like(xi), {}, "b"),
                   ("linear_damping", xi, {}, "c"),
                   ("quadratic_damping", xi * np.abs(xi), {}, "c"),
                   ("nonlinear_damping", xi**3, {"form": "cubic"}, "c")]
        for effect, column, fixed, name in singles:
            if effect == "current" or (i in moving and i not in kinematic):
                yield Family(effect, names[i], [fixed], _in_equation(i, column[:, None], n),
                             coefficient=name)
        if i in kinematic:
            continue  # kinematics: geometry, exact but for a drift (the current above)
        sources = [s for s in moving if s != i]
        restoring = [s for s in sources if s in kinematic]
        for effect, power, chosen in (("coupling", 1, sources),
                                      ("nonlinear_restoring", 3, restoring)):
            if chosen:
                columns = np.column_stack([x[:, s] ** power for s in chosen])
                yield Family(effect, names[i], [{"source": names[s]} for s in chosen],
                             _in_equation(i, columns, n), n_parameters=2)


def change_families(res: Residuals, margin: float = 0.05, times: FloatArray | None = None,
                    target: str | None = None, what: str | None = None) -> Iterator[Family]:
    """A step change, at one of ``times`` (default: ``CHANGE_TIMES`` over the record but its
    ends), of the damping (``c * x_t``) or of a constant force (``what``: ``"damping"`` or
    ``"force"``, default both) in one equation (``target``'s, default: every observable
    state's)."""
    x, t = midpoint_states(res), res.time
    n = len(res.model.state_names)
    if times is None:
        span = t[-1] - t[0]
        times = np.linspace(t[0] + margin * span, t[-1] - margin * span, CHANGE_TIMES)
    after = (t[:, None] >= times[None, :]).astype(float)
    kinematic = displacements(res.model)
    for i in _targets(res):
        if target is not None and res.model.state_names[i] != target:
            continue
        for kind, regressor in (("damping", x[:, i]), ("force", np.ones(len(t)))):
            if (kind == "damping" and i in kinematic) or what not in (kind, None):
                continue  # (a family is tens of MB: build only the one asked for)
            yield Family("parameter_change", res.model.state_names[i],
                         [{"time": float(s), "what": kind} for s in times],
                         _in_equation(i, after * regressor[:, None], n), n_parameters=2,
                         details={"times": times})


# -- inputs ---------------------------------------------------------------------------------------
def input_families(res: Residuals) -> Iterator[Family]:
    """Gain (free), and delay, saturation, dead zone and rate limit (grids) of each input."""
    model, u, dt = res.model, res.u, res.dt
    x = midpoint_states(res)
    base = model.rhs(x, u)

    def terms(effects: list[Effect]) -> FloatArray:
        return np.stack([model.rhs(x, applied_inputs(e, model, u, dt)) - base for e in effects],
                        axis=-1)

    for j, name in enumerate(model.input_names):
        c = u[:, j] - model.u0[j]
        if np.std(c) <= 0 or name not in model.actuator_names:  # not a measured wind
            continue
        if name in res.sensed:  # its position was recorded: judged there (.actuators)
            continue
        yield Family("input_gain", name, [{}], terms([Effect("input_gain", name, {"k": 2.0})]),
                     coefficient="k", offset=1.0)
        magnitude = np.abs(c)
        levels = np.linspace(0.5, 0.995, GRID_POINTS)
        grids = {
            "input_delay": ("tau", dt * np.arange(1, max(2, int(round(3.0 / dt))) + 1)),
            "input_saturation": ("limit", np.quantile(magnitude, levels)),
            "input_deadzone": ("width", np.quantile(magnitude, np.linspace(*DEADZONE_SHARES,
                                                                            GRID_POINTS))),
            "input_rate_limit": ("rate", rate_limit_grid(model.input_units[j], float(
                np.max(np.abs(np.diff(c)))) / dt, GRID_POINTS)),
        }
        for effect, (parameter, grid) in grids.items():
            grid = np.unique(grid[grid > 0])
            if grid.size:
                effects = [Effect(effect, name, {parameter: float(g)}) for g in grid]
                yield Family(effect, name, [dict(e.parameters) for e in effects],
                             terms(effects), coefficient=None, details={"grid": parameter})


# -- sensors --------------------------------------------------------------------------------------
def bias_families(res: Residuals) -> Iterator[Family]:
    """A constant offset on each measured channel."""
    T, m = len(res.time), len(res.channels)
    for j, channel in enumerate(res.channels):
        v = np.zeros((T, m, 1))
        v[:, j, 0] = 1.0
        yield Family("sensor_bias", channel, [{}], v=v, coefficient="b")


def bias_term(res: Residuals, channel: str, b: float) -> FloatArray:
    """What a bias ``b`` on ``channel`` does to the nominal equations evaluated on the smoothed
    states (which followed the biased channel): ``f(x - b dx/dy) - f(x)`` ``(T, n)``."""
    x, u = midpoint_states(res), res.u
    direction = np.linalg.pinv(_output_matrix(res.model, res.channels))[:, res.channels.index(
        channel)]
    return res.model.rhs(x - b * direction, u) - res.model.rhs(x, u)


# -- narrow-band motion ---------------------------------------------------------------------------
def wave_families(res: Residuals, alpha: float = 1e-4, max_zeta: float = 0.1) -> Iterator[Family]:
    """A narrow-band process in one state's equation: a significant, narrow peak of its
    equation-error spectrum over a smooth background, found again in each half of the record
    (an unmodelled oscillation persists; a fluctuation of the sea's spectrum does not); the term
    is the error band-passed about the peak (its coefficient is fitted). An unmeasured state's
    error is the smoother's, shaped by the modes it rings (a USV roll rate known only through the
    roll angle): its line is looked for in the measured channels' whitened innovations."""
    names, modes = res.model.state_names, _ringing_modes(res.model)
    targets = _dynamic_targets(res)
    unmeasured = _innovation_line(res, modes, alpha, max_zeta) \
        if any(names[i] not in res.channels for i in targets) else None
    for i in targets:
        error = res.error[:, i]
        peak = _error_line(error, res.dt, modes, alpha, max_zeta) \
            if names[i] in res.channels else unmeasured
        if peak is None:
            continue
        band = _band_pass(error, peak["omega"], max(peak["zeta"], peak["resolution"]), res.dt)
        column = np.append(band, band[-1])
        yield Family("wave_frequency", names[i],
                     [{"omega": peak["omega"], "zeta": peak["zeta"]}],
                     _in_equation(i, column[:, None], len(names)), coefficient="gain",
                     n_parameters=2, details=peak)


def _error_line(error: FloatArray, dt: float, modes: Sequence[tuple[float, float]],
                alpha: float, max_zeta: float) -> dict[str, float] | None:
    """The most significant peak of a measured state's equation error if it is narrow, not on
    one of the ringing ``modes`` and found in each half; else None."""
    peak = spectral_peak(error, dt)
    if peak is None or peak["p_value"] > alpha or peak["zeta"] > max_zeta \
            or _near(peak["omega"], modes, peak["resolution"]) \
            or not _in_both_halves(error, peak["omega"], dt, alpha):
        return None
    return peak


def _innovation_line(res: Residuals, modes: Sequence[tuple[float, float]], alpha: float,
                     max_zeta: float) -> dict[str, float] | None:
    """The strongest (largest ratio over its background) significant narrow peak, away from the
    ringing ``modes``, of the measured channels' whitened innovations (Bonferroni over the
    channels), found in each half; None if
    there is none. The innovations are white but for what the model misses, and for the modes
    the sea rings harder than the filter's white process noise."""
    if res.innovations is None:
        return None
    best = None
    for nu in res.innovations.nu.T:
        peak = spectral_peak(nu, res.dt, beside=modes)
        if peak is None or peak["zeta"] > max_zeta \
                or peak["p_value"] * len(res.channels) > alpha \
                or not _in_both_halves(nu, peak["omega"], res.dt, CONFIRMATION_ALPHA):
            continue
        if best is None or peak["ratio"] > best["ratio"]:
            best = peak
    return best


def _ringing_modes(model: VehicleModel) -> list[tuple[float, float]]:
    """``(omega (rad/s), zeta)`` of the nominal model's lightly damped (or lightly growing)
    oscillatory modes: the sea rings them, and the filter's process noise (white, the sea is
    not) leaves a peak there in every record. Wrong damping of such a mode is a
    ``linear_damping`` finding instead. A real pole (``zeta`` +-1) rings at no frequency: the
    ROV's unstable real pole at 1.01 1/s once hid every heave wave forcing near 1 rad/s."""
    return [(omega, zeta) for omega, zeta in model_modes(model, model.state_names)
            if abs(zeta) < 0.3]


def _near(omega: FloatArray | float, modes: Sequence[tuple[float, float]], resolution: float
          ) -> NDArray[np.bool_]:
    """Whether each frequency (rad/s) lies on one of the ``(omega, zeta)`` modes' peaks."""
    near = np.zeros(np.shape(omega), bool)
    for centre, zeta in modes:
        near |= np.abs(omega - centre) <= max(2 * resolution, 2 * zeta * centre)
    return near


def _in_both_halves(x: FloatArray, omega: float, dt: float, alpha: float) -> bool:
    """Whether each half of ``x`` has a significant peak at ``omega`` (within one bin)."""
    for half in (x[:len(x) // 2], x[len(x) // 2:]):
        spectrum = _welch_over_background(half, dt)
        if spectrum is None:
            return False
        w, psd, background, dof = spectrum
        k = int(np.argmin(np.abs(w - omega)))
        near = slice(max(k - 1, 0), k + 2)
        if 3 * stats.chi2.sf((psd[near] / background[near]).max() * dof, dof) > alpha:
            return False  # Bonferroni over the three bins
    return True


def _welch_over_background(x: FloatArray, dt: float, segment: float = 60.0
                           ) -> tuple[FloatArray, FloatArray, FloatArray, float] | None:
    """``(omega (rad/s), Welch spectrum, its running-median background, chi-square degrees of
    freedom of a bin)`` of ``x`` with segments up to ``segment`` s; None if ``x`` is short."""
    nperseg = min(len(x) // 4, int(segment / dt))
    if nperseg < 32:
        return None
    f, psd = signal.welch(x, fs=1 / dt, nperseg=nperseg)
    background = np.exp(signal.medfilt(np.log(psd + 1e-300), 2 * (len(psd) // 16) + 1))
    dof = 2 * 1.8 * (2 * len(x) / nperseg - 1)  # Hann, half overlap
    return 2 * np.pi * f, psd, background, dof


def spectral_peak(x: FloatArray, dt: float, segment: float = 60.0,
                  beside: Sequence[tuple[float, float]] = ()) -> dict[str, float] | None:
    """The most significant peak of the Welch spectrum of ``x`` over a running-median background,
    off the peaks of the ``beside`` modes ``(omega (rad/s), zeta)``: ``omega`` (rad/s), ``zeta``
    (from the half-power width), ``ratio`` (peak/background), ``p_value`` (chi-square,
    Bonferroni over the frequencies), ``resolution`` (rad/s)."""
    spectrum = _welch_over_background(x, dt, segment)
    if spectrum is None:
        return None
    omega, psd, background, dof = spectrum
    usable = (omega > 0.15) & (omega < min(0.8 * np.pi / dt, MAX_WAVE_FREQUENCY))
    usable &= ~_near(omega, beside, float(omega[1] - omega[0]))
    if usable.sum() < 10:
        return None
    ratio = psd / background
    if beside:  # a peak tops its neighbours; a mode's skirt falls away from the mode
        ratio[1:-1] *= (ratio[1:-1] >= ratio[:-2]) & (ratio[1:-1] >= ratio[2:])
    ratio = np.where(usable, ratio, 0.0)
    k = int(np.argmax(ratio))
    p_value = min(1.0, float(stats.chi2.sf(ratio[k] * dof, dof)) * int(usable.sum()))
    half = psd[k] / 2
    lo, hi = k, k
    while lo > 0 and psd[lo] > half:
        lo -= 1
    while hi < len(psd) - 1 and psd[hi] > half:
        hi += 1
    resolution = float(omega[1] - omega[0])
    peak = _parabolic(omega, np.log(psd + 1e-300), k)
    # the Hann window's main lobe holds a pure line above half power over ~3 bins
    width = max(omega[hi] - omega[lo] - 2 * resolution, resolution / 2)
    return {"omega": float(peak), "zeta": float(width / (2 * peak)), "ratio": float(ratio[k]),
            "p_value": p_value, "resolution": resolution}


def _parabolic(x: FloatArray, y: FloatArray, k: int) -> float:
    if k == 0 or k == len(x) - 1:
        return float(x[k])
    a, b, _ = np.polyfit(x[k - 1:k + 2], y[k - 1:k + 2], 2)
    return float(np.clip(-b / (2 * a), x[k - 1], x[k + 1])) if a < 0 else float(x[k])


def _band_pass(x: FloatArray, omega: float, zeta: float, dt: float) -> FloatArray:
    nyquist = np.pi / dt
    lo, hi = omega * max(1 - 2 * zeta, 0.2), min(omega * (1 + 2 * zeta), 0.95 * nyquist)
    sos = signal.butter(2, [lo / nyquist, hi / nyquist], btype="bandpass", output="sos")
    return signal.sosfiltfilt(sos, x)


# -- anything else --------------------------------------------------------------------------------
def unlisted_families(res: Residuals) -> Iterator[Family]:
    """A library of products the catalogue does not name (``x_a * x_b``, ``x_a * u_j``,
    ``x_a**2``, ``u_j**2``), each as a member, in each equation: the sparse regression's one
    term, chosen on the training data."""
    model, x = res.model, midpoint_states(res)
    variables = [(model.state_names[i], x[:, i]) for i in _moving(res)]
    variables += [(n, res.u[:, j]) for j, n in enumerate(model.input_names)
                  if np.ptp(res.u[:, j]) > 0]
    library = [(f"{a}*{b}", va * vb)
               for (a, va), (b, vb) in itertools.combinations_with_replacement(variables, 2)]
    library = [(name, column) for name, column in library if np.ptp(column) > 0]
    if not library:
        return
    columns = np.column_stack([column for _, column in library])
    for i in _dynamic_targets(res):
        yield Family("unlisted", model.state_names[i],
                     [{"expression": name} for name, _ in library],
                     _in_equation(i, columns, len(model.state_names)), n_parameters=2)
