"""Replanning while driving (control.simulation.replan and the input rule ``replan``), ROS-free:
the time law from a moving start, the nearest point of a new plan (behind, beside, a lap that
comes back), the splice's continuity, and a lap driven on a plan republished every second
through the tracker's input rules, against the same lap given once."""
from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.tracker import Command, TrackerConfig
from nonfragile_tracker.control.simulation.plant import PlantConfig
from nonfragile_tracker.control.simulation.timing import step_time_ns
from nonfragile_tracker.control.simulation.replan import nearest_point, splice_path
from nonfragile_tracker.control.simulation.simulate import run_loop
from nonfragile_tracker.control.simulation.trajectory import TrajectoryError, time_law
from nonfragile_tracker.interface.tracker_inputs import TrackerInputs, input_rules

from conftest import CONFIG

DT = 0.02
CRUISE, ACCEL = 0.4, 0.5


def _hdr(ns=0):
    return NS(stamp=NS(sec=ns // 10 ** 9, nanosec=ns % 10 ** 9), frame_id='odom')


def _pose(x, y, th):
    return NS(position=NS(x=x, y=y, z=0.0),
              orientation=NS(x=0.0, y=0.0, z=math.sin(th / 2), w=math.cos(th / 2)))


def path_msg(x, y):
    yaw = np.arctan2(np.gradient(y), np.gradient(x))
    return NS(header=_hdr(), poses=[NS(header=_hdr(), pose=_pose(a, b, c))
                                    for a, b, c in zip(x, y, yaw)])


def lap(step=0.05, straight=2.0, radius=0.5):
    """A stadium lap (m): two straights, two half circles, counter-clockwise from (0, 0)."""
    s = np.arange(0.0, 2 * straight + 2 * math.pi * radius, step)
    out = []
    for si in s:
        if si < straight:
            out.append((si, 0.0))
        elif si < straight + math.pi * radius:
            a = (si - straight) / radius
            out.append((straight + radius * math.sin(a), radius - radius * math.cos(a)))
        elif si < 2 * straight + math.pi * radius:
            out.append((straight - (si - straight - math.pi * radius), 2 * radius))
        else:
            a = (si - 2 * straight - math.pi * radius) / radius
            out.append((-radius * math.sin(a), radius + radius * math.cos(a)))
    out.append((0.0, 0.0))
    return np.array(out).T


def cross_track(px, py, x, y):
    return np.array([nearest_point(px, py, a, b, search_distance=1e9).distance
                     for a, b in zip(x, y)])


# ------------------------------------------------------------------ pieces
@pytest.mark.parametrize('v0', [0.1, 0.4, 0.7])
def test_the_time_law_from_a_moving_start(v0):
    x = np.linspace(0.0, 3.0, 301)
    t = time_law(x, 0 * x, CRUISE, ACCEL, start_speed=v0)
    s_mid = 0.5 * (x[1:] + x[:-1])
    v = np.diff(x) / np.diff(t)
    assert v[0] == pytest.approx(v0, abs=0.025)       # the mean over the first 1 cm
    assert v.max() <= max(v0, CRUISE) + 1e-9 and v[-1] < 0.05
    a = np.diff(v) / (0.5 * (np.diff(t)[1:] + np.diff(t)[:-1]))
    assert np.abs(a).max() <= ACCEL * 1.02
    assert np.all(np.diff(t) > 0) and s_mid.size == v.size
    assert np.array_equal(time_law(x, 0 * x, CRUISE, ACCEL),
                          time_law(x, 0 * x, CRUISE, ACCEL, start_speed=0.0))


def test_the_nearest_point_of_a_plan_behind_beside_and_coming_back():
    px, py = lap()
    # a plan starting 0.3 m behind the robot, the robot 2 cm to its left
    near = nearest_point(px, py, 0.3, 0.02)
    assert near.s == pytest.approx(0.3) and near.distance == pytest.approx(0.02)
    # the lap's end comes back to (0, 0): with the search near the start only, the start wins
    near = nearest_point(px, py, -0.01, 0.0)
    assert near.s == pytest.approx(0.0) and near.segment == 0
    far = nearest_point(px, py, -0.01, 0.03, search_distance=1e9)
    assert far.s > 5.0                           # the whole lap searched: its end


def test_a_splice_continues_position_and_velocity():
    px, py = lap()
    yaw = np.arctan2(np.gradient(py), np.gradient(px))
    traj, near = splice_path(px, py, yaw, anchor=(0.52, -0.01), t0=7.5, start_speed=0.35,
                             cruise_speed=CRUISE, max_accel=ACCEL)
    assert traj.spliced and traj.t_start == 7.5
    r = traj.sample(7.5)
    assert (r.x, r.y) == pytest.approx((0.52, 0.0), abs=1e-12)
    assert (r.vx, r.vy) == pytest.approx((0.35, 0.0), abs=1e-9)
    assert near.distance == pytest.approx(0.01)
    with pytest.raises(TrajectoryError, match='past the plan'):
        splice_path([0.0, 1.0], [0.0, 0.0], [0.0, 0.0], anchor=(1.5, 0.0), t0=0.0,
                    start_speed=0.2, cruise_speed=CRUISE, max_accel=ACCEL)


# ------------------------------------------------------------------ a lap, replanned
def drive(plans, seconds, *, replan=True):
    """The lap through the tracker's input rules on the unicycle; ``plans(k, x, y)`` gives the
    Path to send before odometry step ``k`` (or None)."""
    config = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'),
                           max_linear_speed=1.0, max_angular_speed=2.0)
    inputs = TrackerInputs(config, input_rules({'cruise_speed': CRUISE, 'max_accel': ACCEL,
                                                'replan': replan}, mode='lockstep'))

    def command(meas, th, k, ref):
        msg = plans(k, meas.x, meas.y)
        if msg is not None:
            inputs.trajectory(msg, 'path', 'planner', defer=True)
        ns = step_time_ns(meas.step, DT)
        odom = NS(header=_hdr(ns), pose=NS(pose=_pose(meas.x, meas.y, th)),
                  twist=NS(twist=NS(linear=NS(x=meas.v, y=0.0, z=0.0),
                                 angular=NS(x=0.0, y=0.0, z=meas.w))))
        step = inputs.odom(odom)
        return step.command if step is not None else Command(0.0, 0.0)

    run = run_loop(PlantConfig(dt=DT), int(seconds / DT), command, lambda k: ref0)
    return run, inputs


ref0 = NS(x=0.0, y=0.0, vx=0.0, vy=0.0)


def planner(px, py, period_steps, rng):
    """Every ``period_steps``: the lap from 0.2 m behind the robot, a 5 mm wiggle, new spacing."""
    s = np.concatenate([[0.0], np.cumsum(np.hypot(np.diff(px), np.diff(py)))])
    done = [0.0]                    # the progress along the lap (the lap's end meets its start)

    def plan(k, x, y):
        if k % period_steps or k == 0:
            return None if k else path_msg(px, py)
        i = min(max(int(np.searchsorted(s, done[0], side='right')) - 1, 0), s.size - 2)
        near = nearest_point(px[i:], py[i:], x, y, search_distance=1.0)
        done[0] = s[i] + near.s
        start = max(done[0] - 0.2, 0.0)
        if s[-1] - start < 0.3:
            return None
        ss = np.arange(start + rng.uniform(0, 0.05), s[-1], 0.05)
        ss = np.append(ss, s[-1])
        x2, y2 = np.interp(ss, s, px), np.interp(ss, s, py)
        wiggle = 0.005 * math.sin(rng.uniform(0, math.tau) + ss[0]) * np.sin(ss)
        nx, ny = -np.gradient(y2), np.gradient(x2)
        nrm = np.hypot(nx, ny)
        return path_msg(x2 + wiggle * nx / nrm, y2 + wiggle * ny / nrm)
    return plan


def test_a_lap_replanned_every_second_drives_on_without_stops_or_lurches():
    px, py = lap()
    once, _ = drive(lambda k, x, y: path_msg(px, py) if k == 0 else None, 22.0)
    rep, inputs = drive(planner(px, py, int(1.0 / DT), np.random.default_rng(0)), 22.0)
    assert inputs.splices >= 15 and inputs.rejected == 0
    for run in (once, rep):                       # the lap completed, at rest at its end
        assert math.hypot(run.x[-1], run.y[-1]) < 0.02 and abs(run.speed[-1]) < 0.02
    moving = (rep.t > 1.5) & (rep.t < 17.0)       # after the start ramp, before the braking
    assert rep.cmd_v[moving].min() > 0.9 * CRUISE           # no stop between plans
    jerk = lambda run: np.abs(np.diff(run.cmd_v[5:])).max()  # noqa: E731 - after the first
    assert jerk(rep) <= 1.15 * ACCEL * DT and jerk(rep) < jerk(once) + 1e-3    # no lurch
    assert np.abs(rep.cmd_v).max() <= CRUISE * 1.05 and np.abs(rep.cmd_w).max() < 2.0
    e_once = cross_track(px, py, once.x[moving], once.y[moving])
    e_rep = cross_track(px, py, rep.x[moving], rep.y[moving])
    rms = lambda e: float(np.sqrt(np.mean(e ** 2)))  # noqa: E731
    assert rms(e_rep) < rms(e_once) + 0.006 and e_rep.max() < e_once.max() + 0.012
    # the same plans without the rule: each one a new run from rest 0.2 m behind the robot
    # (the dips it avoids: the speed falls below half the cruise speed at every plan)
    stop, _ = drive(planner(px, py, int(1.0 / DT), np.random.default_rng(0)), 22.0,
                    replan=False)
    assert stop.cmd_v[moving].min() < 0.5 * CRUISE


# ------------------------------------------------------------------ overridden downstream
def monitored(seconds, scale, tolerance):
    """The lap once, its commands scaled by ``scale(t)`` on the way to the base (a stand-in
    collision monitor); the tracker's own commands and the run."""
    px, py = lap()
    config = TrackerConfig(K=read_gain_file(CONFIG / 'tracker_gains.yaml'),
                           max_linear_speed=1.0, max_angular_speed=2.0)
    inputs = TrackerInputs(config, input_rules({'cruise_speed': CRUISE, 'max_accel': ACCEL,
                                                'override_tolerance': tolerance},
                                               mode='lockstep'))
    sent = []

    def command(meas, th, k, ref):
        if k == 0:
            inputs.trajectory(path_msg(px, py), 'path', 'planner', defer=True)
        odom = NS(header=_hdr(step_time_ns(meas.step, DT)), pose=NS(pose=_pose(meas.x, meas.y, th)),
                  twist=NS(twist=NS(linear=NS(x=meas.v, y=0.0, z=0.0),
                                 angular=NS(x=0.0, y=0.0, z=meas.w))))
        step = inputs.odom(odom)
        c = step.command if step is not None else Command(0.0, 0.0)
        sent.append(c.v)
        g = scale(k * DT)
        return Command(c.v * g, c.w * g)

    run = run_loop(PlantConfig(dt=DT), int(seconds / DT), command, lambda k: ref0)
    return run, inputs, np.array(sent), cross_track(px, py, run.x, run.y)


def test_commands_zeroed_or_scaled_downstream_do_not_wind_up_and_the_lap_resumes():
    def scale(t):                               # stop 4-6 s, half speed 9-11 s
        return 0.0 if 4 <= t < 6 else 0.5 if 9 <= t < 11 else 1.0
    run, inputs, sent, e = monitored(30.0, scale, 0.1)
    assert inputs.override.count >= 2 and not inputs.override.overridden
    assert sent.max() < 1.1 * CRUISE                 # no wind-up while held, no chase after
    held = (run.t >= 4.5) & (run.t < 6.0)
    assert np.abs(run.speed[held]).max() < 1e-9      # (the monitor held it)
    assert e.max() < 0.02                            # back on the lap after each release
    assert math.hypot(run.x[-1], run.y[-1]) < 0.02   # the lap completed, at rest
    after = (run.t >= 6.0) & (run.t < 8.0)
    assert np.abs(np.diff(run.cmd_v[after])).max() <= 1.15 * ACCEL * DT    # a ramp, no leap
    # unwatched, the same stop winds the compensator up: the tracker leaps ahead when released
    run0, _, sent0, e0 = monitored(30.0, scale, 0.0)
    assert sent0.max() > 2 * CRUISE and e0.max() > 0.1
