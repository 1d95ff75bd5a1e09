"""The bring-up's designed excitation: a reference that is informative and stays in a box.

``nonfragile_tracker bringup`` drives the robot closed-loop along the reference planned
here, records commands and odometry and identifies latency, lags and limits from them
(:mod:`nonfragile_tracker.control.identification.identify`).  The plan is a figure eight
of two circles touching at the start pose, sized to the box, with a staircase of speed
levels (steps in ``v`` and ``w``) and (``accel_segment``, the default) steps faster than a
base follows, so that its acceleration limits bind; :func:`plan_trial` plans the trial
after the design on the same figure eight.  Pure numpy, no ROS.

See doc/tutorial.md, section "One command (bringup)" (the phases and why this
excitation).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..simulation.trajectory import Trajectory, from_states
from .errors import IdentificationError

__all__ = ['ExcitationError', 'Extent', 'Plan', 'plan_excitation', 'plan_trial',
           'DEFAULT_BOX', 'DEFAULT_SPEED', 'DEFAULT_TURN_RATE', 'GENTLE_LINEAR_ACCEL',
           'GENTLE_ANGULAR_ACCEL', 'FAST_LINEAR_ACCEL']

#: Default box: stay within this distance (m) of the start pose.
DEFAULT_BOX = 1.0
#: Default speed limits of the bring-up (m/s, rad/s); a robot file's lower ones win.
DEFAULT_SPEED = 0.3
DEFAULT_TURN_RATE = 1.0
#: Ramps of the steps outside the acceleration segment (m/s^2, rad/s^2): gentle, so that
#: the base's limits (when no robot file gives them) do not bind.
GENTLE_LINEAR_ACCEL = 0.4
GENTLE_ANGULAR_ACCEL = 1.2
#: Ramp of the acceleration segment: faster than a base follows, so its limit binds.
FAST_LINEAR_ACCEL = 6.0
#: Speed levels of the acceleration segment's steps (fractions of the top speed), each
#: held :data:`FAST_HOLD` s, over :data:`FAST_SHARE` of the excitation: steps of 0.8 of
#: the top speed (0.19 m/s, 0.48 rad/s on the default box) in 30 ms, so that a limit below
#: about 2 m/s^2 / 5 rad/s^2 binds behind a lag up to 80 ms for several odometry periods.
FAST_LEVELS = (0.2, 1.0)
#: How long (s) each level of the acceleration segment is held.
FAST_HOLD = 1.0
#: The acceleration segment's share of the excitation's duration.
FAST_SHARE = 0.3
#: Speed levels of the staircase, as fractions of the plan's top speed.
LEVELS = (0.5, 1.0, 0.6, 0.9, 0.4, 0.8, 0.55, 1.0)
#: Fraction of the speed limits the reference uses: the rest is the feedback's.
HEADROOM = 0.8
#: Longest clothoid at a crossing of the figure eight (in radii; its turn rate reverses
#: there at the gentle angular ramp): three radii let the turns reach 1.1 rad/s at the gentle
#: 1.2 rad/s^2 (a lap's arcs, where a skid-steer's side slip grows), one radius 0.6 rad/s.
CLOTHOID_RADII = 3.0
#: Knot spacing of the reference trajectory (s).
KNOT_DT = 0.02
#: Integration step of the plan (s).
PLAN_DT = 0.002


class ExcitationError(IdentificationError):
    """No informative excitation fits the box and limits given (an ``InputError``)."""


@dataclass(frozen=True)
class Extent:
    """What a plan does: its reach, length and largest speeds (the ``--dry-run`` figures)."""

    max_distance: float        #: farthest distance of the reference from the start pose (m)
    duration: float            #: robot time (s)
    max_speed: float           #: largest ``|v|`` (m/s)
    max_turn_rate: float       #: largest ``|w|`` (rad/s)
    max_linear_accel: float    #: largest ``|dv/dt|`` of the reference (m/s^2)
    max_angular_accel: float   #: largest ``|dw/dt|`` of the reference (rad/s^2)

    def describe(self) -> str:
        """One line with the figures."""
        return (f'farthest {self.max_distance:.3f} m from the start pose, {self.duration:.1f} s, '
                f'|v| <= {self.max_speed:.3f} m/s, |w| <= {self.max_turn_rate:.3f} rad/s, '
                f'|dv/dt| <= {self.max_linear_accel:.2f} m/s^2, |dw/dt| <= '
                f'{self.max_angular_accel:.2f} rad/s^2')


@dataclass(frozen=True)
class Plan:
    """A planned reference in the start pose's frame (start at the origin, heading 0).

    Arrays are sampled every :data:`PLAN_DT` s: time ``t`` (s), pose ``x, y`` (m) and
    heading ``th`` (rad), speed ``v`` (m/s), turn rate ``w`` (rad/s), acceleration ``a``
    (m/s^2), arc length ``s`` (m) along the figure eight.  ``segments`` names its parts
    ``(name, t_start, t_end)``; ``radius`` is the figure eight's circle radius (m),
    ``transition`` the length of its clothoids (m).
    """

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    th: np.ndarray
    v: np.ndarray
    w: np.ndarray
    a: np.ndarray
    s: np.ndarray
    radius: float
    segments: tuple[tuple[str, float, float], ...]
    box_radius: float
    notes: tuple[str, ...] = field(default=())
    #: length (m) of the clothoids where the curvature flips
    transition: float = 0.0

    @property
    def duration(self) -> float:
        """Robot time of the plan (s)."""
        return float(self.t[-1] - self.t[0])

    def extent(self) -> Extent:
        """The plan's reach and largest speeds."""
        dw = np.diff(self.w) / np.diff(self.t)
        return Extent(max_distance=float(np.max(np.hypot(self.x, self.y))),
                      duration=self.duration, max_speed=float(np.max(np.abs(self.v))),
                      max_turn_rate=float(np.max(np.abs(self.w))),
                      max_linear_accel=float(np.max(np.abs(self.a))),
                      max_angular_accel=float(np.max(np.abs(dw))) if dw.size else 0.0)

    def trajectory(self, origin: tuple[float, float, float] = (0.0, 0.0, 0.0),
                   source: str = 'bring-up excitation') -> Trajectory:
        """The plan as a trajectory in the odometry frame, the start pose at ``origin``.

        Parameters
        ----------
        origin : (float, float, float)
            The start pose ``(x, y, yaw)`` in the odometry frame (m, m, rad).
        source : str
            Name for messages.

        Returns
        -------
        Trajectory
            Quintic Hermite through knots every :data:`KNOT_DT` s (position, velocity and
            acceleration exact at the knots); time 0 is the plan's start.
        """
        step = max(int(round(KNOT_DT / PLAN_DT)), 1)
        idx = np.arange(0, self.t.size, step)
        if idx[-1] != self.t.size - 1:
            idx = np.append(idx, self.t.size - 1)
        x0, y0, yaw0 = origin
        c, s = math.cos(yaw0), math.sin(yaw0)
        th = self.th[idx] + yaw0
        v, w, a = self.v[idx], self.w[idx], self.a[idx]
        vx, vy = v * np.cos(th), v * np.sin(th)
        ax = a * np.cos(th) - v * w * np.sin(th)
        ay = a * np.sin(th) + v * w * np.cos(th)
        px = x0 + c * self.x[idx] - s * self.y[idx]
        py = y0 + s * self.x[idx] + c * self.y[idx]
        t = self.t[idx] - self.t[0]
        return from_states(t, px, py, vx, vy, ax, ay, yaw=th, source=source)


def _positive(name: str, value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ExcitationError(f'{name} must be a number > 0, got {value!r}') from None
    if not (math.isfinite(out) and out > 0):
        raise ExcitationError(f'{name} must be a finite number > 0, got {value!r}')
    return out


def _nonneg(name: str, value: Any) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ExcitationError(f'{name} must be a number >= 0, got {value!r}') from None
    if not (math.isfinite(out) and out >= 0):
        raise ExcitationError(f'{name} must be a finite number >= 0, got {value!r}')
    return out


def margin_for(box_radius: float) -> float:
    """Room (m) kept between the figure eight and the box for the tracking error.

    Parameters
    ----------
    box_radius : float
        The box (m).

    Returns
    -------
    float
        ``0.05 + 0.15 box_radius``: 0.2 m of a 1 m box.
    """
    return 0.05 + 0.15 * box_radius


def _curvature(s: np.ndarray, radius: float, transition: float) -> np.ndarray:
    """Curvature of the figure eight at arc length ``s`` (clothoids at the crossings).

    Lobe ``k`` (``+1/r`` for even ``k``, ``-1/r`` for odd) spans ``[k L, (k + 1) L]``,
    ``L = 2 pi r``; around each crossing ``k L`` the curvature ramps linearly over
    ``transition`` m (centred on the crossing), so the heading change of a lobe stays
    ``2 pi`` and the figure closes.
    """
    L = 2.0 * math.pi * radius
    k = np.floor(s / L)
    sign = np.where(k % 2 == 0, 1.0, -1.0)
    kappa = sign / radius
    if transition <= 0:
        return kappa
    half = 0.5 * transition
    # distance to the nearest crossing (a crossing at j L switches from lobe j-1 to lobe j)
    near = np.round(s / L)
    d = s - near * L
    within = (np.abs(d) < half) & (near > 0)
    j = near
    after = np.where(j % 2 == 0, 1.0, -1.0)             # curvature sign of lobe j
    ramp = after * (d / half) / radius                  # -sign/r at d = -half, sign/r at +half
    return np.where(within, ramp, kappa)


def _speed_profile(levels: list[tuple[float, float, float]], dt: float) -> tuple[np.ndarray,
                                                                                np.ndarray]:
    """Speed (m/s) and acceleration (m/s^2) every ``dt`` s for ``(level, hold, ramp rate)``.

    From rest, each level is approached at its ramp rate and held for ``hold`` s once
    reached; the last level should be 0 (the stop).
    """
    v_out: list[float] = []
    a_out: list[float] = []
    v = 0.0
    for level, hold, rate in levels:
        while abs(v - level) > 1e-12:
            step = math.copysign(min(rate * dt, abs(level - v)), level - v)
            v_out.append(v)
            a_out.append(step / dt)
            v += step
        v = level
        for _ in range(int(round(hold / dt))):
            v_out.append(v)
            a_out.append(0.0)
    v_out.append(v)
    a_out.append(0.0)
    return np.array(v_out), np.array(a_out)


def _integrate(v: np.ndarray, a: np.ndarray, dt: float, radius: float, transition: float,
               s0: float = 0.0) -> tuple[np.ndarray, ...]:
    """Pose along the figure eight for the speed profile ``v`` (exact arcs per step)."""
    n = v.size
    s = s0 + np.concatenate([[0.0], np.cumsum(0.5 * (v[1:] + v[:-1]) * dt)])
    kappa = _curvature(s, radius, transition)
    w = kappa * v
    th = np.concatenate([[0.0], np.cumsum(0.5 * (w[1:] + w[:-1]) * dt)])
    # positions by the midpoint heading of each step (error O(dt^2) per unit length)
    mid = 0.5 * (th[1:] + th[:-1])
    ds = np.diff(s)
    x = np.concatenate([[0.0], np.cumsum(ds * np.cos(mid))])
    y = np.concatenate([[0.0], np.cumsum(ds * np.sin(mid))])
    t = np.arange(n) * dt
    return t, x, y, th, w, s


def plan_excitation(box_radius: float = DEFAULT_BOX, max_speed: float = DEFAULT_SPEED,
                    max_turn_rate: float = DEFAULT_TURN_RATE, *, accel_segment: bool = True,
                    odom_rate: float = 50.0, max_linear_accel: float = 0.0,
                    max_angular_accel: float = 0.0, duration: float = 55.0) -> Plan:
    """The excitation: speed and turn-rate steps on a figure eight inside the box.

    Parameters
    ----------
    box_radius : float
        Stay within this distance (m) of the start pose; the figure eight keeps
        :func:`margin_for` of it for the tracking error.
    max_speed : float
        Largest ``|v|`` (m/s).
    max_turn_rate : float
        Largest ``|w|`` (rad/s).
    accel_segment : bool
        Add a segment whose steps are faster than a base follows (its acceleration
        limits bind and are identified; the default, unless the robot file knows both);
        False: every ramp is gentle.
    odom_rate : float
        Odometry rate (Hz): each level is held for at least 25 odometry periods.
    max_linear_accel, max_angular_accel : float
        The base's known limits (m/s^2, rad/s^2; 0 = unknown): the gentle ramps never
        exceed them.
    duration : float
        Robot time to aim for (s); the plan ends at rest within a few seconds of it.

    Returns
    -------
    Plan

    Raises
    ------
    ExcitationError
        If a value is bad or the box is too small for the turn-rate limit (what to change
        is named).
    """
    box = _positive('box radius', box_radius)
    vmax = _positive('max speed', max_speed)
    wmax = _positive('max turn rate', max_turn_rate)
    rate = _positive('odometry rate', odom_rate)
    lin = _nonneg('max_linear_accel', max_linear_accel)
    ang = _nonneg('max_angular_accel', max_angular_accel)
    total = _positive('duration', duration)
    a_lin = GENTLE_LINEAR_ACCEL if lin == 0 else min(GENTLE_LINEAR_ACCEL, lin)
    a_ang = GENTLE_ANGULAR_ACCEL if ang == 0 else min(GENTLE_ANGULAR_ACCEL, ang)
    notes = []
    fast = accel_segment and (lin == 0 or ang == 0)
    if accel_segment and not fast:
        notes.append('the acceleration limits are known (robot file): no acceleration segment')
    radius = 0.5 * (box - margin_for(box))
    if radius <= 0.05:
        raise ExcitationError(f'a box of {box:g} m leaves no room for a figure eight (radius '
                              f'{radius:.3f} m after the margin for the tracking error); '
                              'give a box of at least 0.3 m')
    # the figure eight's reach grows with its clothoids: shrink it until it fits (a few %)
    for _ in range(20):
        plan = _plan(radius, box, vmax, wmax, rate, a_lin, a_ang, lin, fast, total,
                     tuple(notes))
        if plan.extent().max_distance <= box - 0.5 * margin_for(box):
            return plan
        radius *= 0.95
    raise ExcitationError(f'no figure eight fits a box of {box:g} m with |v| <= {vmax:g} m/s '
                          f'and |w| <= {wmax:g} rad/s; give a larger box')


def _plan(radius: float, box: float, vmax: float, wmax: float, rate: float, a_lin: float,
          a_ang: float, lin: float, fast: bool, total: float, notes: tuple[str, ...]) -> Plan:
    """The excitation on circles of ``radius`` (see :func:`plan_excitation`)."""
    # the top speed: within the turn-rate limit on the circles, and a clothoid at the
    # crossings (dw/dt = v^2 dkappa/ds <= a_ang) no longer than CLOTHOID_RADII radii
    v_top = HEADROOM * min(vmax, wmax * radius,
                           radius * math.sqrt(0.5 * CLOTHOID_RADII * a_ang))
    if v_top < 0.05:
        raise ExcitationError(f'with a box of {box:g} m (circles of {radius:.2f} m) and '
                              f'|w| <= {wmax:g} rad/s the top speed would be {v_top:.3f} m/s, '
                              'too slow to excite a base: give a larger box or a larger '
                              'max turn rate')
    transition = 2.0 * v_top ** 2 / (radius * a_ang)
    hold = max(2.5, 25.0 / rate)
    levels: list[tuple[float, float, float]] = []
    seg_main = total * (1.0 - FAST_SHARE if fast else 1.0)
    spent = 0.0
    i = 0
    while spent < seg_main - hold:
        lv = LEVELS[i % len(LEVELS)] * v_top
        prev = levels[-1][0] if levels else 0.0
        levels.append((lv, hold, a_lin))
        spent += hold + abs(lv - prev) / a_lin
        i += 1
    n_main = len(levels)
    if fast:
        a_fast = FAST_LINEAR_ACCEL if lin == 0 else lin
        j = 0
        while spent < total - FAST_HOLD:
            lv = FAST_LEVELS[j % len(FAST_LEVELS)] * v_top
            levels.append((lv, FAST_HOLD, a_fast))
            spent += FAST_HOLD
            j += 1
    levels.append((0.0, 0.5, a_lin))
    v, a = _speed_profile(levels, PLAN_DT)
    t, x, y, th, w, s = _integrate(v, a, PLAN_DT, radius, transition)
    segments = []
    # segment times: where each level is first reached
    t_seg = 0.0
    vv = 0.0
    for k, (lv, h, r) in enumerate(levels):
        t_end = t_seg + abs(lv - vv) / r + h
        name = ('stop' if k == len(levels) - 1 else
                f'{"fast step" if k >= n_main else "step"} v = {lv:.3f} m/s, '
                f'|w| = {lv / radius:.3f} rad/s')
        segments.append((name, t_seg, t_end))
        t_seg, vv = t_end, lv
    return Plan(t=t, x=x, y=y, th=th, v=v, w=w, a=a, s=s, radius=radius,
                segments=tuple(segments), box_radius=box, notes=notes, transition=transition)


def plan_trial(excitation: Plan, *, speed_fraction: float = 0.7, duration: float = 20.0,
               max_linear_accel: float = 0.0) -> Plan:
    """The trial after the design: on the excitation's figure eight from where it stopped.

    Parameters
    ----------
    excitation : Plan
        The excitation just driven (its end is the trial's start; same frame).
    speed_fraction : float
        The trial's cruise speed as a fraction of the excitation's top speed.
    duration : float
        Robot time (s), ramps included.
    max_linear_accel : float
        The base's linear-acceleration limit (m/s^2; 0 = unknown): the ramps never exceed it.

    Returns
    -------
    Plan
        In the excitation's frame (start pose at the origin, heading 0).
    """
    frac = _positive('speed fraction', speed_fraction)
    total = _positive('duration', duration)
    lin = _nonneg('max_linear_accel', max_linear_accel)
    a_lin = GENTLE_LINEAR_ACCEL if lin == 0 else min(GENTLE_LINEAR_ACCEL, lin)
    v_top = float(np.max(excitation.v)) * min(frac, 1.0)
    ramp = v_top / a_lin
    hold = max(total - 2.0 * ramp, 1.0)
    v, a = _speed_profile([(v_top, hold, a_lin), (0.0, 0.5, a_lin)], PLAN_DT)
    radius, transition = excitation.radius, excitation.transition
    s0 = float(excitation.s[-1])
    _, x2, y2, th2, w, s = _integrate(v, a, PLAN_DT, radius, transition, s0=s0)
    x0, y0, th0 = float(excitation.x[-1]), float(excitation.y[-1]), float(excitation.th[-1])
    x = x0 + np.cos(th0) * x2 - np.sin(th0) * y2
    y = y0 + np.sin(th0) * x2 + np.cos(th0) * y2
    t = np.arange(v.size) * PLAN_DT
    return Plan(t=t, x=x, y=y, th=th0 + th2, v=v, w=w, a=a, s=s, radius=radius,
                segments=((f'trial v = {v_top:.3f} m/s', 0.0, float(t[-1])),),
                box_radius=excitation.box_radius, transition=transition)
