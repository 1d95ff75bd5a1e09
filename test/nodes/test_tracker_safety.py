"""Tracker safety: malformed inputs are rejected and counted, commands always finite and
within limits (seeded fuzz through the real node callbacks), far initial poses converge."""
import math

import numpy as np
import pytest
import rclpy
from geometry_msgs.msg import AccelStamped, PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.parameter import Parameter

from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.simulation.tracker import Tracker, TrackerConfig
from nonfragile_tracker.control.simulation.reference import RefSample, circle
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.nodes.common import fill_pose, fill_reference, ns_to_stamp
from nonfragile_tracker.nodes.tracker import TrackerNode
from nonfragile_tracker.interface.scenario import paper_plant_config

from conftest import CONFIG

VMAX, WMAX = 0.4, 1.5


@pytest.fixture(scope='module')
def node():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=232)
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    n = TrackerNode(context=ctx, parameter_overrides=[
        Parameter('K', value=[float(v) for v in K.ravel()]),
        Parameter('max_linear_speed', value=VMAX), Parameter('max_angular_speed', value=WMAX)])
    sent = []
    n.pub_cmd.publish = lambda msg: sent.append((msg.linear.x, msg.angular.z))
    n.sent = sent
    yield n
    n.destroy_node()
    rclpy.try_shutdown(context=ctx)


def messages(k, x, y, th, v, ref: RefSample, frame='odom'):
    odom = Odometry()
    odom.header.frame_id = frame
    ns_to_stamp(k * 10_000_000, odom.header.stamp)
    fill_pose(odom.pose.pose, x, y, th if math.isfinite(th) else 0.0)
    if not math.isfinite(th):
        odom.pose.pose.orientation.z = th
    odom.twist.twist.linear.x = v
    parts = (PoseStamped(), TwistStamped(), AccelStamped())
    for m in parts:
        m.header.frame_id = 'odom'
        ns_to_stamp(k * 10_000_000, m.header.stamp)
    fill_reference(ref._replace(heading=0.0), *parts)
    if not math.isfinite(ref.x):
        parts[0].pose.position.x = ref.x
    return odom, parts


def feed(node, odom, parts):
    node._on_ref_pose(parts[0])
    node._on_ref_twist(parts[1])
    node._on_ref_accel(parts[2])
    node._on_odom(odom)


def test_fuzz_commands_finite_and_within_limits(node):
    rng = np.random.default_rng(12345)
    bad_values = [math.nan, math.inf, -math.inf, 1e308, -1e308, 0.0]
    node.sent.clear()
    rejected0 = node.inputs.rejected
    n_bad = 0
    for k in range(1, 4001):
        vals = list(rng.normal(scale=rng.choice([0.1, 1.0, 100.0]), size=11))
        malformed = rng.random() < 0.3
        if malformed:
            vals[rng.integers(0, 11)] = bad_values[rng.integers(0, len(bad_values))]
        ref = RefSample(0.0, *vals[4:10], vals[10])
        odom, parts = messages(k, vals[0], vals[1], vals[2], vals[3], ref)
        if rng.random() < 0.05:           # zero / non-unit quaternion
            q = odom.pose.pose.orientation
            q.x = q.y = q.z = q.w = 0.0 if rng.random() < 0.5 else 0.7
            malformed = True
        if rng.random() < 0.03:            # wrong frame
            odom.header.frame_id = 'map'
            malformed = True
        n_bad += malformed
        feed(node, odom, parts)
    assert len(node.sent) > 2000                      # good samples were acted on
    for v, w in node.sent:
        assert math.isfinite(v) and math.isfinite(w)
        assert abs(v) <= VMAX and abs(w) <= WMAX
    assert node.inputs.rejected - rejected0 > 0.5 * n_bad * 0.5   # malformed ones were counted


def test_stamps_backwards_and_duplicates_are_ignored(node):
    node.sent.clear()
    ref = circle().sample(0.0)
    base = 10_000
    for k in (base, base + 1):
        feed(node, *messages(k, 0.5, 0.0, 1.57, 0.05, ref))
    assert len(node.sent) == 2
    j0 = node.inputs.jumps
    before = node.inputs.rejected
    feed(node, *messages(base + 1, 0.5, 0.0, 1.57, 0.05, ref))      # duplicate: ignored silently
    assert len(node.sent) == 2 and node.inputs.rejected == before
    feed(node, *messages(base - 5, 0.5, 0.0, 1.57, 0.05, ref))      # backwards: rejected
    assert len(node.sent) == 2 and node.inputs.rejected == before + 1
    law = node._law                                # our law (inside the default tuning)
    law.v = 0.9                                                       # a stale compensator
    feed(node, *messages(base + 500, 0.5, 0.0, 1.57, 0.05, ref))    # 4.99 s jump ahead
    assert node.inputs.jumps == j0 + 1 and len(node.sent) == 3
    assert law.v == pytest.approx(0.05, abs=0.05)                     # re-initialised from odom


def test_core_tracker_never_returns_non_finite():
    tr = Tracker(TrackerConfig(K=[[-1, -2, 0, 0], [0, 0, -1, -2]]))
    cmd = tr.step(math.nan, 0.0, 0.0, RefSample(0, 0, 0, 0, 0, 0, 0, 0), 0.1)
    assert (cmd.v, cmd.w) == (0.0, 0.0) and tr.v == 0.1


@pytest.mark.parametrize('dist, heading', [(2.0, math.pi), (2.0, 0.0), (5.0, math.pi)])
def test_converges_from_far_initial_poses(dist, heading):
    """2 m (and 5 m) away, heading opposite to / along the path, at rest: converges."""
    K = read_gain_file(CONFIG / 'tracker_gains.yaml')
    pc = paper_plant_config(x0=0.5 + dist, y0=0.0, th0=math.pi / 2 + heading, v0=0.0)
    tc = TrackerConfig(K=K, max_linear_speed=1.0, max_angular_speed=2.0,
                       delay_compensation=True, A_tau=pc.A_tau, tau=pc.tau)
    run = simulate_tracking(pc, tc, circle(), 12000)
    assert np.abs(run.cmd_v).max() <= 1.0 and np.abs(run.cmd_w).max() <= 2.0
    m = run.metrics()
    assert m.final_error < 1e-3 and m.settling_time < 100
