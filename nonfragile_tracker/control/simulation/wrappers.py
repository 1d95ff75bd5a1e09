"""Parts any tracking law can be wrapped with: the latency predictor, the rate and speed limits.

Our law (:class:`~.tracker.Tracker`) has them built in, fused with its compensator (the lag
inversion needs the compensator's next speed); these wrappers give the same parts to any
:class:`~.interfaces.Controller` - a peer's law, a user's - without touching it:
:class:`Predicted` evaluates the law on the pose predicted at the time the command acts
(:class:`~.predictor.LatencyPredictor`, the tracker's own), :class:`RateLimited` keeps each
command within the base's acceleration limits of the previous one (:func:`~.actuator.within`,
the tracker's own rule), :class:`Clamped` within the speed limits (:func:`clamp_command`, the
rule of every ``cmd_vel``).  Timing is each law's ``timing`` (a
:class:`~.timing.PeriodEstimator`), which the wrappers pass through.

See doc/theory.md, section "Latency predictor", and doc/developing.md, section "Layout".
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

from .actuator import ActuatorModel, within
from .predictor import SUBSTEP, LatencyPredictor
from .timing import MAX_INTERVAL

if TYPE_CHECKING:    # pragma: no cover - types only
    from .interfaces import Controller
    from .tracker import Command
    from .reference import RefSample
    from .timing import PeriodEstimator

__all__ = ['Wrapper', 'Predicted', 'RateLimited', 'Clamped', 'clamp_command', 'measurement_time']


def measurement_time(ref: RefSample, stamp: float | None, stamp_ns: int | None) -> float:
    """The time (s) a step's pose was measured: ``stamp_ns``, else ``stamp``, else ``ref.t``.

    Parameters
    ----------
    ref : RefSample
        The step's reference sample (its time is the default).
    stamp : float or None
        Measurement time (s).
    stamp_ns : int or None
        The same in integer nanoseconds (preferred when given).

    Returns
    -------
    float
    """
    if stamp_ns is not None:
        return stamp_ns * 1e-9
    return ref.t if stamp is None else float(stamp)


class Wrapper:
    """The base of the wrappers: what each passes through to its ``law`` unchanged.

    The law's timing, horizon and reset; a wrapper overrides what it changes.
    """

    law: Controller

    @property
    def timing(self) -> PeriodEstimator:
        """The wrapped law's period estimate."""
        return self.law.timing

    @property
    def horizon(self) -> float:
        """The wrapped law's horizon (s)."""
        return self.law.horizon

    def reset(self, v: float | None = None) -> None:
        """Reset the wrapped law.

        Parameters
        ----------
        v : float, optional
            Speed (m/s) it starts from.
        """
        self.law.reset(v)


class Predicted(Wrapper):
    """A law evaluated where the robot will be when its command acts.

    The pose measured at ``stamp`` is replaced by the pose predicted at ``stamp +
    odom_latency + cmd_latency`` from the commands already sent through the assumed actuator
    (lags, limits), and the reference by the reference at that time; the wrapped law's
    command is recorded for the next prediction.  ``horizon`` adds the two latencies, so a
    :class:`~.follow.Follower` samples the trajectory there.

    Parameters
    ----------
    law : Controller
        The law to wrap.
    cmd_latency, odom_latency : float
        Assumed command and odometry latencies (s).
    lag_v, lag_w : float, optional
        Assumed first-order actuator time constants (s).
    max_linear_accel, max_angular_accel : float, optional
        Assumed acceleration limits (0 = none).
    """

    def __init__(self, law: Controller, cmd_latency: float, odom_latency: float = 0.0, *,
                 lag_v: float = 0.0, lag_w: float = 0.0, max_linear_accel: float = 0.0,
                 max_angular_accel: float = 0.0):
        self.law = law
        self.predictor = LatencyPredictor(
            cmd_latency, odom_latency,
            ActuatorModel(lag_v, lag_w, max_linear_accel, max_angular_accel), SUBSTEP)

    @property
    def horizon(self) -> float:
        """The predictor's horizon plus the wrapped law's (s)."""
        return self.predictor.horizon + self.law.horizon

    def reset(self, v: float | None = None) -> None:
        """Forget the commands sent and the wrapped law's state.

        Parameters
        ----------
        v : float, optional
            Speed (m/s) the wrapped law starts from.
        """
        self.predictor.reset()
        self.law.reset(v)

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
        """The wrapped law's command for the predicted pose and reference.

        Parameters
        ----------
        x, y, th : float
            Measured pose (m, m, rad).
        ref : RefSample
            The reference sample (extrapolated to the time the command acts).
        measured_speed : float, optional
            Measured speed (m/s): starts the prediction.
        stamp : float, optional
            Measurement time (s; default ``ref.t``).
        stamp_ns : int, optional
            The same in integer nanoseconds.
        measured_rate : float, optional
            Measured yaw rate (rad/s), passed on.

        Returns
        -------
        Command
        """
        pred = self.predictor
        t = measurement_time(ref, stamp, stamp_ns)
        speed = measured_speed if measured_speed is not None and math.isfinite(
            measured_speed) else 0.0
        p = pred.predict(x, y, th, t, speed)
        ahead = pred.reference(ref, p.t)
        shift = None if stamp_ns is None else stamp_ns + int(round(pred.horizon * 1e9))
        cmd = self.law.step(p.x, p.y, p.th, ahead, p.v, stamp=p.t, stamp_ns=shift,
                            measured_rate=p.w)
        pred.record(p.t, cmd.v, cmd.w)
        return cmd


class RateLimited(Wrapper):
    """A law whose commands change by at most the base's acceleration limits per interval.

    Each command is moved at most ``max_linear_accel`` (``max_angular_accel``) times the
    time since the previous command (from the stamps) away from it; the first after a reset
    from ``(measured speed, 0)`` over the measured period.  A limited command counts as
    ``saturated``.

    Parameters
    ----------
    law : Controller
        The law to wrap.
    max_linear_accel, max_angular_accel : float
        The base's limits (m/s^2, rad/s^2; 0 = that channel unlimited).
    """

    def __init__(self, law: Controller, max_linear_accel: float, max_angular_accel: float):
        self.law = law
        self.limits = (float(max_linear_accel), float(max_angular_accel))
        self._last: tuple[float, float] | None = None
        self._last_t: float | None = None

    def reset(self, v: float | None = None) -> None:
        """Forget the previous command (the next starts from the measured speed).

        Parameters
        ----------
        v : float, optional
            Speed (m/s) the wrapped law starts from.
        """
        self._last = None
        self._last_t = None
        self.law.reset(v)

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
        """The wrapped law's command, rate-limited.

        Parameters
        ----------
        x, y, th : float
            Measured pose (m, m, rad).
        ref : RefSample
            The reference sample.
        measured_speed : float, optional
            Measured speed (m/s): the previous command of the first step.
        stamp : float, optional
            Measurement time (s; default ``ref.t``).
        stamp_ns : int, optional
            The same in integer nanoseconds.
        measured_rate : float, optional
            Measured yaw rate (rad/s), passed on.

        Returns
        -------
        Command
        """
        cmd = self.law.step(x, y, th, ref, measured_speed, stamp, stamp_ns, measured_rate)
        t = measurement_time(ref, stamp, stamp_ns)
        last, last_t = self._last, self._last_t
        self._last_t = t
        if last is None or last_t is None or not 0.0 <= t - last_t <= MAX_INTERVAL:
            v0 = measured_speed if measured_speed is not None and math.isfinite(
                measured_speed) else 0.0
            last, since = (v0, 0.0), self.timing.period or 0.0
        else:
            since = t - last_t
        av, aw = self.limits
        cv = within(cmd.v, last[0], av * since) if av > 0.0 else cmd.v
        cw = within(cmd.w, last[1], aw * since) if aw > 0.0 else cmd.w
        self._last = (cv, cw)
        if cv == cmd.v and cw == cmd.w:
            return cmd
        return cmd._replace(v=cv, w=cw, saturated=True)


def clamp_command(v: float, w: float, max_linear_speed: float, max_angular_speed: float
                  ) -> tuple[float, float, bool]:
    """``(v, w)`` within the speed limits (a non-finite one: stop), and whether it changed.

    The rule of every command a tracker sends on ``cmd_vel`` (the node's, the bag replay's).

    Parameters
    ----------
    v, w : float
        Speed (m/s) and yaw rate (rad/s).
    max_linear_speed, max_angular_speed : float
        The limits (m/s, rad/s).

    Returns
    -------
    (float, float, bool)
    """
    v, w = float(v), float(w)
    if not (math.isfinite(v) and math.isfinite(w)):
        return 0.0, 0.0, True
    cv = max(-max_linear_speed, min(max_linear_speed, v))
    cw = max(-max_angular_speed, min(max_angular_speed, w))
    return cv, cw, cv != v or cw != w


class Clamped(Wrapper):
    """A law whose commands are held within the speed limits (:func:`clamp_command`).

    Our law clamps its own commands; a peer's or a user's may not: the tracker's input
    rules wrap any other law in this, so the node, its bag replay and an in-process run
    send the same clamped command.  A clamped command counts as ``saturated``.

    Parameters
    ----------
    law : Controller
        The law to wrap.
    max_linear_speed, max_angular_speed : float
        The limits (m/s, rad/s).
    """

    def __init__(self, law: Controller, max_linear_speed: float, max_angular_speed: float):
        self.law = law
        self.limits = (float(max_linear_speed), float(max_angular_speed))

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
        """The wrapped law's command, within the limits.

        Parameters
        ----------
        x, y, th : float
            Measured pose (m, m, rad).
        ref : RefSample
            The reference sample.
        measured_speed : float, optional
            Measured speed (m/s).
        stamp : float, optional
            Measurement time (s).
        stamp_ns : int, optional
            The same in integer nanoseconds.
        measured_rate : float, optional
            Measured yaw rate (rad/s).

        Returns
        -------
        Command
        """
        cmd = self.law.step(x, y, th, ref, measured_speed, stamp, stamp_ns, measured_rate)
        v, w, changed = clamp_command(cmd.v, cmd.w, *self.limits)
        return cmd._replace(v=v, w=w, saturated=True) if changed else cmd
