"""The reader's fast CDR path gives exactly the fields of a full deserialization."""
from __future__ import annotations

import math

from test_bag_foreign import write_foreign_bag

from conftest import ROOT
from nonfragile_tracker.bag.reader import fast_fields, open_reader
from nonfragile_tracker.bag.writer import jazzy_typestore


def _slow(msg, msgtype, command):
    if msgtype == 'geometry_msgs/msg/Twist':
        return (msg.linear.x, msg.angular.z)
    st = msg.header.stamp.sec * 10 ** 9 + msg.header.stamp.nanosec
    if msgtype == 'nav_msgs/msg/Odometry':
        p = msg.pose.pose
        return (st, p.position.x, p.position.y, p.orientation.x, p.orientation.y,
                p.orientation.z, p.orientation.w, msg.twist.twist.linear.x)
    if msgtype == 'geometry_msgs/msg/PoseStamped':
        p = msg.pose
        return (st, p.position.x, p.position.y, p.orientation.x, p.orientation.y,
                p.orientation.z, p.orientation.w)
    if command and msgtype == 'geometry_msgs/msg/TwistStamped':
        return (st, msg.twist.linear.x, msg.twist.angular.z)
    vec = msg.twist.linear if hasattr(msg, 'twist') else msg.accel.linear
    return (st, vec.x, vec.y)


def test_fast_path_equals_deserialization(tmp_path):
    write_foreign_bag(tmp_path / 'f')                    # frames of several lengths
    ts = jazzy_typestore()
    checked = 0
    for bag in (ROOT / 'test' / 'data' / 'golden_paper', tmp_path / 'f'):
        reader = open_reader(bag)
        try:
            for conn, _, raw in reader.messages():
                for command in (False, True):
                    fast = fast_fields(raw, conn.msgtype, command)
                    if fast is None:
                        continue
                    slow = _slow(ts.deserialize_cdr(raw, conn.msgtype), conn.msgtype, command)
                    assert len(fast) == len(slow)
                    assert all(a == b or (math.isnan(a) and math.isnan(b))
                               for a, b in zip(fast, slow)), (conn.topic, fast, slow)
                    checked += 1
        finally:
            reader.close()
    assert checked > 5000
