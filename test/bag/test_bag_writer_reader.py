"""BagWriter / read_bag: round trip of a simulated run, metadata, an independent MCAP reader,
flush policy, run directories and the errors of the reader.

The helpers at the top (``simulated_run``, ``run_messages``, ``write_run_bag``) are reused by
test_bag_repair.py and test_bag_report.py.
"""
from __future__ import annotations

import shutil
import time
from pathlib import Path

import numpy as np
import pytest
import yaml
from geometry_msgs.msg import AccelStamped, PoseStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import serialize_message

from conftest import ROOT
from nonfragile_tracker.interface import topics
from nonfragile_tracker.bag.reader import (BagError, BagNotFoundError, MissingTopicsError,
                                           read_bag, read_messages, resolve_topics)
from nonfragile_tracker.bag.repair import scan_mcap
from nonfragile_tracker.bag.writer import (BagExistsError, BagWriter, make_qos, new_run_dir,
                                           qos_to_dicts)
from nonfragile_tracker.control.simulation.tracker import TrackerConfig
from nonfragile_tracker.control.simulation.timing import step_time_ns
from nonfragile_tracker.control.simulation.model import yaw_to_quaternion
from nonfragile_tracker.control.simulation.reference import make_path
from nonfragile_tracker.control.simulation.simulate import simulate_tracking
from nonfragile_tracker.interface.scenario import paper_plant_config

DT = 0.01
TYPES = {f'/{n}': t for n, t in topics.TYPES.items() if not n.startswith('/')}
RUN = ['/odom', '/pose', '/reference/pose', '/reference/twist', '/reference/accel', '/cmd_vel']


def gain():
    # the paper's ideal plant: the max-decay design (bag_report's test needs a run that
    # settles within 1 cm in 6 s; the shipped default settles at 4.4 s with compensation)
    data = yaml.safe_load((ROOT / 'config' / 'max_decay_gains.yaml').read_text())
    return np.array(data['/**/tracker']['ros__parameters']['K'], float).reshape(2, 4)


def simulated_run(steps: int = 300):
    path = make_path('circle')
    run = simulate_tracking(paper_plant_config(dt=DT), TrackerConfig(K=gain(), dt=DT), path, steps)
    return run, path


def _header(msg, ns: int) -> None:
    msg.header.stamp.sec, msg.header.stamp.nanosec = divmod(ns, 1_000_000_000)
    msg.header.frame_id = topics.ODOM_FRAME


def run_messages(run, path, ns: str = '', skip=(), topics_=RUN):
    """[(topic, timestamp_ns, raw CDR, msg)] of a simulated run in publish order."""
    out = []
    for k in range(run.t.size):
        stamp = step_time_ns(k, DT)
        ref = path.sample(run.t[k])
        odom = Odometry()
        _header(odom, stamp)
        odom.child_frame_id = topics.BASE_FRAME
        p = odom.pose.pose
        p.position.x, p.position.y = float(run.x[k]), float(run.y[k])
        q = yaw_to_quaternion(float(run.th[k]))
        p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w = q
        odom.twist.twist.linear.x = float(run.speed[k])
        pose = PoseStamped()
        _header(pose, stamp)
        pose.pose = p
        rp, rt, ra = PoseStamped(), TwistStamped(), AccelStamped()
        for m in (rp, rt, ra):
            _header(m, stamp)
        rp.pose.position.x, rp.pose.position.y = ref.x, ref.y
        rq = yaw_to_quaternion(ref.heading)
        rp.pose.orientation.z, rp.pose.orientation.w = rq[2], rq[3]
        rt.twist.linear.x, rt.twist.linear.y = ref.vx, ref.vy
        ra.accel.linear.x, ra.accel.linear.y = ref.ax, ref.ay
        cmd = Twist()
        cmd.linear.x, cmd.angular.z = float(run.cmd_v[k]), float(run.cmd_w[k])
        for topic, msg in (('/odom', odom), ('/pose', pose), ('/reference/pose', rp),
                           ('/reference/twist', rt), ('/reference/accel', ra), ('/cmd_vel', cmd)):
            if topic in topics_ and (topic, k) not in skip and topic not in skip:
                out.append((ns + topic, stamp + (1000 if topic == '/cmd_vel' else 0),
                            serialize_message(msg), msg))
    return out


def write_run_bag(bag: Path, run, path, *, ns: str = '', topics_=RUN, skip=(), **kw):
    msgs = run_messages(run, path, ns, skip, topics_)
    conns = {ns + t: TYPES[t] for t in topics_}
    with BagWriter(bag, connections=conns, **kw) as w:
        for topic, stamp, raw, _ in msgs:
            w.write(topic, stamp, raw)
    return msgs


@pytest.fixture(scope='module')
def sim():
    return simulated_run(300)


@pytest.fixture(scope='module')
def sim_bag(sim, tmp_path_factory):
    bag = tmp_path_factory.mktemp('wr') / 'bag'
    msgs = write_run_bag(bag, *sim)
    return bag, msgs


# ---------------------------------------------------------------------------------------------

def test_round_trip_counts_bytes_and_stamps(sim, sim_bag):
    run, path = sim
    bag, msgs = sim_bag
    n = run.t.size
    data = read_bag(bag)
    assert data.counts == {t: n for t in RUN}
    assert data.msgtypes == {t: TYPES[t] for t in RUN}
    for topic in RUN:
        sent = [(s, raw) for t, s, raw, _ in msgs if t == topic]
        assert data.receive_ns[topic].tolist() == [s for s, _ in sent]
    # bytes unchanged: rosbags raw read gives exactly what rclpy serialized
    from rosbags.rosbag2 import Reader
    with Reader(bag) as reader:
        got = [(c.topic, ts, bytes(raw)) for c, ts, raw in reader.messages()]
    assert sorted(got) == sorted((t, s, raw) for t, s, raw, _ in msgs)
    # arrays of the run
    r = data.run
    assert r.pose.topic == '/odom'
    assert np.array_equal(r.pose.t, run.t) and np.array_equal(r.reference.t, run.t)
    assert np.array_equal(r.pose.x, run.x) and np.array_equal(r.pose.y, run.y)
    assert np.allclose(np.angle(np.exp(1j * (r.pose.th - run.th))), 0.0, atol=1e-12)
    assert np.array_equal(r.pose.v, run.speed)
    assert np.array_equal(r.reference.x, run.xd) and np.array_equal(r.reference.vy, run.vyd)
    assert np.array_equal(r.reference.ax, [path.sample(t).ax for t in run.t])
    assert np.array_equal(r.commands.v, run.cmd_v) and np.array_equal(r.commands.w, run.cmd_w)
    assert r.commands.receive_ns.tolist() == [step_time_ns(k, DT) + 1000 for k in range(n)]
    assert data.duplicates == {}
    # read_messages: logical and stored names
    first = next(read_messages(bag, 'odom'))
    assert first[0] == 0 and first[1].pose.pose.position.x == run.x[0]
    assert sum(1 for _ in read_messages(bag, '/cmd_vel')) == n


def test_metadata_yaml_is_rosbag2_v9_mcap(sim_bag):
    bag, msgs = sim_bag
    info = yaml.safe_load((bag / 'metadata.yaml').read_text())['rosbag2_bagfile_information']
    assert info['version'] == 9
    assert info['storage_identifier'] == 'mcap'
    assert info['relative_file_paths'] == ['bag.mcap']
    assert info['message_count'] == len(msgs)
    topics_meta = {t['topic_metadata']['name']: t for t in info['topics_with_message_count']}
    odom = topics_meta['/odom']['topic_metadata']
    assert odom['type'] == 'nav_msgs/msg/Odometry'
    assert odom['type_description_hash'] == \
        'RIHS01_3cc97dc7fb7502f8714462c526d369e35b603cfc34d946e3f2eda2766dfec6e0'
    qos = odom['offered_qos_profiles']       # v9: a YAML list of dicts with policy names
    assert isinstance(qos, list) and len(qos) == 1
    assert qos[0]['reliability'] == 'reliable' and qos[0]['durability'] == 'volatile'
    assert qos[0]['history'] == 'keep_last' and qos[0]['depth'] == topics.DEPTH
    assert qos[0]['deadline'] == {'sec': 0, 'nsec': 0}


def test_independent_mcap_reader_decodes_the_values(sim, sim_bag):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    run, _ = sim
    bag, msgs = sim_bag
    with open(bag / 'bag.mcap', 'rb') as f:
        reader = make_reader(f, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None and summary.statistics.message_count == len(msgs)
        assert summary.chunk_indexes, 'messages are in chunks'
        odom_x, cmd_w, stamps = [], [], []
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            assert schema.encoding == 'ros2msg' and channel.message_encoding == 'cdr'
            if channel.topic == '/odom':
                odom_x.append(decoded.pose.pose.position.x)
                stamps.append(decoded.header.stamp.sec * 10 ** 9 + decoded.header.stamp.nanosec)
                assert message.log_time == stamps[-1]
            elif channel.topic == '/cmd_vel':
                cmd_w.append(decoded.angular.z)
        offered = yaml.safe_load(summary.channels[1].metadata['offered_qos_profiles'])
    assert odom_x == run.x.tolist()
    assert cmd_w == run.cmd_w.tolist()
    assert stamps == [step_time_ns(k, DT) for k in range(run.t.size)]
    assert offered[0]['reliability'] == 'reliable'


def test_never_overwrites(tmp_path):
    bag = tmp_path / 'bag'
    bag.mkdir()
    with pytest.raises(BagExistsError, match='exists already; a bag is never overwritten'):
        BagWriter(bag)
    assert isinstance(BagExistsError('x'), FileExistsError)
    assert list(bag.iterdir()) == []


def test_chunks_reach_the_disk_while_recording(tmp_path, sim):
    msgs = run_messages(*sim)[:600]
    # size-based: 4 KiB chunks
    w = BagWriter(tmp_path / 'a', connections={t: TYPES[t] for t in RUN}, chunk_size=4096,
                  flush_period=None)
    for topic, stamp, raw, _ in msgs:
        w.write(topic, stamp, raw)
    scan = scan_mcap(w.mcap_path)              # what a kill now would leave
    assert not scan.complete and scan.chunks >= 10
    assert len(scan.messages) >= len(msgs) - 4096 // 60
    assert [m.data for m in scan.messages] == [raw for _, _, raw, _ in msgs[:len(scan.messages)]]
    w.close()
    # time-based: a huge chunk size, flush_period 0.05 s
    w = BagWriter(tmp_path / 'b', connections={'/cmd_vel': TYPES['/cmd_vel']},
                  chunk_size=2 ** 20, flush_period=0.05)
    cmds = [m for m in msgs if m[0] == '/cmd_vel']
    w.write('/cmd_vel', cmds[0][1], cmds[0][2])
    assert len(scan_mcap(w.mcap_path).messages) == 0
    time.sleep(0.06)
    w.write('/cmd_vel', cmds[1][1], cmds[1][2])
    assert len(scan_mcap(w.mcap_path).messages) == 2
    w.write('/cmd_vel', cmds[2][1], cmds[2][2])
    assert w.flush() is True and w.flush() is False      # explicit flush (recorder timer)
    assert len(scan_mcap(w.mcap_path).messages) == 3
    w.close()
    assert read_bag(tmp_path / 'b', strict=False).counts == {'/cmd_vel': 3}


def test_new_run_dir_is_fresh_and_contained(tmp_path):
    a = new_run_dir(tmp_path / 'runs')
    assert a.is_dir() and a.parent == tmp_path / 'runs'
    assert a.name.startswith('run_') and len(a.name) == len('run_20250101_120000')
    b = new_run_dir(tmp_path / 'runs', 'circle')
    c = new_run_dir(tmp_path / 'runs', 'circle')
    assert (b.name, c.name) == ('circle', 'circle_1')
    for bad in ('../x', 'a/b', '..', '', 'x/../y', '/abs'):
        with pytest.raises(BagError, match='run name'):
            new_run_dir(tmp_path / 'runs', bad)
    assert sorted(p.name for p in (tmp_path / 'runs').iterdir()) == sorted([a.name, 'circle',
                                                                            'circle_1'])


def test_offered_qos_is_stored_and_read_back(tmp_path):
    q = make_qos(history='keep_last', depth=1, reliability='best_effort',
                 durability='transient_local', deadline_ns=2 ** 63 - 1, liveliness='automatic')
    with BagWriter(tmp_path / 'q', connections={'/run_done': ('std_msgs/msg/UInt64', [q])}) as w:
        w.write('/run_done', 5, b'\x00\x01\x00\x00' + (300).to_bytes(8, 'little'))
    data = read_bag(tmp_path / 'q', strict=False)
    assert data.offered_qos['/run_done'] == [q]
    assert qos_to_dicts([q])[0]['deadline'] == {'sec': 9223372036, 'nsec': 854775807}
    assert next(read_messages(tmp_path / 'q', 'run_done'))[1].data == 300
    with pytest.raises(ValueError, match='not one of'):
        make_qos(reliability='sometimes')


def test_namespaced_topics_and_repeated_stamps(tmp_path, sim):
    run, path = sim
    msgs = run_messages(run, path, ns='/robot1')
    dup = [m for m in msgs if m[0] == '/robot1/odom'][:5]        # republished steps
    with BagWriter(tmp_path / 'ns', connections={'/robot1' + t: TYPES[t] for t in RUN}) as w:
        for topic, stamp, raw, _ in msgs:
            w.write(topic, stamp, raw)
        for topic, stamp, raw, _ in dup:
            w.write(topic, stamp + 1, raw)
    data = read_bag(tmp_path / 'ns')
    assert data.topic_map['odom'] == '/robot1/odom'
    assert data.topic_map['reference/pose'] == '/robot1/reference/pose'
    assert data.counts['/robot1/odom'] == run.t.size + 5
    assert data.duplicates == {'/robot1/odom': 5}
    assert np.array_equal(data.run.pose.x, run.x)
    assert resolve_topics(['/a/odom', '/a/cmd_vel', '/b/odom'], ['odom', 'cmd_vel']) == \
        {'odom': '/a/odom', 'cmd_vel': '/a/cmd_vel'}
    assert resolve_topics(['/b/odom'], ['odom'], namespace='/b') == {'odom': '/b/odom'}


def test_reader_errors_say_what_to_do(tmp_path, sim_bag):
    bag, _ = sim_bag
    with pytest.raises(BagNotFoundError, match='does not exist'):
        read_bag(tmp_path / 'nope')
    (tmp_path / 'empty').mkdir()
    with pytest.raises(BagError, match='neither metadata.yaml nor a .mcap'):
        read_bag(tmp_path / 'empty')
    (tmp_path / 'file').write_text('x')
    with pytest.raises(BagError, match='is a file'):
        read_bag(tmp_path / 'file')
    cut = tmp_path / 'cut'
    cut.mkdir()
    data = (bag / 'bag.mcap').read_bytes()
    (cut / 'cut.mcap').write_bytes(data[:len(data) // 2])
    with pytest.raises(BagError, match=r'nonfragile_tracker bag repair .*cut'):
        read_bag(cut)
    with pytest.raises(BagError, match='truncated'):
        next(read_messages(cut, 'odom'))
    shutil.copytree(bag, tmp_path / 'nometa')                    # complete MCAP, no yaml
    (tmp_path / 'nometa' / 'metadata.yaml').unlink()
    assert read_bag(tmp_path / 'nometa').counts['/odom'] == 301
    part = tmp_path / 'part'
    with BagWriter(part, connections={'/odom': TYPES['/odom'],
                                      '/clock': 'rosgraph_msgs/msg/Clock'}):
        pass
    with pytest.raises(MissingTopicsError) as exc:
        read_bag(part)
    text = str(exc.value)
    for name in ('reference/pose', 'reference/twist', 'reference/accel', 'cmd_vel'):
        assert name in text and name in exc.value.missing
    assert 'odom' not in exc.value.missing
    with pytest.raises(MissingTopicsError, match="no topic 'pose'"):
        next(read_messages(part, 'pose'))
    assert read_bag(part, strict=False).missing == exc.value.missing
    with BagWriter(tmp_path / 'w') as w:
        with pytest.raises(BagError, match='no connection for topic'):
            w.write('/odom', 0, b'')
        with pytest.raises(BagError, match='not a ROS 2 Jazzy type'):
            w.add_connection('/x', 'my_msgs/msg/Unknown')
    with pytest.raises(BagError, match='is closed'):
        w.write('/odom', 0, b'')
