"""A trajectory starts when the robot can follow it (control.simulation.follow.Follower's start rule).

The tracker that starts following a trajectory after its start stamp (a reference node or
planner that started earlier) re-bases it: the robot drives the trajectory's own speed
profile, it never chases.  A start stamp in the future is waited for at rest; a robot too
far from the start is refused with the distance.
"""
import math

import numpy as np
import pytest

from conftest import CONFIG
from nonfragile_tracker.control.simulation.follow import Follower, simulate_following, start_offset
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.trajectory import from_waypoints, load_waypoints
from nonfragile_tracker.interface.scenario import paper_plant_config

LAP = CONFIG / 'trajectories' / 'lap.csv'


def lap_run(origin_s: float, **kw):
    """3 s of the lap on the paper plant, its clock started at ``origin_s`` (s)."""
    traj = load_waypoints(LAP)
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    pc = paper_plant_config(x0=0.0, y0=0.0, th0=0.0, v0=0.0)
    tc = TrackerConfig(K=K, A_tau=pc.A_tau, tau=pc.tau)
    steps = int(round(3.0 / pc.dt))
    return traj, simulate_following(pc, tc, traj, steps, origin_ns=int(origin_s * 1e9), **kw)


def test_reference_started_5_s_earlier_does_not_make_the_robot_chase():
    """The first second's commanded speed stays within 10 % of the trajectory's profile."""
    traj, run = lap_run(-5.0)          # trajectory time 5 s at the tracker's first step
    first = run.t <= 1.0
    profile = traj.evaluate(np.linspace(0.0, 1.0, 201))
    peak = float(np.hypot(profile.vx, profile.vy).max())
    assert peak > 0.1                  # the lap accelerates within its first second
    assert float(np.abs(run.cmd_v[first]).max()) <= 1.1 * peak
    # on the stamps (the rule before re-basing, no distance check) the robot chases
    _, chase = lap_run(-5.0, start_tolerance=1e9, max_start_distance=0.0)
    assert float(np.abs(chase.cmd_v[first]).max()) > 1.5 * peak


def test_start_offset_rule():
    """Late and at rest: re-based; within the tolerance or in motion: on the stamps."""
    traj = from_waypoints([0.0, 1.0, 2.0], [0.0, 0.5, 1.0], [0.0, 0.0, 0.0], source='t')
    assert start_offset(traj, 0.05) == 0.0          # within the tolerance: on the stamps
    assert start_offset(traj, 3.5) == pytest.approx(3.5)
    moving = from_waypoints([0.0, 1.0, 2.0], [0.0, 0.5, 1.0], [0.0, 0.0, 0.0],
                            speed=[0.5, 0.5, 0.5], yaw=[0.0, 0.0, 0.0], source='t')
    assert start_offset(moving, 3.5) == 0.0        # a replan in motion: on its stamps


def test_future_start_is_waited_for_and_a_far_robot_is_refused():
    """Zero command until a future start; 1.5 m away with a 0.5 m limit: refused."""
    traj = from_waypoints([2.0, 3.0, 4.0], [0.0, 0.5, 1.0], [0.0, 0.0, 0.0], source='plan')
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    f = Follower(Tracker(TrackerConfig(K=K)), traj)
    for t in (0.0, 1.0, 1.99):
        cmd = f.step(0.0, 0.0, 0.0, t, 0.0)
        assert (cmd.v, cmd.w) == (0.0, 0.0) and not f.started
    f.step(0.0, 0.0, 0.0, 2.0, 0.0)
    assert f.started and f.offset == 0.0 and f.refused is None
    far = Follower(Tracker(TrackerConfig(K=K)), traj, max_start_distance=0.5)
    cmd = far.step(1.2, -0.9, 0.0, 2.5, 0.0)
    assert (cmd.v, cmd.w) == (0.0, 0.0)
    assert far.refused is not None and '1.500 m' in far.refused
    assert 'max_start_distance = 0.5 m' in far.refused
    assert far.step(1.2, -0.9, 0.0, 3.0, 0.0).v == 0.0     # stays at rest
    far.set_trajectory(traj)                                # a new trajectory: new start
    assert far.refused is None and not far.started
    assert math.isfinite(far.step(0.0, 0.0, 0.0, 2.0, 0.0).v)


class _Turning:
    """A law that, past the trajectory's end, still asks for a turn at rest (v 1 mm/s)."""

    horizon = 0.0

    def __init__(self, config):
        self.config, self.resets = config, 0

    def reset(self, *args):
        self.resets += 1

    def step(self, x, y, th, ref, measured_speed=None, stamp=None, measured_rate=None):
        from nonfragile_tracker.control.simulation.tracker import Command
        return Command(v=0.001, w=-0.69)


@pytest.mark.parametrize('max_angular_accel', [0.0, 6.0])
def test_the_stop_at_the_end_ramps_within_the_acceleration_limit(max_angular_accel):
    """At rest after the end, the last command (w -0.69 rad/s, a skid-steer's at its lap's
    end) ramps to zero at max_angular_accel (0.12 rad/s per 20 ms step; the run finishes
    when it is there), not in one step (35 rad/s^2); without a limit one zero command."""
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    law = _Turning(TrackerConfig(K=K, max_angular_accel=max_angular_accel))
    traj = from_waypoints([0.0, 1.0], [0.0, 0.0], [0.0, 0.0], source='t')
    f = Follower(law, traj)
    out = []
    for k in range(60):
        out.append(f.step(0.0, 0.0, 0.0, 0.02 * k))
        if f.finished:
            break
    w = np.array([c.w for c in out])
    after = w[int(round(1.0 / 0.02)) + 1:]
    assert after[-1] == 0.0 and f.finished
    if max_angular_accel:
        assert np.abs(np.diff(w)).max() <= 6.0 * 0.02 + 1e-12
        assert f.finished_at == pytest.approx(1.02 + 0.02 * math.ceil(0.69 / 0.12))
        assert np.all(after[1:-1] < 0) and np.all(np.diff(after) > 0)      # toward zero
    else:
        assert after.tolist() == [0.0] and f.finished_at == pytest.approx(1.02)
