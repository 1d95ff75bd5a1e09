"""Actuator dynamics of a wheeled base: first-order lag and acceleration limit, exact per step.

A velocity command ``c`` held over an interval of length ``h`` drives the actual speed
``s`` (linear ``v`` or angular ``w``) through

    s' = sat((c - s) / T, a_max)

(``T`` the time constant, ``a_max`` the acceleration limit).  Special cases: ``T = 0``
and no limit - ``s`` jumps to ``c`` (the ideal actuator of the paper's plant);
``T = 0`` with a limit - a rate limiter (``s`` ramps at ``a_max`` until it reaches
``c``); ``T > 0`` without a limit - the first-order lag ``s(t) = c + (s0 - c) e^{-t/T}``.
With both, ``s`` ramps at ``a_max`` while ``|c - s| > a_max T`` and then decays
exponentially.  :func:`first_order_step` returns the speed at the end of the interval
and its mean over the interval, both in closed form (no sub-stepping): the mean is what
moves the robot, so heading and travelled distance over the step are exact.

:func:`unicycle_arc` advances a pose with constant ``(v, w)`` along the exact arc.  The
plant (:class:`control.simulation.loop.UnicyclePlant`) and the tracker's predictor
(:class:`control.simulation.predictor.LatencyPredictor`) both use these functions, so a predictor
that knows the plant exactly predicts it to round-off.  Plain floats; no ROS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ['ActuatorModel', 'first_order_step', 'actuate', 'unicycle_arc']


@dataclass(frozen=True)
class ActuatorModel:
    """Time constants (s) and acceleration limits of the base; 0 means none (ideal)."""

    lag_v: float = 0.0                 # time constant of the linear speed (s)
    lag_w: float = 0.0                 # time constant of the angular speed (s)
    max_linear_accel: float = 0.0      # |v'| limit (m/s^2), 0 = unlimited
    max_angular_accel: float = 0.0     # |w'| limit (rad/s^2), 0 = unlimited

    @property
    def ideal(self) -> bool:
        """True when the actual speeds equal the commands at once (the paper's plant)."""
        return not (self.lag_v or self.lag_w or self.max_linear_accel or self.max_angular_accel)


def first_order_step(s: float, c: float, T: float, a_max: float, h: float
                     ) -> tuple[float, float]:
    """Speed after ``h`` seconds of ``s' = sat((c - s)/T, a_max)`` and its mean over them.

    Parameters
    ----------
    s : float
        Actual speed at the start of the interval.
    c : float
        Command held over the interval.
    T : float
        Time constant (s); ``0`` for none.
    a_max : float
        Acceleration limit (per s); ``0`` for none.
    h : float
        Interval length (s), ``> 0``.

    Returns
    -------
    (end, mean) : tuple of float
        Speed at ``t + h`` and ``(1/h) * integral of s over [t, t + h]`` (closed form).
    """
    d = c - s
    if d == 0.0:
        return c, c
    if a_max > 0.0 and abs(d) > a_max * T:
        # ramp at a_max until |c - s| = a_max T (T = 0: until s = c)
        sign = 1.0 if d > 0 else -1.0
        t1 = (abs(d) - a_max * T) / a_max
        if t1 >= h:
            end = s + sign * a_max * h
            return end, 0.5 * (s + end)
        s1 = s + sign * a_max * t1
        area = 0.5 * (s + s1) * t1
        rest = h - t1
        if T > 0.0:
            em1 = -math.expm1(-rest / T)
            end = c + (s1 - c) * (1.0 - em1)
            area += c * rest + (s1 - c) * T * em1
        else:
            end = c
            area += c * rest
        return end, area / h
    if T > 0.0:
        em1 = -math.expm1(-h / T)               # 1 - e^{-h/T}, accurate for small h/T
        return c - d * (1.0 - em1), c - d * T * em1 / h
    return c, c


def actuate(model: ActuatorModel, v: float, w: float, cv: float, cw: float, h: float
            ) -> tuple[float, float, float, float]:
    """Both channels over one interval: ``(v_end, w_end, v_mean, w_mean)``.

    Parameters
    ----------
    model : ActuatorModel
        Time constants and acceleration limits.
    v, w : float
        Actual speed [m/s] and angular rate [rad/s] at the start of the interval.
    cv, cw : float
        Commands held over the interval [m/s, rad/s].
    h : float
        Interval length [s], ``> 0``.

    Returns
    -------
    tuple of 4 float
        End values and means over the interval (:func:`first_order_step`).
    """
    v_end, v_mean = first_order_step(v, cv, model.lag_v, model.max_linear_accel, h)
    w_end, w_mean = first_order_step(w, cw, model.lag_w, model.max_angular_accel, h)
    return v_end, w_end, v_mean, w_mean


def unicycle_arc(x: float, y: float, th: float, v: float, w: float, h: float
                 ) -> tuple[float, float, float]:
    """Pose after ``h`` seconds at constant ``(v, w)``.

    Exact arc; ``th`` wrapped to ``[-pi, pi]``.

    Parameters
    ----------
    x, y : float
        Position [m].
    th : float
        Heading [rad].
    v : float
        Speed [m/s].
    w : float
        Angular rate [rad/s].
    h : float
        Duration [s].

    Returns
    -------
    tuple of 3 float
        ``(x, y, th)`` at the end.
    """
    half = 0.5 * w * h
    sinc = math.sin(half) / half if abs(half) > 1e-8 else 1.0 - half * half / 6.0
    mid = th + half
    arc = v * h * sinc
    return (x + arc * math.cos(mid), y + arc * math.sin(mid),
            math.remainder(th + w * h, math.tau))
