"""Nav2 Jazzy's MPPI controller (``nav2_mppi_controller``), a numpy port vectorised over the batch.

Source: ros-navigation/navigation2 tag 1.3.13 (Jazzy), ``nav2_mppi_controller/``:
``src/optimizer.cpp`` (``getParams``, ``setOffset``, ``evalControl``, ``prepare``,
``generateNoisedTrajectories``, ``integrateStateVelocities``, ``updateControlSequence``,
``applyControlSequenceConstraints``, ``shiftControlSequence``,
``getControlFromSequenceAsTwist``), ``include/.../motion_models.hpp`` (``MotionModel::
predict``, DiffDrive), ``src/noise_generator.cpp``, ``include/.../tools/utils.hpp``
(``savitskyGolayFilter``, ``findPathFurthestReachedPoint``, ``findClosestPathPt``,
``posePointAngle``, ``withinPositionGoalTolerance``, ``normalize_angles``),
``src/path_handler.cpp`` (``transformPath``), ``src/critics/*.cpp``; the settings are
``nav2_bringup/params/nav2_params.yaml`` (``controller_server.FollowPath``).  Our own port,
not a transcription; every formula names the function it follows.  The Rolling variant's
model delay: branch ``main`` (Rolling), commit 374cd2556 "[mppi] Add per-axis delay
compensation with cmd-history replay (#6154)": parameters ``model_delay_vx``,
``model_delay_vy``, ``model_delay_wz`` (``src/optimizer.cpp`` ``getParams``), applied in
``include/.../motion_models.hpp`` ``MotionModel::predict`` / ``applyDelayShift`` with the
history ``pushCommandHistory`` fills in ``getControlFromSequenceAsTwist``.

The bring-up's settings (nav2_params.yaml, Jazzy) and where the code's defaults differ:
``time_steps`` 56, ``model_dt`` 0.05, ``batch_size`` 2000 (code 1000), ``iteration_count`` 1,
``temperature`` 0.3, ``gamma`` 0.015, ``vx_std`` 0.2, ``wz_std`` 0.4, ``vx_max`` 0.5,
``vx_min`` -0.35, ``vy_max`` 0.5, ``wz_max`` 1.9, ``ax_max`` 3.0, ``ax_min`` -3.0, ``az_max``
3.5, ``prune_distance`` 1.7 (code 1.5), ``regenerate_noises`` true (code false),
``motion_model`` DiffDrive; critics ``[ConstraintCritic, CostCritic, GoalCritic,
GoalAngleCritic, PathAlignCritic, PathFollowCritic, PathAngleCritic, PreferForwardCritic]``
with: Constraint weight 4.0; Goal weight 5.0, threshold 1.4; GoalAngle weight 3.0, threshold
0.5; PreferForward weight 5.0, threshold 0.5; PathAlign weight 14.0 (code 10.0),
``max_path_occupancy_ratio`` 0.05 (code 0.07), ``trajectory_point_step`` 4,
threshold 0.5, ``offset_from_furthest`` 20, ``use_path_orientations`` false; PathFollow weight
5.0, ``offset_from_furthest`` 5 (code 6), threshold 1.4; PathAngle weight 2.0 (code 2.2),
``offset_from_furthest`` 4, threshold 0.5, ``max_angle_to_furthest`` 1.0 (code 0.785398),
mode 0 (forward preference); every ``cost_power`` 1.  ConstraintCritic reads the parent's
``vy_max`` (0.5 in the bring-up, although DiffDrive has no vy): its speed bounds are
``sqrt(vx_max^2 + vy_max^2)`` = 0.707 and ``-sqrt(vx_min^2 + vy_max^2)`` = -0.610 m/s.

Dropped: CostCritic (cost_weight 3.81) - there is no costmap here, and on a free costmap its
cost is 0 for every trajectory inside the 3 m window (``CostCritic::score`` skips free cells;
``fail_flag`` is never set, so ``fallback`` never resets the optimizer).  Every path point is
valid (``findPathCosts`` on a free costmap), so PathAlign's occupancy test always passes.
The visualisation and speed-limit topics are not ported.  Arithmetic in float64 (Nav2:
float32); the noise is numpy's normal generator, seeded (Nav2: xtensor's, unseeded).

Variants (:func:`make_mppi`): ``'stock'``; ``'open_loop'`` (``open_loop: true``: the rollouts
start from the last command instead of the odometry twist, ``Optimizer::prepare``);
``'rolling_delay'`` (labelled Rolling: Jazzy's optimizer with Rolling's ``model_delay_vx`` =
``model_delay_wz`` = the latency; the rest of Rolling's optimizer - its one-period
prediction of the initial speed, inter-iteration constraints, filter inside the update - is
not ported).

Behaviour worth knowing before reading a table (measured with this port, ideal unicycle or
the issue's base, 50 Hz odometry): it follows a line to 2 mm and half circles of radius 1.5,
1.0, 0.75, 0.5 m to 6, 5, 9, 30 mm RMS cross-track.  On the issue's figure eight (radius
1 m, one lap; every point within 1.12 m of the crossing) it does not get going: the plan's
end is always within GoalCritic's 1.4 m (PathFollowCritic is then off and GoalCritic pulls
across), and with the goal thresholds set to 0 (a diagnostic, not a variant) it stalls in
the first lobe - PathAlignCritic scores only rollouts that reach ``offset_from_furthest``
(20) path points, so stopping escapes its cost.  Both are Nav2's design, not this port's.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .nav2_common import (COSTMAP_SIZE, Nav2Server, closest_pose, factory,
                          first_after_integrated_distance, table_span, wrap)

__all__ = ['MPPIParams', 'MPPI', 'make_mppi', 'MODES', 'VARIANTS', 'PEERS', 'LABELS',
           'compute_per_command',
           'SG_COEFFICIENTS', 'predict',
           'integrate', 'rollout', 'softmax_weights', 'savitzky_golay',
           'furthest_reached_path_point', 'closest_path_points', 'constraint_cost',
           'goal_cost', 'goal_angle_cost', 'prefer_forward_cost', 'path_follow_cost',
           'path_angle_cost', 'path_align_cost', 'delay_offset', 'apply_delay_shift']

#: Savitzky-Golay, quadratic, 9 points (utils.hpp ``savitskyGolayFilter``).
SG_COEFFICIENTS = np.array([-21.0, 14.0, 39.0, 54.0, 59.0, 54.0, 39.0, 14.0, -21.0]) / 231.0
MODES = ('stock', 'open_loop', 'rolling_delay')


@dataclass(frozen=True)
class MPPIParams:
    """The bring-up's MPPI settings (nav2_params.yaml, Jazzy; code defaults in the module doc)."""

    model_dt: float = 0.05
    time_steps: int = 56
    batch_size: int = 2000
    iteration_count: int = 1
    temperature: float = 0.3
    gamma: float = 0.015
    vx_max: float = 0.5
    vx_min: float = -0.35
    vy_max: float = 0.5           # read by ConstraintCritic only (DiffDrive)
    wz_max: float = 1.9
    ax_max: float = 3.0
    ax_min: float = -3.0
    az_max: float = 3.5
    vx_std: float = 0.2
    wz_std: float = 0.4
    prune_distance: float = 1.7
    #: path_handler.cpp ``getMaxCostmapDist``: half the local costmap's size (3 m).
    max_robot_pose_search_dist: float = COSTMAP_SIZE / 2.0
    open_loop: bool = False
    regenerate_noises: bool = True
    #: Rolling only (#6154): input delay (s) of the rollouts, per axis; 0 in Jazzy.
    model_delay_vx: float = 0.0
    model_delay_wz: float = 0.0
    # critics (cost_power 1 throughout)
    constraint_weight: float = 4.0
    goal_weight: float = 5.0
    goal_threshold: float = 1.4
    goal_angle_weight: float = 3.0
    goal_angle_threshold: float = 0.5
    prefer_forward_weight: float = 5.0
    prefer_forward_threshold: float = 0.5
    path_align_weight: float = 14.0
    path_align_occupancy_ratio: float = 0.05
    path_align_point_step: int = 4
    path_align_threshold: float = 0.5
    path_align_offset: int = 20
    path_follow_weight: float = 5.0
    path_follow_offset: int = 5
    path_follow_threshold: float = 1.4
    path_angle_weight: float = 2.0
    path_angle_offset: int = 4
    path_angle_threshold: float = 0.5
    path_angle_max_angle: float = 1.0


# ----------------------------------------------------------------------------- the model

def predict(v0: float, w0: float, cvx: np.ndarray, cwz: np.ndarray, p: MPPIParams
            ) -> tuple[np.ndarray, np.ndarray]:
    """``MotionModel::predict`` (DiffDrive): the velocities the controls give, in place.

    Column 0 is the initial speed (``updateInitialStateVelocities``); column ``j`` is the
    control ``j - 1`` clamped to the acceleration limits from column ``j - 1`` (``vx``:
    ``[v + ax_min dt, v + ax_max dt]`` when ``v > 0``, ``[v - ax_max dt, v - ax_min dt]``
    otherwise; ``wz``: ``w +- az_max dt``).  The clamped controls are written back into
    ``cvx``, ``cwz`` (columns ``0..T-2``; the last is left as sampled), as Nav2 does.

    Parameters
    ----------
    v0, w0 : float
        Initial linear and angular speed.
    cvx, cwz : numpy.ndarray
        ``(B, T)`` sampled controls (modified).
    p : MPPIParams
        Settings (``model_dt``, accelerations).

    Returns
    -------
    vx, wz : numpy.ndarray
        ``(B, T)`` velocities.
    """
    B, T = cvx.shape
    dt = p.model_dt
    dmax, dmin, dw = dt * p.ax_max, dt * p.ax_min, dt * p.az_max
    # time-major copies: each step is a contiguous row (the same arithmetic, faster)
    cv, cw = np.ascontiguousarray(cvx.T), np.ascontiguousarray(cwz.T)
    vx = np.empty((T, B))
    wz = np.empty((T, B))
    vx[0] = v0
    wz[0] = w0
    for j in range(1, T):
        last = vx[j - 1]
        pos = last > 0
        lo = last + np.where(pos, dmin, -dmax)
        hi = last + np.where(pos, dmax, -dmin)
        np.minimum(np.maximum(cv[j - 1], lo), hi, out=vx[j])
        np.minimum(np.maximum(cw[j - 1], wz[j - 1] - dw), wz[j - 1] + dw, out=wz[j])
    cvx[:, :T - 1] = vx[1:].T
    cwz[:, :T - 1] = wz[1:].T
    return vx.T.copy(), wz.T.copy()


def delay_offset(delay: float, dt: float) -> int:
    """Rolling ``MotionModel::offsetSteps``: a delay in whole model steps, to the nearest.

    Parameters
    ----------
    delay, dt : float
        Delay and ``model_dt`` (s).

    Returns
    -------
    int
    """
    return int(math.floor(delay / dt + 0.5)) if delay > 0.0 and dt > 0.0 else 0


def apply_delay_shift(vel: np.ndarray, offset: int, history: np.ndarray) -> None:
    """Rolling ``MotionModel::applyDelayShift`` on one axis, in place.

    The velocities from column 1 move right by ``offset - 1`` columns (column ``k`` to
    ``k + offset - 1``), and columns ``1 .. offset - 1`` replay the commands still in flight,
    ``history[1:]`` (the ring of the last ``offset`` commands sent, oldest first; its oldest
    is the one acting now).  ``offset`` 0 or 1 changes nothing.

    Parameters
    ----------
    vel : numpy.ndarray
        ``(B, T)`` velocities.
    offset : int
        :func:`delay_offset`.
    history : numpy.ndarray
        ``(offset,)`` commands sent, oldest first.
    """
    T = vel.shape[1]
    if offset <= 1 or T == 0:
        return
    if offset < T:
        vel[:, offset:] = vel[:, 1:T - offset + 1].copy()
    for j in range(1, min(offset, T)):
        vel[:, j] = history[j]


def integrate(x0: float, y0: float, yaw0: float, vx: np.ndarray, wz: np.ndarray,
              dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``Optimizer::integrateStateVelocities``: poses of the velocity rollouts.

    ``yaw_j = yaw0 + dt sum_{i<=j} wz_i``; ``x_j = x0 + dt sum_{i<=j} vx_i cos(yaw_{i-1})``
    (``yaw_{-1} = yaw0``), ``y`` alike: each step moves along the heading before it.

    Parameters
    ----------
    x0, y0, yaw0 : float
        The robot's pose.
    vx, wz : numpy.ndarray
        ``(B, T)`` velocities.
    dt : float
        ``model_dt``.

    Returns
    -------
    x, y, yaw : numpy.ndarray
        ``(B, T)``.
    """
    yaw = np.cumsum(wz * dt, axis=1) + yaw0
    prev = np.empty_like(yaw)
    prev[:, 0] = yaw0
    prev[:, 1:] = yaw[:, :-1]
    x = x0 + np.cumsum(vx * np.cos(prev) * dt, axis=1)
    y = y0 + np.cumsum(vx * np.sin(prev) * dt, axis=1)
    return x, y, yaw


def rollout(pose: tuple[float, float, float], speed: tuple[float, float], cvx: np.ndarray,
            cwz: np.ndarray, p: MPPIParams, history: tuple[np.ndarray, np.ndarray] | None = None
            ) -> dict[str, np.ndarray]:
    """``generateNoisedTrajectories`` after the noise: velocities and poses of the controls.

    Parameters
    ----------
    pose : (float, float, float)
        The robot's pose.
    speed : (float, float)
        Initial ``(v, w)`` (odometry, or the last command with ``open_loop``).
    cvx, cwz : numpy.ndarray
        ``(B, T)`` sampled controls (clamped in place, :func:`predict`).
    p : MPPIParams
        Settings.
    history : (numpy.ndarray, numpy.ndarray), optional
        Rolling's command rings ``(vx, wz)`` for the model delay.

    Returns
    -------
    dict
        ``vx, wz, x, y, yaw``: ``(B, T)`` arrays.
    """
    vx, wz = predict(speed[0], speed[1], cvx, cwz, p)
    if history is not None:
        apply_delay_shift(vx, delay_offset(p.model_delay_vx, p.model_dt), history[0])
        apply_delay_shift(wz, delay_offset(p.model_delay_wz, p.model_dt), history[1])
    x, y, yaw = integrate(pose[0], pose[1], pose[2], vx, wz, p.model_dt)
    return dict(vx=vx, wz=wz, x=x, y=y, yaw=yaw)


def softmax_weights(costs: np.ndarray, temperature: float) -> np.ndarray:
    """``updateControlSequence``'s weights: ``exp(-(c - min c) / temperature)``, normalised.

    Parameters
    ----------
    costs : numpy.ndarray
        ``(B,)`` trajectory costs (the control cost included).
    temperature : float
        ``temperature``.

    Returns
    -------
    numpy.ndarray
    """
    e = np.exp(-1.0 / temperature * (costs - costs.min()))
    return e / e.sum()


def savitzky_golay(seq: np.ndarray, history: np.ndarray) -> np.ndarray:
    """``utils::savitskyGolayFilter`` on one axis: the filtered sequence.

    Points ``0 .. T-2`` become the 9-point quadratic Savitzky-Golay smoothing
    (:data:`SG_COEFFICIENTS`) of the window from 4 before to 4 after; before the start the
    window takes the last 4 commands sent (``history``, oldest first), past the end it
    repeats the last point; the last point is left as it is.  Sequences under 21 points are
    not filtered.

    Parameters
    ----------
    seq : numpy.ndarray
        ``(T,)`` control sequence.
    history : numpy.ndarray
        ``(4,)`` the last commands, oldest first.

    Returns
    -------
    numpy.ndarray
    """
    n = seq.size - 1
    if n < 20:
        return seq.copy()
    padded = np.concatenate((history, seq, np.full(4, seq[n])))
    out = seq.copy()
    windows = np.lib.stride_tricks.sliding_window_view(padded, 9)[:n]
    out[:n] = windows @ SG_COEFFICIENTS
    return out


# ----------------------------------------------------------------------------- critics

def _within(pose: tuple[float, float, float], goal: tuple[float, float, float],
            tol: float) -> bool:
    """``withinPositionGoalTolerance(float, robot, goal)``: squared distance < ``tol^2``."""
    return (goal[0] - pose[0]) ** 2 + (goal[1] - pose[1]) ** 2 < tol * tol


def constraint_cost(vx: np.ndarray, p: MPPIParams) -> np.ndarray:
    """ConstraintCritic (DiffDrive): ``w dt sum(max(vx - v_max, 0) + max(v_min - vx, 0))``.

    ``v_max = sqrt(vx_max^2 + vy_max^2)``, ``v_min = -sqrt(vx_min^2 + vy_max^2)`` (sign of
    ``vx_min``), ``vy_max`` the parent's (``ConstraintCritic::initialize``).

    Parameters
    ----------
    vx : numpy.ndarray
        ``(B, T)`` rollout speeds.
    p : MPPIParams
        Settings.

    Returns
    -------
    numpy.ndarray
    """
    vmax = math.sqrt(p.vx_max ** 2 + p.vy_max ** 2)
    vmin = (1.0 if p.vx_min > 0 else -1.0) * math.sqrt(p.vx_min ** 2 + p.vy_max ** 2)
    over = np.maximum(vx - vmax, 0.0) + np.maximum(vmin - vx, 0.0)
    return p.constraint_weight * np.sum(over * p.model_dt, axis=1)


def goal_cost(x: np.ndarray, y: np.ndarray, goal: tuple[float, float, float],
              p: MPPIParams) -> np.ndarray:
    """GoalCritic: ``w mean_t |traj_t - goal|`` (used within ``goal_threshold`` of the goal).

    Parameters
    ----------
    x, y : numpy.ndarray
        ``(B, T)`` rollout positions.
    goal : (float, float, float)
        Goal pose.
    p : MPPIParams
        Settings.

    Returns
    -------
    numpy.ndarray
    """
    return p.goal_weight * np.mean(np.hypot(x - goal[0], y - goal[1]), axis=1)


def goal_angle_cost(yaw: np.ndarray, goal_yaw: float, p: MPPIParams) -> np.ndarray:
    """GoalAngleCritic: ``w mean_t |yaw_t - goal_yaw|`` (wrapped; within its threshold).

    Parameters
    ----------
    yaw : numpy.ndarray
        ``(B, T)`` rollout headings.
    goal_yaw : float
        The last path pose's orientation.
    p : MPPIParams
        Settings.

    Returns
    -------
    numpy.ndarray
    """
    return p.goal_angle_weight * np.mean(np.abs(wrap(goal_yaw - yaw)), axis=1)


def prefer_forward_cost(vx: np.ndarray, p: MPPIParams) -> np.ndarray:
    """PreferForwardCritic: ``w dt sum max(-vx, 0)``.

    Parameters
    ----------
    vx : numpy.ndarray
        ``(B, T)`` rollout speeds.
    p : MPPIParams
        Settings.

    Returns
    -------
    numpy.ndarray
    """
    return p.prefer_forward_weight * np.sum(np.maximum(-vx, 0.0) * p.model_dt, axis=1)


def furthest_reached_path_point(x_end: np.ndarray, y_end: np.ndarray, path_x: np.ndarray,
                                path_y: np.ndarray) -> int:
    """``utils::findPathFurthestReachedPoint``: how far along the path the rollouts end.

    For each trajectory in turn, the path point closest to its end point among those not
    before the furthest found so far (first of equals); the result is the furthest.
    Vectorised: the first-argmin of every suffix of the path per trajectory, then the
    sequential scan jumps from one increase to the next.

    Parameters
    ----------
    x_end, y_end : numpy.ndarray
        ``(B,)`` trajectories' last points.
    path_x, path_y : numpy.ndarray
        ``(N,)`` path.

    Returns
    -------
    int
    """
    d = (path_x[None, :] - x_end[:, None]) ** 2 + (path_y[None, :] - y_end[:, None]) ** 2
    B, N = d.shape
    sarg = np.empty((B, N), dtype=np.int64)
    best = d[:, N - 1].copy()
    arg = np.full(B, N - 1)
    sarg[:, N - 1] = arg
    for s in range(N - 2, -1, -1):
        better = d[:, s] <= best                  # an earlier point of equal distance wins
        best = np.where(better, d[:, s], best)
        arg = np.where(better, s, arg)
        sarg[:, s] = arg
    m, i = 0, 0
    while i < B:
        up = np.flatnonzero(sarg[i:, m] > m)
        if up.size == 0:
            break
        i += int(up[0])
        m = int(sarg[i, m])
        i += 1
    return m


def path_follow_cost(x: np.ndarray, y: np.ndarray, path_x: np.ndarray, path_y: np.ndarray,
                     furthest: int, p: MPPIParams) -> np.ndarray:
    """PathFollowCritic: ``w |traj_end - path[min(furthest + offset, N - 1)]|``.

    Parameters
    ----------
    x, y : numpy.ndarray
        ``(B, T)`` rollout positions.
    path_x, path_y : numpy.ndarray
        ``(N,)`` path.
    furthest : int
        :func:`furthest_reached_path_point`.
    p : MPPIParams
        Settings.

    Returns
    -------
    numpy.ndarray
    """
    i = min(furthest + p.path_follow_offset, path_x.size - 1)
    return p.path_follow_weight * np.hypot(x[:, -1] - path_x[i], y[:, -1] - path_y[i])


def path_angle_cost(pose: tuple[float, float, float], x: np.ndarray, y: np.ndarray,
                    yaw: np.ndarray, path_x: np.ndarray, path_y: np.ndarray, furthest: int,
                    p: MPPIParams) -> np.ndarray | None:
    """PathAngleCritic, mode 0 (forward preference).

    The point ``path[min(furthest + offset, N - 1)]``; nothing (None) when the robot heads
    within ``max_angle_to_furthest`` of it (``posePointAngle`` forward); else ``w |yaw_end -
    bearing(traj_end -> point)|`` (wrapped).

    Parameters
    ----------
    pose : (float, float, float)
        The robot's pose.
    x, y, yaw : numpy.ndarray
        ``(B, T)`` rollouts.
    path_x, path_y : numpy.ndarray
        ``(N,)`` path.
    furthest : int
        :func:`furthest_reached_path_point`.
    p : MPPIParams
        Settings.

    Returns
    -------
    numpy.ndarray or None
    """
    i = min(furthest + p.path_angle_offset, path_x.size - 1)
    gx, gy = path_x[i], path_y[i]
    if abs(float(wrap(pose[2] - math.atan2(gy - pose[1], gx - pose[0])))) < p.path_angle_max_angle:
        return None
    bearing = np.arctan2(gy - y[:, -1], gx - x[:, -1])
    return p.path_angle_weight * np.abs(wrap(bearing - yaw[:, -1]))


def closest_path_points(cum: np.ndarray, dist: np.ndarray) -> np.ndarray:
    """``utils::findClosestPathPt`` for non-decreasing distances, vectorised.

    The path point whose integrated distance ``cum`` is nearest ``dist``: with ``i`` the
    first point past ``dist``, ``i - 1`` if ``dist`` is strictly nearer it, else ``i``; the
    last point when none is past.  (Nav2 searches from the previous answer; with the
    distances along a trajectory non-decreasing that gives the same points.)

    Parameters
    ----------
    cum : numpy.ndarray
        ``(F,)`` integrated path distances, ``cum[0] = 0``.
    dist : numpy.ndarray
        Integrated trajectory distances (any shape).

    Returns
    -------
    numpy.ndarray
    """
    i = np.searchsorted(cum, dist, side='right')
    i = np.maximum(i, 1)
    last = cum.size - 1
    ic = np.minimum(i, last)
    lower = (dist - cum[ic - 1]) < (cum[ic] - dist)
    out = np.where(lower, ic - 1, ic)
    return np.where(i > last, last, out)


def path_align_cost(x: np.ndarray, y: np.ndarray, path_x: np.ndarray, path_y: np.ndarray,
                    furthest: int, p: MPPIParams) -> np.ndarray | None:
    """PathAlignCritic (path orientations off): mean distance from the path's matching points.

    Nothing (None) when ``furthest < offset_from_furthest``.  Every ``trajectory_point_step``-th
    point of a trajectory (from its first) is matched to the path point (among the first
    ``furthest``) at the same integrated distance (:func:`closest_path_points`); the cost is
    ``w`` times the mean distance between them over points ``1..``.

    Parameters
    ----------
    x, y : numpy.ndarray
        ``(B, T)`` rollout positions.
    path_x, path_y : numpy.ndarray
        ``(N,)`` path.
    furthest : int
        :func:`furthest_reached_path_point`.
    p : MPPIParams
        Settings.

    Returns
    -------
    numpy.ndarray or None
    """
    F = furthest
    if F < p.path_align_offset:
        return None
    px, py = path_x[:F], path_y[:F]
    cum = np.concatenate(([0.0], np.cumsum(np.hypot(np.diff(px), np.diff(py)))))
    tx, ty = x[:, ::p.path_align_point_step], y[:, ::p.path_align_point_step]
    seg = np.hypot(np.diff(tx, axis=1), np.diff(ty, axis=1))
    dist = np.cumsum(seg, axis=1)
    k = closest_path_points(cum, dist)
    d = np.hypot(px[k] - tx[:, 1:], py[k] - ty[:, 1:])
    return p.path_align_weight * d.mean(axis=1)


# ----------------------------------------------------------------------------- controller

class MPPI(Nav2Server):
    """Nav2 Jazzy MPPI in the bring-up's chain (:class:`~.nav2_common.Nav2Server`).

    Per control tick (``MPPIController::computeVelocityCommands``): the goal (the plan's last
    pose), the plan near the robot (``PathHandler::transformPath``: from the closest pose
    within ``max_robot_pose_search_dist``, ``prune_distance`` of path, inside the 3 m
    costmap; the poses before it pruned), then ``Optimizer::evalControl``: ``iteration_count``
    times (sample ``batch_size`` noised copies of the control sequence, roll them out, score
    them with the critics and the control cost, the softmax-weighted mean as the new
    sequence, clipped), the Savitzky-Golay filter, the command (element 1 when the control
    period equals ``model_dt``: ``shift_control_sequence``, else element 0), the shift.

    Parameters
    ----------
    path_xy : array_like
        ``(N, 2)`` path positions (m).
    path_yaw : array_like, optional
        ``(N,)`` pose orientations (rad).
    params : MPPIParams, optional
        Default the bring-up's.
    seed : int
        Seed of the noise.
    **server
        :class:`~.nav2_common.Nav2Server` options.
    """

    def __init__(self, path_xy: Any, path_yaw: Any = None, params: MPPIParams | None = None,
                 seed: int = 0, **server: Any):
        self.params = params or MPPIParams()
        self.seed = seed
        super().__init__(path_xy, path_yaw, **server)

    def _reset(self) -> None:
        # Optimizer::reset
        p = self.params
        self.rng = np.random.default_rng(self.seed)
        self.cs_vx = np.zeros(p.time_steps)
        self.cs_wz = np.zeros(p.time_steps)
        self.sg_history = np.zeros((4, 2))            # control_history_: 4 x (vx, wz)
        self.last_command = (0.0, 0.0)
        n_vx = delay_offset(p.model_delay_vx, p.model_dt)
        n_wz = delay_offset(p.model_delay_wz, p.model_dt)
        self.delay = (n_vx > 0 or n_wz > 0)
        self.cmd_history = (np.zeros(n_vx), np.zeros(n_wz))
        self._noise = None if p.regenerate_noises else self._draw()
        self.last_rollouts: dict[str, np.ndarray] | None = None
        self.last_costs: np.ndarray | None = None

    def _draw(self) -> tuple[np.ndarray, np.ndarray]:
        # NoiseGenerator::generateNoisedControls
        p = self.params
        shape = (p.batch_size, p.time_steps)
        return (self.rng.normal(0.0, p.vx_std, shape), self.rng.normal(0.0, p.wz_std, shape))

    def _set_plan(self, lo: int, hi: int) -> None:
        # MPPIController::setPlan -> PathHandler::setPath (the optimizer keeps its state)
        self.plan_lo, self.plan_hi = lo, hi

    def transform_path(self, x: float, y: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``PathHandler::transformPath``: the plan near the robot (odom frame); prunes it.

        Parameters
        ----------
        x, y : float
            The robot's position.

        Returns
        -------
        px, py, pyaw : numpy.ndarray
        """
        p = self.params
        lo, hi = self.plan_lo, self.plan_hi
        upper = first_after_integrated_distance(self.xy, lo, hi, p.max_robot_pose_search_dist)
        begin = closest_pose(self.xy, lo, max(upper, lo + 1), x, y)
        end = first_after_integrated_distance(self.xy, begin, hi, p.prune_distance)
        half = COSTMAP_SIZE / 2.0
        seg = self.xy[begin:end]
        outside = np.flatnonzero((np.abs(seg[:, 0] - x) >= half) | (np.abs(seg[:, 1] - y) >= half))
        if outside.size:
            end = begin + int(outside[0])
        self.plan_lo = begin
        return self.xy[begin:end, 0], self.xy[begin:end, 1], self.yaw[begin:end]

    def score(self, pose: tuple[float, float, float], r: dict[str, np.ndarray],
              path: tuple[np.ndarray, np.ndarray, np.ndarray],
              goal: tuple[float, float, float]) -> np.ndarray:
        """The critics' summed cost of the rollouts ``r`` (``evalTrajectoriesScores``).

        Parameters
        ----------
        pose : (float, float, float)
            The robot's pose.
        r : dict
            :func:`rollout`'s arrays.
        path : (numpy.ndarray, numpy.ndarray, numpy.ndarray)
            The transformed plan ``(x, y, yaw)``.
        goal : (float, float, float)
            The goal pose.

        Returns
        -------
        numpy.ndarray
        """
        p = self.params
        px, py, pyaw = path
        costs = constraint_cost(r['vx'], p)
        if _within(pose, goal, p.goal_threshold) and self.plan_hi < len(self.xy):
            self.near_goal_ticks += 1            # an intermediate leg's end within reach
        if _within(pose, goal, p.goal_threshold):
            costs = costs + goal_cost(r['x'], r['y'], goal, p)
        if _within(pose, goal, p.goal_angle_threshold):
            costs = costs + goal_angle_cost(r['yaw'], float(pyaw[-1]), p)
        furthest: int | None = None

        def reached() -> int:
            nonlocal furthest
            if furthest is None:
                furthest = furthest_reached_path_point(r['x'][:, -1], r['y'][:, -1], px, py)
            return furthest

        if not _within(pose, goal, p.path_align_threshold):
            c = path_align_cost(r['x'], r['y'], px, py, reached(), p)
            if c is not None:
                costs = costs + c
        if px.size >= 2 and not _within(pose, goal, p.path_follow_threshold):
            costs = costs + path_follow_cost(r['x'], r['y'], px, py, reached(), p)
        if not _within(pose, goal, p.path_angle_threshold):
            c = path_angle_cost(pose, r['x'], r['y'], r['yaw'], px, py, reached(), p)
            if c is not None:
                costs = costs + c
        if not _within(pose, goal, p.prefer_forward_threshold):
            costs = costs + prefer_forward_cost(r['vx'], p)
        return costs

    def _compute(self, x: float, y: float, th: float, v: float, w: float,
                 period: float) -> tuple[float, float]:
        p = self.params
        # Optimizer::setOffset: the control period against model_dt
        if period > p.model_dt + 1e-6:
            raise ValueError(f'MPPI: controller period {period:g} s more than model_dt '
                             f'{p.model_dt:g} s (Nav2 refuses: "set it equal to model dt")')
        shift = abs(period - p.model_dt) < 1e-6
        g = self.plan_hi - 1
        goal = (float(self.xy[g, 0]), float(self.xy[g, 1]), float(self.yaw[g]))
        path = self.transform_path(x, y)
        if path[0].size == 0:         # InvalidPath in Nav2
            return 0.0, 0.0
        pose = (x, y, th)
        speed = self.last_command if p.open_loop else (v, w)       # Optimizer::prepare
        history = self.cmd_history if self.delay else None
        acc = np.zeros(p.batch_size)      # costs_: zeroed in prepare only (not per iteration)
        for _ in range(p.iteration_count):
            nvx, nwz = self._draw() if self._noise is None else self._noise
            cvx = self.cs_vx + nvx
            cwz = self.cs_wz + nwz
            r = rollout(pose, speed, cvx, cwz, p, history)
            costs = acc + self.score(pose, r, path, goal)
            # updateControlSequence: the control cost, the softmax, the weighted mean
            costs = costs + p.gamma / p.vx_std ** 2 * ((cvx - self.cs_vx) @ self.cs_vx)
            costs = costs + p.gamma / p.wz_std ** 2 * ((cwz - self.cs_wz) @ self.cs_wz)
            acc = costs
            wts = softmax_weights(costs, p.temperature)
            self.cs_vx = wts @ cvx
            self.cs_wz = wts @ cwz
            self._constrain()
            self.last_rollouts, self.last_costs = r, costs
        # evalControl: filter, command, shift
        self.cs_vx = savitzky_golay(self.cs_vx, self.sg_history[:, 0])
        self.cs_wz = savitzky_golay(self.cs_wz, self.sg_history[:, 1])
        k = 1 if shift else 0
        self.sg_history = np.vstack((self.sg_history[1:], [self.cs_vx[k], self.cs_wz[k]]))
        cmd = (float(self.cs_vx[k]), float(self.cs_wz[k]))
        self.last_command = cmd
        if self.delay:                # Rolling: pushCommandHistory
            for ring, val in zip(self.cmd_history, cmd):
                if ring.size:
                    ring[:-1] = ring[1:].copy()
                    ring[-1] = val
        if shift:
            self.cs_vx = np.append(self.cs_vx[1:], self.cs_vx[-1])
            self.cs_wz = np.append(self.cs_wz[1:], self.cs_wz[-1])
        return cmd

    def _constrain(self) -> None:
        """``applyControlSequenceConstraints``: speed bounds, then acceleration from element 0."""
        p = self.params
        vx = np.clip(self.cs_vx, p.vx_min, p.vx_max)
        wz = np.clip(self.cs_wz, -p.wz_max, p.wz_max)
        dmax, dmin, dw = p.model_dt * p.ax_max, p.model_dt * p.ax_min, p.model_dt * p.az_max
        for i in range(1, vx.size):
            last = vx[i - 1]
            if last > 0:
                vx[i] = min(max(vx[i], last + dmin), last + dmax)
            else:
                vx[i] = min(max(vx[i], last - dmax), last - dmin)
            wz[i] = min(max(wz[i], wz[i - 1] - dw), wz[i - 1] + dw)
        self.cs_vx, self.cs_wz = vx, wz


def make_mppi(trajectory: Any, variant: str = 'stock', delay: float | None = 0.0,
              seed: int = 0, params: MPPIParams | None = None, t_span: Any = None,
              **server: Any):
    """A factory ``tracker_config -> MPPI`` following ``trajectory``'s path.

    Parameters
    ----------
    trajectory : Trajectory
        The path is its positions every 5 cm (:func:`~.nav2_common.path_from_trajectory`).
    variant : str
        ``'stock'``, ``'open_loop'`` (``open_loop: true``) or ``'rolling_delay'`` (Rolling's
        ``model_delay_vx`` = ``model_delay_wz`` = ``delay``).
    delay : float or None
        The latency (s) for ``'rolling_delay'``; None: the plant's ``cmd_latency`` when the
        factory is called with ``plant_config=``.
    seed : int
        Noise seed.
    params : MPPIParams, optional
        Default the bring-up's (a stock peer: change only to study it).
    t_span : (float, float), optional
        For an analytic trajectory: the times the path covers.
    **server
        :class:`~.nav2_common.Nav2Server` options and ``batch_size`` (a smaller batch, for
        tests of the math only).

    Returns
    -------
    callable
    """
    if variant not in MODES:
        raise ValueError(f'variant must be one of {MODES}, got {variant!r}')
    base = params or MPPIParams()
    if 'batch_size' in server:
        base = replace(base, batch_size=int(server.pop('batch_size')))
    if variant == 'open_loop':
        base = replace(base, open_loop=True)
    build = factory(MPPI, trajectory, t_span, params=base, seed=seed, **server)
    if variant != 'rolling_delay':
        return build

    def build_delayed(tracker_config: Any = None, plant_config: Any = None, **_: Any) -> MPPI:
        d = delay
        if d is None:
            if plant_config is None:
                raise ValueError("make_mppi(variant='rolling_delay', delay=None) needs "
                                 'plant_config= (its cmd_latency)')
            d = float(plant_config.cmd_latency)
        q = replace(base, model_delay_vx=float(d), model_delay_wz=float(d))
        xy, yaw = build.path
        return MPPI(xy, yaw, params=q, seed=seed, **server)

    return build_delayed


#: Labels for tables: the variant and the Nav2 branch it comes from.
LABELS = {'stock': 'Nav2 MPPI (Jazzy)', 'open_loop': 'Nav2 MPPI open_loop (Jazzy)',
          'rolling_delay': 'Nav2 MPPI model_delay (Rolling)'}


def compute_per_command(seconds: float = 10.0, seed: int = 0) -> dict[str, float]:
    """Wall time (ms) of MPPI's compute per command, bring-up settings, on a 3 m line.

    The run: :func:`~nonfragile_tracker.control.simulation.follow.simulate_following` on the
    ideal unicycle with 50 Hz odometry (one command per 20 Hz tick).

    Parameters
    ----------
    seconds : float
        Simulated time (s).
    seed : int
        Noise seed.

    Returns
    -------
    dict
        ``median``, ``p99`` (ms) and ``commands``.
    """
    from nonfragile_tracker.control.simulation.follow import simulate_following
    from nonfragile_tracker.control.simulation.plant import PlantConfig
    from nonfragile_tracker.control.simulation.tracker import TrackerConfig
    from nonfragile_tracker.control.simulation.trajectory import from_poses

    x = np.linspace(0.0, 3.0, 61)
    traj = from_poses(np.zeros_like(x), x, 0 * x, 0 * x, cruise_speed=0.4, max_accel=0.5)
    made: list[MPPI] = []
    build = make_mppi(traj, seed=seed)
    K = ((-1.0, -1.0, 0.0, 0.0), (0.0, 0.0, -1.0, -1.0))     # unread by a peer
    simulate_following(PlantConfig(dt=0.01, odom_rate=50.0), TrackerConfig(K=K), traj,
                       int(seconds / 0.01), controller=lambda tc: made.append(build(tc))
                       or made[-1], max_start_distance=0)
    ms = 1e3 * np.array(made[-1].compute_times)
    return dict(median=float(np.median(ms)), p99=float(np.percentile(ms, 99)),
                commands=float(ms.size))


if __name__ == '__main__':
    r = compute_per_command()
    print(f"MPPI {MPPIParams().batch_size} x {MPPIParams().time_steps}: compute per command "
          f"median {r['median']:.1f} ms, p99 {r['p99']:.1f} ms ({r['commands']:.0f} commands)")


def _peer(mode: str) -> Any:
    """The table driver's factory of ``mode``: the path from the trajectory it is given."""
    def make(tracker_config: Any, *, trajectory: Any, plant_config: Any = None) -> MPPI:
        seed = int(plant_config.noise_seed) if plant_config is not None else 0
        build = make_mppi(trajectory, mode, delay=None if mode == 'rolling_delay' else 0.0,
                          seed=seed, t_span=table_span(trajectory))
        if mode == 'rolling_delay':
            return build(tracker_config, plant_config=plant_config)
        return build(tracker_config)
    return make


#: The table driver's peers (``benchmarks/peers.py``): each variant by its label.
PEERS = {LABELS[m]: _peer(m) for m in MODES}
#: The labels that are not Nav2 Jazzy's MPPI as its bring-up ships it: ``open_loop: true``
#: (a user's change for latency) and Rolling's model delay set to the base's latency.
VARIANTS = (LABELS['open_loop'], LABELS['rolling_delay'])
#: MPPI follows the path, not the timed reference: judged on cross-track (its own speed).
PATH_FOLLOWERS = tuple(PEERS)
#: Seconds per run (2000 x 56 rollouts at 20 Hz in numpy): ``--quick`` runs fewer of them.
HEAVY = tuple(PEERS)
