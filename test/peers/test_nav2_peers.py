"""The Nav2 peers (benchmarks/peers/nav2_rpp.py, nav2_mppi.py, nav2_common.py) against their
source: hand-computed cases of each formula (navigation2 tag 1.3.13, Rolling for the model
delay), then closed-loop runs on a line and a circle.

The MPPI math tests use a small batch (3 to 200 trajectories: they test formulas, not the
sampling); the closed-loop runs use the bring-up's 2000 x 56.
"""
from __future__ import annotations

import math
import sys
from dataclasses import replace

import numpy as np
import pytest

from conftest import ROOT

if str(ROOT) not in sys.path:          # benchmarks/ is not a package on the test path
    sys.path.insert(0, str(ROOT))

from benchmarks.peers import nav2_mppi as mppi  # noqa: E402
from benchmarks.peers import nav2_rpp as rpp  # noqa: E402
from benchmarks.peers.nav2_common import (ControlClock, GoalChecker, Route,  # noqa: E402
                                          VelocitySmoother, path_from_trajectory)
from nonfragile_tracker.control.simulation.follow import simulate_following  # noqa: E402
from nonfragile_tracker.control.simulation.interfaces import Controller  # noqa: E402
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig  # noqa: E402
from nonfragile_tracker.control.simulation.reference import RefSample  # noqa: E402
from nonfragile_tracker.control.simulation.trajectory import from_poses  # noqa: E402

K = [[-4.4453, -4.8047, -1.4766, -1.5234], [-1.4766, -1.5234, -4.4453, -4.8047]]
REF = RefSample(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)
P_RPP = rpp.RPPParams()
P_MPPI = mppi.MPPIParams()


def line_path(y=0.0, x0=-1.0, x1=3.0):
    x = np.arange(x0, x1 + 1e-9, 0.05)
    return np.column_stack((x, np.full_like(x, y)))


# ------------------------------------------------------------------ RPP (parameter_handler.cpp,
# regulated_pure_pursuit_controller.cpp, regulation_functions.hpp)

def test_rpp_code_defaults():
    p = P_RPP
    assert (p.desired_linear_vel, p.lookahead_dist, p.min_lookahead_dist, p.max_lookahead_dist,
            p.lookahead_time) == (0.5, 0.6, 0.3, 0.9, 1.5)
    assert (p.rotate_to_heading_angular_vel, p.rotate_to_heading_min_angle,
            p.max_angular_accel) == (1.8, 0.785, 3.2)
    assert (p.regulated_linear_scaling_min_radius, p.regulated_linear_scaling_min_speed) == \
        (0.9, 0.25)
    assert (p.approach_velocity_scaling_dist, p.min_approach_linear_velocity) == (0.6, 0.05)
    assert p.use_velocity_scaled_lookahead_dist is False and p.use_rotate_to_heading is True
    assert p.max_robot_pose_search_dist == 1.5           # costmap_size_x / 2 of the 3 m map


def test_rpp_lookahead_from_speed():
    assert rpp.lookahead_distance(0.4, P_RPP) == 0.6      # default: fixed lookahead_dist
    scaled = rpp.with_velocity_scaled_lookahead()
    # |v| * lookahead_time 1.5, clamped to [0.3, 0.9]
    assert rpp.lookahead_distance(0.1, scaled) == 0.3     # 0.15 -> min
    assert rpp.lookahead_distance(-0.4, scaled) == pytest.approx(0.6)
    assert rpp.lookahead_distance(0.5, scaled) == pytest.approx(0.75)
    assert rpp.lookahead_distance(1.0, scaled) == 0.9     # 1.5 -> max


def test_rpp_curvature_of_the_carrot():
    assert rpp.curvature(0.6, 0.1) == pytest.approx(2 * 0.1 / 0.37)
    assert rpp.curvature(0.5, -0.5) == pytest.approx(-2.0)
    assert rpp.curvature(0.02, 0.02) == 0.0               # |carrot|^2 = 0.0008 <= 0.001


def test_rpp_curvature_regulation():
    # radius 0.5 < min radius 0.9: v (1 - |0.5 - 0.9| / 0.9) = 0.5 * 5/9
    assert rpp.curvature_constraint(0.5, 2.0, 0.9) == pytest.approx(0.5 * 5 / 9)
    assert rpp.curvature_constraint(0.5, -2.0, 0.9) == pytest.approx(0.5 * 5 / 9)
    assert rpp.curvature_constraint(0.5, 1.0, 0.9) == 0.5      # radius 1 >= 0.9
    assert rpp.curvature_constraint(0.5, 0.0, 0.9) == 0.5      # straight


def test_rpp_approach_scaling():
    near = np.array([[0.0, 0.0], [0.2, 0.0], [0.4, 0.0]])      # 0.4 m of plan < 0.6
    assert rpp.approach_velocity_constraint(0.5, near, 0.05, 0.6) == pytest.approx(0.5 * 0.4 / 0.6)
    at = np.array([[0.0, 0.0], [0.02, 0.0]])                    # 0.5 * 0.02/0.6 -> 0.05
    assert rpp.approach_velocity_constraint(0.5, at, 0.05, 0.6) == pytest.approx(0.05)
    far = np.array([[0.0, 0.0], [0.35, 0.0], [0.7, 0.0]])       # 0.7 m: no scaling
    assert rpp.approach_velocity_constraint(0.5, far, 0.05, 0.6) == 0.5


def test_rpp_rotate_to_heading():
    # from rest: 1.8 clamped to 0 + 3.2 * 0.05 = 0.16 (below sqrt(2 * 3.2 * 1.0))
    assert rpp.rotate_to_heading(1.0, 0.0, P_RPP, 0.05) == (0.0, pytest.approx(0.16))
    assert rpp.rotate_to_heading(-1.0, 0.0, P_RPP, 0.05) == (0.0, pytest.approx(-0.16))
    # turning at 1.7 rad/s: 1.8 within 1.7 +- 0.16, then at most sqrt(2 * 3.2 * 0.1) = 0.8
    assert rpp.rotate_to_heading(1.0, 1.7, P_RPP, 0.05)[1] == pytest.approx(1.8)
    assert rpp.rotate_to_heading(0.1, 1.7, P_RPP, 0.05)[1] == pytest.approx(0.8)


def test_rpp_carrot_on_the_segment():
    plan = np.array([[0.0, 0.1], [0.5, 0.1], [1.0, 0.1]])
    c = rpp.lookahead_point(plan, 0.6)
    assert c == pytest.approx([math.sqrt(0.35), 0.1])
    assert rpp.lookahead_point(plan, 2.0) == pytest.approx([1.0, 0.1])   # none: last pose


def test_rpp_command_on_a_line_beside_the_robot():
    """No smoother: the plugin's own (v, w): carrot (sqrt(0.35), 0.1), k = 0.2 / 0.36."""
    c = rpp.RegulatedPurePursuit(line_path(0.1), smoother=False)
    assert isinstance(c, Controller) and c.horizon == 0.0
    cmd = c.step(0.0, 0.0, 0.0, REF, 0.0, stamp=0.0)
    assert cmd.v == pytest.approx(0.5) and cmd.w == pytest.approx(0.5 * 0.2 / 0.36)
    assert not c.rotating


def test_rpp_rotates_to_a_path_off_its_heading():
    y = np.arange(0.0, 3.0, 0.05)
    c = rpp.RegulatedPurePursuit(np.column_stack((np.zeros_like(y), y)), smoother=False)
    cmd = c.step(0.0, 0.0, 0.0, REF, 0.0, stamp=0.0)   # carrot at 90 deg > 0.785
    assert c.rotating and cmd.v == 0.0 and cmd.w == pytest.approx(0.16)


# ------------------------------------------------------------------ the chain (nav2_common)

def test_velocity_smoother_clamps_acceleration_over_a_period():
    s = VelocitySmoother()                       # bring-up: 2.5 m/s^2, 3.2 rad/s^2, 20 Hz
    assert s.smooth(0.5, 2.0) == pytest.approx((0.125, 0.16))
    assert s.smooth(0.5, 2.0) == pytest.approx((0.25, 0.32))
    s.reset(0.5, 0.0)
    assert s.smooth(0.0, 0.0)[0] == pytest.approx(0.375)             # decelerating
    s.reset(0.1, 0.0)
    assert s.smooth(-0.5, 0.0)[0] == pytest.approx(-0.025)           # through zero: decel
    s.reset(0.0, 1.9)
    assert s.smooth(0.0, 3.0)[1] == pytest.approx(2.0)               # max_velocity 2.0
    assert s.smooth(0.0, 0.0, dt=0.02)[1] == pytest.approx(2.0 - 3.2 * 0.02)


def test_control_clock_ticks_at_20_hz_on_50_hz_stamps():
    """Ticks 0, 50, 100, 150, 200 ms, each at the last message before it."""
    ms = 1_000_000
    c = ControlClock(20.0)
    due = [k * 20 for k in range(11) if c.due(k * 20 * ms, 20 * ms)]
    assert due == [0, 40, 100, 140, 200]
    c = ControlClock(20.0)                           # 20 Hz odometry, jittered: every one
    assert all(c.due(t * ms, 50 * ms) for t in (0, 49, 101, 150, 198, 252))
    c = ControlClock(20.0)                           # period unknown: at or after the tick
    assert [t for t in (0, 20, 40, 60, 80, 100) if c.due(t * ms)] == [0, 60, 100]


def test_goal_checker_is_stateful():
    g = GoalChecker()
    assert not g.reached(0.3, 0.0, 0.0, 0.0, 0.0, 0.0)                # 0.3 > 0.25 m
    assert not g.reached(0.2, 0.0, 1.0, 0.0, 0.0, 0.0)                # xy in, yaw 1.0 out
    assert g.reached(0.5, 0.0, 0.2, 0.0, 0.0, 0.0)                    # xy latched
    g.reset()
    assert not g.reached(0.5, 0.0, 0.2, 0.0, 0.0, 0.0)


def test_path_from_a_trajectory_and_its_legs():
    x = np.linspace(0.0, 6.0, 61)
    traj = from_poses(np.zeros_like(x), x, 0 * x, 0 * x, cruise_speed=0.5, max_accel=0.5)
    xy, yaw = path_from_trajectory(traj)
    assert np.diff(xy[:, 0]) == pytest.approx(np.full(len(xy) - 1, 0.05), abs=1e-6)
    assert xy[-1] == pytest.approx([6.0, 0.0]) and np.all(yaw == 0.0)
    r = Route(xy)
    # a leg: 2..4 m along, the pose furthest from its start (4 m), exclusive end 81
    assert r.leg_end(0) == 81
    assert r.leg_end(len(xy) - 70) == len(xy)                         # 3.45 m left: the end


# ------------------------------------------------------------------ MPPI

def test_mppi_bringup_settings():
    p = P_MPPI
    assert (p.batch_size, p.time_steps, p.model_dt, p.iteration_count) == (2000, 56, 0.05, 1)
    assert (p.vx_std, p.wz_std, p.temperature, p.gamma) == (0.2, 0.4, 0.3, 0.015)
    assert (p.constraint_weight, p.goal_weight, p.goal_angle_weight, p.path_align_weight,
            p.path_follow_weight, p.path_angle_weight, p.prefer_forward_weight) == \
        (4.0, 5.0, 3.0, 14.0, 5.0, 2.0, 5.0)
    assert (p.prune_distance, p.path_align_offset, p.path_follow_offset,
            p.path_angle_offset) == (1.7, 20, 5, 4)


def test_diffdrive_rollout_of_a_constant_control():
    """At v = 0.5, w = 0.5 from the same speed: yaw_j = 0.025 (j + 1), each step along the
    heading before it (Optimizer::integrateStateVelocities)."""
    B, T, dt = 3, 56, 0.05
    cvx, cwz = np.full((B, T), 0.5), np.full((B, T), 0.5)
    r = mppi.rollout((1.0, 2.0, 0.3), (0.5, 0.5), cvx, cwz, P_MPPI)
    assert np.all(r['vx'] == 0.5) and np.all(r['wz'] == 0.5)
    j = np.arange(T)
    assert r['yaw'][0] == pytest.approx(0.3 + 0.025 * (j + 1))
    heading = 0.3 + 0.025 * j                    # yaw before step j
    assert r['x'][1] == pytest.approx(1.0 + dt * 0.5 * np.cumsum(np.cos(heading)))
    assert r['y'][2] == pytest.approx(2.0 + dt * 0.5 * np.cumsum(np.sin(heading)))
    # ~ the arc of radius 1 m: after 2.8 s the chord is 2 sin(0.7) within 1 %
    chord = math.hypot(r['x'][0, -1] - 1.0, r['y'][0, -1] - 2.0)
    assert chord == pytest.approx(2 * math.sin(0.7), rel=0.01)


def test_diffdrive_rollout_from_rest_is_acceleration_limited():
    cvx, cwz = np.full((2, 8), 0.5), np.full((2, 8), 0.5)
    r = mppi.rollout((0.0, 0.0, 0.0), (0.0, 0.0), cvx, cwz, P_MPPI)
    # ax_max 3.0 * 0.05 = 0.15 per step; az_max 3.5 * 0.05 = 0.175
    assert r['vx'][0] == pytest.approx([0, 0.15, 0.30, 0.45, 0.5, 0.5, 0.5, 0.5])
    assert r['wz'][0] == pytest.approx([0, 0.175, 0.35, 0.5, 0.5, 0.5, 0.5, 0.5])
    assert cvx[0, 0] == pytest.approx(0.15)      # the clamped control written back
    assert cvx[0, -1] == 0.5                     # the last control is never clamped


def test_softmax_weights_with_temperature():
    w = mppi.softmax_weights(np.array([1.0, 1.3, 1.6]), 0.3)
    e = np.exp([0.0, -1.0, -2.0])
    assert w == pytest.approx(e / e.sum())


def test_savitzky_golay_coefficients_and_filter():
    c = mppi.SG_COEFFICIENTS * 231
    assert c == pytest.approx([-21, 14, 39, 54, 59, 54, 39, 14, -21])
    i = np.arange(-4, 5)
    # quadratic 9-point: sum 1, first and second moments 0 (keeps polynomials of degree 2)
    assert (mppi.SG_COEFFICIENTS.sum(), mppi.SG_COEFFICIENTS @ i,
            mppi.SG_COEFFICIENTS @ i ** 2) == pytest.approx((1.0, 0.0, 0.0), abs=1e-12)
    seq = np.arange(30.0)                         # a ramp, history -4..-1 continuing it
    out = mppi.savitzky_golay(seq, np.array([-4.0, -3.0, -2.0, -1.0]))
    assert out[:26] == pytest.approx(seq[:26])    # windows inside the ramp: unchanged
    # idx 26: the window's last point is the repeated end (29, not 30): + 21/231
    assert out[26] == pytest.approx(26 + 21 / 231)
    assert out[29] == 29.0                        # the last point is left as it is
    short = np.arange(20.0)                       # < 21 points: not filtered
    assert np.array_equal(mppi.savitzky_golay(short, np.zeros(4)), short)


def _furthest_loop(xe, ye, px, py):
    """utils.hpp findPathFurthestReachedPoint, loop for loop (the reference)."""
    m = 0
    for i in range(len(xe)):
        best, arg = math.inf, 0
        for j in range(m, len(px)):
            d = (px[j] - xe[i]) ** 2 + (py[j] - ye[i]) ** 2
            if d < best:
                best, arg = d, j
        m = max(m, arg)
    return m


def test_furthest_reached_path_point():
    px, py = 0.2 * np.arange(10.0), np.zeros(10)
    # utils_test.cpp FurthestAndClosestReachedPoint: trajectories ending at (1, 0) -> 5
    assert mppi.furthest_reached_path_point(np.ones(100), np.zeros(100), px, py) == 5
    rng = np.random.default_rng(3)
    for _ in range(20):
        xe, ye = rng.uniform(-0.5, 2.5, 200), rng.uniform(-1, 1, 200)
        assert mppi.furthest_reached_path_point(xe, ye, px, py) == _furthest_loop(xe, ye, px, py)


def _closest_loop(vec, dist, init=0):
    """utils.hpp findClosestPathPt, loop for loop."""
    distim1 = vec[init] if init != 0 else 0.0
    for i in range(init + 1, len(vec)):
        disti = vec[i]
        if disti > dist:
            if i > 0 and dist - distim1 < disti - dist:
                return i - 1
            return i
        distim1 = disti
    return len(vec) - 1


def test_closest_path_points_match_the_sequential_search():
    rng = np.random.default_rng(5)
    cum = np.concatenate(([0.0], np.cumsum(rng.uniform(0.02, 0.08, 30))))
    for _ in range(50):
        dist = np.sort(rng.uniform(0, cum[-1] * 1.2, 13))
        pt, seq = 0, []
        for d in dist:
            pt = _closest_loop(cum, d, pt)
            seq.append(pt)
        assert list(mppi.closest_path_points(cum, dist)) == seq


def test_critics_on_hand_cases():
    p = P_MPPI
    # ConstraintCritic with the bring-up's vy_max 0.5: bound sqrt(0.5^2 + 0.5^2)
    vx = np.full((2, 56), 1.0)
    assert mppi.constraint_cost(vx, p) == pytest.approx(
        np.full(2, 4.0 * 56 * 0.05 * (1.0 - math.sqrt(0.5))))
    vx[1] = -0.7                                  # below -sqrt(0.35^2 + 0.5^2)
    assert mppi.constraint_cost(vx, p)[1] == pytest.approx(
        4.0 * 56 * 0.05 * (0.7 - math.sqrt(0.35 ** 2 + 0.25)))
    assert mppi.prefer_forward_cost(vx, p)[1] == pytest.approx(5.0 * 56 * 0.05 * 0.7)
    # PathFollowCritic: 5 * |end - path[min(furthest + 5, N - 1)]|
    x, y = np.zeros((1, 56)), np.zeros((1, 56))
    x[0, -1] = 1.0
    px, py = 0.1 * np.arange(20.0), np.full(20, 0.5)
    assert mppi.path_follow_cost(x, y, px, py, 5, p) == pytest.approx([5.0 * 0.5])
    assert mppi.path_follow_cost(x, y, px, py, 18, p) == pytest.approx(
        [5.0 * math.hypot(0.9, 0.5)])
    # GoalCritic: 5 * mean distance to the goal
    x2 = np.tile(np.linspace(0.0, 1.0, 56), (1, 1))
    assert mppi.goal_cost(x2, 0 * x2, (1.0, 0.0, 0.0), p) == pytest.approx([5.0 * 0.5])


def test_path_align_critic_on_a_parallel_trajectory():
    """A trajectory 0.1 m beside a straight path, moving 0.05 m per step: every sampled
    point matches the path point as far along: 14 * 0.1."""
    px, py = 0.05 * np.arange(60.0), np.zeros(60)
    x = np.tile(0.05 * np.arange(56.0), (2, 1))
    y = np.full((2, 56), 0.1)
    assert mppi.path_align_cost(x, y, px, py, 60, P_MPPI) == pytest.approx([1.4, 1.4])
    assert mppi.path_align_cost(x, y, px, py, 19, P_MPPI) is None    # furthest < 20


def test_path_angle_critic():
    p = P_MPPI
    px, py = np.array([0.0, 1.0]), np.array([0.0, 1.0])
    x, y, yaw = np.zeros((1, 5)), np.zeros((1, 5)), np.zeros((1, 5))
    # the robot heads 0, the point at 45 deg < 1.0 rad: the critic does not act
    assert mppi.path_angle_cost((0.0, 0.0, 0.0), x, y, yaw, px, py, 0, p) is None
    # heading pi: 135 deg off; the cost is 2 * |yaw_end - bearing| = 2 * pi/4
    c = mppi.path_angle_cost((0.0, 0.0, math.pi), x, y, yaw, px, py, 0, p)
    assert c == pytest.approx([2.0 * math.pi / 4])


def test_rolling_model_delay_shift():
    """motion_model_tests.cpp (main) DelayReplayAllAxes: delays 0.10 / 0.15 s at dt 0.05 ->
    offsets 2 / 3; after the pushes 1, 5, 9 (vx) and 3, 7, 4 (wz) the rings hold [5, 9] and
    [3, 7, 4]; column 1 replays 9 and 7, column 2 of wz replays 4, the rest stays 0."""
    assert mppi.delay_offset(0.10, 0.05) == 2 and mppi.delay_offset(0.15, 0.05) == 3
    assert mppi.delay_offset(0.02, 0.05) == 0 and mppi.delay_offset(0.0, 0.05) == 0
    vx, wz = np.zeros((8, 20)), np.zeros((8, 20))
    mppi.apply_delay_shift(vx, 2, np.array([5.0, 9.0]))
    mppi.apply_delay_shift(wz, 3, np.array([3.0, 7.0, 4.0]))
    assert np.all(vx[:, 1] == 9.0) and np.all(vx[:, 2:] == 0.0) and np.all(vx[:, 0] == 0.0)
    assert np.all(wz[:, 1] == 7.0) and np.all(wz[:, 2] == 4.0) and np.all(wz[:, 3:] == 0.0)
    v = np.tile(np.arange(6.0), (1, 1))           # the rest moves right by offset - 1
    mppi.apply_delay_shift(v, 3, np.array([0.0, 7.0, 8.0]))
    assert v[0] == pytest.approx([0, 7, 8, 1, 2, 3])


def test_mppi_variants():
    x = np.linspace(0.0, 3.0, 31)
    traj = from_poses(np.zeros_like(x), x, 0 * x, 0 * x, cruise_speed=0.5, max_accel=0.5)
    tc = TrackerConfig(K=K)
    assert mppi.make_mppi(traj, 'open_loop', batch_size=8)(tc).params.open_loop
    d = mppi.make_mppi(traj, 'rolling_delay', delay=None, batch_size=8)(
        tc, plant_config=PlantConfig(cmd_latency=0.1))
    assert (d.params.model_delay_vx, d.params.model_delay_wz) == (0.1, 0.1)
    assert [r.size for r in d.cmd_history] == [2, 2]
    with pytest.raises(ValueError, match='variant'):
        mppi.make_mppi(traj, 'tuned')


# ------------------------------------------------------------------ closed loop

def _cross_track(run, traj):
    """Distance (m) of each true position from the trajectory's path (2000 segments)."""
    s = traj.evaluate(np.linspace(traj.t_start, traj.t_end, 2001))
    a = np.column_stack((s.x[:-1], s.y[:-1]))
    ab = np.column_stack((np.diff(s.x), np.diff(s.y)))
    ab2 = np.maximum(np.sum(ab * ab, axis=1), 1e-18)
    out = []
    for k in range(0, len(run.x), 400):
        q = np.column_stack((run.x[k:k + 400], run.y[k:k + 400]))[:, None, :] - a[None]
        u = np.clip(np.sum(q * ab[None], axis=2) / ab2, 0.0, 1.0)
        out.append(np.min(np.hypot(*(q - u[..., None] * ab[None]).transpose(2, 0, 1)), axis=1))
    return np.concatenate(out)


def _line():
    x = np.linspace(0.0, 3.0, 61)
    return from_poses(np.zeros_like(x), x, 0 * x, 0 * x, cruise_speed=0.4, max_accel=0.5)


def _circle(r=1.5, turn=2 * math.pi):
    a = np.linspace(0.0, turn, int(100 * turn / math.pi) + 1)
    return from_poses(np.zeros_like(a), r * np.sin(a), r * (1 - np.cos(a)), a,
                      cruise_speed=0.4, max_accel=0.5)


def _follow(factory, traj, seconds):
    """The ideal unicycle, odometry at 50 Hz, the robot on the path's start at rest."""
    pc = PlantConfig(dt=0.01, odom_rate=50.0)
    run = simulate_following(pc, TrackerConfig(K=K), traj, int(seconds / 0.01),
                             controller=factory, max_start_distance=0)
    d = _cross_track(run, traj)
    end = traj.sample(traj.t_end)
    return run, d, math.hypot(run.x[-1] - end.x, run.y[-1] - end.y)


def test_rpp_follows_a_line_and_a_full_circle():
    run, d, end = _follow(rpp.make_rpp(_line()), _line(), 12.0)
    assert d.max() < 0.001 and end < 0.26 and run.speed[-1] == 0.0   # stops at 0.25 m
    assert run.cmd_v.max() == pytest.approx(0.5)                     # desired_linear_vel
    # a closed lap (its end is its start: handed as 1 Hz legs)
    run, d, end = _follow(rpp.make_rpp(_circle()), _circle(), 30.0)
    moving = run.speed > 0.05
    assert math.sqrt(np.mean(d[moving] ** 2)) < 0.002 and d.max() < 0.005    # 0.9, 3.1 mm
    assert end < 0.26 and run.speed[-1] == 0.0
    assert run.t[moving][-1] > 18.0                  # went round (9.4 m at <= 0.5 m/s)


def test_mppi_follows_a_line_and_a_half_circle():
    """The bring-up's 2000 x 56 (a few seconds)."""
    fac = mppi.make_mppi(_line(), seed=1)
    made = []
    run, d, end = _follow(lambda tc: made.append(fac(tc)) or made[-1], _line(), 10.0)
    assert d.max() < 0.005 and end < 0.26 and abs(run.speed[-1]) < 0.01     # 1.9 mm
    assert len(made[-1].compute_times) > 100        # a command at 20 Hz
    half = _circle(turn=math.pi)
    run, d, end = _follow(mppi.make_mppi(half, seed=1), half, 16.0)
    moving = run.speed > 0.05
    assert math.sqrt(np.mean(d[moving] ** 2)) < 0.012 and d.max() < 0.02     # 6.7, 10.3 mm
    assert end < 0.26


def test_rpp_command_through_the_smoother():
    """The chain's order: the plugin's (0.5, 0.278) then the smoother from rest: 2.5 * 0.05
    and 3.2 * 0.05."""
    c = rpp.RegulatedPurePursuit(line_path(0.1))
    cmd = c.step(0.0, 0.0, 0.0, REF, 0.0, stamp=0.0)
    assert (cmd.v, cmd.w) == pytest.approx((0.125, 0.16))
    held = c.step(0.0, 0.0, 0.0, REF, 0.0, stamp=0.02)     # before the next 20 Hz tick
    assert held is c.held and (held.v, held.w) == (cmd.v, cmd.w)


def test_mppi_open_loop_and_rolling_delay_in_the_optimizer():
    """Small batch (8): what the variants change.  open_loop: the rollouts start from the
    last command, not the odometry; Rolling's delay: the ring of the commands sent (oldest
    first) replayed in the rollouts' first columns."""
    x = np.linspace(0.0, 3.0, 31)
    traj = from_poses(np.zeros_like(x), x, 0 * x, 0 * x, cruise_speed=0.5, max_accel=0.5)
    stock = mppi.make_mppi(traj, batch_size=8, smoother=False)(None)
    ol = mppi.make_mppi(traj, 'open_loop', batch_size=8, smoother=False)(None)
    for c in (stock, ol):
        c.step(0.0, 0.0, 0.0, REF, 0.3, stamp=0.0)
        first = c.held
        c.step(0.0, 0.0, 0.0, REF, 0.3, stamp=0.05)
        assert np.all(c.last_rollouts['vx'][:, 0] == (0.3 if c is stock else first.v))
    d = mppi.make_mppi(traj, 'rolling_delay', delay=0.15, batch_size=8, smoother=False)(None)
    sent = [d.step(0.0, 0.0, 0.0, REF, 0.0, stamp=0.05 * k).v for k in range(4)]
    assert d.cmd_history[0] == pytest.approx(sent[1:])            # offset 3: the last three
    d.step(0.0, 0.0, 0.0, REF, 0.0, stamp=0.2)
    r = d.last_rollouts['vx']
    assert np.all(r[:, 1] == sent[2]) and np.all(r[:, 2] == sent[3])


def test_rpp_rotates_to_the_goal_heading_at_the_end():
    """At the goal's position 1 rad off its heading: the goal checker waits for the yaw,
    RPP turns in place towards the goal's orientation (shouldRotateToGoalHeading)."""
    c = rpp.RegulatedPurePursuit(line_path(0.0, 0.0, 1.0), smoother=False)
    cmd = c.step(0.95, 0.0, -1.0, REF, 0.0, stamp=0.0)
    assert not c.done and c.rotating and c.has_reached_xy_tolerance
    assert cmd.v == 0.0 and cmd.w == pytest.approx(0.16)
    cmd = c.step(0.95, 0.0, -0.2, REF, 0.0, stamp=0.05)          # within 0.25 rad: done
    assert c.done and (cmd.v, cmd.w) == (0.0, 0.0)


def test_path_helpers_and_mppi_path_handler():
    """geometry_utils.hpp first_after_integrated_distance (first pose past the distance,
    excluded) and min_by (the later of equals); MPPI's transformPath: from the closest pose,
    prune_distance 1.7 m of path inside the local costmap, the poses before it pruned."""
    from benchmarks.peers.nav2_common import closest_pose, first_after_integrated_distance
    xy = line_path(0.0, 0.0, 5.0)
    assert first_after_integrated_distance(xy, 0, len(xy), 0.12) == 3
    assert first_after_integrated_distance(xy, 4, 6, 1.0) == 6            # none: the end
    quarter = np.array([[0.0, 0.0], [0.25, 0.0], [0.5, 0.0], [0.75, 0.0]])
    assert closest_pose(quarter, 0, 4, 0.375, 0.3) == 2                   # 0.25 / 0.5 tie
    c = mppi.MPPI(xy, params=replace(P_MPPI, batch_size=4))
    px, py, _ = c.transform_path(0.52, 0.05)
    assert c.plan_lo == 10 and px[0] == pytest.approx(0.5)
    # 1.7 m of path would reach 2.2; the 3 m local costmap (1.5 m each side of the robot)
    # ends it first: the last pose inside is at 2.0 (2.02 - 0.52 = 1.5 is outside)
    assert px[-1] == pytest.approx(2.0)
    assert c.transform_path(0.2, 0.0)[0][0] == pytest.approx(0.5)         # pruned: no way back
    diag = line_path(0.0, 0.0, 5.0) @ np.array([[1.0, 1.0], [-1.0, 1.0]]) / math.sqrt(2)
    c = mppi.MPPI(diag, params=replace(P_MPPI, batch_size=4))
    px, py, _ = c.transform_path(*diag[10])                               # at 45 deg: inside
    assert c.plan_lo == 10
    assert math.hypot(px[-1] - px[0], py[-1] - py[0]) == pytest.approx(1.7, abs=0.051)
