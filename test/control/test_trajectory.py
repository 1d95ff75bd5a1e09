"""Timed trajectories (control/simulation/trajectory.py): analytic, splines, Hermite, time law, files."""
import math

import numpy as np
import pytest

from conftest import ROOT
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.reference import circle, figure_eight
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.control.simulation.trajectory import (Trajectory, TrajectoryError,
                                                              check_frame, from_poses, from_states,
                                                              from_waypoints, load_waypoints,
                                                              read_waypoint_file, time_law)
from nonfragile_tracker.errors import InputError, exit_code

LAP = ROOT / 'config' / 'trajectories' / 'lap.csv'
K_NF = [[-4.4453, -4.8047, -1.4766, -1.5234], [-1.4766, -1.5234, -4.4453, -4.8047]]
NO_DELAY = dict(A_tau=np.zeros((4, 4)), tau=0.0)


def as_rows(s):
    return np.column_stack([s.t, s.x, s.y, s.vx, s.vy, s.ax, s.ay, s.heading])


@pytest.mark.parametrize('make', [circle, figure_eight])
def test_analytic_trajectory_is_the_path_exactly(make):
    path = make(radius=0.7, rate=0.05, center_x=0.1, center_y=-0.2, phase=0.3)
    tr = Trajectory.analytic(path)
    ts = [0.0, 0.01, 1.23, 17.0, 628.31, -2.0]
    for t in ts:
        assert tr.sample(t) == path.sample(t)          # the same floats
    rows = as_rows(tr.evaluate(ts))
    np.testing.assert_array_equal(rows, np.array([path.sample(t) for t in ts]))
    assert tr.is_analytic and tr.t_end == math.inf


def circle_points(dt=0.1, T=6.0, r=0.5, w=1.0):
    t = np.arange(0.0, T + 1e-12, dt)
    return t, r * np.cos(w * t), r * np.sin(w * t)


def test_cubic_spline_interpolates_and_is_c2():
    t, x, y = circle_points()
    tr = from_waypoints(t, x, y, ends='natural')
    s = tr.evaluate(t)
    np.testing.assert_allclose(s.x, x, atol=1e-12)
    np.testing.assert_allclose(s.y, y, atol=1e-12)
    # C2: velocity and acceleration continuous across every interior knot
    eps = 1e-7
    left, right = tr.evaluate(t[1:-1] - eps), tr.evaluate(t[1:-1] + eps)
    assert np.max(np.abs(left.vx - right.vx)) < 1e-5
    assert np.max(np.abs(left.ax - right.ax)) < 1e-5
    # away from the natural ends the spline reproduces the circle's derivatives
    mid = np.linspace(1.0, 5.0, 101)
    m = tr.evaluate(mid)
    np.testing.assert_allclose(m.vx, -0.5 * np.sin(mid), atol=2e-5)
    np.testing.assert_allclose(m.ay, -0.5 * np.sin(mid), atol=2e-3)
    # heading = direction of travel (counter-clockwise circle: angle + pi/2)
    np.testing.assert_allclose(np.cos(m.heading - (mid + math.pi / 2)), 1.0, atol=1e-8)


def test_rest_ends_and_hold_outside_the_time_range():
    t, x, y = circle_points()
    tr = from_waypoints(t, x, y)                       # default: clamped, at rest
    s = tr.evaluate([t[0], t[-1]])
    np.testing.assert_allclose([s.vx, s.vy], 0.0, atol=1e-12)
    before, after = tr.sample(-3.0), tr.sample(t[-1] + 5.0)
    assert (before.x, before.y) == pytest.approx((x[0], y[0]), abs=1e-12)
    assert (after.x, after.y) == pytest.approx((x[-1], y[-1]), abs=1e-12)
    assert (after.vx, after.vy, after.ax, after.ay) == (0.0, 0.0, 0.0, 0.0)
    # the heading at rest is the heading of the nearest motion, not 0
    assert math.cos(after.heading - tr.sample(t[-1] - 0.05).heading) > 0.99
    assert tr.t_start == 0.0 and tr.t_end == pytest.approx(6.0)


def test_scalar_and_vectorised_agree():
    tr = load_waypoints(LAP)
    ts = np.linspace(-1.0, tr.t_end + 1.0, 2001)
    rows = np.array([tr.sample(float(t)) for t in ts])
    np.testing.assert_allclose(rows, as_rows(tr.evaluate(ts)), rtol=0, atol=1e-12)


def test_quintic_hermite_matches_given_velocity_and_acceleration():
    t = np.array([0.0, 1.0, 2.5, 3.0, 4.2])
    x, y = np.sin(t), t ** 2
    vx, vy, ax, ay = np.cos(t), 2 * t, -np.sin(t), 2 * np.ones_like(t)
    tr = from_states(t, x, y, vx, vy, ax, ay)
    s = tr.evaluate(t)
    for got, want in ((s.x, x), (s.y, y), (s.vx, vx), (s.vy, vy), (s.ax, ax), (s.ay, ay)):
        np.testing.assert_allclose(got, want, atol=1e-12)
    # y = t^2 is a quintic: reproduced exactly between the points too
    mid = np.linspace(0.0, 4.2, 57)
    np.testing.assert_allclose(tr.evaluate(mid).y, mid ** 2, atol=1e-12)
    assert tr.kind == 'quintic Hermite'


def test_backwards_trajectory_heading_is_against_the_velocity():
    t = np.linspace(0.0, 4.0, 9)
    x = -0.25 * t                                       # moving in -x
    y = np.zeros_like(t)
    fwd = from_waypoints(t, x, y, yaw=np.full_like(t, math.pi))
    back = from_waypoints(t, x, y, yaw=np.zeros_like(t))          # facing +x: reversing
    back_speed = from_waypoints(t, x, y, speed=np.full_like(t, -0.25))
    assert math.cos(fwd.sample(2.0).heading - math.pi) == pytest.approx(1.0)
    assert back.sample(2.0).heading == pytest.approx(0.0, abs=1e-12)
    assert back_speed.sample(2.0).heading == pytest.approx(0.0, abs=1e-12)
    assert back.sample(-1.0).heading == pytest.approx(0.0, abs=1e-12)   # at rest: same


def test_backwards_trajectory_is_tracked_backwards():
    t = np.linspace(0.0, 10.0, 21)
    tr = from_waypoints(t, -0.1 * t, 0.02 * t, yaw=np.zeros_like(t))
    pc = PlantConfig(x0=0.0, y0=0.0, th0=0.0, v0=0.0, dt=0.01, **NO_DELAY)
    run = simulate_tracking(pc, TrackerConfig(K=K_NF), tr, 1200)
    assert run.error[-1] < 1e-3
    assert np.min(run.cmd_v) < -0.09                  # drove in reverse
    moving = (run.t > 3.0) & (run.t < 9.0)
    heading = tr.evaluate(run.t[moving]).heading        # ~ -0.197 rad: facing +x, reversing
    assert np.max(np.abs(run.th[moving] - heading)) < 1e-3
    assert np.all(run.cmd_v[moving] < -0.09)


def test_time_law_trapezoid_and_triangle():
    x = np.linspace(0.0, 4.0, 401)
    y = np.zeros_like(x)
    t = time_law(x, y, 0.5, 0.25)
    # accelerate 2 s over 0.5 m, cruise 3 m in 6 s, brake 2 s: 10 s
    assert t[-1] == pytest.approx(10.0)
    assert t[50] == pytest.approx(2.0)                 # x = 0.5 m at the end of the ramp
    v = np.diff(x) / np.diff(t)
    assert v.max() == pytest.approx(0.5, abs=1e-9)
    tt = time_law(x[:41], y[:41], 0.5, 0.25)           # 0.4 m: cannot reach 0.5 m/s
    assert tt[-1] == pytest.approx(2 * math.sqrt(0.4 / 0.25))


def test_path_with_zero_stamps_gets_a_time_law():
    x = np.array([0.0, 1.0, 1.0, 2.0, 3.0])           # a duplicate point is dropped
    y = np.array([0.0, 0.0, 0.0, 0.5, 0.5])
    tr = from_poses(np.zeros(5), x, y, np.zeros(5), cruise_speed=0.4, max_accel=0.5)
    s = tr.evaluate(np.linspace(0.0, tr.t_end, 2001))
    np.testing.assert_allclose([s.vx[0], s.vy[0], s.vx[-1], s.vy[-1]], 0.0, atol=1e-12)
    assert np.max(np.hypot(s.vx, s.vy)) < 0.4 * 1.25   # spline overshoot stays small
    assert len(tr.knots) == 4
    with pytest.raises(TrajectoryError, match='cruise_speed'):
        from_poses(np.zeros(3), x[:3], y[:3], np.zeros(3))


def test_smoothing_spline_for_noisy_points():
    rng = np.random.default_rng(1)
    t, x, y = circle_points(dt=0.05, T=6.0, r=1.0, w=0.5)
    xn, yn = x + 2e-3 * rng.standard_normal(t.size), y + 2e-3 * rng.standard_normal(t.size)
    raw = from_waypoints(t, xn, yn, ends='natural')
    smooth = from_waypoints(t, xn, yn, smoothing=1e-2)
    mid = np.linspace(1.0, 5.0, 400)
    acc_true = 0.25                                   # r w^2
    acc_raw = np.hypot(raw.evaluate(mid).ax, raw.evaluate(mid).ay)
    acc_smooth = np.hypot(smooth.evaluate(mid).ax, smooth.evaluate(mid).ay)
    assert np.max(np.abs(acc_smooth - acc_true)) < 0.05 < 1.0 < np.max(np.abs(acc_raw - acc_true))
    sm = smooth.evaluate(mid)
    assert np.max(np.hypot(sm.x - np.cos(0.5 * mid), sm.y - np.sin(0.5 * mid))) < 1.5e-3


def test_lap_file_is_a_lap_with_a_tight_turn_and_a_straight():
    w = read_waypoint_file(LAP)
    assert w.yaw is not None and w.speed is None
    tr = load_waypoints(LAP)
    s = tr.evaluate(np.linspace(0.0, tr.t_end, 4001))
    speed = np.hypot(s.vx, s.vy)
    assert 0.45 < speed.max() < 0.55
    assert (s.x[0], s.y[0]) == pytest.approx((s.x[-1], s.y[-1]), abs=1e-9)   # closed lap
    moving = speed > 0.05
    rate = np.abs(np.diff(np.unwrap(s.heading)) / np.diff(s.t))[moving[1:]]
    assert 1.0 < rate.max() < 2.0                      # tight turn, within the tracker's 2 rad/s
    pc = PlantConfig(x0=0.0, y0=-0.02, th0=0.0, v0=0.0, dt=0.01, **NO_DELAY)
    run = simulate_tracking(pc, TrackerConfig(K=K_NF), tr, int(round((tr.t_end + 3) / 0.01)))
    m = run.metrics()
    assert m.final_error < 1e-3 and m.rms_error < 0.02
    assert run.cmd_v[-1] == pytest.approx(0.0, abs=1e-3)     # at rest after the end


# ------------------------------------------------------------------------- bad input

def write(tmp_path, name, text):
    p = tmp_path / name
    p.write_text(text)
    return p


@pytest.mark.parametrize('name,text,needle', [
    ('one.csv', 't,x,y\n0,0,0\n', 'at least 2 points'),
    ('order.csv', 't,x,y\n0,0,0\n1,1,0\n1,2,0\n', 'point 2: time t = 1.0'),
    ('nan.csv', 't,x,y\n0,0,0\n1,nan,0\n', "point 1: x = 'nan' is not finite"),
    ('inf.yaml', 'waypoints:\n- {t: 0, x: 0, y: 0}\n- {t: 1, x: .inf, y: 0}\n',
     "point 1: x = inf is not finite"),
    ('word.csv', 't,x,y\n0,0,0\n1,one,0\n', "point 1: x = 'one' is not a number"),
    ('short.csv', 't,x,y\n0,0,0\n1,1\n', 'point 1: 2 values'),
    ('cols.csv', 't,x\n0,0\n1,1\n', "missing column 'y'"),
    ('frame.yaml', 'frame_id: map\nwaypoints:\n- {t: 0, x: 0, y: 0}\n- {t: 1, x: 1, y: 0}\n',
     "frame_id 'map'"),
    ('broken.yaml', 'waypoints: [ {t: 0\n', 'not valid YAML'),
    ('list.yaml', '42\n', 'expected a list'),
    ('empty.csv', '', 'empty file'),
    ('type.txt', 't,x,y\n', "unknown waypoint file type '.txt'"),
])
def test_bad_waypoint_files_name_file_index_and_value(tmp_path, name, text, needle):
    p = write(tmp_path, name, text)
    with pytest.raises(TrajectoryError) as info:
        load_waypoints(p)
    msg = str(info.value)
    assert str(p) in msg and needle in msg
    assert isinstance(info.value, InputError) and exit_code(info.value) == 2


def test_bad_arrays_and_frames():
    with pytest.raises(TrajectoryError, match=r'topic /plan: point 3: vy = inf'):
        from_states([0, 1, 2, 3], [0] * 4, [0] * 4, [0] * 4, [0, 0, 0, math.inf],
                    source='topic /plan')
    with pytest.raises(TrajectoryError, match=r'x has 2 values, expected 3'):
        from_waypoints([0, 1, 2], [0, 1], [0, 1, 2])
    with pytest.raises(TrajectoryError, match=r"frame_id 'map'.*'odom'"):
        check_frame('map', 'odom', 'topic /plan')
    with pytest.raises(TrajectoryError, match='smoothing'):
        from_waypoints([0, 1, 2], [0, 1, 2], [0, 0, 0], smoothing=-1.0)


# ------------------------------------------------------------------------- CLI

def test_cli_trajectory_check_prints_the_summary(capsys):
    from nonfragile_tracker.cli import main
    assert main(['trajectory', 'check', str(LAP)]) == 0
    out = capsys.readouterr().out
    assert '61 points, cubic spline' in out and 'peak speed 0.505 m/s' in out


@pytest.mark.parametrize('text,needle', [
    ('t,x,y\n0,0,0\n', 'at least 2 points'),
    ('t,x,y\n0,0,0\n2,1,0\n1,2,0\n', 'point 2: time t = 1.0 s is not after'),
    ('t,x,y\n0,0,0\n1,inf,0\n', "point 1: x = 'inf' is not finite"),
    ('t;x;y\n0;0;0\n', "missing column 't'"),
])
def test_cli_refuses_bad_trajectories_with_exit_2(tmp_path, capsys, text, needle):
    from nonfragile_tracker.cli import main
    p = write(tmp_path, 'plan.csv', text)
    for argv in (['trajectory', 'check', str(p)],
                 ['run', '--trajectory', str(p), '--out', str(tmp_path / 'runs')]):
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert err.startswith(f'error: {p}: ') and needle in err and 'Traceback' not in err
    assert not (tmp_path / 'runs').exists()             # nothing started
