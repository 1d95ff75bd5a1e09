"""repair_bag: bags cut at many byte offsets (a killed recorder) are recovered chunk by chunk."""
from __future__ import annotations

import shutil
from io import BytesIO

import pytest
import yaml
from mcap.data_stream import ReadDataStream
from mcap.reader import make_reader
from mcap.records import Chunk, Message
from mcap.stream_reader import breakup_chunk
from test_bag_writer_reader import RUN, TYPES, run_messages, simulated_run

from nonfragile_tracker.bag.errors import BagError
from nonfragile_tracker.bag.reader import BagNotFoundError, read_bag, read_messages
from nonfragile_tracker.bag.repair import repair_bag, scan_mcap
from nonfragile_tracker.bag.writer import BagExistsError, BagWriter, make_qos


@pytest.fixture(scope='module')
def source(tmp_path_factory):
    run, path = simulated_run(200)
    bag = tmp_path_factory.mktemp('rp') / 'bag'
    best_effort = make_qos(reliability='best_effort', depth=7)
    msgs = run_messages(run, path)
    conns = {t: TYPES[t] for t in RUN}
    conns['/cmd_vel'] = (TYPES['/cmd_vel'], [best_effort])
    with BagWriter(bag, connections=conns, chunk_size=8192) as w:
        for topic, stamp, raw, _ in msgs:
            w.write(topic, stamp, raw)
    data = (bag / 'bag.mcap').read_bytes()
    # chunk layout from the summary, read with the mcap package (independent of repair.py)
    with open(bag / 'bag.mcap', 'rb') as f:
        summary = make_reader(f).get_summary()
    chunks = []
    for ci in sorted(summary.chunk_indexes, key=lambda c: c.chunk_start_offset):
        stream = ReadDataStream(BytesIO(data[ci.chunk_start_offset + 9:
                                             ci.chunk_start_offset + ci.chunk_length]))
        n = sum(isinstance(r, Message) for r in breakup_chunk(Chunk.read(stream)))
        chunks.append((ci.chunk_start_offset + ci.chunk_length, n))
    return bag, msgs, data, chunks, best_effort


def _cut_copy(tmp_path, data: bytes, cut: int):
    bag = tmp_path / f'cut{cut}'
    bag.mkdir()
    (bag / f'cut{cut}.mcap').write_bytes(data[:cut])     # no metadata.yaml, like a SIGKILL
    return bag


def test_cuts_recover_every_complete_chunk(tmp_path, source):
    bag, msgs, data, chunks, best_effort = source
    assert len(chunks) >= 8
    ends = [e for e, _ in chunks]
    cuts = sorted({ends[0] - 1, ends[0], ends[0] + 5, ends[2] + 100, ends[len(ends) // 2],
                   ends[-2] + 1, ends[-1], len(data) - 9, len(data) - 1})
    for cut in cuts:
        cbag = _cut_copy(tmp_path, data, cut)
        with pytest.raises(BagError, match='bag repair'):
            read_bag(cbag)
        expected = sum(n for end, n in chunks if end <= cut)
        if cut < ends[0]:                       # not even the first chunk is complete
            with pytest.raises(BagError, match='nothing recoverable'):
                repair_bag(cbag)
            continue
        res = repair_bag(cbag)
        assert res.output == tmp_path / f'cut{cut}_repaired'
        assert res.total >= expected > 0 and res.total == expected, cut
        # recovered = a prefix of what was written, same bytes and timestamps
        got = [(t, s, bytes(raw)) for t, s, raw in _raw(res.output)]
        assert got == [(t, s, raw) for t, s, raw, _ in msgs[:res.total]], cut
        info = yaml.safe_load((res.output / 'metadata.yaml').read_text())
        info = info['rosbag2_bagfile_information']
        assert info['version'] == 9 and info['storage_identifier'] == 'mcap'
        assert info['message_count'] == res.total
        assert res.qos_recovered['/cmd_vel']
        assert read_bag(res.output, strict=False).offered_qos['/cmd_vel'] == [best_effort]
        assert res.complete_source is False and 0 <= res.discarded_bytes < cut


def _raw(bag):
    from rosbags.rosbag2 import Reader
    with Reader(bag) as reader:
        return [(c.topic, ts, raw) for c, ts, raw in reader.messages()]


def test_repaired_bag_is_a_complete_run(tmp_path, source):
    bag, msgs, data, chunks, _ = source
    cbag = _cut_copy(tmp_path, data, chunks[-3][0] + 10)
    res = repair_bag(cbag, tmp_path / 'fixed')
    assert res.output == tmp_path / 'fixed'
    counts = {t: sum(1 for m in msgs[:res.total] if m[0] == t) for t in RUN}
    assert res.counts == counts
    assert read_bag(res.output).counts == counts
    stamps = [s for s, _ in read_messages(res.output, '/odom')]
    assert stamps == [m[1] for m in msgs[:res.total] if m[0] == '/odom']
    assert 'messages in' in res.summary() and scan_mcap(res.output / 'fixed.mcap').complete


def test_missing_metadata_with_complete_mcap(tmp_path, source):
    bag, msgs, *_ = source
    shutil.copytree(bag, tmp_path / 'nometa')
    (tmp_path / 'nometa' / 'metadata.yaml').unlink()
    res = repair_bag(tmp_path / 'nometa')
    assert res.complete_source and res.discarded_bytes == 0 and res.problems == ()
    assert res.total == len(msgs)
    assert [(t, s, bytes(r)) for t, s, r in _raw(res.output)] == \
        [(t, s, r) for t, s, r, _ in msgs]


def test_repair_errors(tmp_path, source):
    bag, msgs, data, chunks, _ = source
    with pytest.raises(BagError, match='nothing to repair'):
        repair_bag(bag)
    with pytest.raises(BagNotFoundError, match='does not exist'):
        repair_bag(tmp_path / 'nope')
    early = _cut_copy(tmp_path, data, 40)                   # before the first chunk ends
    with pytest.raises(BagError, match='nothing recoverable'):
        repair_bag(early)
    cbag = _cut_copy(tmp_path, data, chunks[1][0])
    (tmp_path / 'taken').mkdir()
    with pytest.raises(BagExistsError, match='never overwritten'):
        repair_bag(cbag, tmp_path / 'taken')
    assert list((tmp_path / 'taken').iterdir()) == []
    repair_bag(cbag)
    with pytest.raises(BagExistsError):                     # default output now exists
        repair_bag(cbag)
