"""Latency predictor of the tracker: the state at the time the next command will act.

A command computed now acts ``L_c`` later and the pose it uses was measured ``L_o`` ago; the
tracker's *now* is the odometry stamp plus the assumed ``L_o`` (never a clock, so lockstep
runs stay deterministic) and the command acts from ``t_act = stamp + L_o + L_c``.
:class:`LatencyPredictor` keeps the commands sent with the times they act, integrates the
unicycle (and the actuator lag) from the measured pose through them to ``t_act``, and
extrapolates the reference there (third order); :func:`invert_lag` is the command that brings
a first-order actuator exactly to a target within one command interval.  The law evaluated
on the prediction is in :class:`.control.simulation.tracker.Tracker`.  Plain floats.

The three steps and their error terms are in the documentation: doc/theory.md, section
"Latency predictor" (#latency-predictor).
"""
from __future__ import annotations

import math
from collections import deque
from typing import NamedTuple, cast

from .actuator import ActuatorModel, actuate, unicycle_arc
from .reference import RefSample

__all__ = ['Prediction', 'LatencyPredictor', 'extrapolate_reference', 'invert_lag',
           'JERK_WINDOW', 'SUBSTEP']

#: Longest gap (s) between two reference samples used to estimate the jerk.
JERK_WINDOW = 1.0
#: Longest integration sub-step (s) of the actuator model when the tracker takes its step
#: from the odometry (an accuracy setting of the prediction, not the odometry period).
SUBSTEP = 0.01


class Prediction(NamedTuple):
    """Predicted pose and actual speeds at ``t`` (the time the next command acts)."""

    t: float
    x: float
    y: float
    th: float
    v: float
    w: float


def extrapolate_reference(ref: RefSample, t: float, jerk: tuple[float, float] = (0.0, 0.0)
                          ) -> RefSample:
    """Third-order Taylor step of a reference sample from ``ref.t`` to ``t``.

    Parameters
    ----------
    ref : RefSample
        Position, velocity and acceleration at ``ref.t``.
    t : float
        Target time (s).
    jerk : (float, float)
        Third derivative of the position (m/s^3), e.g. from two samples.

    Returns
    -------
    RefSample
        At ``t``; heading is the tangent of the extrapolated velocity (``ref.heading``
        at rest).
    """
    h = t - ref.t
    if h == 0.0:
        return ref
    jx, jy = jerk
    h2, h3 = h * h / 2.0, h * h * h / 6.0
    x = ref.x + ref.vx * h + ref.ax * h2 + jx * h3
    y = ref.y + ref.vy * h + ref.ay * h2 + jy * h3
    vx = ref.vx + ref.ax * h + jx * h2
    vy = ref.vy + ref.ay * h + jy * h2
    ax, ay = ref.ax + jx * h, ref.ay + jy * h
    heading = math.atan2(vy, vx) if vx * vx + vy * vy > 1e-24 else ref.heading
    return RefSample(t, x, y, vx, vy, ax, ay, heading)


def invert_lag(target: float, s: float, T: float, h: float) -> float:
    """Command held for ``h`` that takes ``s' = (c - s)/T`` from ``s`` exactly to ``target``.

    Parameters
    ----------
    target : float
        State wanted at the end of the interval.
    s : float
        State at its start.
    T : float
        Time constant of the first-order actuator (s; 0: no lag, the target itself).
    h : float
        Length of the interval the command is held (s).

    Returns
    -------
    float
        The command.
    """
    em1 = -math.expm1(-h / T)                    # 1 - e^{-h/T}
    return (target - s * (1.0 - em1)) / em1


class LatencyPredictor:
    """Buffer of the tracker's own commands and the prediction of the state when the next acts.

    Parameters
    ----------
    cmd_latency, odom_latency : float
        Assumed command-to-motion and odometry latencies (s, ``>= 0``).
    actuator : ActuatorModel
        Assumed actuator (time constants; acceleration limits if known).
    dt : float
        Longest integration sub-step (s) of the actuator model: the tracker's ``dt`` when
        set, else :data:`SUBSTEP`.
    max_gap : float
        A stamp more than this (s) away from the previous one restarts the model from the
        measured speed (the commands sent before the gap are forgotten).
    """

    def __init__(self, cmd_latency: float, odom_latency: float, actuator: ActuatorModel,
                 dt: float, max_gap: float = 1.0):
        self.max_gap = float(max_gap)
        self.cmd_latency = float(cmd_latency)
        self.odom_latency = float(odom_latency)
        self.actuator = actuator
        self.dt = float(dt)
        self.reset()

    @property
    def horizon(self) -> float:
        """``t_act - stamp``: assumed odometry plus command latency (s)."""
        return self.odom_latency + self.cmd_latency

    def reset(self) -> None:
        """Forget the commands sent and the reference history (re-initialise on next call)."""
        # (t_start, cv, cw), increasing t_start
        self._segs: deque[tuple[float, float, float]] = deque()
        self._anchor: tuple[float, float, float] | None = None   # (t, v, w) of the model
        self._ref_prev: RefSample | None = None
        self._ref_last: RefSample | None = None

    def seed(self, t: float, v: float, w: float) -> None:
        """Start the model at ``t`` with the actuator at ``(v, w)``, commanded ``(v, w)``.

        A predictor made while the tracker runs (online tuning) starts from the last
        command, not from a yaw rate of 0.

        Parameters
        ----------
        t : float
            Time (s) the command acts from.
        v, w : float
            Speed (m/s) and yaw rate (rad/s) commanded and reached.
        """
        self._segs = deque([(float(t), float(v), float(w))])
        self._anchor = (float(t), float(v), float(w))

    # ------------------------------------------------------------------ state
    def _run(self, x: float, y: float, th: float, v: float, w: float, cv: float, cw: float,
             t0: float, t1: float, pose: bool) -> tuple[float, float, float, float, float]:
        """Hold ``(cv, cw)`` over ``[t0, t1]``: actuator (and pose if ``pose``)."""
        span = t1 - t0
        if span <= 0.0:
            return x, y, th, v, w
        act = self.actuator
        if act.ideal:
            if pose:
                x, y, th = unicycle_arc(x, y, th, cv, cw, span)
            return x, y, th, cv, cw
        n = max(1, math.ceil(span / self.dt - 1e-6))
        h = span / n
        for _ in range(n):
            v, w, vm, wm = actuate(act, v, w, cv, cw, h)
            if pose:
                x, y, th = unicycle_arc(x, y, th, vm, wm, h)
        return x, y, th, v, w

    def predict(self, x: float, y: float, th: float, stamp: float, speed: float
                ) -> Prediction:
        """State at ``stamp + horizon`` from the pose measured at ``stamp``.

        ``speed`` (the measured speed) initialises the model on the first call.
        A stamp slightly before the last is treated as the last one; a gap of more
        than ``max_gap`` either way restarts the model.

        Parameters
        ----------
        x, y : float
            Measured position (m).
        th : float
            Measured heading (rad).
        stamp : float
            Measurement time (s).
        speed : float
            Measured speed (m/s).

        Returns
        -------
        Prediction
        """
        segs = self._segs
        if self._anchor is not None and abs(stamp - self._anchor[0]) > self.max_gap:
            self._anchor = None                  # odometry gap: restart from the measurement
        if self._anchor is None:
            segs.clear()
            segs.append((stamp, speed, 0.0))
            self._anchor = (stamp, speed, 0.0)
        t, va, wa = self._anchor
        stamp = max(stamp, t)
        while len(segs) > 1 and segs[1][0] <= stamp:       # commands acting before the stamp
            t1, (_, cv, cw) = segs[1][0], segs[0]
            _, _, _, va, wa = self._run(0.0, 0.0, 0.0, va, wa, cv, cw, t, t1, False)
            t = max(t, t1)
            segs.popleft()
        _, cv, cw = segs[0]
        _, _, _, va, wa = self._run(0.0, 0.0, 0.0, va, wa, cv, cw, t, stamp, False)
        self._anchor = (stamp, va, wa)
        t_act = stamp + self.horizon
        v, w, t = va, wa, stamp
        for i, (_, cv, cw) in enumerate(segs):
            end = min(segs[i + 1][0], t_act) if i + 1 < len(segs) else t_act
            x, y, th, v, w = self._run(x, y, th, v, w, cv, cw, t, end, True)
            t = max(t, end)
            if t >= t_act:
                break
        return Prediction(t_act, x, y, th, v, w)

    def record(self, t_act: float, cv: float, cw: float) -> None:
        """The command just sent, acting from ``t_act`` until the next one acts.

        Parameters
        ----------
        t_act : float
            Time the command acts from (s).
        cv, cw : float
            Commanded speed (m/s) and yaw rate (rad/s).
        """
        segs = self._segs
        if segs and t_act <= segs[-1][0]:
            segs[-1] = (segs[-1][0], cv, cw)     # same (or earlier) act time: replaces
        else:
            segs.append((t_act, cv, cw))

    # ------------------------------------------------------------------ reference
    def reference(self, ref: RefSample, t: float) -> RefSample:
        """The reference at ``t`` extrapolated from ``ref`` (jerk from the previous sample).

        Parameters
        ----------
        ref : RefSample
            The reference sample at hand.
        t : float
            Time to extrapolate to (s, the time the command acts).

        Returns
        -------
        RefSample
        """
        last = self._ref_last
        if last is None or ref.t > last.t:
            self._ref_prev, self._ref_last = last, ref
        prev, last = self._ref_prev, cast(RefSample, self._ref_last)   # set just above
        jerk = (0.0, 0.0)
        if prev is not None and ref.t == last.t and 0.0 < ref.t - prev.t <= JERK_WINDOW:
            gap = ref.t - prev.t
            jerk = ((ref.ax - prev.ax) / gap, (ref.ay - prev.ay) / gap)
        return extrapolate_reference(ref, t, jerk)
