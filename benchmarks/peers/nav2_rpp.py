"""Nav2 Jazzy's Regulated Pure Pursuit controller, a numpy port with its code defaults.

Source: ros-navigation/navigation2 tag 1.3.13 (Jazzy), ``nav2_regulated_pure_pursuit_
controller/``: ``src/parameter_handler.cpp`` (defaults), ``src/regulated_pure_pursuit_
controller.cpp`` (``computeVelocityCommands`` and what it calls), ``include/.../regulation_
functions.hpp`` (the ``heuristics``), ``src/path_handler.cpp`` (``transformGlobalPlan``),
``src/collision_checker.cpp``.  Our own port, not a transcription; every formula names the
function it follows.

The defaults are the code's (``ParameterHandler::ParameterHandler``); the bring-up's
nav2_params.yaml runs MPPI, so it sets none of them.  Where the package README's "fully
described" example differs from the code: ``approach_velocity_scaling_dist`` (README 1.0,
code 0.6), ``use_cost_regulated_linear_velocity_scaling`` (README false, code true),
``curvature_lookahead_dist`` (README 1.0, code 0.6), ``max_robot_pose_search_dist`` (README
10.0, code half the local costmap's width: 1.5 m with the bring-up's 3 m costmap),
``cost_scaling_dist`` (README 0.3, code 0.6); the README omits ``stateful`` (code true),
``allow_reversing`` (false), ``use_cancel_deceleration`` (false).

What is off or absent because there is no costmap here (no obstacles): the cost regulation
(``heuristics::costConstraint`` returns the speed unchanged at a ``FREE_SPACE`` pose, so
``use_cost_regulated_linear_velocity_scaling: true`` changes nothing) and the collision
check (``CollisionChecker::isCollisionImminent`` finds no lethal cell; off the costmap
``inCollision`` is false).  ``use_velocity_scaled_lookahead_dist`` is false in the code
(fixed 0.6 m lookahead); :func:`lookahead_distance` implements both.  Cancel deceleration,
reversing, ``use_fixed_curvature_lookahead`` and ``interpolate_curvature_after_goal`` are
off by default and not ported.  The rest of the chain (controller server at 20 Hz, goal
checker, velocity smoother, the plan) is :mod:`.nav2_common`.

Measured with this port (ideal unicycle, 50 Hz odometry): a line to well under 1 mm, a full
circle of radius 1.5 m to 0.9 mm RMS (3.1 mm max) cross-track; on the issue's figure eight
(radius 1 m) its fixed 0.6 m lookahead cuts the lobes: 70 mm RMS, 207 mm max.  It drives
at ``desired_linear_vel`` 0.5 m/s whatever the trajectory's timing (a path follower), slower
on turns tighter than 0.9 m, and stops 0.25 m short of the end (the goal checker).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .nav2_common import (COSTMAP_SIZE, XY_GOAL_TOLERANCE, Nav2Server, closest_pose,
                          factory, first_after_integrated_distance, table_span, wrap)

__all__ = ['RPPParams', 'RegulatedPurePursuit', 'make_rpp', 'lookahead_distance',
           'curvature', 'curvature_constraint', 'approach_velocity_constraint',
           'rotate_to_heading', 'circle_segment_intersection', 'lookahead_point']


@dataclass(frozen=True)
class RPPParams:
    """RPP's parameters with the code's defaults (parameter_handler.cpp, 1.3.13)."""

    desired_linear_vel: float = 0.5
    lookahead_dist: float = 0.6
    min_lookahead_dist: float = 0.3
    max_lookahead_dist: float = 0.9
    lookahead_time: float = 1.5
    rotate_to_heading_angular_vel: float = 1.8
    use_velocity_scaled_lookahead_dist: bool = False
    min_approach_linear_velocity: float = 0.05
    approach_velocity_scaling_dist: float = 0.6
    use_regulated_linear_velocity_scaling: bool = True
    regulated_linear_scaling_min_radius: float = 0.90
    regulated_linear_scaling_min_speed: float = 0.25
    use_rotate_to_heading: bool = True
    rotate_to_heading_min_angle: float = 0.785
    max_angular_accel: float = 3.2
    #: ``costmap_size_x / 2.0`` (parameter_handler.cpp) with the bring-up's 3 m costmap.
    max_robot_pose_search_dist: float = COSTMAP_SIZE / 2.0
    stateful: bool = True


def lookahead_distance(speed: float, p: RPPParams) -> float:
    """``getLookAheadDistance``: ``lookahead_dist``, or ``|v| lookahead_time`` clamped.

    With ``use_velocity_scaled_lookahead_dist`` the distance is ``|v| * lookahead_time``
    clamped to ``[min_lookahead_dist, max_lookahead_dist]``; otherwise the fixed
    ``lookahead_dist`` (the default).

    Parameters
    ----------
    speed : float
        Odometry linear speed (m/s).
    p : RPPParams
        Parameters.

    Returns
    -------
    float
    """
    if not p.use_velocity_scaled_lookahead_dist:
        return p.lookahead_dist
    return min(max(abs(speed) * p.lookahead_time, p.min_lookahead_dist), p.max_lookahead_dist)


def curvature(px: float, py: float) -> float:
    """``calculateCurvature``: ``2 y / (x^2 + y^2)`` of the carrot in the robot frame.

    0 when the squared distance is not above 0.001 m^2.

    Parameters
    ----------
    px, py : float
        Carrot in the robot frame (m).

    Returns
    -------
    float
    """
    d2 = px * px + py * py
    return 2.0 * py / d2 if d2 > 0.001 else 0.0


def curvature_constraint(v: float, kappa: float, min_radius: float) -> float:
    """``heuristics::curvatureConstraint``: slow down on turns tighter than ``min_radius``.

    ``r = |1 / kappa|``; below ``min_radius``: ``v (1 - |r - min_radius| / min_radius)``.

    Parameters
    ----------
    v : float
        Speed to regulate (m/s).
    kappa : float
        Curvature (1/m).
    min_radius : float
        ``regulated_linear_scaling_min_radius`` (m).

    Returns
    -------
    float
    """
    radius = abs(1.0 / kappa) if kappa != 0.0 else math.inf
    if radius < min_radius:
        return v * (1.0 - abs(radius - min_radius) / min_radius)
    return v


def approach_velocity_constraint(v: float, plan_robot: np.ndarray, min_approach: float,
                                 scaling_dist: float) -> float:
    """``heuristics::approachVelocityConstraint`` (with ``approachVelocityScalingFactor``).

    When the transformed plan's length (``calculate_path_length``) is below ``scaling_dist``
    the speed is scaled by the straight-line distance to its last pose over
    ``scaling_dist``, not below ``min_approach``, and never above ``v``.

    Parameters
    ----------
    v : float
        Speed after the other regulations (m/s).
    plan_robot : numpy.ndarray
        ``(M, 2)`` transformed plan (robot frame).
    min_approach : float
        ``min_approach_linear_velocity`` (m/s).
    scaling_dist : float
        ``approach_velocity_scaling_dist`` (m).

    Returns
    -------
    float
    """
    length = float(np.sum(np.hypot(*np.diff(plan_robot, axis=0).T))) if len(plan_robot) > 1 \
        else 0.0
    scale = math.hypot(*plan_robot[-1]) / scaling_dist if length < scaling_dist else 1.0
    approach = max(v * scale, min_approach)
    return min(v, approach)


def rotate_to_heading(angle: float, w_now: float, p: RPPParams, dt: float) -> tuple[float, float]:
    """``rotateToHeading``: turn in place towards ``angle`` within the angular acceleration.

    ``w = sign(angle) rotate_to_heading_angular_vel`` clamped to ``w_now +- max_angular_accel
    dt`` (``dt``: the controller period ``1 / controller_frequency``), then to
    ``sqrt(2 max_angular_accel |angle|)`` so as to stop on the heading; ``v = 0``.

    Parameters
    ----------
    angle : float
        Angle to turn (rad; robot frame).
    w_now : float
        Odometry yaw rate (rad/s).
    p : RPPParams
        Parameters.
    dt : float
        Controller period (s).

    Returns
    -------
    (float, float)
        ``(v, w)``.
    """
    sign = 1.0 if angle > 0.0 else -1.0
    w = sign * p.rotate_to_heading_angular_vel
    w = min(max(w, w_now - p.max_angular_accel * dt), w_now + p.max_angular_accel * dt)
    stop = math.sqrt(2.0 * p.max_angular_accel * abs(angle))
    if abs(w) > stop:
        w = sign * stop
    return 0.0, w


def circle_segment_intersection(p1: np.ndarray, p2: np.ndarray, r: float) -> np.ndarray:
    """``circleSegmentIntersection``: where the segment ``p1 p2`` crosses the circle ``r``.

    The circle is centred on the robot (the origin of the robot frame); of the line's two
    crossings the one on the segment (``p1`` inside, ``p2`` outside): the quadratic's root
    signed by ``copysign(1, |p2|^2 - |p1|^2)``.

    Parameters
    ----------
    p1, p2 : numpy.ndarray
        Segment ends (robot frame, m).
    r : float
        Radius (m).

    Returns
    -------
    numpy.ndarray
        The point (m).
    """
    (x1, y1), (x2, y2) = p1, p2
    dx, dy = x2 - x1, y2 - y1
    dr2 = dx * dx + dy * dy
    D = x1 * y2 - x2 * y1
    sgn = math.copysign(1.0, (x2 * x2 + y2 * y2) - (x1 * x1 + y1 * y1))
    sq = math.sqrt(max(r * r * dr2 - D * D, 0.0))
    return np.array([(D * dy + sgn * dx * sq) / dr2, (-D * dx + sgn * dy * sq) / dr2])


def lookahead_point(plan_robot: np.ndarray, L: float) -> np.ndarray:
    """``getLookAheadPoint`` (no interpolation after the goal): the carrot at distance ``L``.

    The first pose at least ``L`` from the robot; before it, the crossing of the circle with
    the segment leading to it; none: the plan's last pose; the first pose itself if it is.

    Parameters
    ----------
    plan_robot : numpy.ndarray
        ``(M, 2)`` transformed plan (robot frame).
    L : float
        Lookahead distance (m).

    Returns
    -------
    numpy.ndarray
    """
    far = np.flatnonzero(np.hypot(plan_robot[:, 0], plan_robot[:, 1]) >= L)
    if far.size == 0:
        return plan_robot[-1].copy()
    i = int(far[0])
    if i == 0:
        return plan_robot[0].copy()
    return circle_segment_intersection(plan_robot[i - 1], plan_robot[i], L)


class RegulatedPurePursuit(Nav2Server):
    """Nav2 Jazzy RPP in the bring-up's chain (:class:`~.nav2_common.Nav2Server`).

    ``computeVelocityCommands``: the plan transformed to the robot frame and pruned
    (``PathHandler::transformGlobalPlan``), the carrot at the lookahead distance, its
    curvature; rotate to the goal heading once the carrot is within the goal tolerance
    (stateful), or to the path when the carrot is more than ``rotate_to_heading_min_angle``
    off the heading; else ``desired_linear_vel`` regulated (``applyConstraints``: curvature,
    not below ``regulated_linear_scaling_min_speed``, approach, at most ``desired_linear_vel``)
    and ``w = v * curvature``.

    Parameters
    ----------
    path_xy : array_like
        ``(N, 2)`` path positions (m).
    path_yaw : array_like, optional
        ``(N,)`` pose orientations (rad).
    params : RPPParams, optional
        Default the code's defaults.
    **server
        :class:`~.nav2_common.Nav2Server` options (``controller_frequency``, ``smoother``,
        ``leg_length``, ``leg_window``, ``replan_rate``).
    """

    def __init__(self, path_xy: Any, path_yaw: Any = None, params: RPPParams | None = None,
                 **server: Any):
        self.params = params or RPPParams()
        super().__init__(path_xy, path_yaw, **server)

    def _reset(self) -> None:
        self.has_reached_xy_tolerance = False
        self.last_carrot: np.ndarray | None = None
        self.rotating = False

    def _set_plan(self, lo: int, hi: int) -> None:
        # setPlan: a new plan resets the stateful goal-heading rotation
        self.has_reached_xy_tolerance = False
        self.plan_lo, self.plan_hi = lo, hi

    def transform_plan(self, x: float, y: float, th: float) -> np.ndarray:
        """``PathHandler::transformGlobalPlan``: the near plan in the robot frame; prunes it.

        The closest pose within ``max_robot_pose_search_dist`` of integrated path from the
        plan's start (``min_by``; not the last pose before that bound, so at least two
        remain), to the first pose further than the costmap's half extent (1.5 m) from the
        robot; the poses before the closest are erased from the plan.

        Parameters
        ----------
        x, y, th : float
            The robot's pose.

        Returns
        -------
        numpy.ndarray
            ``(M, 2)`` poses in the robot frame.
        """
        p = self.params
        lo, hi = self.plan_lo, self.plan_hi
        upper = first_after_integrated_distance(self.xy, lo, hi, p.max_robot_pose_search_dist)
        begin = closest_pose(self.xy, lo, upper, x, y)
        if upper != lo and hi - lo > 1 and begin == upper - 1:
            begin = max(upper - 2, lo)
        d = np.hypot(self.xy[begin:hi, 0] - x, self.xy[begin:hi, 1] - y)
        out = np.flatnonzero(d > COSTMAP_SIZE / 2.0)        # getCostmapMaxExtent
        end = begin + int(out[0]) if out.size else hi
        self.plan_lo = begin                                 # pruning
        self.transformed_last = end - 1                      # its last pose (index)
        c, s = math.cos(th), math.sin(th)
        dx, dy = self.xy[begin:end, 0] - x, self.xy[begin:end, 1] - y
        return np.column_stack((c * dx + s * dy, -s * dx + c * dy))

    def _compute(self, x: float, y: float, th: float, v: float, w: float,
                 period: float) -> tuple[float, float]:
        p = self.params
        plan = self.transform_plan(x, y, th)
        if len(plan) == 0:           # InvalidPath in Nav2: the server would stop the robot
            return 0.0, 0.0
        L = lookahead_distance(v, p)
        carrot = lookahead_point(plan, L)
        self.last_carrot = carrot
        kappa = curvature(*carrot)
        linear = p.desired_linear_vel
        # shouldRotateToGoalHeading: the carrot (the last pose near the end) within the goal
        # checker's xy tolerance, remembered (stateful)
        dist_to_goal = math.hypot(*carrot)
        if p.use_rotate_to_heading and p.stateful:
            if not self.has_reached_xy_tolerance and dist_to_goal < XY_GOAL_TOLERANCE:
                self.has_reached_xy_tolerance = True
            to_goal = self.has_reached_xy_tolerance
        else:
            to_goal = p.use_rotate_to_heading and dist_to_goal < XY_GOAL_TOLERANCE
        angle_to_path = math.atan2(carrot[1], carrot[0])
        if to_goal:
            self.rotating = True
            # the transformed plan's last pose's orientation, in the robot frame
            goal_yaw = float(wrap(self.yaw[self.transformed_last] - th))
            return rotate_to_heading(goal_yaw, w, p, period)
        if p.use_rotate_to_heading and abs(angle_to_path) > p.rotate_to_heading_min_angle:
            self.rotating = True
            return rotate_to_heading(angle_to_path, w, p, period)
        self.rotating = False
        # applyConstraints (cost regulation: no change on a free costmap)
        if p.use_regulated_linear_velocity_scaling:
            linear = curvature_constraint(linear, kappa, p.regulated_linear_scaling_min_radius)
        linear = max(linear, p.regulated_linear_scaling_min_speed)
        linear = approach_velocity_constraint(linear, plan, p.min_approach_linear_velocity,
                                              p.approach_velocity_scaling_dist)
        linear = min(max(abs(linear), 0.0), p.desired_linear_vel)
        return linear, linear * kappa


def make_rpp(trajectory: Any, params: RPPParams | None = None, t_span: Any = None,
             **server: Any):
    """A factory ``tracker_config -> RegulatedPurePursuit`` following ``trajectory``'s path.

    Parameters
    ----------
    trajectory : Trajectory
        The path is its positions every 5 cm (:func:`~.nav2_common.path_from_trajectory`).
    params : RPPParams, optional
        Default the code's defaults (a stock peer: change only to study it).
    t_span : (float, float), optional
        For an analytic trajectory: the times the path covers.
    **server
        :class:`~.nav2_common.Nav2Server` options.

    Returns
    -------
    callable
    """
    return factory(RegulatedPurePursuit, trajectory, t_span, params=params, **server)


def with_velocity_scaled_lookahead(params: RPPParams | None = None) -> RPPParams:
    """The parameters with ``use_velocity_scaled_lookahead_dist: true`` (a common user change).

    Parameters
    ----------
    params : RPPParams, optional
        Start from these (default the code's defaults).

    Returns
    -------
    RPPParams
    """
    return replace(params or RPPParams(), use_velocity_scaled_lookahead_dist=True)


def _stock(tracker_config: Any, *, trajectory: Any) -> RegulatedPurePursuit:
    """The table driver's factory: stock RPP (code defaults) on the trajectory's path."""
    return make_rpp(trajectory, t_span=table_span(trajectory))(tracker_config)


#: The table driver's peers (``benchmarks/peers.py``): RPP with its code defaults, followed
#: by the velocity smoother with the bring-up's (:mod:`.nav2_common`).
PEERS = {'Nav2 RPP (Jazzy)': _stock}
#: RPP follows the path, not the timed reference: judged on cross-track (its own speed).
PATH_FOLLOWERS = tuple(PEERS)
