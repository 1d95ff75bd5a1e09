"""What Nav2's controllers run inside in the Jazzy bring-up, as numpy: path, server, smoother.

A Nav2 controller plugin (:mod:`.nav2_rpp`, :mod:`.nav2_mppi`) is called by the controller
server at ``controller_frequency`` with the robot's pose and odometry twist and a path
(``nav_msgs/Path``: poses, no timing); its ``cmd_vel`` goes through the velocity smoother
before the base.  This module is that chain, so that each port is only its plugin:

* :func:`path_from_trajectory` - a timed trajectory's positions as a planner's path (poses
  every :data:`PATH_SPACING` m, oriented along the robot's heading);
* :class:`ControlClock` - the server's 20 Hz loop on the odometry stamps;
* :class:`GoalChecker` - ``nav2_controller::SimpleGoalChecker`` with the bring-up's tolerances;
* :class:`VelocitySmoother` - ``nav2_velocity_smoother`` with the bring-up's limits;
* :class:`Route` - the plan handed to the plugin, as legs re-sent at the behaviour tree's
  replanning rate (a closed path handed whole has its goal at its start: see below);
* :class:`Nav2Server` - the :class:`~nonfragile_tracker.control.simulation.interfaces.Controller`
  that strings them together around a plugin's ``_compute``.

Sources (ros-navigation/navigation2, tag 1.3.13 = Jazzy): ``nav2_bringup/params/
nav2_params.yaml`` (controller_server, local_costmap, velocity_smoother),
``nav2_controller/src/controller_server.cpp``, ``nav2_controller/plugins/
simple_goal_checker.cpp``, ``nav2_velocity_smoother/src/velocity_smoother.cpp``,
``nav2_util/include/nav2_util/geometry_utils.hpp``, ``nav2_bt_navigator/behavior_trees/
navigate_to_pose_w_replanning_and_recovery.xml``.

How the adapter's calls become Nav2's rates (the adapter calls ``step`` at the odometry
rate): the server computes a command for each tick of its 20 Hz clock
(:class:`ControlClock`: ticks 50 ms apart on the stamps, as ``rclcpp::WallRate``; each is
computed at the last odometry message before it, from that message); between ticks the
command in force is held (the base keeps the last ``cmd_vel``).  Odometry slower than
20 Hz: one command per message (Nav2's server would compute again on the same pose).
The smoother ticks at the same 20 Hz right after the
controller (its timer's phase against the controller's is arbitrary on a robot; right after
adds no delay - the peer's best case).  With ``controller_frequency=None`` the server runs
at every odometry message instead and the periods in the formulas are the measured one
(``timing.period``) - not a bring-up setting, for comparison only.

The odometry twist: the server passes ``odom.twist`` thresholded
(``controller_server.hpp`` ``getThresholdedTwist``: ``|v| <= min_x_velocity_threshold``
0.001 and ``|w| <= min_theta_velocity_threshold`` 0.001 are 0).  The adapter gives the
measured speed ``v``; the yaw rate is the measured heading's difference over the stamps'
interval (wheel odometry's twist; the seam passes no yaw rate).
"""
from __future__ import annotations

import math
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from nonfragile_tracker.control.simulation.tracker import Command
from nonfragile_tracker.control.simulation.reference import RefSample
from nonfragile_tracker.control.simulation.timing import PeriodEstimator

__all__ = ['PATH_SPACING', 'CONTROLLER_FREQUENCY', 'COSTMAP_SIZE', 'XY_GOAL_TOLERANCE',
           'YAW_GOAL_TOLERANCE', 'MIN_X_VELOCITY_THRESHOLD', 'MIN_THETA_VELOCITY_THRESHOLD',
           'REPLAN_RATE', 'LEG_LENGTH', 'LEG_WINDOW', 'path_from_trajectory',
           'first_after_integrated_distance', 'closest_pose', 'ControlClock', 'GoalChecker',
           'VelocitySmoother', 'Route', 'Nav2Server', 'wrap']

#: Spacing (m) of the path's poses: a planner's path on the bring-up's 5 cm costmap grid
#: (nav2_params.yaml ``global_costmap.resolution: 0.05``).
PATH_SPACING = 0.05
#: nav2_params.yaml ``controller_server.controller_frequency: 20.0`` (Hz).
CONTROLLER_FREQUENCY = 20.0
#: nav2_params.yaml ``local_costmap``: ``width: 3``, ``height: 3`` (m), rolling window on the
#: robot.  No obstacles here: the costmap only bounds how much of the path a plugin sees
#: (MPPI: the square ``+-1.5`` m around the robot, so 1.5 m of a straight path ahead, not
#: ``prune_distance`` 1.7 m; RPP: 1.5 m straight-line).  Modelled as centred on the robot at
#: every tick (Nav2 moves its rolling window at ``update_frequency: 5.0``, on 5 cm cells).
COSTMAP_SIZE = 3.0
#: nav2_params.yaml ``general_goal_checker`` (SimpleGoalChecker): ``xy_goal_tolerance: 0.25``,
#: ``yaw_goal_tolerance: 0.25``, ``stateful: True``.
XY_GOAL_TOLERANCE = 0.25
YAW_GOAL_TOLERANCE = 0.25
#: nav2_params.yaml ``controller_server.min_x_velocity_threshold: 0.001``,
#: ``min_theta_velocity_threshold: 0.001``.
MIN_X_VELOCITY_THRESHOLD = 0.001
MIN_THETA_VELOCITY_THRESHOLD = 0.001
#: The bring-up's behaviour tree re-sends a plan at 1 Hz
#: (navigate_to_pose_w_replanning_and_recovery.xml: ``<RateController hz="1.0">``).
REPLAN_RATE = 1.0
#: A leg of the route (:class:`Route`) reaches at least this far along the path (m): past
#: everything a plugin looks at (MPPI ``prune_distance`` 1.7 m, RPP's costmap extent 1.5 m).
LEG_LENGTH = 2.0
#: ... and ends within this much further (m), where the straight line from its start is
#: longest.
LEG_WINDOW = 2.0


def wrap(a: Any) -> Any:
    """Angle(s) wrapped to ``[-pi, pi)`` (``angles::normalize_angle`` up to the end point)."""
    return (np.asarray(a) + math.pi) % math.tau - math.pi


#: The times an endless (analytic) trajectory's path covers in the table driver (s): longer
#: than any run of it (the figure eight runs 40 s), as a planner plans the whole route.
ANALYTIC_SPAN = (0.0, 60.0)


def table_span(trajectory: Any) -> tuple[float, float] | None:
    """:data:`ANALYTIC_SPAN` for an endless trajectory, else None (its own start and end)."""
    return ANALYTIC_SPAN if not math.isfinite(trajectory.t_end) else None


def path_from_trajectory(trajectory: Any, spacing: float = PATH_SPACING,
                         t_span: tuple[float, float] | None = None
                         ) -> tuple[np.ndarray, np.ndarray]:
    """The trajectory's positions as a planner's path: poses ``spacing`` m apart along it.

    Parameters
    ----------
    trajectory : Trajectory
        :class:`~nonfragile_tracker.control.simulation.trajectory.Trajectory` (its
        ``evaluate``), sampled over ``[t_start, t_end]``.
    spacing : float
        Arc length (m) between poses (the last pose is the trajectory's end).
    t_span : (float, float), optional
        The times to cover; needed for an analytic path (no start or end).

    Returns
    -------
    xy : numpy.ndarray
        ``(N, 2)`` positions (m).
    yaw : numpy.ndarray
        ``(N,)`` orientations (rad): the robot's heading on the trajectory (a planner that
        allows reversing orients a reversing pose backwards, as the heading is).
    """
    t0, t1 = t_span if t_span is not None else (trajectory.t_start, trajectory.t_end)
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 > t0):
        raise ValueError(f'path_from_trajectory: give t_span for a trajectory without a finite '
                         f'start and end (got {t0!r}..{t1!r})')
    n = max(int(math.ceil((t1 - t0) / 0.002)), 2) + 1
    s = trajectory.evaluate(np.linspace(t0, t1, n))
    ds = np.hypot(np.diff(s.x), np.diff(s.y))
    arc = np.concatenate(([0.0], np.cumsum(ds)))
    keep = np.concatenate(([True], ds > 1e-9))          # drop the stops (no new position)
    arc, x, y = arc[keep], s.x[keep], s.y[keep]
    yaw = np.unwrap(s.heading[keep])
    if arc[-1] <= 0.0:
        raise ValueError('path_from_trajectory: the trajectory does not move')
    q = np.arange(0.0, arc[-1], spacing)
    q = np.append(q, arc[-1]) if arc[-1] - q[-1] > 1e-6 else q
    xy = np.column_stack((np.interp(q, arc, x), np.interp(q, arc, y)))
    return xy, wrap(np.interp(q, arc, yaw))


def first_after_integrated_distance(xy: np.ndarray, lo: int, hi: int, dist: float) -> int:
    """Index of the first pose past ``dist`` m of path from pose ``lo``, else ``hi``.

    nav2_util/geometry_utils.hpp ``first_after_integrated_distance``: summing the segment
    lengths from ``lo``, the first ``i`` whose sum exceeds ``dist`` (strictly), ``hi`` (the
    end) when none does.

    Parameters
    ----------
    xy : numpy.ndarray
        ``(N, 2)`` path positions.
    lo, hi : int
        The plan ``xy[lo:hi]``.
    dist : float
        Integrated distance (m).

    Returns
    -------
    int
    """
    if hi - lo < 2:
        return hi
    cum = np.cumsum(np.hypot(*np.diff(xy[lo:hi], axis=0).T))
    i = int(np.searchsorted(cum, dist, side='right'))
    return lo + i + 1 if i < cum.size else hi


def closest_pose(xy: np.ndarray, lo: int, hi: int, x: float, y: float) -> int:
    """Index of the pose of ``xy[lo:hi]`` closest to ``(x, y)``; the last one of equals.

    nav2_util/geometry_utils.hpp ``min_by`` (``<=``: a later pose at the same distance wins),
    with ``euclidean_distance`` in the plane.

    Parameters
    ----------
    xy : numpy.ndarray
        ``(N, 2)`` path positions.
    lo, hi : int
        The range searched (``hi > lo``).
    x, y : float
        The robot's position (m).

    Returns
    -------
    int
    """
    d = np.hypot(xy[lo:hi, 0] - x, xy[lo:hi, 1] - y)
    return lo + int(d.size - 1 - np.argmin(d[::-1]))


class ControlClock:
    """A loop at ``frequency`` fed by odometry: each tick computed at the last message before it.

    ``rclcpp::WallRate`` of ``ControllerServer::computeControl``.

    Ticks are ``1 / frequency`` apart from the first message.  A message at ``t`` is the last
    one before the next tick ``T`` when the next message (one odometry period later) would
    come after it, ``T < t + odom_period``: the command is computed then, from that
    message, as the server's tick would from the latest odometry (it acts ``T - t`` early:
    no delay between the measurement and the command - the peer's best case).  Ticks
    already past are skipped (a missed tick: the rate restarts, ``loop_rate.reset()``).
    Until the odometry period is known a message is due at or after its tick.
    ``frequency=None``: due at every message.

    Parameters
    ----------
    frequency : float or None
        Hz.
    """

    def __init__(self, frequency: float | None):
        self.period_ns = None if frequency is None else int(round(1e9 / frequency))
        self.reset()

    def reset(self) -> None:
        """Start again: due at the next message."""
        self._next: int | None = None

    def due(self, t_ns: int, odom_period_ns: int | None = None) -> bool:
        """Whether the loop runs at the message stamped ``t_ns``; if so the next tick is set.

        Parameters
        ----------
        t_ns : int
            The odometry stamp (ns).
        odom_period_ns : int, optional
            The odometry period (ns), when known.

        Returns
        -------
        bool
        """
        if self.period_ns is None:
            return True
        if self._next is None:
            self._next = t_ns
        horizon = t_ns + odom_period_ns if odom_period_ns else t_ns + 1
        if self._next >= horizon:
            return False
        self._next += self.period_ns
        while self._next <= t_ns:                          # missed ticks: skipped
            self._next += self.period_ns
        return True


class GoalChecker:
    """``nav2_controller::SimpleGoalChecker`` (simple_goal_checker.cpp ``isGoalReached``).

    Within ``xy`` of the goal (squared distance ``<=`` ``xy**2``; stateful: once reached it is
    not checked again), the goal is reached when the heading is within ``yaw`` of the goal's
    (``<=``).  The bring-up's tolerances (:data:`XY_GOAL_TOLERANCE`, :data:`YAW_GOAL_TOLERANCE`).

    Parameters
    ----------
    xy, yaw : float
        Tolerances (m, rad).
    stateful : bool
        Keep the position reached once reached.
    """

    def __init__(self, xy: float = XY_GOAL_TOLERANCE, yaw: float = YAW_GOAL_TOLERANCE,
                 stateful: bool = True):
        self.xy, self.yaw, self.stateful = xy, yaw, stateful
        self.reset()

    def reset(self) -> None:
        """``SimpleGoalChecker::reset``: check the position again."""
        self.check_xy = True

    def reached(self, x: float, y: float, th: float, gx: float, gy: float, gyaw: float) -> bool:
        """Whether the pose ``(x, y, th)`` has reached the goal ``(gx, gy, gyaw)``.

        Parameters
        ----------
        x, y, th : float
            The robot's pose.
        gx, gy, gyaw : float
            The goal pose.

        Returns
        -------
        bool
        """
        if self.check_xy:
            if (x - gx) ** 2 + (y - gy) ** 2 > self.xy * self.xy:
                return False
            if self.stateful:
                self.check_xy = False
        return abs(float(wrap(gyaw - th))) <= self.yaw


class VelocitySmoother:
    """``nav2_velocity_smoother`` (velocity_smoother.cpp ``smootherTimer``), bring-up settings.

    nav2_params.yaml ``velocity_smoother``: ``smoothing_frequency: 20.0``, ``feedback:
    "OPEN_LOOP"`` (the current velocity is the last smoothed command), ``scale_velocities:
    False`` (each axis limited on its own, eta = 1), ``max_velocity: [0.5, 0.0, 2.0]``,
    ``min_velocity: [-0.5, 0.0, -2.0]``, ``max_accel: [2.5, 0.0, 3.2]``, ``max_decel:
    [-2.5, 0.0, -3.2]``, ``deadband_velocity: [0.0, 0.0, 0.0]``, ``velocity_timeout: 1.0``
    (never reached: the server sends a command every tick).  The code's own defaults differ
    in the angular velocity limit (``max_velocity`` 2.5, ``min_velocity`` -2.5 rad/s).

    Per axis (``applyConstraints``): the command clipped to ``[min, max]`` velocity; the
    change from the current velocity clipped to ``+-accel / smoothing_frequency`` when
    accelerating (``|cmd| >= |cur|`` and same sign or zero), else to ``+-|decel| /
    smoothing_frequency``.

    Parameters
    ----------
    max_velocity, min_velocity, max_accel, max_decel : (float, float)
        ``(linear x, angular z)`` of the bring-up's vectors.
    smoothing_frequency : float
        Hz; ``1 / smoothing_frequency`` is the step of the acceleration limits.
    """

    def __init__(self, max_velocity=(0.5, 2.0), min_velocity=(-0.5, -2.0),
                 max_accel=(2.5, 3.2), max_decel=(-2.5, -3.2),
                 smoothing_frequency: float = 20.0):
        self.max_velocity, self.min_velocity = max_velocity, min_velocity
        self.max_accel, self.max_decel = max_accel, max_decel
        self.smoothing_frequency = smoothing_frequency
        self.reset()

    def reset(self, v: float = 0.0, w: float = 0.0) -> None:
        """The last smoothed command (the open-loop current velocity) set to ``(v, w)``.

        Parameters
        ----------
        v, w : float
            Linear (m/s) and angular (rad/s) velocity.
        """
        self.last = (float(v), float(w))

    @staticmethod
    def limit(v_curr: float, v_cmd: float, accel: float, decel: float, dt: float) -> float:
        """One axis of ``VelocitySmoother::applyConstraints`` (eta = 1) over a step ``dt``.

        Parameters
        ----------
        v_curr, v_cmd : float
            Current and commanded velocity.
        accel, decel : float
            ``max_accel`` (> 0) and ``max_decel`` (< 0) of the axis.
        dt : float
            The step (s): ``1 / smoothing_frequency`` in Nav2.

        Returns
        -------
        float
        """
        dv = v_cmd - v_curr
        if abs(v_cmd) >= abs(v_curr) and v_curr * v_cmd >= 0.0:
            lo, hi = -accel * dt, accel * dt
        else:
            lo, hi = decel * dt, -decel * dt
        return v_curr + min(max(dv, lo), hi)

    def smooth(self, v: float, w: float, dt: float | None = None) -> tuple[float, float]:
        """The smoothed command for the command ``(v, w)``; it becomes the current velocity.

        Parameters
        ----------
        v, w : float
            The controller's command.
        dt : float, optional
            The step (s); default ``1 / smoothing_frequency`` (Nav2's).

        Returns
        -------
        (float, float)
        """
        dt = 1.0 / self.smoothing_frequency if dt is None else dt
        v = min(max(v, self.min_velocity[0]), self.max_velocity[0])
        w = min(max(w, self.min_velocity[1]), self.max_velocity[1])
        out = (self.limit(self.last[0], v, self.max_accel[0], self.max_decel[0], dt),
               self.limit(self.last[1], w, self.max_accel[1], self.max_decel[1], dt))
        self.last = out
        return out


class Route:
    """The plan a plugin is handed: legs of the path, re-sent at :data:`REPLAN_RATE`.

    A path handed whole is Nav2's ``FollowPath`` with that path: its goal is its last pose.  A
    closed or self-approaching path (a lap, a figure eight) then has its goal at (or near) its
    start: the goal checker would end the task at once, and MPPI's goal critics act whenever
    the robot is within their thresholds (1.4 m) of it.  A user hands such a route in
    pieces; here, as the bring-up's behaviour tree re-sends a plan at 1 Hz, every
    ``1 / replan_rate`` s the plugin is given a new plan (``setPlan``): from the pose it has
    reached (its own pruning) to the pose, among those ``leg_length`` to ``leg_length +
    leg_window`` m further along the path, furthest (straight line) from where the leg starts
    - the goal as far away as the route allows; the path's end once it is within
    ``leg_length + leg_window``.  A plugin looks at most 1.7 m along the path (MPPI's
    ``prune_distance``), so a leg differs from the whole path only in its goal: MPPI's goal
    critics still act when the route keeps every far point within 1.4 m (a figure eight of
    radius 1 m near its crossing; :attr:`Nav2Server.near_goal_ticks` counts those ticks).

    Parameters
    ----------
    xy : numpy.ndarray
        ``(N, 2)`` path positions.
    leg_length, leg_window : float or None
        ``leg_length`` None: the path is handed whole, once.
    replan_rate : float
        Hz.
    """

    def __init__(self, xy: np.ndarray, leg_length: float | None = LEG_LENGTH,
                 leg_window: float = LEG_WINDOW, replan_rate: float = REPLAN_RATE):
        self.xy = xy
        self.leg_length, self.leg_window = leg_length, leg_window
        self.replan_period = 1.0 / replan_rate
        self.reset()

    def reset(self) -> None:
        """Back to the start: the next call of :meth:`due` sends the first plan."""
        self._next_t: float | None = None

    def due(self, t: float) -> bool:
        """Whether a plan is sent at time ``t`` (s): the first call and every replan period.

        Parameters
        ----------
        t : float
            Time (s).

        Returns
        -------
        bool
        """
        if self._next_t is not None and (self.leg_length is None or t < self._next_t - 1e-9):
            return False
        self._next_t = t + self.replan_period
        return True

    def leg_end(self, lo: int) -> int:
        """End (exclusive) of the leg that starts at pose ``lo``.

        Parameters
        ----------
        lo : int
            First pose of the leg.

        Returns
        -------
        int
        """
        n = len(self.xy)
        if self.leg_length is None:
            return n
        cum = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(self.xy[lo:], axis=0).T))))
        if cum[-1] <= self.leg_length + self.leg_window:
            return n
        cand = np.flatnonzero((cum >= self.leg_length) & (cum <= self.leg_length
                                                          + self.leg_window))
        far = np.hypot(*(self.xy[lo + cand] - self.xy[lo]).T)
        return lo + int(cand[np.argmax(far)]) + 1


class Nav2Server:
    """A Nav2 controller plugin in its bring-up chain, as a seam ``Controller``.

    (:class:`~nonfragile_tracker.control.simulation.interfaces.Controller`.)

    Per odometry message (``step``): the odometry twist (thresholded; the yaw rate from the
    headings); when the server's clock is due (:class:`ControlClock`): a new plan if the route
    re-sends one (:class:`Route`), the goal check on the plan's last pose (:class:`GoalChecker`;
    once reached the server sends zero, as ``publishZeroVelocity``, for good), else the
    plugin's ``_compute``; the command through the :class:`VelocitySmoother`.  Between ticks
    the command in force is returned.  ``compute_times`` holds the wall time (s) of each
    ``_compute`` call (the plugin's compute per command).

    Subclasses give ``_compute(x, y, th, v, w, period) -> (v, w)``, ``_set_plan(lo, hi)``
    (the plan is ``self.xy[lo:hi]``; the plugin prunes ``self.plan_lo``) and ``_reset()``.

    Parameters
    ----------
    path_xy : array_like
        ``(N, 2)`` path positions (m), about :data:`PATH_SPACING` apart.
    path_yaw : array_like, optional
        ``(N,)`` pose orientations (rad); default along the path.
    controller_frequency : float or None
        The server's rate (Hz; None: every odometry message).
    smoother : bool
        Pass the commands through the bring-up's velocity smoother.
    leg_length, leg_window, replan_rate
        :class:`Route`.
    """

    timing: PeriodEstimator

    def __init__(self, path_xy: Any, path_yaw: Any = None, *,
                 controller_frequency: float | None = CONTROLLER_FREQUENCY,
                 smoother: bool = True, leg_length: float | None = LEG_LENGTH,
                 leg_window: float = LEG_WINDOW, replan_rate: float = REPLAN_RATE):
        xy = np.asarray(path_xy, dtype=float)
        if xy.ndim != 2 or xy.shape[1] != 2 or len(xy) < 2 or not np.all(np.isfinite(xy)):
            raise ValueError(f'path_xy must be a finite (N >= 2, 2) array, got shape {xy.shape}')
        if path_yaw is None:
            d = np.diff(xy, axis=0)
            yaw = np.arctan2(d[:, 1], d[:, 0])
            path_yaw = np.append(yaw, yaw[-1])
        self.xy = xy
        self.yaw = np.asarray(path_yaw, dtype=float)
        self.controller_frequency = controller_frequency
        self.clock = ControlClock(controller_frequency)
        self.route = Route(xy, leg_length, leg_window, replan_rate)
        self.goal_checker = GoalChecker()
        self.smoother = VelocitySmoother() if smoother else None
        self.timing = PeriodEstimator()
        self.compute_times: list[float] = []
        #: MPPI: ticks at which its goal critics acted on an intermediate leg's end (kept,
        #: as ``compute_times``, across resets)
        self.near_goal_ticks = 0
        self.reset()

    @property
    def horizon(self) -> float:
        """0: a path follower samples no reference (the seam's ``horizon``)."""
        return 0.0

    def reset(self, v: float | None = None) -> None:
        """Back to the path's start: the plan, the clock, the goal checker, the smoother.

        Parameters
        ----------
        v : float, optional
            Speed (m/s) the smoother's current velocity starts from (default 0).
        """
        self.timing.reset()
        self.clock.reset()
        self.route.reset()
        self.goal_checker.reset()
        if self.smoother is not None:
            self.smoother.reset(0.0 if v is None else v, 0.0)
        self.plan_lo, self.plan_hi = 0, len(self.xy)
        self.done = False
        self.held = Command(v=0.0, w=0.0)
        self._last_pose: tuple[int, float] | None = None
        self._w_meas = 0.0
        self._reset()

    def _odometry_twist(self, t_ns: int, th: float, measured_speed: float | None,
                        measured_rate: float | None = None) -> tuple[float, float]:
        """The thresholded odometry twist ``(v, w)`` at stamp ``t_ns``.

        The odometry's yaw rate when given (Nav2 reads ``twist.angular.z``); else the
        heading's difference over the stamp interval.
        """
        if measured_rate is not None:
            self._w_meas = float(measured_rate)
        elif self._last_pose is not None and t_ns > self._last_pose[0]:
            self._w_meas = float(wrap(th - self._last_pose[1])) / ((t_ns - self._last_pose[0])
                                                                   * 1e-9)
        self._last_pose = (t_ns, th)
        v = self.held.v if measured_speed is None else float(measured_speed)
        w = self._w_meas
        return (v if abs(v) > MIN_X_VELOCITY_THRESHOLD else 0.0,
                w if abs(w) > MIN_THETA_VELOCITY_THRESHOLD else 0.0)

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
        """The command in force after the odometry ``(x, y, th, measured_speed)`` at ``stamp``.

        Parameters
        ----------
        x, y, th : float
            Measured pose.
        ref : RefSample
            Ignored but for its time (the default stamp): a path follower.
        measured_speed : float, optional
            Measured linear speed (m/s).
        stamp : float, optional
            Measurement time (s), default ``ref.t``.
        stamp_ns : int, optional
            The same in integer ns (preferred when given).
        measured_rate : float, optional
            Measured yaw rate (rad/s, the odometry's ``twist.angular.z``).

        Returns
        -------
        Command
        """
        if stamp_ns is None:
            stamp_ns = int(round((ref.t if stamp is None else stamp) * 1e9))
        self.timing.observe_ns(stamp_ns)
        v_meas, w_meas = self._odometry_twist(stamp_ns, th, measured_speed, measured_rate)
        odom_period = self.timing.period
        if not self.clock.due(stamp_ns, None if odom_period is None
                              else int(round(odom_period * 1e9))):
            return self.held
        t = stamp_ns * 1e-9
        if self.clock.period_ns is not None:
            period = self.clock.period_ns * 1e-9
        else:
            period = self.timing.period or 1.0 / CONTROLLER_FREQUENCY
        if not self.done and self.route.due(t):
            self.plan_hi = self.route.leg_end(self.plan_lo)
            self.goal_checker.reset()        # ControllerServer::setPlannerPath resets it
            self._set_plan(self.plan_lo, self.plan_hi)
        # isGoalReached on the plan's last pose: checked on the last leg only (an earlier
        # leg's end is re-chosen every second, >= LEG_LENGTH m along the path ahead)
        g = self.plan_hi - 1
        if not self.done and g == len(self.xy) - 1:
            self.done = self.goal_checker.reached(x, y, th, self.xy[g, 0], self.xy[g, 1],
                                                  self.yaw[g])
        if self.done:
            v, w = 0.0, 0.0
        else:
            t0 = time.perf_counter()
            v, w = self._compute(x, y, th, v_meas, w_meas, period)
            self.compute_times.append(time.perf_counter() - t0)
        if self.smoother is not None:
            dt = None if self.clock.period_ns is not None else period
            v, w = self.smoother.smooth(v, w, dt)
        self.held = Command(v=float(v), w=float(w))
        return self.held

    # --- the plugin -------------------------------------------------------------------
    def _compute(self, x: float, y: float, th: float, v: float, w: float,
                 period: float) -> tuple[float, float]:   # pragma: no cover - abstract
        raise NotImplementedError

    def _set_plan(self, lo: int, hi: int) -> None:   # pragma: no cover - abstract
        raise NotImplementedError

    def _reset(self) -> None:   # pragma: no cover - abstract
        raise NotImplementedError


def factory(make: Callable[..., Nav2Server], trajectory: Any, t_span: Any = None,
            **kwargs: Any) -> Callable[..., Nav2Server]:
    """A ``tracker_config -> Controller`` factory of ``make(path_xy, path_yaw, **kwargs)``.

    The path is :func:`path_from_trajectory` of ``trajectory`` (computed once).  The tracker
    config is not read: a stock peer keeps its own limits (the adapter clamps for the base).

    Parameters
    ----------
    make : callable
        The plugin's class.
    trajectory : Trajectory
        What the path is taken from.
    t_span : (float, float), optional
        For an analytic trajectory: the times the path covers.
    **kwargs
        Passed to ``make``.

    Returns
    -------
    callable
    """
    xy, yaw = path_from_trajectory(trajectory, t_span=t_span)

    def build(tracker_config: Any = None, **_: Any) -> Nav2Server:
        return make(xy, yaw, **kwargs)

    build.path = (xy, yaw)          # type: ignore[attr-defined]
    return build
