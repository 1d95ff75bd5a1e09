"""The plant's step: the kinematic unicycle :class:`UnicyclePlant` and its vector twin.

:class:`UnicyclePlant` is the unicycle driven by ``(v, w)`` with the paper's delayed-state
term and, each off by default, the command line (latency, schedule, jitter, stalls), actuator
dynamics and late, decimated, noisy odometry, behind the plant seam
(:class:`.interfaces.Plant`); :class:`PlantConfig` its validated settings;
:class:`VectorPlant` the same step for N cases at once (test_batch.py checks the pair
step by step), with a fast step for odometry of its own state.  Plain floats and numpy;
no ROS.

See doc/theory.md, section "Model", and doc/ros-interface.md, section "plant".
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, cast

import numpy as np

from ..validate import as_finite_float, as_matrix
from .actuator import ActuatorModel, VectorActuator, actuate
from .batch_data import Settings
from .command_line import CommandLine
from .errors import LoopConfigError
from .model import wrap_due, xi_from_state
from .sensors import Odometer, OdometryModel, OdometrySample
from .timing import step_time

__all__ = ['PlantConfig', 'UnicyclePlant', 'VectorPlant', 'delay_steps', 'odometry_period_steps',
           'S1', 'S2', 'S3', 'ANCHOR']


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


@dataclass(frozen=True)
class PlantConfig:
    """Unicycle plant settings (SI units).  ``A_tau`` acts on ``xi = [x, x', y, y']``.

    Defaults are neutral (no delay term, at rest at the origin); the paper's scenario
    is ``nonfragile_tracker.interface.scenario.paper_plant_config()`` (``config/``).

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
        self.line = CommandLine(config.cmd_latency_steps, config.latency_schedule_steps(),
                                delay_steps(config.cmd_latency_jitter, config.dt)[0],
                                config.stall_steps, int(config.noise_seed), float(config.v0))
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
        self.line.reset(self.v)
        if self.odometer is not None:
            self.odometer.reset()
            self.odometer.measure(0, self.x, self.y, self.th, self.v, self.w)

    @property
    def t(self) -> float:
        """Time of the current step in s."""
        return step_time(self.k, self.config.dt)

    @property
    def dt(self) -> float:
        """The plant's step (s)."""
        return self.config.dt

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
        self.line.send(self.k, v, w)

    @property
    def cmd(self) -> tuple[float, float]:
        """The command in force (:class:`~.command_line.CommandLine`)."""
        return self.line.cmd

    @property
    def cmd_delay(self) -> int:
        """The command latency in force (steps)."""
        return self.line.cmd_delay

    @property
    def last_act_step(self) -> int:
        """The step the newest command acts from (-1: none yet)."""
        return self.line.last_act_step

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
        v, w = self.line.in_force(self.k)
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


def _dot_terms(terms: list[tuple[int, float]], xi: Any, out: np.ndarray) -> None:
    """``out = sum(a * xi[j])`` over the nonzero terms, left to right (as the plant).

    The plant starts from ``0.0``: that changes at most the sign of a zero.  Rows
    without terms are left as they are (zero).
    """
    if not terms:
        return
    j, a = terms[0]
    np.multiply(a, xi[j], out=out)
    for j, a in terms[1:]:
        out += a * xi[j]


class _PlantDelay:
    """The plant's delayed-state term ``d = A_tau xi(t - tau)`` for every case.

    A history of the parts of ``xi = (x, x', y, y')`` that ``A_tau`` uses, by step
    ``% (Nd + 1)``; ``diag``: the paper's form ``d_x = a x(t - tau)``, ``d_y = b y(t - tau)``
    (one product for both).  :meth:`update` fills ``dpos`` and ``dvel`` for a step.
    """

    def __init__(self, plant: PlantConfig, pos: np.ndarray, pv: np.ndarray, th: np.ndarray):
        n = pv.size
        self.Nd = Nd = delay_steps(plant.tau, plant.dt)[0]
        At = np.array(plant.A_tau, dtype=float)
        terms = [[(j, float(At[i, j])) for j in range(4) if At[i, j] != 0.0] for i in range(4)]
        self.terms = terms
        self.on = any(terms)
        self.diag = self.need_vel = self.has_off = False
        self.ax = self.ay = 0.0
        if not self.on:
            return
        self.cols = cols = sorted({j for row in terms for j, _ in row})
        self.need_vel = 1 in cols or 3 in cols
        self.has_off = bool(terms[1] or terms[3])   # else the velocity offset stays 0
        self.hterms = [[(cols.index(j), a) for j, a in row] for row in terms]
        self.diag = (cols == [0, 2] and not self.has_off
                     and [len(r) for r in terms] == [1, 0, 1, 0]
                     and terms[0][0][0] == 0 and terms[2][0][0] == 2)
        if self.diag:
            self.ax, self.ay = terms[0][0][1], terms[2][0][1]
        xi0 = (pos[0], pv * np.cos(th), pos[1], pv * np.sin(th))
        self.hist = np.empty((Nd + 1, len(cols), n))
        self.hist[:] = np.array([xi0[j] for j in cols])[None]
        self.dbuf = np.zeros((4, n))
        self.dpos, self.dvel = self.dbuf[0::2], self.dbuf[1::2]

    def update(self, k: int, pos: np.ndarray, v: np.ndarray, csp: np.ndarray | None,
               off: np.ndarray) -> None:
        """``dpos``, ``dvel`` of step ``k``; the history takes the state of step ``k``."""
        Nd = self.Nd
        if self.diag and Nd > 0:
            old = self.hist[k % (Nd + 1)]               # (x, y) at step k - N
            np.multiply(self.ax, old[0], out=self.dpos[0])
            np.multiply(self.ay, old[1], out=self.dpos[1])
            old[...] = pos
            return
        xi: tuple[Any, Any, Any, Any]
        if self.need_vel:
            vel = v * csp
            if self.has_off:
                vel += off
            xi = (pos[0], vel[0], pos[1], vel[1])       # xi_now = (x, vel_x, y, vel_y)
        else:
            xi = (pos[0], None, pos[1], None)
        if Nd == 0:
            for i in range(4):
                _dot_terms(self.terms[i], xi, self.dbuf[i])
        else:
            old = self.hist[k % (Nd + 1)]               # the used parts of xi at step k - N
            for i in range(4):
                _dot_terms(self.hterms[i], old, self.dbuf[i])
            for r, j in enumerate(self.cols):
                old[r] = xi[j]


class VectorPlant:
    """:meth:`.control.simulation.plant.UnicyclePlant.advance` for every case: pose, speed, delay.

    ``pos`` (2, N), ``th``, the speed and rate at the end of the last step ``pv``, ``pw``
    and the velocity offset ``off`` of the delay term.  Without ``exact`` the arc's sine
    and cosines come from series (``small_arc``, when ``|w| dt / 2 <= 0.01`` holds for
    every command) and, with ``recur``, the tracker's heading cosine and sine are carried
    to the next step by angle addition.

    Parameters
    ----------
    plant : PlantConfig
        The shared plant settings (step, state delay).
    s : control.simulation.batch_data.Settings
        The resolved per-case settings (initial state, actuator).
    exact : bool
        The single run's operations (else cheaper forms of the same values).
    ideal_odom : bool
        VectorOdometer of the plant's own state every step (:class:`.sensors.VectorOdometer`).
    wmax : float
        The tracker's largest angular speed (rad/s).
    """

    def __init__(self, plant: PlantConfig, s: Settings, exact: bool, ideal_odom: bool,
                 wmax: float):
        n = s.n
        dt = self.dt = plant.dt
        self.hdt = 0.5 * dt
        self.pos = np.stack((s.x0, s.y0))           # (x, y) as (2, N)
        self.th, self.pv = s.th0.copy(), s.v0.copy()
        self.pw = np.zeros(n)
        self.off = np.zeros((2, n))                 # velocity offset (ox, oy)
        self.delay = _PlantDelay(plant, self.pos, self.pv, self.th)
        self.act = VectorActuator(s, dt)
        self.exact, self.ideal_odom = exact, ideal_odom
        # |w| <= max_angular_speed for every command (clipped, held, or a mean of two
        # through the actuator): the arc's series applies at every step when
        # 0.5 wmax dt <= 0.01
        self.small_arc = not exact and 0.5 * wmax * dt <= _SERIES_MAX
        # the heading's cosine and sine carried from step to step by angle addition (the
        # tracker measures the plant's own heading), evaluated afresh every ANCHOR steps
        self.recur = self.small_arc and ideal_odom
        # the heading moves at most wmax dt per step: after a look at max |th| = m the wrap
        # (|th| > pi) cannot be needed for (pi - m) / (wmax dt) steps
        self.wstep = wmax * dt * (1.0 + 1e-9)
        self.wrap_next = 0
        self.mid = np.empty((2, n))
        self.tmp = np.empty((2, n))
        self.arcbuf = np.empty((4, n))
        # the common case in fewer whole-array operations (:meth:`_advance_fast`): the
        # heading carried, no actuator dynamics, no delay term or the paper's diagonal one
        d = self.delay
        self.fast = (self.recur and not self.act.on
                     and (not d.on or (d.diag and d.Nd > 0)))
        if self.fast:
            hh = self.hdt * self.hdt
            self.q = [np.array(self.hdt * c * hh ** i)
                      for i, c in ((3, S3), (2, S2), (1, S1), (0, 1.0))]
            self.dt_ = np.array(dt)
            self.dtmp = np.empty((2, n))
            if d.on:
                self.axdt, self.aydt = np.array(d.ax * dt), np.array(d.ay * dt)

    def _advance_fast(self, k: int, v: np.ndarray, w: np.ndarray, cs: np.ndarray) -> None:
        """:meth:`advance` for ``fast``: the same values to round-off, fewer operations.

        The arc's series is a polynomial in ``w**2`` (``Q = dt sin(h) / (2h)``,
        ``h = w dt / 2``), ``cos h = sqrt(1 - sin(h)**2)`` and the next heading's cosine
        and sine are ``2 cos(h) mid - (cos, sin)(th)`` from the midpoint direction ``mid``.
        """
        mul, sub = np.multiply, np.subtract
        W2, Q, ch, sh = self.arcbuf
        q3, q2, q1, q0 = self.q
        mid, tmp = self.mid, self.tmp
        mul(w, w, out=W2)
        mul(W2, q3, out=Q)
        Q += q2
        Q *= W2
        Q += q1
        Q *= W2
        Q += q0
        mul(w, Q, out=sh)                           # sin h
        mul(sh, sh, out=ch)                         # cos h = sqrt(1 - sin(h)**2)
        sub(1.0, ch, out=ch)
        np.sqrt(ch, out=ch)
        _rotate(cs, ch, sh, mid, tmp)               # cos, sin (th + h)
        ch += ch                                    # cos, sin (th + 2 h) = 2 cos(h) mid - cs
        mul(mid, ch, out=tmp)
        sub(tmp, cs, out=cs)
        mul(v, Q, out=Q)                            # v dt sin(h) / h
        Q += Q
        mul(mid, Q, out=tmp)
        d = self.delay
        pos = self.pos                              # (its own array: updated in place)
        if d.on:
            old = d.hist[k % (d.Nd + 1)]            # (x, y) at step k - Nd
            dtmp = self.dtmp
            mul(old[0], self.axdt, out=dtmp[0])
            mul(old[1], self.aydt, out=dtmp[1])
            tmp += dtmp
            old[...] = pos
        pos += tmp
        thstep = ch                                 # (free now)
        mul(w, self.dt_, out=thstep)
        self.th += thstep
        if k >= self.wrap_next:
            self.th, self.wrap_next = wrap_due(self.th, k, self.wstep)
        self.pv, self.pw = v, w

    def advance(self, k: int, v: np.ndarray, w: np.ndarray, cs: np.ndarray) -> None:
        """Advance step ``k`` under the command ``(v, w)`` in force.

        ``cs``: the tracker's cosine and sine of the heading it measured (carried to the
        next step with ``recur``).

        Parameters
        ----------
        k : int
            The step.
        v, w : numpy.ndarray
            The command in force.
        cs : numpy.ndarray
            Cosine and sine of the measured heading (2, N).
        """
        if self.fast:
            self._advance_fast(k, v, w, cs)
            return
        dt = self.dt
        act, d = self.act, self.delay
        if act.on:
            v_end, v, w_end, w = act.step(self.pv, self.pw, v, w)
        if self.ideal_odom and not self.exact:      # the tracker measured this very heading
            csp: np.ndarray | None = cs
        elif d.on:
            csp = np.stack((np.cos(self.th), np.sin(self.th)))
        else:
            csp = None
        if d.on:
            d.update(k, self.pos, v, csp, self.off)
        half = w * self.hdt                         # = 0.5 w dt (halving is exact)
        mid = self.mid
        if self.small_arc and csp is not None:
            sinc, ch, sh = _arc_series(half, csp, mid, self.tmp, self.arcbuf)
            if self.recur:                          # cos, sin (th + 2 half) for the tracker
                _rotate(mid, ch, sh, cs, self.tmp)
        else:
            sinc = _arc_terms(self.th, half, csp, self.exact, mid)
        arc = v * dt
        arc *= sinc
        step = mid * arc
        if d.on:
            if d.has_off:
                step += (d.dpos + self.off) * dt
                step += 0.5 * d.dvel * dt * dt
                self.off = self.off + d.dvel * dt
            else:                                   # the velocity terms are exact zeros
                step += d.dpos * dt
        self.pos = self.pos + step
        th = self.th + w * dt
        if k >= self.wrap_next:
            th, self.wrap_next = wrap_due(th, k, self.wstep)
        self.th = th
        if act.on:
            self.pv, self.pw = v_end, w_end
        else:
            self.pv, self.pw = v, w


# Taylor coefficients of sin(h)/h and cos(h) in h^2 (to h^6; |h| <= 0.01: truncation < 1e-20)
S1, S2, S3 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0


_C1, _C2, _C3 = -1.0 / 2.0, 1.0 / 24.0, -1.0 / 720.0


#: Largest ``|half|`` (rad) for which the arc's series are used.
_SERIES_MAX = 1e-2


#: Steps between fresh evaluations of the heading's cosine and sine when they are carried
#: by angle addition (each step adds about an ulp; the fresh values bound the drift).
ANCHOR = 16


def _arc_series(half: np.ndarray, cs: np.ndarray, mid: np.ndarray, tmp: np.ndarray,
                buf: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(sin(h)/h, cos h, sin h)`` of ``h = half`` from their series.

    ``mid`` receives ``cos, sin (th + half)`` from ``cs = (cos th, sin th)`` by angle
    addition.  The operations of the non-exact branch of :func:`_arc_terms` (the same values) into
    the rows of ``buf`` (4, N); for ``|half| <= _SERIES_MAX``.
    """
    h2, sinc, ch, sh = buf
    np.multiply(half, half, out=h2)
    for out, c3, c2, c1 in ((sinc, S3, S2, S1), (ch, _C3, _C2, _C1)):
        np.multiply(h2, c3, out=out)
        out += c2
        out *= h2
        out += c1
        out *= h2
        out += 1.0
    np.multiply(half, sinc, out=sh)
    _rotate(cs, ch, sh, mid, tmp)
    return sinc, ch, sh


def _rotate(cs: np.ndarray, ch: np.ndarray, sh: np.ndarray, out: np.ndarray,
            tmp: np.ndarray) -> None:
    """``out = (c ch - s sh, s ch + c sh)`` for ``cs = (c, s)`` (angle addition)."""
    c, s = cs
    t = tmp[0]
    np.multiply(c, ch, out=out[0])
    np.multiply(s, sh, out=t)
    out[0] -= t
    np.multiply(s, ch, out=out[1])
    np.multiply(c, sh, out=t)
    out[1] += t


def _arc_terms(th: np.ndarray, half: np.ndarray, cs: np.ndarray | None, exact: bool,
               mid: np.ndarray) -> np.ndarray:
    """``sin(half) / half`` of the exact arc; ``mid`` receives ``cos, sin (th + half)``.

    ``exact``: the plant's own operations.  Otherwise, for ``|half| <= 0.01``
    (``|w| dt <= 0.02``), ``sin(half) / half`` from its Taylor series (truncation below
    1e-20) and, given ``cs = (cos th, sin th)`` (else ``None``), the angle-addition
    formulas: up to three transcendental calls per step fewer, the same values to
    round-off.
    """
    if not exact and np.max(np.abs(half)) <= _SERIES_MAX:
        h2 = half * half
        sinc: np.ndarray = ((h2 * S3 + S2) * h2 + S1) * h2 + 1.0
        if cs is not None:
            sh = half * sinc
            ch = ((h2 * _C3 + _C2) * h2 + _C1) * h2 + 1.0
            c, s = cs[0], cs[1]
            np.subtract(c * ch, s * sh, out=mid[0])
            np.add(s * ch, c * sh, out=mid[1])
            return sinc
    else:
        big = np.abs(half) > 1e-8
        sinc = np.where(big, np.sin(half) / np.where(big, half, 1.0), 1.0 - half * half / 6.0)
    a = th + half
    np.cos(a, out=mid[0])
    np.sin(a, out=mid[1])
    return sinc


_PI = math.pi


_TAU = math.tau
