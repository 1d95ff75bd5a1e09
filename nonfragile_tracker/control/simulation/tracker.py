"""The tracking law's step: the scalar :class:`Tracker` and its vector twin for the batch.

:class:`Tracker` is the tracking law (:func:`.law.feedback`) with its dynamic extension,
limits, stamp timing, delay compensation and latency predictor, behind the controller seam
(:class:`.interfaces.Controller`); :class:`TrackerConfig` its validated settings (one
parameters mapping: :func:`nonfragile_tracker.interface.msgconv.tracker_config`);
:class:`VectorTracker` the same step for N cases at once (test/control/test_twins.py and
test_batch.py check the pair).  The nodes call these methods in the order of
:func:`.simulate.simulate_tracking`, so a lockstep run and an in-process run agree to
round-off.  Plain floats and numpy; no ROS.

See doc/theory.md, section "Model", and doc/ros-interface.md, section "Time and lockstep".
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field, replace
from typing import Any, NamedTuple, cast

import numpy as np

from ..validate import as_finite_float, as_matrix
from .actuator import ActuatorModel, within
from .batch_data import Schedule, Settings
from .errors import LoopConfigError
from .law import VectorLaw, feedback
from .limits import Limits
from .plant import ANCHOR
from .predictor import SUBSTEP, LatencyPredictor, invert_lag
from .reference import RefSample
from .slip import SlideReckoner, check_slip_table
from .timing import MAX_INTERVAL, PeriodEstimator

__all__ = ['TrackerConfig', 'Command', 'Tracker', 'VectorTracker', 'validate_gain']


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
    and its predictor models them (see :class:`Tracker`).  Every limit is the command's
    (``cmd_vel``, as the base's firmware and ``identify`` see it); with channel gains the
    law works within the limits of the motion, :attr:`motion_limits`.

    ``controller`` names the law (``package.module:factory``, :mod:`.interfaces`; '', the
    default, our :class:`Tracker`): every other field is the tracker's setting for any law.

    ``dt`` (s): 0 (the default) takes the tracker's step from the odometry stamps (the
    interval that passed, the measured period: :mod:`.control.simulation.timing`); a value
    > 0 is an override, a constant step used whatever the stamps say (the behaviour before
    the step came from the stamps; a node reports when it disagrees with the odometry).

    ``gain_v``, ``gain_w`` (> 0, default 1: none): the base's static channel gains, the
    speeds it reaches per commanded unit (``identify``'s ``gain_v``, ``gain_w``; a
    skid-steer turns at about 0.6-0.7 of its commanded rate).  The law, its limits, its
    rate limit and its predictor work on the motion the base makes; the command sent is
    that motion over the gain (``v / gain_v``, ``w / gain_w``), clipped to
    ``max_linear_speed`` / ``max_angular_speed`` (limits of the command, ``cmd_vel``, as the
    node clips it; a clipped one counts as saturated), the last operation of a step.  The
    law's speed clamps and its predictor's actuator model use the limits times the gains
    (:attr:`motion_limits`: a skid-steer turning at 0.63 of its command turns at most 0.63
    of ``max_angular_speed``, and its firmware's ramp of the command is 0.63 of
    ``max_angular_accel`` in its motion); its rate limit holds the motion to the limits'
    numbers (the command may change at up to ``max_angular_accel / gain_w``, which the
    base's firmware ramps).  With both at 1 the commands are unchanged bit for bit.
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
    gain_v: float = 1.0
    gain_w: float = 1.0
    side_slip_rates: tuple[float, ...] = ()
    side_slip: tuple[float, ...] = ()
    #: The tracking law, ``module:factory`` (:mod:`.interfaces`); '' = this module's
    #: :class:`Tracker`.  Whatever runs a controller from this configuration makes this one.
    controller: str = ''
    #: The gain actually applied, ``K + E D F`` (set from ``K`` and ``perturbation``).
    K_effective: tuple[tuple[float, ...], ...] = field(init=False, repr=False, compare=False)
    #: The limits of the motion the law commands: the command's limits times the gains.
    motion_limits: Limits = field(init=False, repr=False, compare=False)

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
            as_finite_float(self.tau, 'tau', low=0.0, error=LoopConfigError)
        if not isinstance(self.controller, str):
            raise LoopConfigError(f'controller must be a string "package.module:factory" (or '
                                  f'empty for the default law), got {self.controller!r}')
        for name in ('predict_latency', 'predict_odom_latency', 'predict_lag_v',
                     'predict_lag_w', 'max_linear_accel', 'max_angular_accel'):
            object.__setattr__(self, name, as_finite_float(getattr(self, name), name, low=0.0,
                                                           error=LoopConfigError))
        for name in ('gain_v', 'gain_w'):
            val = getattr(self, name)
            if isinstance(val, bool) or not isinstance(val, (int, float)) \
                    or not math.isfinite(val) or val <= 0:
                raise LoopConfigError(f'{name} (the base\'s static {name[-1]} gain, identify\'s '
                                      f'{name}) must be a finite number > 0, got {val!r}')
            object.__setattr__(self, name, float(val))
        rates, coefficients = check_slip_table(self.side_slip_rates, self.side_slip)
        object.__setattr__(self, 'side_slip_rates', rates)
        object.__setattr__(self, 'side_slip', coefficients)

        K_eff = self.K if self.perturbation is None else tuple(
            tuple(a + b for a, b in zip(rk, rp)) for rk, rp in zip(self.K, self.perturbation))
        object.__setattr__(self, 'K_effective', K_eff)   # the gain actually applied: K + E D F
        object.__setattr__(self, 'motion_limits', Limits(
            self.max_linear_speed, self.max_linear_accel, self.max_angular_speed,
            self.max_angular_accel).of_motion(self.gain_v, self.gain_w))

    def __deepcopy__(self, memo: dict[int, Any]) -> TrackerConfig:
        """Itself: every field is immutable (tuples of floats), so copies share it."""
        return self

    @property
    def rate_limited(self) -> bool:
        """True if the commands are rate-limited (an acceleration limit is set)."""
        return bool(self.max_linear_accel or self.max_angular_accel)

    @property
    def compensates(self) -> bool:
        """True if the commands are divided by channel gains (``gain_v`` or ``gain_w`` != 1)."""
        return self.gain_v != 1.0 or self.gain_w != 1.0

    @property
    def slides(self) -> bool:
        """True if a side-slip table with a coefficient != 0 is set (it corrects the pose)."""
        return any(self.side_slip)

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

    Timing (:mod:`.control.simulation.timing`; ``config.dt = 0``, the default): the time of a
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
    reference ``xi*`` instead of ``xi_d`` (see ``_compensated_reference``), so
    that the error ``e = xi - xi*`` obeys ``e' = (A + B K) e + A_tau e(t - tau)``
    exactly and the steady-state bias caused by ``A_tau xi(t - tau)`` vanishes.

    Predictor (``config.predicts``; :mod:`.control.simulation.predictor`): the pose measured at
    ``stamp`` is replaced by the pose predicted at ``t_act = stamp +
    predict_odom_latency + predict_latency`` (the time this command acts), from the
    commands already sent and the assumed actuator lag, and the reference by the
    reference at ``t_act``; the law above is evaluated there.  With a time constant
    the command is the one that takes the predicted actual speed to the law's value at
    the end of the command interval ``h`` (:func:`.control.simulation.predictor.invert_lag`: the
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
            m = config.motion_limits
            self.predictor = LatencyPredictor(
                config.predict_latency, config.predict_odom_latency,
                ActuatorModel(config.predict_lag_v, config.predict_lag_w,
                              m.max_linear_accel, m.max_angular_accel),
                config.dt or SUBSTEP)
        #: The last command sent (v, w), for the rate limit; None until the first.
        self._last_cmd: tuple[float, float] | None = None
        #: ``(t, v, w)``: the last command of the law (before the gain compensation) and the
        #: time it acts from; a predictor made by :meth:`retune` starts from it.
        self._sent: tuple[float, float, float] | None = None
        #: ``(v, a, h)`` of the previous step: the compensator's ramp to re-integrate over
        #: the interval that passed (None: nothing to integrate).
        self._ramp: tuple[float, float, float] | None = None
        #: The time (ns) of the previous step (its interval to this one is what passed).
        self._last_step_ns: int | None = None
        #: The side slip's dead reckoning (``config.slides``), None without a table.
        self.slide: SlideReckoner | None = (
            SlideReckoner(config.side_slip_rates, config.side_slip)
            if config.slides else None)

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
        self._sent = None
        self._ramp = None
        if self._ref_hist is not None:
            self._ref_hist.clear()
        if self.predictor is not None:
            self.predictor.reset()
        if self.slide is not None:
            self.slide.forget()

    def retune(self, predict_latency: float, lag_v: float, lag_w: float) -> None:
        """Assume another command latency and actuator lags from now on (online tuning).

        The predictor's latency and actuator model and the lag inversion change together
        (``config`` is replaced); a tracker without a predictor gets one, whose actuator
        starts at the last command (a tracker that assumed no lag had its command acting):
        no kick.  The commands already sent stay in the predictor's buffer.

        Parameters
        ----------
        predict_latency : float
            Command latency (s) to predict.
        lag_v, lag_w : float
            Actuator time constants (s) to predict and invert.
        """
        c = replace(self.config, predict_latency=predict_latency, predict_lag_v=lag_v,
                    predict_lag_w=lag_w)
        self.config = c
        m = c.motion_limits
        actuator = ActuatorModel(c.predict_lag_v, c.predict_lag_w, m.max_linear_accel,
                                 m.max_angular_accel)
        if self.predictor is None:
            self.predictor = LatencyPredictor(c.predict_latency, c.predict_odom_latency,
                                              actuator, c.dt or SUBSTEP)
            if self._sent is not None:
                self.predictor.seed(*self._sent)
        else:
            self.predictor.cmd_latency = c.predict_latency
            self.predictor.actuator = actuator

    def _passed(self, t_meas: float, stamp_ns: int | None) -> float | None:
        """The interval (s) since the previous step; the step's time goes to :attr:`timing`.

        The interval is the step's own (None at the first step, after a time that went back
        or jumped by more than :data:`~control.simulation.timing.MAX_INTERVAL`); the
        estimator may have seen this time already (the input rules measure the odometry
        rate while no step is due, :meth:`TrackerInputs.compute
        <nonfragile_tracker.interface.tracker_inputs.TrackerInputs.compute>`): it is not counted
        twice.
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
    def horizon(self) -> float:
        """Time (s) ahead of the measurement the law is evaluated at (the predictor's)."""
        return 0.0 if self.predictor is None else self.predictor.horizon

    @property
    def hold(self) -> float:
        """The coming interval ``h`` (s): ``dt`` if set, else the measured period (0: unknown)."""
        return self.config.dt or (self.timing.period or 0.0)

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
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
        measured_rate : float, optional
            Measured yaw rate (rad/s); only the side-slip correction uses it (with
            ``config.slides``: the slide of an interval needs the speed and the yaw rate).

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
        if self.slide is not None:              # the slide the odometry does not see
            dx, dy = self.slide.update(
                th, math.nan if measured_speed is None else float(measured_speed),
                math.nan if measured_rate is None else float(measured_rate), passed)
            x, y = x + dx, y + dy
            th = th + self.slide.course_offset(measured_speed)
        m = c.motion_limits
        vmax, wmax = m.max_linear_speed, m.max_angular_speed
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
        amax = m.max_linear_accel
        if amax > 0.0 and abs(a) > amax:          # the base cannot follow more than this
            a, saturated = math.copysign(amax, a), True
        if w > wmax:
            w, saturated = wmax, True
        elif w < -wmax:
            w, saturated = -wmax, True
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
            self._sent = (p.t, cmd_v, w)
        else:
            self._sent = (t_meas, cmd_v, w)
        if c.compensates:                          # the motion over the base's gains,
            cmd_v, w = cmd_v / c.gain_v, w / c.gain_w      # within the command's limits
            if abs(cmd_v) > c.max_linear_speed:
                cmd_v, saturated = math.copysign(c.max_linear_speed, cmd_v), True
            if abs(w) > c.max_angular_speed:
                w, saturated = math.copysign(c.max_angular_speed, w), True
        return Command(v=cmd_v, w=w, a=a, u=(u1, u2), error=e, saturated=saturated,
                       floored=floored)

    def _invert_lags(self, cmd_v: float, w: float, v_next: float, p: Any, h: float
                     ) -> tuple[float, float, bool]:
        """The commands that take the predicted actual speeds ``p`` to the law's over ``h``.

        Each within its speed limit (a clipped one counts as saturated); non-finite: stop.
        """
        c = self.config
        saturated = False
        m = c.motion_limits
        vmax, wmax = m.max_linear_speed, m.max_angular_speed
        if c.predict_lag_v > 0.0:
            cmd_v = invert_lag(v_next, p.v, c.predict_lag_v, h)
            if abs(cmd_v) > vmax:
                cmd_v, saturated = math.copysign(vmax, cmd_v), True
        if c.predict_lag_w > 0.0:
            w = invert_lag(w, p.w, c.predict_lag_w, h)
            if abs(w) > wmax:
                w, saturated = math.copysign(wmax, w), True
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
        # the command's limits on the motion (not times the gains): a skid-steer's command
        # then changes at up to max_angular_accel / gain_w, which its firmware ramps; held
        # to the firmware's own ramp (times gain_w) a 100 Hz loop fell into a limit cycle of
        # the rate limit against the lag inversion (skid-steer lap 28 mm against 7 mm)
        c = self.config
        pv, pw = self._last_cmd if self._last_cmd is not None else (v0, 0.0)
        if c.max_linear_accel > 0.0:
            cv2 = within(cv, pv, c.max_linear_accel * since)
        else:
            cv2 = cv
        if c.max_angular_accel > 0.0:
            cw2 = within(cw, pw, c.max_angular_accel * since)
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


class VectorTracker:
    """:meth:`.control.simulation.tracker.Tracker.step` for every case, in the same order.

    Holds the tracker's state (its speed ``tv``, started cases, the gain in force, the
    compensation history) and the buffers of one step; :meth:`command` computes the
    command ``(v, w)`` of the cases whose odometry is due (with a command every step,
    straight into the metrics block ``cblk``).

    Parameters
    ----------
    s : control.simulation.batch_data.Settings
        The resolved per-case settings.
    tracker : TrackerConfig
        The shared tracker settings (limits, delay compensation).
    schedule : control.simulation.batch_data.Schedule
        The per-case gains and perturbations by segment.
    tdt : float or numpy.ndarray
        The tracker's step (s): shared, or one per case.
    cblk : numpy.ndarray
        The metrics' block of commands (``BLOCK``, 2, N).
    exact : bool
        The single run's operations (else cheaper forms of the same values).
    recur : bool
        The plant carries the heading's cosine and sine (:class:`.plant.VectorPlant`).
    ideal_odom : bool
        VectorOdometer of the plant's own state every step (:class:`.sensors.VectorOdometer`).
    """

    def __init__(self, s: Settings, tracker: TrackerConfig, schedule: Schedule,
                 tdt: np.ndarray | float, cblk: np.ndarray, exact: bool, recur: bool,
                 ideal_odom: bool):
        n = s.n
        self.n, self.idx = n, np.arange(n)
        self.schedule = schedule
        self.seg = 0                                # segment_index(0, ...) is 0
        self.Kc = schedule.gain(0)                  # (2, 4, N)
        self.tv = np.zeros(n)
        self.started = np.zeros(n, dtype=bool)
        self.all_started = False
        self.tdt = tdt
        self.vmax, self.wmax = tracker.max_linear_speed, tracker.max_angular_speed
        self.vmin = tracker.min_speed
        self.exact, self.recur, self.ideal_odom, self.cblk = exact, recur, ideal_odom, cblk
        # the step from the odometry: no interval known at a case's first command, whose
        # speed is then the measured one (control.simulation.tracker.Tracker)
        self.first_hold_zero = tracker.dt == 0
        self.comp = tracker.delay_compensation
        if self.comp:
            Atc = np.array(tracker.A_tau, dtype=float)
            self.cterms = [[(j, float(Atc[i, j])) for j in range(4)] for i in range(4)]
            self.Lc = s.comp_n
            self.cbuf_ref = np.zeros((int(self.Lc.max()), 8, n))
            self.ccount = np.zeros(n, dtype=np.int64)
        self.cs = np.empty((2, n))                  # cos, sin of the measured heading
        self.law = VectorLaw(n, self.vmax, self.wmax, self.vmin, ordered=True)
        self.epos = self.law.E[0::2]                # the position error (x, y)
        self.cmd_log = np.stack((s.v0, np.zeros(n)))    # the command in force: (v0, 0)

    def command(self, k: int, j: int, due: Any, mpos: np.ndarray, mth: np.ndarray,
                mv: np.ndarray, ref: tuple[Any, Any, Any]) -> np.ndarray:
        """The command ``(v, w)`` (2, N) at step ``k`` (block row ``j``) from odometry.

        Parameters
        ----------
        k, j : int
            The step and its row in the metrics block.
        due : bool or numpy.ndarray
            The cases whose odometry is due (True: every case).
        mpos, mth, mv : numpy.ndarray
            The measured position (2, N), heading and speed.
        ref : tuple
            The reference's position, velocity and acceleration.

        Returns
        -------
        numpy.ndarray
        """
        n = self.n
        qpos, qvel, qacc = ref
        vmax = self.vmax
        first = None
        if not self.all_started:
            new = ~self.started if due is True else (~self.started & due)
            if new.any():
                first = new if self.first_hold_zero else None
                v_init = np.where(np.isfinite(mv), mv, 0.0)
                v_init = np.maximum(-vmax, np.minimum(vmax, v_init))
                self.tv = np.where(new, v_init, self.tv)
                self.started = self.started | new
                self.all_started = bool(self.started.all())
        v = self.tv
        if self.exact:
            # yaw through the message's quaternion (its qx = qy = 0 terms add exact
            # zeros: left out), as the tracker node reads it
            # (libm's atan2 per element: numpy's SIMD arctan2 differs from it by an
            # ulp for about 3 % of arguments)
            qz, qw = np.sin(0.5 * mth), np.cos(0.5 * mth)
            mth = _ATAN2(2.0 * (qw * qz), qw * qw - qz * qz).astype(float)
        # (otherwise the yaw is used as measured: the same angle to round-off)
        cs = self.cs
        if not self.recur or k % ANCHOR == 0:
            np.cos(mth, out=cs[0])
            np.sin(mth, out=cs[1])
        if self.comp:
            xdpos, xdvel, ud = _compensated(self.cbuf_ref, self.ccount, self.Lc, self.cterms,
                                            qpos, qvel, qacc, due, self.idx, n)
        else:
            xdpos, xdvel, ud = qpos, qvel, qacc
        sg = self.schedule.segment(k)
        if sg != self.seg:
            self.Kc = self.schedule.gain(sg)
            self.seg = sg
        # (v, w) sent; with a command every step, straight into the block
        cmd = self.cblk[j] if self.ideal_odom else np.empty((2, n))
        self.law.command(self.Kc, mpos, cs, v, xdpos, xdvel, ud, self.tdt, cmd)
        cv = cmd[0]
        v_next = cv.copy()
        cv += v
        if first is not None:                     # a first command: no ramp, the speed
            cv[first] = v[first] + v[first]
        cv *= 0.5                                 # (v + v_next) / 2
        w = cmd[1]
        # the sum is finite unless a value is nan (all are clipped)
        if math.isfinite(np.add.reduce(cmd, axis=None)):
            self.tv = v_next if due is True else np.where(due, v_next, self.tv)
        else:       # non-finite: stop, keep the compensator state
            ok = np.isfinite(w) & np.isfinite(v_next)
            self.tv = np.where(ok if due is True else ok & due, v_next, self.tv)
            cmd[...] = np.where(ok, cmd, 0.0)
        self.cmd_log = cmd if due is True else np.where(due, cmd, self.cmd_log)
        return cmd


_ATAN2 = np.frompyfunc(math.atan2, 2, 1)


def _compensated(buf: np.ndarray, count: np.ndarray, L: np.ndarray,
                 terms: list[list[tuple[int, float]]], qpos: Any, qvel: Any, qacc: Any,
                 due: Any, idx: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`control.simulation.tracker.Tracker._compensated_reference` for every case that is due.

    ``buf`` holds per case the last ``L`` pairs ``(xi*, xi*')`` (8 rows) in a ring
    indexed by the case's call ``count``; returns ``xi*`` as position and velocity
    pairs and ``u*`` (each ``(2, N)``).
    """
    rx, ry = np.broadcast_to(qpos[0], (n,)), np.broadcast_to(qpos[1], (n,))
    vx, vy = np.broadcast_to(qvel[0], (n,)), np.broadcast_to(qvel[1], (n,))
    ax, ay = qacc[0], qacc[1]
    first = count == 0
    if due is not True:
        first = first & due
    if first.any():
        init = _stack((rx, vx, ry, vy, vx, 0.0 * vx, vy, 0.0 * vy), n)
        buf[:, :, first] = init[:, first][None]
    cs = count % L
    z = buf[cs, :, idx].T                           # (8, N): xi*, xi*' at t - tau
    d = [_dot4(terms[i], z[0:4]) for i in range(4)]
    dd = [_dot4(terms[i], z[4:8]) for i in range(4)]
    xs = (rx, vx - d[0], ry, vy - d[2])
    us = (ax - dd[0] - d[1], ay - dd[2] - d[3])
    row = _stack((xs[0], xs[1], xs[2], xs[3], vx, us[0] + d[1], vy, us[1] + d[3]), n)
    if due is True:
        buf[cs, :, idx] = row.T
        count += 1
    else:
        w_idx = np.flatnonzero(due)
        buf[cs[w_idx], :, w_idx] = row[:, w_idx].T
        count[w_idx] += 1
    return (_stack((xs[0], xs[2]), n), _stack((xs[1], xs[3]), n), _stack(us, n))


def _stack(values: Any, n: int) -> np.ndarray:
    """Rows of scalars or arrays of ``n`` as one ``(len(values), n)`` array."""
    return np.stack([np.broadcast_to(v, (n,)) for v in values])


def _dot4(terms: list[tuple[int, float]], z: Any) -> Any:
    """``sum(A[i][j] * z[j] for j in range(4))`` left to right (Python's ``sum`` from 0)."""
    out = 0
    for j, a in terms:
        out = out + a * z[j]
    return out
