"""Replanning while driving: a new untimed path spliced onto the current motion.

A planner republishes its plan (untimed poses) every second or so; starting a new run from
rest on each would stop the robot at every plan.  :func:`splice_path` continues the motion
on the new plan instead: cut at its point nearest the reference followed now, timed from
the current reference speed, marked :attr:`~.trajectory.Trajectory.spliced` so that a
:class:`~.follow.Follower` takes it with :meth:`~.follow.Follower.splice` (no reset, no
re-base); :func:`blend_into` is the transition to it, :class:`OverrideWatch` and
:func:`reanchor` handle commands slowed downstream.  The tracker's input rules apply it
(parameter ``replan``).  No ROS import.

See doc/nav2.md, sections "A plan replaced every second" and "Slowed or stopped downstream".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .errors import TrajectoryError
from .trajectory import MIN_POINTS, Trajectory, from_states, from_waypoints, time_law

__all__ = ['SEARCH_DISTANCE', 'MIN_GAP', 'MAX_TURN', 'BLEND', 'BLEND_STEP', 'Nearest',
           'nearest_point', 'splice_path', 'blend_into', 'OVERRIDE_TIME', 'RECENT',
           'OverrideWatch', 'reanchor']

#: Default arc length (m) from a plan's start within which its nearest point is looked for
#: (Nav2's controllers: ``max_robot_pose_search_dist``, by default the local costmap's half
#: width); a lap that comes back near its start is not matched at its end.
SEARCH_DISTANCE = 2.0
#: Largest angle (rad) between the motion's direction and a new plan's first chord for the
#: splice to keep the motion's direction (:func:`splice_path`).
MAX_TURN = math.radians(30.0)
#: Default duration (s) of the transition from the followed trajectory to a new plan
#: (:func:`blend_into`): shorter than a planner's period (0.5-2 s).
BLEND = 0.5
#: Sampling step (s) of the transition.
BLEND_STEP = 0.02
#: A plan point closer than this (m) to the splice point is dropped (no millimetre chord).
MIN_GAP = 1e-3


@dataclass(frozen=True)
class Nearest:
    """The point of a polyline nearest a query point.

    ``segment`` is the index of the segment ``[segment, segment + 1]``, ``fraction`` the
    place on it in ``[0, 1]``, ``s`` the arc length from the polyline's start (m),
    ``distance`` from the query point (m), ``x``, ``y`` the point (m).
    """

    segment: int
    fraction: float
    s: float
    distance: float
    x: float
    y: float


def nearest_point(px: Any, py: Any, x: float, y: float, *,
                  search_distance: float = SEARCH_DISTANCE) -> Nearest:
    """The point of the polyline ``(px, py)`` nearest ``(x, y)``, searched near its start.

    Parameters
    ----------
    px, py : array_like
        The polyline's points (m), at least 2, consecutive duplicates removed.
    x, y : float
        The query point (m).
    search_distance : float
        Only segments that start within this arc length (m) of the first point are searched.

    Returns
    -------
    Nearest
    """
    px = np.asarray(px, float)
    py = np.asarray(py, float)
    dx, dy = np.diff(px), np.diff(py)
    length = np.hypot(dx, dy)
    s = np.concatenate([[0.0], np.cumsum(length)])
    n = int(np.searchsorted(s[:-1], search_distance, side='right'))
    n = max(n, 1)
    u = ((x - px[:n]) * dx[:n] + (y - py[:n]) * dy[:n]) / np.maximum(length[:n] ** 2, 1e-300)
    u = np.clip(u, 0.0, 1.0)
    qx, qy = px[:n] + u * dx[:n], py[:n] + u * dy[:n]
    d = np.hypot(qx - x, qy - y)
    i = int(np.argmin(d))
    return Nearest(i, float(u[i]), float(s[i] + u[i] * length[i]), float(d[i]), float(qx[i]),
                   float(qy[i]))


def splice_path(px: Any, py: Any, pyaw: Any, *, anchor: tuple[float, float], t0: float,
                start_speed: float, cruise_speed: float, max_accel: float,
                search_distance: float = SEARCH_DISTANCE,
                direction: tuple[float, float] | None = None,
                current: Trajectory | None = None, blend: float = BLEND,
                source: str = 'path') -> tuple[Trajectory, Nearest]:
    """The trajectory that continues a motion on a new untimed path (module docstring).

    Parameters
    ----------
    px, py, pyaw : array_like
        The new path's points (m) and headings (rad; they say forwards or backwards).
    anchor : (float, float)
        Where the motion is now (m): the reference point followed (or the robot).
    t0 : float
        Trajectory time (s) of the splice: the result starts there.
    start_speed : float
        Speed (m/s, >= 0) the motion has there: the time law starts at it.
    cruise_speed, max_accel : float
        The time law of untimed paths (m/s, m/s^2).
    search_distance : float
        Arc length (m) from the path's start within which the nearest point is looked for.
    direction : (float, float), optional
        The motion's direction of travel now (the reference velocity): the first velocity
        points along it when it is within :data:`MAX_TURN` of the path's first chord (the
        chord of a curve is off its tangent by half its turn: a velocity along it would make
        the spline swerve); default, or beyond that, along the chord.
    current : Trajectory, optional
        The trajectory followed until now: the result moves from it to the new plan over
        ``blend`` seconds (:func:`blend_into`), so position, velocity and acceleration are
        continuous; default none (the new plan from ``t0`` on).
    blend : float
        Duration (s) of that transition (0: none).
    source : str
        Where the path came from (for messages).

    Returns
    -------
    (Trajectory, Nearest)
        The trajectory (from ``t0``, marked ``spliced``) and the point it starts from.

    Raises
    ------
    TrajectoryError
        Fewer than 2 distinct points, or fewer than 2 left after the splice point (the
        motion is past the plan's end).
    """
    px = np.asarray(px, float)
    py = np.asarray(py, float)
    pyaw = np.asarray(pyaw, float)
    keep = np.concatenate([[True], np.hypot(np.diff(px), np.diff(py)) > 0])
    px, py, pyaw = px[keep], py[keep], pyaw[keep]
    if px.size < MIN_POINTS:
        raise TrajectoryError(f'{source}: {px.size} distinct point(s); a trajectory needs '
                              f'at least {MIN_POINTS}')
    if not (math.isfinite(t0) and math.isfinite(start_speed) and start_speed >= 0):
        raise TrajectoryError(f'{source}: splice at t0 = {t0!r} s, start_speed = '
                              f'{start_speed!r} m/s: both must be finite, the speed >= 0')
    near = nearest_point(px, py, anchor[0], anchor[1], search_distance=search_distance)
    i = near.segment
    rest = slice(i + 1, None)
    gap = np.hypot(px[rest] - near.x, py[rest] - near.y)
    first = i + 1 + int(np.argmax(gap >= MIN_GAP)) if np.any(gap >= MIN_GAP) else px.size
    x = np.concatenate([[near.x], px[first:]])
    y = np.concatenate([[near.y], py[first:]])
    yaw = np.concatenate([[pyaw[i]], pyaw[first:]])
    if x.size < MIN_POINTS:
        raise TrajectoryError(f'{source}: the motion at ({anchor[0]:.3f}, {anchor[1]:.3f}) m '
                              'is at or past the plan\'s end: nothing left to splice')
    t = time_law(x, y, cruise_speed, max_accel, source=source, start_speed=start_speed)
    chord = np.array([x[1] - x[0], y[1] - y[0]])
    unit = chord / float(np.hypot(*chord))
    if direction is not None and math.hypot(*direction) > 0:
        d = np.asarray(direction, float) / math.hypot(*direction)
        if float(d @ unit) >= math.cos(MAX_TURN):
            unit = d
    v0 = start_speed * unit
    traj = from_waypoints(t0 + t, x, y, yaw=yaw, source=f'{source} (spliced)',
                          start_velocity=(float(v0[0]), float(v0[1])))
    if current is not None and blend > 0 and traj.t_end > t0 + blend:
        traj = blend_into(current, traj, t0, blend)
    traj.spliced = True
    return traj, near


def blend_into(current: Trajectory, new: Trajectory, t0: float, duration: float,
               step: float = BLEND_STEP) -> Trajectory:
    """From ``current`` to ``new`` over ``[t0, t0 + duration]``, C2 at both ends.

    ``p = c + sigma (n - c)`` with the quintic smoothstep ``sigma(u) = 10 u^3 - 15 u^4 +
    6 u^5`` of ``u = (t - t0) / duration`` (zero first and second derivative at both ends),
    its velocity and acceleration by the product rule, sampled every ``step`` seconds; from
    ``t0 + duration`` on ``new`` itself (its knots).  The quintic Hermite form through these
    states (:func:`~.trajectory.from_states`) reproduces ``new``'s cubic pieces exactly.  The
    transition adds ``sigma'' (n - c) / duration^2`` to the acceleration: for plans a few
    millimetres apart, a few hundredths of a m/s^2.

    Parameters
    ----------
    current, new : Trajectory
        The trajectory followed until ``t0`` and the one from ``t0 + duration`` on.
    t0 : float
        Start of the transition (trajectory time, s).
    duration : float
        Its length (s), > 0.
    step : float, optional
        Sampling step of the transition (s).

    Returns
    -------
    Trajectory
    """
    m = max(int(math.ceil(duration / step)), 2)
    tg = t0 + np.linspace(0.0, duration, m + 1)
    u = (tg - t0) / duration
    sg = u ** 3 * (10 - 15 * u + 6 * u * u)
    d1 = 30 * u * u * (1 - u) ** 2 / duration
    d2 = 60 * u * (1 - u) * (1 - 2 * u) / duration ** 2
    c, n = current.evaluate(tg), new.evaluate(tg)
    pos = [c.x + sg * (n.x - c.x), c.y + sg * (n.y - c.y)]
    vel = [c.vx + sg * (n.vx - c.vx) + d1 * (n.x - c.x),
           c.vy + sg * (n.vy - c.vy) + d1 * (n.y - c.y)]
    acc = [c.ax + sg * (n.ax - c.ax) + 2 * d1 * (n.vx - c.vx) + d2 * (n.x - c.x),
           c.ay + sg * (n.ay - c.ay) + 2 * d1 * (n.vy - c.vy) + d2 * (n.y - c.y)]
    later = new.knots[new.knots > tg[-1] + 1e-9]
    a = new.evaluate(later)
    return from_states(np.concatenate([tg, later]), np.concatenate([pos[0], a.x]),
                       np.concatenate([pos[1], a.y]), np.concatenate([vel[0], a.vx]),
                       np.concatenate([vel[1], a.vy]), np.concatenate([acc[0], a.ax]),
                       np.concatenate([acc[1], a.ay]),
                       yaw=np.concatenate([n.heading, a.heading]), source=new.source)


#: Default time (s) a shortfall of the measured speed must last before the commands count as
#: overridden downstream (:class:`OverrideWatch`), and between two re-anchorings while it
#: lasts.
OVERRIDE_TIME = 0.3
#: Trajectory time (s) before now whose path is searched for the robot when the reference is
#: re-anchored at it (:func:`reanchor`).
RECENT = 2.0


class OverrideWatch:
    """Commands overridden downstream: a collision monitor (or a stop) scaling or zeroing them.

    Between the tracker and the base Nav2 puts ``collision_monitor`` (``cmd_vel_nav`` ->
    ``cmd_vel``), which slows or stops the robot near obstacles.  A timed tracker that did not
    notice would keep its reference running and its compensator integrating the growing
    error (wind-up) and would leap ahead when released.  The watch compares the measured
    speed with the last command sent: a shortfall above ``tolerance`` (m/s) for ``hold_time``
    seconds is an override (:meth:`update` says ``held``, then ``anchor`` every
    ``hold_time`` while it lasts); it ends (``released``) once the measured speed is back
    within the tolerance and at least half the command.  The input rules then re-anchor
    the reference at the robot at the measured speed and restart the compensator from it
    (:func:`reanchor`): nothing winds up, and after the release the robot accelerates from
    where it is at ``max_accel``.

    Parameters
    ----------
    tolerance : float
        Shortfall (m/s) of the measured speed below the command that counts; 0 = off.
    hold_time : float
        How long (s) it must last.
    """

    def __init__(self, tolerance: float, hold_time: float = OVERRIDE_TIME):
        if not (math.isfinite(tolerance) and tolerance >= 0):
            raise TrajectoryError(f'override_tolerance must be a finite number >= 0 m/s, got '
                                  f'{tolerance!r}')
        if not (math.isfinite(hold_time) and hold_time > 0):
            raise TrajectoryError(f'override_time must be a finite number > 0 s, got '
                                  f'{hold_time!r}')
        self.tolerance = float(tolerance)
        self.hold_time = float(hold_time)
        self.overridden = False
        self.count = 0                  # overrides noticed
        self._since: float | None = None
        self._anchored = -math.inf

    def reset(self) -> None:
        """Forget the shortfall (a new run)."""
        self.overridden = False
        self._since = None

    def update(self, t: float, commanded: float, measured: float) -> str | None:
        """One odometry: ``held``, ``anchor``, ``released`` or None.

        Parameters
        ----------
        t : float
            Its time (s).
        commanded : float
            The last command sent before it (m/s).
        measured : float
            Its measured speed (m/s).

        Returns
        -------
        str or None
        """
        if not self.tolerance:
            return None
        short = abs(commanded) - abs(measured) > self.tolerance
        if short:
            if self._since is None:
                self._since = t
            if not self.overridden and t - self._since >= self.hold_time - 1e-9:
                self.overridden = True
                self.count += 1
                self._anchored = t
                return 'held'
            if self.overridden and t - self._anchored >= self.hold_time - 1e-9:
                self._anchored = t
                return 'anchor'
            return None
        self._since = None
        if self.overridden and abs(measured) >= 0.5 * abs(commanded):
            self.overridden = False
            return 'released'
        return None


def reanchor(current: Trajectory, t: float, x: float, y: float, speed: float, *,
             cruise_speed: float, max_accel: float) -> Trajectory:
    """``current``'s path from the robot on, timed from its measured speed (an override).

    The path is that of ``current``'s knots from :data:`RECENT` s before ``t`` on (the robot
    held back is behind the reference); it is cut at the robot's nearest point and timed
    from ``speed`` (:func:`splice_path`, no transition: the reference moves back to the
    robot).

    Parameters
    ----------
    current : Trajectory
        The trajectory followed (not analytic).
    t : float
        Trajectory time now (s).
    x, y : float
        The robot (m).
    speed : float
        Its measured speed (m/s).
    cruise_speed, max_accel : float
        The time law (m/s, m/s^2).

    Returns
    -------
    Trajectory
        Spliced, from ``t``.
    """
    k = current.knots
    keep = k >= t - RECENT
    keep[max(int(np.argmax(keep)) - 1, 0)] = True
    s = current.evaluate(k[keep])
    traj, _ = splice_path(s.x, s.y, s.heading, anchor=(x, y), t0=t, start_speed=abs(speed),
                          cruise_speed=cruise_speed, max_accel=max_accel,
                          search_distance=2 * RECENT * max(cruise_speed, abs(speed)) + 0.5,
                          source=current.source.split(' (')[0])
    return traj
