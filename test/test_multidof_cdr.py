"""MultiDOFJointTrajectory as CDR bytes made and read with numpy (msgconv.multidof_cdr,
multidof_from_cdr): the same message as rclpy's own (de)serialization, read into the same
trajectory, and any other layout handed back (None) to the message path."""
import struct

import numpy as np
import pytest
from rclpy.serialization import deserialize_message, serialize_message
from trajectory_msgs.msg import MultiDOFJointTrajectory

from nonfragile_tracker.control.simulation.reference import make_path
from nonfragile_tracker.control.simulation.trajectory import TrajectoryError, analytic_knots
from nonfragile_tracker.interface.msgconv import (multidof_arrays, multidof_cdr, multidof_from_cdr,
                                        multidof_to_trajectory)
from nonfragile_tracker.nodes.trajectory_io import followed_to_multidof, states_to_multidof

T_NS, S = analytic_knots(make_path('figure_eight', radius=1.0, rate=0.7), 30.0)


def _ours(k, origin, frame, joint):
    return multidof_cdr(T_NS[:k], S.x[:k], S.y[:k], S.heading[:k], S.vx[:k], S.vy[:k],
                        S.ax[:k], S.ay[:k], origin, frame, joint)


# frame and joint names of every length mod 4 put the first point at both alignments
@pytest.mark.parametrize('frame', ['odom', 'od', 'o', 'odom1', ''])
@pytest.mark.parametrize('joint', ['base_link', 'b', 'base'])
@pytest.mark.parametrize('k', [0, 1, 2, 5])
def test_bytes_are_the_message_rclpy_serializes(frame, joint, k):
    origin = -12_345_678_901 if k == 2 else 12_345_678_901      # a negative stamp too
    msg = states_to_multidof(T_NS[:k], S, origin, frame, joint)
    raw = _ours(k, origin, frame, joint)
    expected = serialize_message(msg)
    assert len(raw) == len(expected)                # (padding bytes are arbitrary in rclpy's)
    assert deserialize_message(raw, MultiDOFJointTrajectory) == msg
    got, ref = multidof_from_cdr(expected), multidof_arrays(msg)
    assert got is not None
    for name in ('t_ns', 'x', 'y', 'quaternion', 'vel', 'acc', 'counts'):
        assert np.array_equal(getattr(got, name), getattr(ref, name)), name
    assert (got.frame_id, got.origin_ns, got.joint_names, got.have_v, got.have_a) == \
        (ref.frame_id, ref.origin_ns, ref.joint_names, ref.have_v, ref.have_a)


def test_read_from_bytes_is_the_trajectory_read_from_the_message():
    """The tracker (raw bytes) and a bag replay (message object) rebuild the same floats."""
    raw = _ours(len(T_NS), 7 * 10**9, 'odom', 'base_link')
    a, origin_a = multidof_to_trajectory(multidof_from_cdr(raw), frame='odom', source='t')
    b, origin_b = multidof_to_trajectory(deserialize_message(raw, MultiDOFJointTrajectory),
                                         frame='odom', source='t')
    assert origin_a == origin_b == 7 * 10**9
    assert np.array_equal(a._pp.c, b._pp.c) and np.array_equal(a.knots, b.knots)
    times = np.linspace(-1.0, 31.0, 777)
    assert np.array_equal(a.evaluate(times).heading, b.evaluate(times).heading)


def test_followed_trajectory_bytes_hold_its_knots():
    traj, _ = multidof_to_trajectory(multidof_from_cdr(_ours(40, 0, 'odom', 'base_link')),
                                     frame='odom', source='t')
    msg = deserialize_message(followed_to_multidof(traj, 10**9, 'odom', header_ns=3 * 10**9),
                              MultiDOFJointTrajectory)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (3, 0)
    assert len(msg.points) == 40
    back, origin = multidof_to_trajectory(msg, frame='odom', source='t')
    assert origin == 3 * 10**9
    assert np.allclose(back.knots + 2.0, traj.knots, atol=1e-9, rtol=0)   # 2 s later origin


def _other_layouts():
    base = states_to_multidof(T_NS[:4], S, 0, 'odom')
    no_acc = states_to_multidof(T_NS[:4], S, 0, 'odom')
    no_acc.points[2].accelerations = []
    two = states_to_multidof(T_NS[:4], S, 0, 'odom')
    two.points[1].transforms = [two.points[1].transforms[0]] * 2
    joints = states_to_multidof(T_NS[:4], S, 0, 'odom')
    joints.joint_names = ['a', 'b']
    raw = serialize_message(base)
    return {'a point without acceleration': serialize_message(no_acc),
            'two transforms': serialize_message(two),
            'truncated': raw[:-8], 'one byte more': raw + b'\x00',
            'big endian': b'\x00\x00' + raw[2:], 'empty': b'',
            'huge count': raw[:4] + struct.pack('<iI', 0, 0) + struct.pack('<I', 2**31)}, joints


def test_any_other_layout_goes_the_message_way():
    others, joints = _other_layouts()
    for name, raw in others.items():
        assert multidof_from_cdr(raw) is None, name
    # two joints are the compact layout, refused with the message path's reason
    with pytest.raises(TrajectoryError, match='2 joints'):
        multidof_to_trajectory(multidof_from_cdr(serialize_message(joints)), frame='odom',
                               source='t')


def test_bad_points_are_refused_with_the_point():
    msg = states_to_multidof(T_NS[:6], S, 0, 'odom')
    msg.points[3].transforms[0].rotation.w = 3.0
    with pytest.raises(TrajectoryError, match='point 3: orientation .* not a unit quaternion'):
        multidof_to_trajectory(multidof_from_cdr(serialize_message(msg)), frame='odom',
                               source='t')
    msg = states_to_multidof(T_NS[:6], S, 0, 'odom')
    msg.points[4].time_from_start = msg.points[3].time_from_start
    with pytest.raises(TrajectoryError, match='point 4: time'):
        multidof_to_trajectory(multidof_from_cdr(serialize_message(msg)), frame='odom',
                               source='t')
    with pytest.raises(TrajectoryError, match='frame'):
        multidof_to_trajectory(multidof_from_cdr(_ours(6, 0, 'map', 'base_link')),
                               frame='odom', source='t')
