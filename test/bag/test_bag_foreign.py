"""Bags from other systems (written here with rosbags) and `bag compare` on an injected 1 mm."""
from __future__ import annotations

import math
import shutil

import numpy as np
import pytest
from rosbags.rosbag2 import Writer
from rosbags.typesys import Stores, get_typestore

from conftest import ROOT
from nonfragile_tracker import cli
from nonfragile_tracker.bag import compare_bags, format_differences
from nonfragile_tracker.bag.compare import parse_tolerance
from nonfragile_tracker.bag.reader import open_reader
from nonfragile_tracker.bag.report import bag_report, format_report
from nonfragile_tracker.bag.writer import BagWriter, jazzy_typestore

TS = get_typestore(Stores.ROS2_JAZZY)
T = TS.types
R, W, DR = 0.5, 0.5, 0.02          # reference radius (m), rate (rad/s), robot radius offset
T0 = 1_700_000_000 * 10 ** 9        # wall-clock stamps, as a real robot has
N = 600                             # 6 s of odometry at 100 Hz
SKIP = {k for k in range(N) if k % 40 == 39}          # odometry without a command
LATE = {k for k in range(N) if k % 50 == 25}          # command 8.5 ms after its odometry


def _time(ns):
    return T['builtin_interfaces/msg/Time'](sec=ns // 10 ** 9, nanosec=ns % 10 ** 9)


def _header(ns, frame):
    return T['std_msgs/msg/Header'](stamp=_time(ns), frame_id=frame)


def _pose(x, y, yaw):
    P, Q = T['geometry_msgs/msg/Point'], T['geometry_msgs/msg/Quaternion']
    return T['geometry_msgs/msg/Pose'](position=P(x=x, y=y, z=0.0),
                                       orientation=Q(x=0.0, y=0.0, z=math.sin(yaw / 2),
                                                     w=math.cos(yaw / 2)))


def _vec(x=0.0, y=0.0, z=0.0):
    return T['geometry_msgs/msg/Vector3'](x=x, y=y, z=z)


def _odom(ns, t, frame='world', child='base_footprint', radius=R + DR):
    cov = np.zeros(36)
    return T['nav_msgs/msg/Odometry'](
        header=_header(ns, frame), child_frame_id=child,
        pose=T['geometry_msgs/msg/PoseWithCovariance'](
            pose=_pose(radius * math.cos(W * t), radius * math.sin(W * t), W * t + math.pi / 2),
            covariance=cov),
        twist=T['geometry_msgs/msg/TwistWithCovariance'](
            twist=T['geometry_msgs/msg/Twist'](linear=_vec(radius * W), angular=_vec(z=W)),
            covariance=cov))


def write_foreign_bag(path, *, reference=True, second_odom=False):
    """A robot's bag: jittery 100 Hz odometry in frame 'world', TwistStamped commands on
    /robot/cmd_stamped (some late, some missing), a 50 Hz reference, IMU and text topics."""
    rng = np.random.default_rng(7)
    stamps = T0 + np.arange(N) * 10_000_000 + rng.integers(-500_000, 500_000, N)
    recv = stamps + 2_000_000
    out = {'stamps': stamps, 'recv': recv, 'cmd_recv': [], 'lat': []}
    with Writer(path, version=9) as w:
        c_odom = w.add_connection('/wheel/odometry', 'nav_msgs/msg/Odometry', typestore=TS)
        c_odom2 = w.add_connection('/visual/odometry', 'nav_msgs/msg/Odometry',
                                   typestore=TS) if second_odom else None
        c_cmd = w.add_connection('/robot/cmd_stamped', 'geometry_msgs/msg/TwistStamped',
                                 typestore=TS)
        c_imu = w.add_connection('/imu/data', 'sensor_msgs/msg/Imu', typestore=TS)
        c_txt = w.add_connection('/rosout_text', 'std_msgs/msg/String', typestore=TS)
        refs = {}
        if reference:
            for name, typ in (('pose', 'PoseStamped'), ('twist', 'TwistStamped'),
                              ('accel', 'AccelStamped')):
                refs[name] = w.add_connection(f'/reference/{name}', f'geometry_msgs/msg/{typ}',
                                              typestore=TS)
        msgs = []                                         # (receive ns, connection, message)
        for k in range(N):
            t = (stamps[k] - T0) * 1e-9
            msgs.append((recv[k], c_odom, _odom(int(stamps[k]), t)))
            if c_odom2 is not None:
                msgs.append((recv[k] + 1000, c_odom2, _odom(int(stamps[k]), t, radius=3.0)))
            if k not in SKIP:
                lat = 8_500_000 if k in LATE else 3_000_000
                cmd = T['geometry_msgs/msg/TwistStamped'](
                    header=_header(int(stamps[k]), 'base_footprint'),
                    twist=T['geometry_msgs/msg/Twist'](linear=_vec(0.25 + 1e-3 * (k % 7)),
                                                       angular=_vec(z=0.5 - 0.3 * (k == 300))))
                msgs.append((recv[k] + lat, c_cmd, cmd))
                out['cmd_recv'].append(recv[k] + lat)
                out['lat'].append(lat * 1e-9)
            if k % 10 == 0:
                msgs.append((recv[k] + 500, c_imu, T['sensor_msgs/msg/Imu'](
                    header=_header(int(stamps[k]), 'imu_link'),
                    orientation=T['geometry_msgs/msg/Quaternion'](x=0.0, y=0.0, z=0.0, w=1.0),
                    orientation_covariance=np.zeros(9), angular_velocity=_vec(z=W),
                    angular_velocity_covariance=np.zeros(9), linear_acceleration=_vec(),
                    linear_acceleration_covariance=np.zeros(9))))
            if k % 100 == 0:
                msgs.append((recv[k] + 700, c_txt, T['std_msgs/msg/String'](data=f'k={k}')))
        if reference:                        # 50 Hz, from 0.1 s before to 0.1 s after
            for j in range(-5, N // 2 + 5):
                ns = T0 + j * 20_000_000
                t = j * 0.02
                c, s = math.cos(W * t), math.sin(W * t)
                hdr = _header(ns, 'odom')
                msgs.append((ns + 1_000_000, refs['pose'], T['geometry_msgs/msg/PoseStamped'](
                    header=hdr, pose=_pose(R * c, R * s, W * t + math.pi / 2))))
                msgs.append((ns + 1_000_001, refs['twist'], T['geometry_msgs/msg/TwistStamped'](
                    header=hdr, twist=T['geometry_msgs/msg/Twist'](
                        linear=_vec(-R * W * s, R * W * c), angular=_vec()))))
                msgs.append((ns + 1_000_002, refs['accel'], T['geometry_msgs/msg/AccelStamped'](
                    header=hdr, accel=T['geometry_msgs/msg/Accel'](
                        linear=_vec(-R * W * W * c, -R * W * W * s), angular=_vec()))))
        for ts, conn, msg in sorted(msgs, key=lambda m: m[0]):
            w.write(conn, int(ts), TS.serialize_cdr(msg, conn.msgtype))
    return out


def test_report_of_a_foreign_bag(tmp_path):
    made = write_foreign_bag(tmp_path / 'robot')
    rep = bag_report(tmp_path / 'robot', plots=False, late_threshold=0.005)
    assert rep.mode == 'realtime'
    assert rep.pose_topic == '/wheel/odometry'
    # the robot runs DR outside the reference circle at the same angle: error DR throughout
    # (interpolating the 50 Hz reference costs < R (W 0.02)^2 / 8 = 2.5e-6 m)
    assert rep.metrics.rms_error == pytest.approx(DR, abs=1e-5)
    assert rep.metrics.final_error == pytest.approx(DR, abs=1e-5)
    assert rep.metrics.peak_abs_w == pytest.approx(0.5)
    assert rep.matched == N                   # every pose stamp is inside the reference span
    st = made['stamps']
    tm = rep.timing
    assert tm.odom_rate == pytest.approx((N - 1) / ((st[-1] - st[0]) * 1e-9), rel=1e-12)
    assert tm.odom_jitter == pytest.approx(np.std(np.diff(st) * 1e-9), rel=1e-9)
    assert tm.command_count == N - len(SKIP)
    cr = made['cmd_recv']
    assert tm.command_rate == pytest.approx((len(cr) - 1) / ((cr[-1] - cr[0]) * 1e-9))
    assert tm.missing_commands == len(SKIP)
    assert tm.late_commands == len(LATE - SKIP)
    assert tm.latency_median == pytest.approx(float(np.median(made['lat'])), abs=1e-12)
    assert tm.latency_max == pytest.approx(0.0085, abs=1e-12)
    # TwistStamped commands echo the odometry stamp, on the recorder's clock
    assert tm.stamp_latency_median == pytest.approx(0.002 + 0.003, abs=1e-12)
    text = format_report(rep)
    for needle in ('realtime', 'odometry rate', 'late commands (> 5 ms)', '/imu/data',
                   'sensor_msgs/msg/Imu', '/robot/cmd_stamped'):
        assert needle in text, needle


def test_foreign_bag_without_reference_reports_timing_and_path(tmp_path, capsys):
    write_foreign_bag(tmp_path / 'noref', reference=False)
    rep = bag_report(tmp_path / 'noref', tmp_path / 'out')
    assert rep.metrics is None and rep.timing.missing_commands == len(SKIP)
    assert rep.path_length == pytest.approx(W * (R + DR) * 5.99, rel=2e-3)
    assert sorted(rep.plots) == ['commands.png', 'xy.png']
    assert cli.main(['bag', 'report', str(tmp_path / 'noref'), '--no-plots']) == 0
    out = capsys.readouterr().out
    assert 'note: no reference (reference/pose + reference/twist + reference/accel, or a ' \
        'nav_msgs/Path): reporting timing and the path only' in out


def test_two_odometry_topics_need_a_choice(tmp_path, capsys):
    write_foreign_bag(tmp_path / 'two', second_odom=True)
    rep = bag_report(tmp_path / 'two', plots=False)
    assert rep.metrics is None and rep.timing is None
    assert any(n.startswith('no odometry') for n in rep.notes)
    assert cli.main(['bag', 'report', str(tmp_path / 'two'), '--no-plots', '--odom',
                     '/visual/odometry']) == 0
    assert 'pose from /visual/odometry' in capsys.readouterr().out
    assert cli.main(['bag', 'report', str(tmp_path / 'two'), '--odom', '/nope']) == 2
    assert "topic '/nope' (given for odom) is not in the bag" in capsys.readouterr().err


def _copy_with_offset(src, dst, topic, index, dx):
    """Copy a bag, adding dx to pose.pose.position.x of message ``index`` on ``topic``."""
    ts = jazzy_typestore()
    reader = open_reader(src)
    try:
        conns = {c.topic: c.msgtype for c in reader.connections}
        msgs = [(c.topic, c.msgtype, t, bytes(raw)) for c, t, raw in reader.messages()]
    finally:
        reader.close()
    seen = 0
    with BagWriter(dst, connections=conns) as w:
        for name, msgtype, t, raw in msgs:
            if name == topic:
                if seen == index:
                    msg = ts.deserialize_cdr(raw, msgtype)
                    msg.pose.pose.position.x += dx
                    raw = bytes(ts.serialize_cdr(msg, msgtype))
                seen += 1
            w.write(name, t, raw)


def test_compare_finds_an_injected_millimetre(tmp_path, capsys):
    golden = ROOT / 'test' / 'data' / 'golden_paper'
    _copy_with_offset(golden, tmp_path / 'new', '/odom', 100, 1e-3)
    cmp = compare_bags(golden, tmp_path / 'new')
    assert cmp.total_differences == 1
    d = cmp.differences[0]
    assert (d.topic, d.index, d.field) == ('/odom', 100, 'pose.pose.position.x')
    assert d.got - d.expected == pytest.approx(1e-3, abs=1e-12)
    assert cmp.summary['/odom'].align == 'stamp' and cmp.summary['/odom'].differing == 1
    text = format_differences(cmp)
    assert f'/odom[100] pose.pose.position.x: expected {d.expected!r}, got {d.got!r}' in text
    assert '/odom [stamp]: expected 251, got 251; 1 of 251 paired messages differ ' \
        '(pose.pose.position.x)' in text
    # the CLI: exit 1 with the diff; 0 with a tolerance above 1 mm; 1 below it
    assert cli.main(['bag', 'compare', str(golden), str(tmp_path / 'new')]) == 1
    assert '/odom[100] pose.pose.position.x' in capsys.readouterr().out
    assert cli.main(['bag', 'compare', str(golden), str(tmp_path / 'new'), '--tol',
                     '/odom.pose.pose.position.x=1.001e-3']) == 0
    assert cli.main(['bag', 'compare', str(golden), str(tmp_path / 'new'), '--tol',
                     'odom.pose.pose.position=0.999e-3']) == 1
    # relative tolerance: |x| is about 0.7 m here, so 2e-3 relative covers 1 mm
    assert cli.main(['bag', 'compare', str(golden), str(tmp_path / 'new'), '--tol',
                     'odom.*.x=0,2e-3']) == 0
    capsys.readouterr()
    assert cli.main(['bag', 'compare', str(golden), str(tmp_path / 'nothing')]) == 2
    assert 'does not exist' in capsys.readouterr().err
    assert cli.main(['bag', 'compare', str(golden), str(golden), '--tol', 'odom.x=abc']) == 2


def test_compare_time_alignment_and_max_diffs(tmp_path):
    write_foreign_bag(tmp_path / 'a')
    shutil.copytree(tmp_path / 'a', tmp_path / 'b')
    cmp = compare_bags(tmp_path / 'a', tmp_path / 'b', align='time', time_tolerance=0.0)
    assert cmp.equal and cmp.summary['/robot/cmd_stamped'].paired == N - len(SKIP)
    _copy_with_offset(ROOT / 'test' / 'data' / 'golden_paper', tmp_path / 'g', '/odom', 5, 1e-3)
    cmp = compare_bags(ROOT / 'test' / 'data' / 'golden_paper',
                       ROOT / 'test' / 'data' / 'golden_delta2', max_differences=3)
    assert len(cmp.differences) == 3 and cmp.total_differences > 100
    assert f'... and {cmp.total_differences - 3} more' in format_differences(cmp)


def test_parse_tolerance():
    assert parse_tolerance('odom.pose.pose.position.x=1e-3') == \
        ('/odom', 'pose.pose.position.x', parse_tolerance('/odom.pose.pose.position.x=1e-3')[2])
    topic, fld, tol = parse_tolerance('cmd_vel=1e-6,1e-3')
    assert (topic, fld, tol.atol, tol.rtol) == ('/cmd_vel', '*', 1e-6, 1e-3)
    for bad in ('odom', 'odom.x=', 'odom.x=-1', 'odom.x=1,2,3', '=1'):
        with pytest.raises(ValueError, match='tolerance'):
            parse_tolerance(bad)


def test_reference_from_a_path_topic(tmp_path):
    """No reference topics but a nav_msgs/Path (a planner's trajectory with stamped poses):
    the reference is interpolated from it, velocities by differences."""
    made = write_foreign_bag(tmp_path / 'p', reference=False)
    from rosbags.rosbag2 import Reader
    with Reader(tmp_path / 'p') as r:
        conns = [(c.topic, c.msgtype) for c in r.connections]
        msgs = [(c.topic, t, bytes(raw)) for c, t, raw in r.messages()]
    poses = []
    for j in range(-5, N // 5 + 5):                       # 20 Hz trajectory samples
        ns, t = T0 + j * 50_000_000, j * 0.05
        poses.append(T['geometry_msgs/msg/PoseStamped'](
            header=_header(ns, 'odom'), pose=_pose(R * math.cos(W * t), R * math.sin(W * t),
                                                   W * t + math.pi / 2)))
    path_msg = T['nav_msgs/msg/Path'](header=_header(T0, 'odom'), poses=poses)
    with Writer(tmp_path / 'withpath', version=9) as w:
        cs = {name: w.add_connection(name, typ, typestore=TS) for name, typ in conns}
        cp = w.add_connection('/plan', 'nav_msgs/msg/Path', typestore=TS)
        w.write(cp, int(made['recv'][0]) - 1, TS.serialize_cdr(path_msg, 'nav_msgs/msg/Path'))
        for topic, t, raw in msgs:
            w.write(cs[topic], t, raw)
    rep = bag_report(tmp_path / 'withpath', plots=False)
    assert rep.metrics is not None and rep.matched == N
    # chord error of a 20 Hz circle: R (W 0.05)^2 / 8 = 3.9e-5 m at most
    assert rep.metrics.rms_error == pytest.approx(DR, abs=5e-5)
    assert not any('no reference' in n for n in rep.notes)
