"""Damaged and foreign bags: a clear error (exit 2, no traceback) or a repaired read."""
from __future__ import annotations

import shutil

import pytest
from mcap.writer import CompressionType, Writer as McapWriter

from conftest import ROOT
from nonfragile_tracker import cli
from nonfragile_tracker.bag import BagError, bag_report, compare_bags, read_bag, repair_bag, replay
from nonfragile_tracker.bag.reader import open_reader
from nonfragile_tracker.errors import InputError

GOLDEN = ROOT / 'test' / 'data' / 'golden_paper'


def _golden_records():
    reader = open_reader(GOLDEN)
    try:
        conns = {c.topic: (c.msgtype, c.msgdef.data) for c in reader.connections}
        msgs = [(c.topic, t, bytes(raw)) for c, t, raw in reader.messages()]
    finally:
        reader.close()
    return conns, msgs


def write_mcap(path, *, profile='', schema_encoding='ros2msg', message_encoding='cdr',
               compression=CompressionType.ZSTD, chunk_size=1024 * 1024):
    """An MCAP as another recorder writes it: the `mcap` writer, no metadata.yaml."""
    conns, msgs = _golden_records()
    path.parent.mkdir(parents=True, exist_ok=True)
    with open(path, 'wb') as f:
        w = McapWriter(f, compression=compression, chunk_size=chunk_size)
        w.start(profile=profile, library='someone-else')
        ids = {}
        for topic, (msgtype, msgdef) in conns.items():
            sid = w.register_schema(name=msgtype, encoding=schema_encoding, data=msgdef.encode())
            ids[topic] = w.register_channel(topic=topic, message_encoding=message_encoding,
                                            schema_id=sid)
        for topic, t, raw in msgs:
            w.add_message(channel_id=ids[topic], log_time=t, data=raw, publish_time=t)
        w.finish()
    return len(msgs)


def _cli_error(args, capsys):
    code = cli.main(args)
    err = capsys.readouterr().err
    assert 'Traceback' not in err
    return code, err


@pytest.mark.parametrize('make, needle', [
    (lambda p: p.mkdir(), 'holds neither metadata.yaml nor a .mcap file'),
    (lambda p: (p.mkdir(), (p / 'x.mcap').touch()), 'is truncated'),
    (lambda p: (p.mkdir(), (p / 'x.mcap').write_bytes(b'\x00garbage' * 100)), 'is truncated'),
    (lambda p: p.write_text('hello'), 'is a file, not a bag directory'),
    (lambda p: (shutil.copytree(GOLDEN, p), (p / 'metadata.yaml').write_text('a: [')),
     'Could not load YAML'),
    (lambda p: (p.mkdir(), shutil.copy(GOLDEN / 'metadata.yaml', p / 'metadata.yaml')),
     'metadata.yaml names storage files that are not there'),
])
def test_unreadable_inputs_are_clear_errors(tmp_path, capsys, make, needle):
    bag = tmp_path / 'bag'
    make(bag)
    for fn in (read_bag, bag_report, replay, lambda p: compare_bags(GOLDEN, p)):
        with pytest.raises(InputError, match=needle):
            fn(bag)
    for args in (['bag', 'report', str(bag)], ['bag', 'compare', str(GOLDEN), str(bag)],
                 ['bag', 'replay', str(bag)]):
        code, err = _cli_error(args, capsys)
        assert code == 2 and err.startswith('error: ') and needle in err, (args, err)


def test_truncated_bag_is_repaired_and_read(tmp_path, capsys):
    n = write_mcap(tmp_path / 'cut' / 'run.mcap', compression=CompressionType.NONE,
                   chunk_size=20_000)
    data = (tmp_path / 'cut' / 'run.mcap').read_bytes()
    (tmp_path / 'cut' / 'run.mcap').write_bytes(data[:int(len(data) * 0.8)])
    with pytest.raises(BagError, match='bag repair'):
        read_bag(tmp_path / 'cut')
    res = repair_bag(tmp_path / 'cut')
    assert 0 < res.total < n
    assert read_bag(res.output, strict=False).message_count == res.total
    code, err = _cli_error(['bag', 'repair', str(tmp_path / 'cut')], capsys)
    assert code == 2 and 'exists already' in err          # never overwritten


def test_bag_without_metadata_is_read_directly_and_repaired(tmp_path):
    """A recorder's bag whose metadata.yaml was lost (needs reindexing): the complete MCAP
    is read directly, and `repair` rebuilds metadata.yaml without losing a message."""
    shutil.copytree(GOLDEN, tmp_path / 'nometa')
    (tmp_path / 'nometa' / 'metadata.yaml').unlink()
    assert compare_bags(GOLDEN, tmp_path / 'nometa').equal
    res = repair_bag(tmp_path / 'nometa')
    assert res.complete_source and res.discarded_bytes == 0
    assert compare_bags(GOLDEN, res.output).equal
    assert (res.output / 'metadata.yaml').exists()


def test_damaged_metadata_is_rebuilt(tmp_path):
    shutil.copytree(GOLDEN, tmp_path / 'badmeta')
    (tmp_path / 'badmeta' / 'metadata.yaml').write_text('rosbag2_bagfile_information: 3\n')
    with pytest.raises(BagError):
        read_bag(tmp_path / 'badmeta')
    res = repair_bag(tmp_path / 'badmeta')
    assert compare_bags(GOLDEN, res.output).equal


def test_mcap_from_another_recorder(tmp_path, capsys):
    """`mcap` writer, ros2msg schemas, no ros2 profile and no metadata.yaml."""
    n = write_mcap(tmp_path / 'other' / 'recording.mcap')
    with pytest.raises(BagError, match='bag repair'):
        read_bag(tmp_path / 'other')
    code, err = _cli_error(['bag', 'report', str(tmp_path / 'other')], capsys)
    assert code == 2 and 'rewrites it as a rosbag2 bag' in err
    res = repair_bag(tmp_path / 'other' / 'recording.mcap')        # the file itself
    assert res.output == tmp_path / 'other' / 'recording_repaired' and res.total == n
    assert compare_bags(GOLDEN, res.output).equal
    rep = bag_report(res.output, plots=False)
    assert rep.mode == 'lockstep' and rep.matched == 251
    # with the ros2 profile rosbags reads the file as it is
    write_mcap(tmp_path / 'ros2' / 'r.mcap', profile='ros2')
    assert compare_bags(GOLDEN, tmp_path / 'ros2' / 'r.mcap').equal


def test_mcap_without_ros2_data_is_refused_clearly(tmp_path, capsys):
    write_mcap(tmp_path / 'json' / 'j.mcap', schema_encoding='jsonschema',
               message_encoding='json')
    with pytest.raises(BagError, match=r'no ROS 2 data: /cmd_vel \(json messages, '
                       r'jsonschema schema\)'):
        repair_bag(tmp_path / 'json')
    code, err = _cli_error(['bag', 'repair', str(tmp_path / 'json' / 'j.mcap')], capsys)
    assert code == 2 and 'only MCAP channels with cdr messages and ros2msg schemas' in err


def test_empty_bag_reports_nothing_to_report(tmp_path, capsys):
    from nonfragile_tracker.bag.writer import BagWriter
    with BagWriter(tmp_path / 'empty', connections={'/odom': 'nav_msgs/msg/Odometry'}):
        pass
    with pytest.raises(BagError, match='nothing to report'):
        bag_report(tmp_path / 'empty')
    code, err = _cli_error(['bag', 'report', str(tmp_path / 'empty')], capsys)
    assert code == 2 and 'no odometry' in err


def test_custom_message_types_are_compared_from_the_bags_definitions(tmp_path):
    """A robot's own message type (not in the Jazzy typestore) is read with the definition
    stored in the bag, and compared field by field."""
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    from nonfragile_tracker.bag.writer import BagWriter
    msgdef = 'float64 battery\nstring mode\n'
    ts = get_typestore(Stores.ROS2_JAZZY)
    ts.register(get_types_from_msg(msgdef, 'my_msgs/msg/Status'))
    Status = ts.types['my_msgs/msg/Status']
    for name, last in (('a', 0.5), ('b', 0.5 + 1e-3)):
        with BagWriter(tmp_path / name) as w:
            w.add_connection('/status', 'my_msgs/msg/Status', msgdef=msgdef)
            for i, bat in enumerate((0.9, 0.8, last)):
                w.write('/status', i * 10 ** 8, bytes(ts.serialize_cdr(
                    Status(battery=bat, mode='auto'), 'my_msgs/msg/Status')))
    cmp = compare_bags(tmp_path / 'a', tmp_path / 'b')
    assert cmp.total_differences == 1
    d = cmp.differences[0]
    assert (d.topic, d.index, d.field, d.expected) == ('/status', 2, 'battery', 0.5)
    assert compare_bags(tmp_path / 'a', tmp_path / 'b', tolerances=['status.battery=2e-3']).equal
