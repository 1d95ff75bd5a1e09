"""Step functions of the tracking loop, shared by the ROS nodes and the simulation.

* :class:`UnicyclePlant` - kinematic unicycle driven by ``(v, w)`` with the paper's
  delayed-state term ``A_tau xi(t - tau)`` added in linearized coordinates.
* :class:`Tracker` - the tracking law ``u = xi_d'' + (K + E D F)(xi - xi_d)``
  with the dynamic extension ``v' = a`` held as the tracker's own state.
* :func:`step_time` - the time of step ``k`` (integer nanoseconds, as in ROS stamps).

Latency as real bases have it (each optional, off by default, so the paper's plant is
unchanged bit for bit): the plant delays commands by whole steps, passes them through
the actuator (:mod:`control.simulation.actuator`: first-order lag, acceleration limits) and
reports odometry late, decimated and noisy (:mod:`control.simulation.sensors`); the tracker can
predict the state at the time its command will act (:mod:`control.simulation.predictor`).

The ROS nodes call exactly these methods, in the same order as
:func:`nonfragile_tracker.control.simulation.simulate.simulate_tracking`, so a lockstep ROS
run and an in-process run agree to round-off.  Everything is plain floats for
speed; nothing here imports ROS.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field
from typing import Any, NamedTuple, cast

import numpy as np

from .actuator import ActuatorModel, actuate
from .law import feedback
from .model import xi_from_state
from .predictor import SUBSTEP, LatencyPredictor, invert_lag
from .reference import RefSample
from .sensors import Odometer, OdometryModel, OdometrySample
from .timing import MAX_INTERVAL, PeriodEstimator
from ..validate import as_finite_float, as_matrix
from .errors import LoopConfigError

__all__ = ['LoopConfigError', 'PlantConfig', 'UnicyclePlant', 'TrackerConfig', 'Tracker',
           'Command', 'delay_steps', 'step_time', 'step_time_ns', 'yaw_to_quaternion',
           'quaternion_to_yaw', 'validate_gain', 'odometry_period_steps']


def step_time_ns(k: int, dt: float) -> int:
    """Stamp of step ``k`` in integer nanoseconds (``k * round(dt * 1e9)``).

    Parameters
    ----------
    k : int
        Step index.
    dt : float
        Step (s).

    Returns
    -------
    int
    """
    return k * int(round(dt * 1e9))


def step_time(k: int, dt: float) -> float:
    """Time of step ``k`` in seconds, computed exactly as a ROS node reads a stamp.

    Parameters
    ----------
    k : int
        Step index.
    dt : float
        Step (s).

    Returns
    -------
    float
    """
    return step_time_ns(k, dt) * 1e-9


def delay_steps(tau: float, dt: float) -> tuple[int, float]:
    """Delay in whole steps: ``N = round(tau / dt)`` and the effective delay ``N dt``.

    A delay that is not a multiple of the step is rounded to the nearest one; the
    caller reports ``N dt`` when it differs from ``tau``.

    Parameters
    ----------
    tau : float
        Delay (s), >= 0.
    dt : float
        Step (s).

    Returns
    -------
    (int, float)
        ``N`` and ``N dt`` (s).
    """
    if not (math.isfinite(tau) and tau >= 0):
        raise LoopConfigError(f'delay tau must be a finite number >= 0 s, got {tau!r}')
    if not (math.isfinite(dt) and dt > 0):
        raise LoopConfigError(f'step dt must be a finite number > 0 s, got {dt!r}')
    n = int(round(tau / dt))
    return n, n * dt


def yaw_to_quaternion(th: float) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of a rotation by ``th`` about z (REP-103).

    Parameters
    ----------
    th : float
        Yaw (rad).

    Returns
    -------
    (float, float, float, float)
    """
    return (0.0, 0.0, math.sin(0.5 * th), math.cos(0.5 * th))


def quaternion_to_yaw(qx: float, qy: float, qz: float, qw: float) -> float:
    """Yaw (rotation about z) of a quaternion; valid for any non-zero norm.

    Parameters
    ----------
    qx, qy, qz, qw : float
        The quaternion.

    Returns
    -------
    float
        Yaw (rad) in ``[-pi, pi]``.
    """
    return math.atan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)


def _nonneg(name: str, value: Any) -> float:
    return as_finite_float(value, name, low=0.0, error=LoopConfigError)


def odometry_period_steps(rate: float, dt: float) -> tuple[int, float]:
    """Odometry every ``N = round(1 / (rate dt))`` plant steps and the effective rate.

    ``rate = 0`` means every step.  A rate above the plant rate ``1/dt`` is refused;
    one that does not divide it is rounded (the caller reports the effective rate).

    Parameters
    ----------
    rate : float
        Odometry rate (Hz; 0: every step).
    dt : float
        Plant step (s).

    Returns
    -------
    (int, float)
        ``N`` and the effective rate (Hz).

    Raises
    ------
    LoopConfigError
        If ``rate`` is above ``1 / dt``.
    """
    rate = _nonneg('odom_rate', rate)
    if rate == 0.0:
        return 1, 1.0 / dt
    if rate > (1.0 + 1e-9) / dt:
        raise LoopConfigError(f'odom_rate = {rate} Hz is above the plant rate 1/dt = '
                              f'{1.0 / dt:g} Hz; use at most {1.0 / dt:g} Hz (0 = every step)')
    n = max(1, int(round(1.0 / (rate * dt))))
    return n, 1.0 / (n * dt)


def _latency_schedule(value: Any, dt: float) -> tuple[float, ...]:
    """Validated flat ``(t_1, L_1, t_2, L_2, ...)``: times increasing >= 0, latencies >= 0."""
    if isinstance(value, (str, bytes)) or not hasattr(value, '__len__'):
        raise LoopConfigError('cmd_latency_schedule must be a flat list [t_1, L_1, t_2, L_2, '
                              f'...] (s), got {value!r}')
    vals = [as_finite_float(v, f'cmd_latency_schedule[{i}]', low=0.0, error=LoopConfigError)
            for i, v in enumerate(value)]
    if len(vals) % 2:
        raise LoopConfigError('cmd_latency_schedule needs pairs [t_1, L_1, t_2, L_2, ...] (time, '
                              f'latency in s); got {len(vals)} numbers')
    times = vals[0::2]
    if any(b <= a for a, b in zip(times, times[1:])):
        raise LoopConfigError(f'cmd_latency_schedule times must increase, got {times}')
    for t in times:
        if abs(round(t / dt) * dt - t) > 1e-9 * max(1.0, t):
            raise LoopConfigError(f'cmd_latency_schedule time {t} s is not a multiple of the '
                                  f'step dt = {dt} s')
    return tuple(vals)


# ---------------------------------------------------------------------------------------------
# Plant

@dataclass(frozen=True)
class PlantConfig:
    """Unicycle plant settings (SI units).  ``A_tau`` acts on ``xi = [x, x', y, y']``.

    Defaults are neutral (no delay term, at rest at the origin); the paper's scenario
    is ``nonfragile_tracker.scenario.paper_plant_config()`` (``config/``).

    Latency settings (all off by default; delays are rounded to whole steps ``dt``):
    ``cmd_latency`` (s: a command received at step ``k`` acts from step ``k + d``),
    ``lag_v``, ``lag_w`` (first-order actuator time constants, s),
    ``max_linear_accel`` (m/s^2), ``max_angular_accel`` (rad/s^2) (0 = unlimited),
    ``odom_latency`` (s: the measurement of step ``k`` is published at ``k + d`` with
    the stamp of step ``k``), ``odom_rate`` (Hz, 0 = every step), ``odom_noise``
    (standard deviations of x, y (m) and yaw (rad)), ``noise_seed`` and ``odom_jitter``
    (s: each odometry measurement is taken up to this early or late, uniformly over the
    whole steps within it, and stamped with that true time; below half the odometry period).
    ``cmd_latency_schedule`` (flat ``[t_1, L_1, t_2, L_2, ...]``, times increasing, s):
    from ``t_i`` on a command received acts ``L_i`` later (``cmd_latency`` before
    ``t_1``); a command that would act no later than one received before it replaces
    the queued ones (a latency drop skips them, as a transport that delivers the newest).

    Real-base irregularities (off by default): ``cmd_latency_jitter`` (s: each command's
    latency is drawn uniformly from the whole steps in ``[cmd_latency, cmd_latency +
    cmd_latency_jitter]``, from a generator seeded by ``noise_seed`` of its own; commands
    stay in order - one never acts before an earlier one, so a latency is at most its
    draw's upper end) and ``stalls`` (``((start_s, duration_s), ...)``: while a stall lasts
    the base ignores its commands and brakes to rest through its actuator, as a motor
    driver that resets does; afterwards it applies the newest command received).
    """

    dt: float = 0.01
    tau: float = 0.0
    A_tau: tuple[tuple[float, ...], ...] = ((0.0,) * 4,) * 4
    x0: float = 0.0
    y0: float = 0.0
    th0: float = 0.0
    v0: float = 0.0
    cmd_latency: float = 0.0
    lag_v: float = 0.0
    lag_w: float = 0.0
    max_linear_accel: float = 0.0
    max_angular_accel: float = 0.0
    odom_latency: float = 0.0
    odom_rate: float = 0.0
    odom_noise: tuple[float, float, float] = (0.0, 0.0, 0.0)
    noise_seed: int = 0
    cmd_latency_schedule: tuple[float, ...] = ()
    cmd_latency_jitter: float = 0.0
    stalls: tuple[tuple[float, float], ...] = ()
    odom_jitter: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, 'A_tau', tuple(map(tuple, as_matrix(
            self.A_tau, 'A_tau', (4, 4), error=LoopConfigError).tolist())))
        delay_steps(self.tau, self.dt)
        for name in ('x0', 'y0', 'th0', 'v0'):
            if not math.isfinite(getattr(self, name)):
                raise LoopConfigError(f'{name} must be finite, got {getattr(self, name)!r}')
        for name in ('cmd_latency', 'lag_v', 'lag_w', 'max_linear_accel', 'max_angular_accel',
                     'odom_latency', 'odom_rate', 'cmd_latency_jitter', 'odom_jitter'):
            object.__setattr__(self, name, _nonneg(name, getattr(self, name)))
        for name in ('cmd_latency', 'odom_latency', 'cmd_latency_jitter', 'odom_jitter'):
            try:
                delay_steps(getattr(self, name), self.dt)
            except LoopConfigError as exc:
                raise LoopConfigError(f'{name}: {exc}') from None
        period = odometry_period_steps(self.odom_rate, self.dt)[0]
        if 2 * delay_steps(self.odom_jitter, self.dt)[0] >= period:
            raise LoopConfigError(f'odom_jitter ({self.odom_jitter} s) must be below half the '
                                  f'odometry period ({period * self.dt:g} s) so that the '
                                  'measurements stay in order; use a smaller jitter or a finer dt')
        noise = tuple(self.odom_noise) if not isinstance(self.odom_noise, str) else ()
        if len(noise) != 3:
            raise LoopConfigError('odom_noise needs 3 standard deviations [x (m), y (m), '
                                  f'yaw (rad)], got {self.odom_noise!r}')
        object.__setattr__(self, 'odom_noise',
                           tuple(_nonneg(f'odom_noise[{i}]', v) for i, v in enumerate(noise)))
        object.__setattr__(self, 'cmd_latency_schedule',
                           _latency_schedule(self.cmd_latency_schedule, self.dt))
        seed = self.noise_seed
        if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
            raise LoopConfigError(f'noise_seed must be an integer >= 0, got {seed!r}')
        object.__setattr__(self, 'stalls', _stalls(self.stalls))

    @property
    def regular(self) -> bool:
        """True without jitter (command or odometry), stalls or a latency schedule (batch's)."""
        return not (self.cmd_latency_jitter or self.stalls or self.cmd_latency_schedule
                    or self.odom_jitter)

    @property
    def stall_steps(self) -> tuple[tuple[int, int], ...]:
        """Stalls as plant steps ``[first, end)`` (rounded to whole steps)."""
        return tuple((int(round(a / self.dt)), int(round((a + d) / self.dt)))
                     for a, d in self.stalls)

    @property
    def delay_steps(self) -> int:
        """State delay ``tau`` in whole plant steps."""
        return delay_steps(self.tau, self.dt)[0]

    @property
    def cmd_latency_steps(self) -> int:
        """Command latency in whole plant steps."""
        return delay_steps(self.cmd_latency, self.dt)[0]

    def latency_schedule_steps(self) -> tuple[tuple[int, int], ...]:
        """``cmd_latency_schedule`` as (first step, latency in steps) pairs."""
        sch = self.cmd_latency_schedule
        return tuple((int(round(sch[i] / self.dt)), delay_steps(sch[i + 1], self.dt)[0])
                     for i in range(0, len(sch), 2))

    @property
    def actuator(self) -> ActuatorModel:
        """The actuator model (lags and acceleration limits) of this configuration."""
        return ActuatorModel(self.lag_v, self.lag_w, self.max_linear_accel,
                             self.max_angular_accel)

    @property
    def odometry(self) -> OdometryModel:
        """The odometry model (latency, period, noise, seed) of this configuration."""
        return OdometryModel(delay_steps(self.odom_latency, self.dt)[0],
                             odometry_period_steps(self.odom_rate, self.dt)[0],
                             self.odom_noise, int(self.noise_seed),
                             delay_steps(self.odom_jitter, self.dt)[0])


def _stalls(value: Any) -> tuple[tuple[float, float], ...]:
    try:
        rows = [tuple(float(x) for x in row) for row in value]
    except (TypeError, ValueError):
        rows = [()]
    if any(len(r) != 2 or not all(math.isfinite(x) for x in r) or r[0] < 0 or r[1] <= 0
           for r in rows):
        raise LoopConfigError('stalls must be a list of (start_s >= 0, duration_s > 0) pairs, '
                              f'got {value!r}')
    return tuple(cast(tuple[float, float], r) for r in rows)


class UnicyclePlant:
    """Kinematic unicycle with the delayed-state term of paper eq. (5).

    Dynamics over one step, with ``(v, w)`` and ``d = A_tau xi(t_k - N dt)`` held
    constant (zero-order hold) and integrated exactly::

        x' = v cos th + d0 + ox,   y' = v sin th + d2 + oy,   th' = w,
        ox' = d1,                  oy' = d3,

    i.e. the position rows of ``A_tau`` add to the position rates and the velocity
    rows accumulate into a velocity offset ``(ox, oy)``.  The history buffer holds
    ``xi_k = [x, v cos th + ox, y, v sin th + oy]`` at each step (``v`` the speed
    applied from ``t_k``); before ``t = 0`` the history is the initial ``xi``.

    Latency (see :class:`PlantConfig`): :meth:`command` queues a command received at
    step ``k`` to act from step ``k + cmd_latency_steps`` (until then the previous one
    is held; before the first, ``(v0, 0)``); :meth:`advance` applies the command in
    force through the actuator, whose mean speeds over the step move the robot and
    whose end speeds are ``v, w`` (the speeds odometry reports).  :meth:`odometry` is
    the measurement to publish at the current step, if any.  :meth:`step` is
    ``command`` + ``advance``: with the defaults it is the ideal plant of the paper.
    """

    def __init__(self, config: PlantConfig):
        """Plant at step 0 in the initial state of ``config``.

        Parameters
        ----------
        config : PlantConfig
            Step, delay term, initial state, latencies, actuator and odometry settings.
        """
        self.config = config
        self.N = config.delay_steps
        # nonzero entries of A_tau per row: the delay term costs only what it uses
        self._terms = tuple((i, j, a) for i, row in enumerate(config.A_tau)
                            for j, a in enumerate(row) if a != 0.0)
        self.cmd_delay = config.cmd_latency_steps
        self._schedule = config.latency_schedule_steps()
        self._jitter = delay_steps(config.cmd_latency_jitter, config.dt)[0]
        self._stalls = config.stall_steps
        actuator = config.actuator
        self.actuator = None if actuator.ideal else actuator
        odometry = config.odometry
        self.odometer = None if odometry.ideal else Odometer(odometry)
        self.reset()

    def reset(self) -> None:
        """Back to the initial state of the configuration (step 0, no pending commands)."""
        c = self.config
        self.k = 0
        self.x, self.y, self.th = float(c.x0), float(c.y0), float(c.th0)
        self.ox = self.oy = 0.0
        self.v = float(c.v0)            # speed in force (last applied command)
        self.w = 0.0
        xi0 = xi_from_state(self.x, self.y, self.th, self.v)
        self._hist: deque[tuple[float, float, float, float]] = deque([xi0] * (self.N + 1),
                                                                    maxlen=self.N + 1)
        self._queue: deque[tuple[int, float, float]] = deque()    # (first step it acts, v, w)
        self.cmd = (self.v, 0.0)        # command in force
        self.cmd_delay = c.cmd_latency_steps
        self._next_change = 0           # index of the next schedule entry
        # a generator of its own (not the odometry noise's): jitter leaves the noise alone
        self._jitter_rng = (np.random.default_rng([int(c.noise_seed), 1])
                            if self._jitter else None)
        self._last_act = -1
        self.last_act_step = -1         # step the newest command acts from (-1: none yet)
        if self.odometer is not None:
            self.odometer.reset()
            self.odometer.measure(0, self.x, self.y, self.th, self.v, self.w)

    @property
    def t(self) -> float:
        """Time of the current step in s."""
        return step_time(self.k, self.config.dt)

    def xi(self, v: float | None = None) -> tuple[float, float, float, float]:
        """Linearized state at the current step with speed ``v`` (default: in force).

        Parameters
        ----------
        v : float, optional
            Speed (m/s) to use instead of the speed in force.

        Returns
        -------
        (float, float, float, float)
            ``xi = [x, v cos th + ox, y, v sin th + oy]``.
        """
        v = self.v if v is None else v
        c, s = math.cos(self.th), math.sin(self.th)
        return (self.x, v * c + self.ox, self.y, v * s + self.oy)

    def command(self, v: float, w: float) -> None:
        """Receive ``(v, w)`` at the current step: it acts from step ``k + cmd_latency_steps``.

        With a latency schedule the latency in force at step ``k`` applies; queued commands
        that would act no earlier than this one are replaced by it.
        (With ``cmd_latency_jitter``, from a drawn step; :attr:`last_act_step` is the step
        the newest command acts from.)

        Parameters
        ----------
        v, w : float
            Commanded speed (m/s) and yaw rate (rad/s).
        """
        if self._schedule:
            sch = self._schedule
            while self._next_change < len(sch) and sch[self._next_change][0] <= self.k:
                self.cmd_delay = sch[self._next_change][1]
                self._next_change += 1
            act = self.k + self.cmd_delay
            while self._queue and self._queue[-1][0] >= act:
                self._queue.pop()
        if self._jitter_rng is not None:
            d = self.cmd_delay + int(self._jitter_rng.integers(0, self._jitter + 1))
            act = max(self.k + d, self._last_act)        # in order: never before an earlier one
            self._last_act = act
            self._queue.append((act, v, w))
        elif self.cmd_delay == 0 and not self._queue:
            self.cmd = (v, w)
            act = self.k
        else:
            act = self.k + self.cmd_delay
            self._queue.append((act, v, w))
        self.last_act_step = act

    def odometry(self) -> OdometrySample | None:
        """The odometry sample to publish at the current step (measured earlier), if any."""
        if self.odometer is None:               # ideal: the current state, every step
            return OdometrySample(self.k, self.x, self.y, self.th, self.v, self.w)
        return self.odometer.due(self.k)

    def step(self, v: float, w: float) -> None:
        """Receive ``(v, w)`` and advance one step ``dt``: ``k -> k + 1``.

        Parameters
        ----------
        v, w : float
            Commanded speed (m/s) and yaw rate (rad/s).
        """
        self.command(v, w)
        self.advance()

    def advance(self) -> None:
        """Apply the command in force for one step ``dt``: ``k -> k + 1``."""
        queue = self._queue
        while queue and queue[0][0] <= self.k:
            _, cv, cw = queue.popleft()
            self.cmd = (cv, cw)
        v, w = self.cmd
        if self._stalls and any(a <= self.k < b for a, b in self._stalls):
            v = w = 0.0                           # stalled: commands ignored, braking to rest
        h = self.config.dt
        if self.actuator is not None:
            v_end, w_end, v, w = actuate(self.actuator, self.v, self.w, v, w, h)
        xi_now = self.xi(v)
        if self.N == 0:
            d_xi = xi_now
        else:
            d_xi = self._hist[0]          # xi at step k - N
        self._hist.append(xi_now)
        d = [0.0, 0.0, 0.0, 0.0]
        for i, j, a in self._terms:
            d[i] += a * d_xi[j]
        half = 0.5 * w * h
        sinc = math.sin(half) / half if abs(half) > 1e-8 else 1.0 - half * half / 6.0
        mid = self.th + half
        arc = v * h * sinc
        self.x += arc * math.cos(mid) + (d[0] + self.ox) * h + 0.5 * d[1] * h * h
        self.y += arc * math.sin(mid) + (d[2] + self.oy) * h + 0.5 * d[3] * h * h
        self.ox += d[1] * h
        self.oy += d[3] * h
        self.th = math.remainder(self.th + w * h, math.tau)
        if self.actuator is not None:
            self.v, self.w = v_end, w_end
        else:
            self.v, self.w = float(v), float(w)
        self.k += 1
        if self.odometer is not None:
            self.odometer.measure(self.k, self.x, self.y, self.th, self.v, self.w)


# ---------------------------------------------------------------------------------------------
# Tracker

def _within(cmd: float, prev: float, step: float) -> float:
    """``cmd`` moved at most ``step`` (>= 0) away from ``prev`` (``step = 0``: ``prev``)."""
    if cmd > prev + step:
        return prev + step
    if cmd < prev - step:
        return prev - step
    return cmd


def validate_gain(K: Any, *, name: str = 'K', shape: tuple[int, int] = (2, 4),
                  A: Any = None, B: Any = None) -> np.ndarray:
    """The one gain check used everywhere: shape, finiteness, Hurwitz nominal loop.

    ``A, B`` default to the paper's double integrators (eq. 4).

    Parameters
    ----------
    K : array_like
        The gain (nested or flat row-major).
    name : str
        What the gain is called in the messages.
    shape : (int, int)
        Its shape ``(m, n)``.
    A, B : array_like, optional
        The linear model whose nominal loop ``A + B K`` must be Hurwitz.

    Returns
    -------
    numpy.ndarray
        ``K`` as a float array of ``shape``.

    Raises
    ------
    LoopConfigError
        Saying what is wrong and what to do.
    """
    try:
        arr = np.array(K, dtype=float)
    except (TypeError, ValueError):
        raise LoopConfigError(f'{name} must be numbers, got {K!r}') from None
    if arr.size != shape[0] * shape[1]:
        raise LoopConfigError(f'{name} has {arr.size} entries; a {shape[0]}x{shape[1]} gain '
                              f'needs {shape[0] * shape[1]} (row-major)')
    arr = arr.reshape(shape)
    bad = np.argwhere(~np.isfinite(arr))
    if bad.size:
        i, j = bad[0]
        raise LoopConfigError(f'{name}[{i}][{j}] is {arr[i, j]}; every gain entry must be finite')
    if A is None or B is None:
        if shape[1] != 2 * shape[0]:
            raise LoopConfigError(f'{name} has shape {shape}; the tracking model has m double '
                                  'integrators, so K must be m x 2m (2 x 4 for the unicycle)')
        from .model import double_integrator_model
        mdl = double_integrator_model(shape[0])
        A, B = mdl.A, mdl.B
    eig = np.linalg.eigvals(A + B @ arr)
    if not np.all(eig.real < 0):
        worst = eig[np.argmax(eig.real)]
        raise LoopConfigError(
            f'{name} does not stabilize the nominal loop: A + B K has an eigenvalue '
            f'{worst.real:.4g}{worst.imag:+.4g}j with real part >= 0. Use a gain from '
            '`nonfragile_tracker synthesize` (K must make A + B K Hurwitz).')
    return arr


@dataclass(frozen=True)
class TrackerConfig:
    """Tracker settings.  ``K`` is m x n (2 x 4); ``perturbation`` is ``E D F`` (added to K).

    ``max_linear_accel`` (m/s^2) and ``max_angular_accel`` (rad/s^2) are the base's
    acceleration limits (0 = unknown, off): the tracker rate-limits its commands to them
    and its predictor models them (see :class:`Tracker`).

    ``dt`` (s): 0 (the default) takes the tracker's step from the odometry stamps (the
    interval that passed, the measured period: :mod:`control.simulation.timing`); a value
    > 0 is an override, a constant step used whatever the stamps say (the behaviour before
    the step came from the stamps; a node reports when it disagrees with the odometry).
    """

    K: tuple[tuple[float, ...], ...]
    dt: float = 0.0
    max_linear_speed: float = 1.0
    max_angular_speed: float = 2.0
    min_speed: float = 1e-3
    perturbation: tuple[tuple[float, ...], ...] | None = None
    delay_compensation: bool = False
    A_tau: tuple[tuple[float, ...], ...] | None = None
    tau: float = 0.0
    predict_latency: float = 0.0
    predict_odom_latency: float = 0.0
    predict_lag_v: float = 0.0
    predict_lag_w: float = 0.0
    max_linear_accel: float = 0.0
    max_angular_accel: float = 0.0
    #: The gain actually applied, ``K + E D F`` (set from ``K`` and ``perturbation``).
    K_effective: tuple[tuple[float, ...], ...] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        K = validate_gain(self.K)
        object.__setattr__(self, 'K', tuple(tuple(float(v) for v in row) for row in K))
        if self.perturbation is not None:
            P = np.asarray(self.perturbation, dtype=float)
            if P.shape != (2, 4) or not np.all(np.isfinite(P)):
                raise LoopConfigError('perturbation E D F must be a finite 2x4 matrix, got '
                                      f'{np.asarray(self.perturbation)!r}')
            object.__setattr__(self, 'perturbation', tuple(tuple(map(float, r)) for r in P))
        dt = self.dt
        if isinstance(dt, bool) or not isinstance(dt, (int, float)) or not math.isfinite(dt) \
                or dt < 0:
            raise LoopConfigError(f'dt must be a finite number >= 0 s (0: the step from the '
                                  f'odometry stamps), got {dt!r}')
        object.__setattr__(self, 'dt', float(dt))
        for name in ('max_linear_speed', 'max_angular_speed', 'min_speed'):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, float)) \
                    or not math.isfinite(val) or val <= 0:
                raise LoopConfigError(f'{name} must be a finite number > 0, got {val!r}')
        if self.min_speed >= self.max_linear_speed:
            raise LoopConfigError(f'min_speed ({self.min_speed}) must be below '
                                  f'max_linear_speed ({self.max_linear_speed})')
        if self.delay_compensation:
            if self.A_tau is None:
                raise LoopConfigError('delay_compensation needs A_tau')
            object.__setattr__(self, 'A_tau', tuple(map(tuple, as_matrix(
                self.A_tau, 'A_tau', (4, 4), error=LoopConfigError).tolist())))
            _nonneg('tau', self.tau)
        for name in ('predict_latency', 'predict_odom_latency', 'predict_lag_v',
                     'predict_lag_w', 'max_linear_accel', 'max_angular_accel'):
            object.__setattr__(self, name, _nonneg(name, getattr(self, name)))

        K_eff = self.K if self.perturbation is None else tuple(
            tuple(a + b for a, b in zip(rk, rp)) for rk, rp in zip(self.K, self.perturbation))
        object.__setattr__(self, 'K_effective', K_eff)   # the gain actually applied: K + E D F

    @property
    def rate_limited(self) -> bool:
        """True if the commands are rate-limited (an acceleration limit is set)."""
        return bool(self.max_linear_accel or self.max_angular_accel)

    @property
    def predicts(self) -> bool:
        """True if the law is evaluated on a prediction (any latency or lag assumed)."""
        return bool(self.predict_latency or self.predict_odom_latency or self.predict_lag_v
                    or self.predict_lag_w)


class Command(NamedTuple):
    """One tracker output with the quantities behind it (for logs and tests)."""

    v: float                 # commanded linear speed (m/s), cmd_vel.linear.x
    w: float                 # commanded angular speed (rad/s), cmd_vel.angular.z
    a: float = 0.0           # acceleration of the compensator (m/s^2)
    u: tuple[float, float] = (0.0, 0.0)    # linear-model input
    error: tuple[float, float, float, float] = (0.0, 0.0, 0.0, 0.0)   # xi - xi_d
    saturated: bool = False
    floored: bool = False


class Tracker:
    """Dynamic-feedback-linearizing tracker: ``u = xi_d'' + K_eff (xi - xi_d)``.

    The compensator state is the speed ``v`` (``v' = a``).  Per step, with the
    pose ``(x, y, th)`` and the reference sample: ``a = u1 cos th + u2 sin th``,
    ``w = (u2 cos th - u1 sin th) / v_f`` where ``v_f`` is ``v`` floored to
    ``|v_f| >= min_speed`` (keeping its sign; ``+`` at 0), ``w`` is clipped to
    ``max_angular_speed`` and the command speed is the mean of the ramp over the
    coming interval ``h``, ``(v_k + clip(v_k + a_k h)) / 2``, within ``max_linear_speed``.

    Timing (:mod:`control.simulation.timing`; ``config.dt = 0``, the default): the time of a
    step is its ``stamp`` (default ``ref.t``).  The compensator integrates over the
    interval that passed, ``v_k = clip(v_{k-1} + a_{k-1} (t_k - t_{k-1}))`` (intervals in
    whole nanoseconds, as stamps are; a repeated or earlier stamp integrates nothing), and
    the coming interval ``h`` is the measured odometry period (the median of the recent
    intervals, robust to jitter, dropped and bunched messages).  First step of a run (after
    :meth:`reset`, the compensator starts from the measured speed): its interval that
    passed is not used; before any interval is known (the tracker's first step) ``h = 0``:
    the command speed is the measured speed, no lag inversion, and with acceleration limits
    the command is the start state ``(v_0, 0)``.  ``config.dt > 0`` overrides both the
    interval that passed and ``h`` with that constant at every step (the tracker before it
    took its step from the stamps); with a constant period equal to it the two agree after
    the first step.  :attr:`timing` measures the period either way (a node reports a rate
    change or a disagreeing override).

    With ``delay_compensation`` the tracker follows the *delay-consistent*
    reference ``xi*`` instead of ``xi_d`` (see :meth:`_compensated_reference`), so
    that the error ``e = xi - xi*`` obeys ``e' = (A + B K) e + A_tau e(t - tau)``
    exactly and the steady-state bias caused by ``A_tau xi(t - tau)`` vanishes.

    Predictor (``config.predicts``; :mod:`control.simulation.predictor`): the pose measured at
    ``stamp`` is replaced by the pose predicted at ``t_act = stamp +
    predict_odom_latency + predict_latency`` (the time this command acts), from the
    commands already sent and the assumed actuator lag, and the reference by the
    reference at ``t_act``; the law above is evaluated there.  With a time constant
    the command is the one that takes the predicted actual speed to the law's value at
    the end of the command interval ``h`` (:func:`control.simulation.predictor.invert_lag`: the
    compensator's next speed for ``v``, ``w`` itself for ``w``).  The compensator speed
    ``v`` is the speed at ``t_act``.  With every ``predict_*`` at 0 the law is
    today's, operation for operation.

    Acceleration limits (``max_linear_accel``, ``max_angular_accel``; 0 = off, the law
    above operation for operation): the compensator's acceleration ``a`` is clipped to
    ``max_linear_accel`` and each command differs from the previous one sent by at most
    the limit times the interval that passed (the first after a reset from the measured
    speed and ``w = 0``, the state the predictor starts from, by the limit times ``h``);
    a clipped step counts as ``saturated``.  The predictor's actuator model has the same
    limits, so it predicts the speeds the base can reach.
    """

    def __init__(self, config: TrackerConfig):
        """Tracker with its compensator not started (initialised from the first measured speed).

        Parameters
        ----------
        config : TrackerConfig
            Gain, perturbation, limits, delay compensation, predictor settings.
        """
        self.config = config
        self.v: float | None = None
        #: The odometry period and the interval of each step (from the stamps).
        self.timing = PeriodEstimator()
        self._ref_hist: deque[Any] | None = None
        if config.delay_compensation:
            self._ref_hist = deque()
        self.predictor: LatencyPredictor | None = None
        if config.predicts:
            self.predictor = LatencyPredictor(
                config.predict_latency, config.predict_odom_latency,
                ActuatorModel(config.predict_lag_v, config.predict_lag_w,
                              config.max_linear_accel, config.max_angular_accel),
                config.dt or SUBSTEP)
        #: The last command sent (v, w), for the rate limit; None until the first.
        self._last_cmd: tuple[float, float] | None = None
        #: ``(v, a, h)`` of the previous step: the compensator's ramp to re-integrate over
        #: the interval that passed (None: nothing to integrate).
        self._ramp: tuple[float, float, float] | None = None
        #: The time (ns) of the previous step (its interval to this one is what passed).
        self._last_step_ns: int | None = None

    def reset(self, v: float | None = None) -> None:
        """Forget the compensator state (re-initialised from the next measured speed).

        The measured odometry period (:attr:`timing`) is kept: the rate is the stream's.

        Parameters
        ----------
        v : float, optional
            Compensator speed (m/s) to start from at once (default: none, the next
            measured speed).
        """
        self.v = v
        self._last_cmd = None
        self._ramp = None
        if self._ref_hist is not None:
            self._ref_hist.clear()
        if self.predictor is not None:
            self.predictor.reset()

    def _passed(self, t_meas: float, stamp_ns: int | None) -> float | None:
        """The interval (s) since the previous step; the step's time goes to :attr:`timing`.

        The interval is the step's own (None at the first step, after a time that went back
        or jumped by more than :data:`~control.simulation.timing.MAX_INTERVAL`); the
        estimator may have seen this time already (the input rules measure the odometry
        rate while no step is due, :meth:`TrackerInputs.compute
        <nonfragile_tracker.tracker_inputs.TrackerInputs.compute>`): it is not counted twice.
        """
        if stamp_ns is None:
            if not (math.isfinite(t_meas) and abs(t_meas) < 1e12):
                return None
            t_ns = int(round(t_meas * 1e9))
        else:
            t_ns = int(stamp_ns)
        if self.timing.last_ns != t_ns:
            self.timing.observe_ns(t_ns)
        last, self._last_step_ns = self._last_step_ns, t_ns
        if last is None or t_ns < last or t_ns - last > MAX_INTERVAL * 1e9:
            return None
        return (t_ns - last) * 1e-9

    @property
    def hold(self) -> float:
        """The coming interval ``h`` (s): ``dt`` if set, else the measured period (0: unknown)."""
        return self.config.dt or (self.timing.period or 0.0)

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None) -> Command:
        """One command from a measured pose and a reference sample.

        The pose ``(x, y, th)`` is measured at ``stamp`` (s; default ``ref.t``); the
        reference sample may be of any time (the predictor extrapolates it).  ``stamp_ns``
        (the message's stamp in integer nanoseconds, ``stamp`` to within 0.5 ns) times the
        interval exactly.

        Parameters
        ----------
        x, y : float
            Measured position (m).
        th : float
            Measured heading (rad).
        ref : RefSample
            The reference sample.
        measured_speed : float, optional
            Measured speed (m/s): starts the compensator at the first step.
        stamp : float, optional
            Measurement time (s).
        stamp_ns : int, optional
            Measurement time (ns), the same as ``stamp``: the interval's exact clock.

        Returns
        -------
        Command
        """
        c = self.config
        t_meas = ref.t if stamp is None else float(stamp)
        passed = self._passed(t_meas, stamp_ns)
        if c.dt:
            passed = h = c.dt
        else:
            h = self.timing.period or 0.0
        vmax = c.max_linear_speed
        if self.v is None:
            self.v = float(measured_speed) if measured_speed is not None else 0.0
            if not math.isfinite(self.v):
                self.v = 0.0
            self.v = max(-vmax, min(vmax, self.v))
            passed = None
        elif self._ramp is not None and passed is not None and passed != self._ramp[2]:
            v0, a0, _ = self._ramp                 # the interval that passed was not h
            self.v = max(-vmax, min(vmax, v0 + a0 * passed))
        v = self.v
        pred = self.predictor
        if pred is not None:
            if not math.isfinite(t_meas):          # no time, no prediction: stop
                self._ramp = None
                return Command(v=0.0, w=0.0, saturated=True)
            p = pred.predict(x, y, th, t_meas, v)
            x, y, th = p.x, p.y, p.th
            ref = pred.reference(ref, p.t)
        cth, sth = math.cos(th), math.sin(th)
        if self._ref_hist is None:
            xd, ud = ref.xi, (ref.ax, ref.ay)
        else:
            xd, ud = self._compensated_reference(ref, h)
        e, u1, u2, a, w, floored = feedback(x, y, cth, sth, v, xd, ud, c.K_effective,
                                            c.min_speed)
        saturated = False
        amax = c.max_linear_accel
        if amax > 0.0 and abs(a) > amax:          # the base cannot follow more than this
            a, saturated = math.copysign(amax, a), True
        if w > c.max_angular_speed:
            w, saturated = c.max_angular_speed, True
        elif w < -c.max_angular_speed:
            w, saturated = -c.max_angular_speed, True
        v_next = v + a * h
        if v_next > vmax:
            v_next, saturated = vmax, True
        elif v_next < -vmax:
            v_next, saturated = -vmax, True
        if not (math.isfinite(w) and math.isfinite(v_next)):
            # non-finite input slipped through: stop, keep the compensator state
            self._ramp = None
            if pred is not None:
                pred.record(p.t, 0.0, 0.0)
            return Command(v=0.0, w=0.0, a=0.0, u=(u1, u2), error=e, saturated=True,
                           floored=floored)
        self.v = v_next
        self._ramp = (v, a, h)
        cmd_v = 0.5 * (v + v_next)
        if pred is not None and h > 0.0:
            cmd_v, w, lagged = self._invert_lags(cmd_v, w, v_next, p, h)
            saturated = saturated or lagged
        if c.rate_limited:
            since = h if self._last_cmd is None or passed is None else passed
            cmd_v, w, limited = self._rate_limit(cmd_v, w, v, since)
            saturated = saturated or limited
        if pred is not None:
            pred.record(p.t, cmd_v, w)
        return Command(v=cmd_v, w=w, a=a, u=(u1, u2), error=e, saturated=saturated,
                       floored=floored)

    def _invert_lags(self, cmd_v: float, w: float, v_next: float, p: Any, h: float
                     ) -> tuple[float, float, bool]:
        """The commands that take the predicted actual speeds ``p`` to the law's over ``h``.

        Each within its speed limit (a clipped one counts as saturated); non-finite: stop.
        """
        c = self.config
        saturated = False
        vmax = c.max_linear_speed
        if c.predict_lag_v > 0.0:
            cmd_v = invert_lag(v_next, p.v, c.predict_lag_v, h)
            if abs(cmd_v) > vmax:
                cmd_v, saturated = math.copysign(vmax, cmd_v), True
        if c.predict_lag_w > 0.0:
            w = invert_lag(w, p.w, c.predict_lag_w, h)
            if abs(w) > c.max_angular_speed:
                w, saturated = math.copysign(c.max_angular_speed, w), True
        if not (math.isfinite(cmd_v) and math.isfinite(w)):
            cmd_v = w = 0.0
        return cmd_v, w, saturated

    def _rate_limit(self, cv: float, cw: float, v0: float, since: float
                    ) -> tuple[float, float, bool]:
        """``(cv, cw)`` moved at most ``max_*_accel * since`` from the previous command.

        ``since`` is the time since the previous command (s).  Before the first command
        the previous one is ``(v0, 0)`` (the compensator's initial speed, at rest in
        rotation: the predictor's initial state).
        """
        c = self.config
        pv, pw = self._last_cmd if self._last_cmd is not None else (v0, 0.0)
        if c.max_linear_accel > 0.0:
            cv2 = _within(cv, pv, c.max_linear_accel * since)
        else:
            cv2 = cv
        if c.max_angular_accel > 0.0:
            cw2 = _within(cw, pw, c.max_angular_accel * since)
        else:
            cw2 = cw
        limited = cv2 != cv or cw2 != cw
        cv, cw = cv2, cw2
        self._last_cmd = (cv, cw)
        return cv, cw, limited

    def _compensated_reference(self, ref: RefSample, h: float
                               ) -> tuple[tuple[float, float, float, float], tuple[float, float]]:
        """Delay-consistent reference ``xi*`` and its feedforward input ``u*``.

        In the model, per axis ``p' = q + d_p`` and ``q' = u + d_q`` with
        ``d = A_tau xi(t - tau)``.  For the position to follow ``p_d`` exactly, the
        velocity state must be ``q* = p_d' - d*_p`` and the input
        ``u* = q*' - d*_q = p_d'' - (d*_p)' - d*_q``, where ``d* = A_tau xi*(t - tau)``
        and ``(d*)' = A_tau xi*'(t - tau)`` come from the tracker's own history of
        ``(xi*, xi*')`` by time: the latest sample at or before ``t - tau + h / 2`` (the
        sample nearest ``t - tau``; ``h`` the coming interval), and at least one step back;
        before the first sample the history is the first sample at rest.  Then
        ``e = xi - xi*`` obeys ``e' = (A + B K) e + A_tau e(t - tau)``: no steady-state bias.
        """
        # set whenever delay_compensation is
        At = cast(tuple[tuple[float, ...], ...], self.config.A_tau)
        hist = cast(deque[Any], self._ref_hist)
        p_dot = (ref.vx, ref.vy)
        t_ns = int(round(ref.t * 1e9))
        if not hist:
            hist.append((None, ref.xi, (ref.vx, 0.0, ref.vy, 0.0)))    # the first, at rest
        target = t_ns - int(round(self.config.tau * 1e9)) + int(round(0.5 * h * 1e9))
        while len(hist) > 1 and hist[1][0] <= target:
            hist.popleft()                  # a later sample is still at or before the target
        _, z, zdot = hist[0]
        # A_tau z and A_tau zdot, summed left to right from 0.0 (as sum() does on 3.11)
        z0, z1, z2, z3 = z
        y0, y1, y2, y3 = zdot
        d = [0.0 + a0 * z0 + a1 * z1 + a2 * z2 + a3 * z3 for a0, a1, a2, a3 in At]
        dd = [0.0 + a0 * y0 + a1 * y1 + a2 * y2 + a3 * y3 for a0, a1, a2, a3 in At]
        xs = (ref.x, ref.vx - d[0], ref.y, ref.vy - d[2])
        us = (ref.ax - dd[0] - d[1], ref.ay - dd[2] - d[3])
        hist.append((t_ns, xs, (p_dot[0], us[0] + d[1], p_dot[1], us[1] + d[3])))
        return xs, us
