"""Actuator dynamics of a wheeled base: first-order lag and acceleration limit, exact per step.

:func:`first_order_step` gives the speed at the end of a held command's interval and its
mean over it, in closed form (``s' = sat((c - s) / T, a_max)``: a jump, a rate limiter, a
lag, or a ramp then a decay); :func:`unicycle_arc` advances a pose along the exact arc.  The
plant and the tracker's predictor both use them, so a predictor that knows the plant
predicts it to round-off.  Plain floats; no ROS.

See doc/theory.md, section "Model" (the actuator).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .batch_data import Settings, per_value

__all__ = ['ActuatorModel', 'first_order_step', 'actuate', 'unicycle_arc', 'within',
           'VectorActuator']


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


def within(cmd: float, prev: float, step: float) -> float:
    """``cmd`` moved at most ``step`` (>= 0) away from ``prev`` (``step = 0``: ``prev``).

    The rate limit of a command against the previous one (an acceleration limit times the
    interval): the tracker's and :class:`~.wrappers.RateLimited`'s.

    Parameters
    ----------
    cmd, prev : float
        The new and the previous command.
    step : float
        The largest change allowed (>= 0).

    Returns
    -------
    float
    """
    return prev + step if cmd > prev + step else prev - step if cmd < prev - step else cmd


# ---------------------------------------------------------------------------------------------
# The vector twin of first_order_step and actuate: the same step for N cases at once
# (the batch; test/control/test_twins.py checks each pair)

def _first_order_vector(s: np.ndarray, c: np.ndarray, T: np.ndarray, amax: np.ndarray,
                        em1: np.ndarray, has_lag: np.ndarray, has_lim: np.ndarray, h: float
                        ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`control.simulation.actuator.first_order_step` element-wise: ``(end, mean)``."""
    d = c - s
    end = c.copy()
    mean = c.copy()
    if has_lag.any():
        lag = has_lag & (d != 0.0)
        e_end = c - d * (1.0 - em1)
        e_mean = c - d * T * em1 / h
        end = np.where(lag, e_end, end)
        mean = np.where(lag, e_mean, mean)
    if has_lim.any():
        ad = np.abs(d)
        ramp = has_lim & (ad > amax * T) & (d != 0.0)
        if ramp.any():
            with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
                sign = np.where(d > 0, 1.0, -1.0)
                t1 = (ad - amax * T) / amax
                full = t1 >= h
                f_end = s + sign * amax * h
                f_mean = 0.5 * (s + f_end)
                s1 = s + sign * amax * t1
                area = 0.5 * (s + s1) * t1
                rest = h - t1
                em1r = -np.expm1(-rest / T)
                p_end = np.where(T > 0.0, c + (s1 - c) * (1.0 - em1r), c)
                area = np.where(T > 0.0, area + (c * rest + (s1 - c) * T * em1r),
                                area + c * rest)
                p_mean = area / h
            end = np.where(ramp, np.where(full, f_end, p_end), end)
            mean = np.where(ramp, np.where(full, f_mean, p_mean), mean)
    return end, mean


class VectorActuator:
    """:func:`first_order_step` of ``v`` and ``w`` for every case (the twin of :func:`actuate`).

    Parameters
    ----------
    s : control.simulation.batch_data.Settings
        The per-case lags (s) and acceleration limits (m/s^2, rad/s^2; 0 = none).
    dt : float
        The plant's step (s).
    """

    def __init__(self, s: Settings, dt: float):
        self.dt = dt
        self.lag_v, self.lag_w = lag_v, lag_w = s.lag_v, s.lag_w
        self.alv, self.alw = alv, alw = s.max_linear_accel, s.max_angular_accel
        self.on = bool(np.any(lag_v) or np.any(lag_w) or np.any(alv) or np.any(alw))
        self.em1_v = per_value(lambda T: -math.expm1(-dt / T) if T > 0 else 0.0, lag_v, float)
        self.em1_w = per_value(lambda T: -math.expm1(-dt / T) if T > 0 else 0.0, lag_w, float)
        self.lagv_m, self.lagw_m, self.limv_m, self.limw_m = lag_v > 0, lag_w > 0, alv > 0, alw > 0

    def step(self, pv: np.ndarray, pw: np.ndarray, v: np.ndarray, w: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(v_end, v_mean, w_end, w_mean)`` over a step from ``(pv, pw)`` towards ``(v, w)``.

        Parameters
        ----------
        pv, pw : numpy.ndarray
            The speed (m/s) and turn rate (rad/s) at the step's start, one per case.
        v, w : numpy.ndarray
            The commands in force.

        Returns
        -------
        (numpy.ndarray, numpy.ndarray, numpy.ndarray, numpy.ndarray)
        """
        v_end, v = _first_order_vector(pv, v, self.lag_v, self.alv, self.em1_v, self.lagv_m,
                                       self.limv_m, self.dt)
        w_end, w = _first_order_vector(pw, w, self.lag_w, self.alw, self.em1_w, self.lagw_m,
                                       self.limw_m, self.dt)
        return v_end, v, w_end, w
