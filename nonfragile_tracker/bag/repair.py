"""Recover a bag whose recorder died without closing it (SIGKILL, power loss of the node).

:func:`repair_bag` keeps every complete MCAP record of the file (complete chunks unpacked
with the ``mcap`` package), stops at the first incomplete or damaged one and writes a new,
properly closed bag (default ``<path>_repaired``; never overwrites) with the same topics,
types, QoS profiles, timestamps and bytes.  An MCAP without a readable metadata.yaml and
another recorder's MCAP are rebuilt the same way; a complete, readable bag is refused.

See doc/bags.md, section "Robust reading and repair".
"""
from __future__ import annotations

import os
import struct
from dataclasses import dataclass, field
from io import BytesIO
from pathlib import Path

from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, Chunk, Message, Schema
from mcap.stream_reader import breakup_chunk
from rosbags.interfaces import Qos
from rosbags.rosbag2.errors import ReaderError
from rosbags.rosbag2.metadata import parse_qos

from .errors import BagError, BagExistsError
from .reader import MCAP_MAGIC, bag_location, mcap_is_complete, open_reader
from .writer import BagWriter

__all__ = ['BagError', 'McapScan', 'RepairResult', 'scan_mcap', 'repair_bag']

_RECORD_HEADER = 9          # opcode (1 byte) + record length (uint64)


@dataclass
class McapScan:
    """What survived in one MCAP file: schemas, channels and messages in file order."""

    path: Path
    size: int
    complete: bool                       # footer and end magic present
    schemas: dict[int, Schema] = field(default_factory=dict)
    channels: dict[int, Channel] = field(default_factory=dict)
    messages: list[Message] = field(default_factory=list)
    chunks: int = 0                      # complete chunks unpacked
    valid_bytes: int = 0                 # bytes up to the end of the last usable record
    problem: str = ''                    # why scanning stopped early ('' = clean end)

    @property
    def discarded_bytes(self) -> int:
        """Bytes after the last valid record (dropped by a repair)."""
        return self.size - self.valid_bytes


def _take(scan: McapScan, record: object) -> None:
    if isinstance(record, Schema):
        scan.schemas.setdefault(record.id, record)
    elif isinstance(record, Channel):
        scan.channels.setdefault(record.id, record)
    elif isinstance(record, Message):
        scan.messages.append(record)


def scan_mcap(path: str | os.PathLike[str]) -> McapScan:
    """Read every complete record of an MCAP file, tolerating a cut anywhere.

    Parameters
    ----------
    path : path-like
        The MCAP file.

    Returns
    -------
    McapScan
        Schemas, channels and messages of the complete records, and where the valid
        part ends.

    Raises
    ------
    BagError
        If the file does not start with the MCAP magic.
    """
    p = Path(path)
    data = p.read_bytes()
    scan = McapScan(path=p, size=len(data), complete=False)
    if len(data) < len(MCAP_MAGIC):
        scan.problem = f'file is {len(data)} bytes: the recorder died before writing anything'
        return scan
    if data[:len(MCAP_MAGIC)] != MCAP_MAGIC:
        raise BagError(f'{p} is not an MCAP file (no MCAP magic at the start)')
    pos = len(MCAP_MAGIC)
    scan.valid_bytes = pos
    in_summary = False
    while True:
        if pos + _RECORD_HEADER > len(data):
            if pos < len(data):
                scan.problem = f'incomplete record header at byte {pos}'
            break
        opcode = data[pos]
        (length,) = struct.unpack_from('<Q', data, pos + 1)
        end = pos + _RECORD_HEADER + length
        if end > len(data):
            scan.problem = (f'record (opcode 0x{opcode:02x}) at byte {pos} needs {length} bytes, '
                            f'only {len(data) - pos - _RECORD_HEADER} were written')
            break
        body = data[pos + _RECORD_HEADER:end]
        try:
            stream = ReadDataStream(BytesIO(body))
            if opcode == Opcode.CHUNK:
                chunk_records = breakup_chunk(Chunk.read(stream), validate_crc=True)
                for rec in chunk_records:
                    _take(scan, rec)
                scan.chunks += 1
            elif opcode == Opcode.SCHEMA:
                _take(scan, Schema.read(stream))
            elif opcode == Opcode.CHANNEL:
                _take(scan, Channel.read(stream))
            elif opcode == Opcode.MESSAGE and not in_summary:
                _take(scan, Message.read(stream, length))
            elif opcode == Opcode.DATA_END:
                in_summary = True
            elif opcode == Opcode.FOOTER:
                scan.valid_bytes = end
                scan.complete = data[end:end + len(MCAP_MAGIC)] == MCAP_MAGIC
                if scan.complete:
                    scan.valid_bytes = end + len(MCAP_MAGIC)
                break
        except (McapError, ValueError, struct.error, UnicodeDecodeError) as exc:
            scan.problem = f'damaged record (opcode 0x{opcode:02x}) at byte {pos}: {exc}'
            break
        pos = end
        scan.valid_bytes = pos
    return scan


@dataclass(frozen=True)
class RepairResult:
    """Outcome of :func:`repair_bag`: the new bag and what it holds."""

    source: Path
    output: Path
    counts: dict[str, int]               # topic -> messages recovered
    msgtypes: dict[str, str]
    qos_recovered: dict[str, bool]       # topic -> offered QoS taken from the MCAP channel
    chunks: int
    complete_source: bool                # source MCAP was complete (only metadata was missing)
    discarded_bytes: int
    orphan_messages: int                 # messages whose channel record was lost
    problems: tuple[str, ...]

    @property
    def total(self) -> int:
        """Messages written to the repaired bag, all topics."""
        return sum(self.counts.values())

    def summary(self) -> str:
        """What was recovered: messages per topic, chunks, bytes discarded, notes."""
        lines = [f'repaired {self.source} -> {self.output}: {self.total} messages in '
                 f'{self.chunks} chunks, {self.discarded_bytes} bytes discarded']
        lines += [f'  {t}  {self.msgtypes[t]}  {n}' for t, n in sorted(self.counts.items())]
        lines += [f'  note: {p}' for p in self.problems if p]
        if self.orphan_messages:
            lines.append(f'  note: {self.orphan_messages} messages had no channel record and '
                         'were dropped')
        return '\n'.join(lines)


def _offered_qos(channel: Channel) -> list[Qos] | None:
    text = channel.metadata.get('offered_qos_profiles')
    if not text:
        return None
    try:
        profiles = parse_qos(text)
    except (ReaderError, KeyError, TypeError, ValueError, AttributeError):
        return None
    return profiles or None


def _opens(path: Path) -> bool:
    try:
        open_reader(path).close()
    except BagError:
        return False
    return True


def repair_bag(path: str | os.PathLike[str], out: str | os.PathLike[str] | None = None
               ) -> RepairResult:
    """Write a closed copy of a bag that was not closed; return what was recovered.

    ``out`` defaults to ``<path>_repaired``; an existing ``out`` is never
    overwritten (:class:`.BagExistsError`).  Every message of every complete
    chunk is kept with its topic, type, receive timestamp and bytes; the
    chunk that was being filled when the recorder died is lost.

    Parameters
    ----------
    path : path-like
        The bag directory, or one MCAP file.
    out : path-like, optional
        The new bag's directory (must not exist).

    Returns
    -------
    RepairResult

    Raises
    ------
    BagNotFoundError, BagError
        If there is no MCAP file to repair.
    BagError
        If the bag is complete.
        If no ROS 2 data can be recovered (or a topic has two types).
    BagExistsError
        If ``out`` exists.
    """
    src = bag_location(path)
    if src.is_file():
        mcaps = [src]
        default_out = src.with_name(src.stem + '_repaired')
    else:
        mcaps = sorted(src.glob('*.mcap'))
        default_out = src.with_name(src.name + '_repaired')
    if not mcaps:
        raise BagError(f'{src} holds no .mcap file; there is nothing to repair (only MCAP '
                       'bags can be repaired)')
    if src.is_dir() and (src / 'metadata.yaml').exists() \
            and all(mcap_is_complete(m) for m in mcaps) and _opens(src):
        raise BagError(f'{src} is complete (closed MCAP and metadata.yaml); nothing '
                       'to repair - read it directly')
    dst = Path(out) if out is not None else default_out
    if dst.exists():
        raise BagExistsError(f'repair output {dst} exists already; it is never overwritten. '
                             'Pass another output directory (out=...) or remove it.')
    scans = [scan_mcap(m) for m in mcaps]
    channels, foreign = _channels(scans)
    total = sum(len(s.messages) for s in scans)
    if not channels and foreign:
        raise BagError(f'{src} holds no ROS 2 data: {", ".join(sorted(foreign.values()))}; '
                       'only MCAP channels with cdr messages and ros2msg schemas can be '
                       'written into a rosbag2 bag')
    if not channels and total == 0:
        why = '; '.join(f'{s.path.name}: {s.problem or "no chunk was complete"}' for s in scans)
        raise BagError(f'nothing recoverable in {src}: no complete chunk was written before '
                       f'the recorder stopped ({why})')
    counts: dict[str, int] = {}
    orphans = 0
    writer = BagWriter(dst)
    try:
        for topic, (msgtype, qos, msgdef) in channels.items():
            writer.add_connection(topic, msgtype, qos, msgdef=msgdef)
            counts[topic] = 0
        for scan in scans:
            for msg in scan.messages:
                channel = scan.channels.get(msg.channel_id)
                if channel is not None and channel.topic in foreign:
                    continue
                if channel is None or channel.topic not in channels:
                    orphans += 1
                    continue
                writer.write(channel.topic, msg.log_time, msg.data)
                counts[channel.topic] += 1
    finally:
        writer.close()
    return RepairResult(
        source=src, output=dst, counts=counts,
        msgtypes={t: v[0] for t, v in channels.items()},
        qos_recovered={t: v[1] is not None for t, v in channels.items()},
        chunks=sum(s.chunks for s in scans),
        complete_source=all(s.complete for s in scans),
        discarded_bytes=sum(s.discarded_bytes for s in scans), orphan_messages=orphans,
        problems=tuple(f'{s.path.name}: {s.problem}' for s in scans if s.problem)
        + tuple(f'skipped {v}: not ROS 2 (cdr + ros2msg)' for v in sorted(foreign.values())))


def _channels(scans: list[McapScan]) -> tuple[dict[str, tuple[str, list[Qos] | None, str]],
                                         dict[str, str]]:
    """The topics of the scanned files: ROS 2 ones and the others.

    Returns ``{topic: (type, offered QoS, message definition)}`` of the ROS 2 topics and
    ``{topic: its encodings}`` of the others (a rosbag2 bag cannot hold them).
    """
    channels: dict[str, tuple[str, list[Qos] | None, str]] = {}   # topic -> type, qos, msgdef
    foreign: dict[str, str] = {}          # topic -> encodings we cannot write into a bag
    for scan in scans:
        for ch in scan.channels.values():
            schema = scan.schemas.get(ch.schema_id)
            if schema is None:
                continue
            if ch.message_encoding != 'cdr' or schema.encoding != 'ros2msg':
                foreign[ch.topic] = (f'{ch.topic} ({ch.message_encoding} messages, '
                                     f'{schema.encoding or "no"} schema)')
                continue
            msgdef = schema.data.decode('utf-8', errors='replace')
            prev = channels.get(ch.topic)
            if prev is not None and prev[0] != schema.name:
                raise BagError(f'topic {ch.topic} appears with two types, {prev[0]} and '
                               f'{schema.name}; this tool writes one type per topic')
            if prev is None or (prev[1] is None and _offered_qos(ch) is not None):
                channels[ch.topic] = (schema.name, _offered_qos(ch), msgdef)
    return channels, foreign
