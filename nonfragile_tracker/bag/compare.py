"""Compare two bags topic by topic, field by field (bag-based regression tests).

Every message is deserialized with the Jazzy typestore and flattened to its
numeric and string leaves (``pose.pose.position.x`` ...).  Two bags agree when
each compared topic has the same number of messages and every leaf agrees:
numbers within ``atol + rtol * |expected|``, strings exactly.  Header stamps are
message fields and are compared; the bag's receive timestamps are not by default
(``receive_time=True`` compares them): they are the recorder's sim-time clock at
reception, which follows ``/clock`` asynchronously and may differ by a few steps
between two identical runs.  A stamped message repeating a header stamp already
seen on its topic (a lockstep step republished while the plant waited) is dropped
before comparing, as :func:`reader.read_bag` does.
:func:`format_differences` prints a readable diff: topic, message index,
field, expected vs got.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Any, Iterable, Iterator

import numpy as np

from .reader import open_reader
from .writer import jazzy_typestore

__all__ = ['Difference', 'Comparison', 'flatten', 'compare_bags', 'format_differences']


@dataclass(frozen=True)
class Difference:
    """One disagreement between the expected (golden) and the new bag."""

    topic: str
    index: int | None          # message index within the topic; None: topic-level
    field: str
    expected: Any
    got: Any

    def __str__(self) -> str:
        where = self.topic if self.index is None else f'{self.topic}[{self.index}]'
        return f'{where} {self.field}: expected {self.expected!r}, got {self.got!r}'


@dataclass
class Comparison:
    """Result of :func:`compare_bags`."""

    topics: list[str]
    messages: dict[str, int]
    differences: list[Difference] = field(default_factory=list)
    max_abs_error: dict[str, float] = field(default_factory=dict)
    repeats: dict[str, int] = field(default_factory=dict)   # repeated stamps dropped (new bag)

    @property
    def equal(self) -> bool:
        return not self.differences


def flatten(msg: Any, prefix: str = '') -> Iterator[tuple[str, Any]]:
    """Yield ``(dotted.field, value)`` for every leaf of a deserialized message."""
    fields = getattr(msg, '__dataclass_fields__', None)
    if fields is None:
        if isinstance(msg, np.ndarray):
            for i, v in enumerate(msg.ravel().tolist()):
                yield f'{prefix}[{i}]', v
        elif isinstance(msg, (list, tuple)):
            for i, v in enumerate(msg):
                yield from flatten(v, f'{prefix}[{i}]')
        else:
            yield prefix, msg
        return
    for name in fields:
        if name == '__msgtype__':
            continue
        yield from flatten(getattr(msg, name), f'{prefix}.{name}' if prefix else name)


def _messages(path, typestore) -> tuple[dict[str, list[tuple[int, Any]]], dict[str, int]]:
    """Messages per topic; repeats of a header stamp already seen on the topic (the plant
    republishes a lockstep step while it waits) are dropped and counted."""
    out: dict[str, list[tuple[int, Any]]] = {}
    repeats: dict[str, int] = {}
    seen: dict[str, set] = {}
    reader = open_reader(path)
    try:
        for conn, ts, raw in reader.messages():
            msg = typestore.deserialize_cdr(raw, conn.msgtype)
            header = getattr(msg, 'header', None)
            if header is not None:
                stamp = (header.stamp.sec, header.stamp.nanosec)
                stamps = seen.setdefault(conn.topic, set())
                if stamp in stamps:
                    repeats[conn.topic] = repeats.get(conn.topic, 0) + 1
                    continue
                stamps.add(stamp)
            out.setdefault(conn.topic, []).append((ts, msg))
    finally:
        reader.close()
    return out, repeats


def compare_bags(expected: str | os.PathLike, got: str | os.PathLike, *,
                 topics: Iterable[str] | None = None, rtol: float = 0.0, atol: float = 1e-9,
                 receive_time: bool = False, max_differences: int = 50) -> Comparison:
    """Compare ``got`` with the golden bag ``expected`` (see module docstring)."""
    ts = jazzy_typestore()
    (exp, _), (new, repeats) = _messages(expected, ts), _messages(got, ts)
    names = sorted(topics) if topics is not None else sorted(set(exp) | set(new))
    result = Comparison(topics=names, messages={k: len(v) for k, v in exp.items()},
                        repeats=repeats)
    diffs = result.differences

    def add(d: Difference) -> bool:
        diffs.append(d)
        return len(diffs) >= max_differences

    for topic in names:
        a, b = exp.get(topic), new.get(topic)
        if a is None or b is None:
            if add(Difference(topic, None, 'topic', 'present' if a is not None else 'absent',
                              'present' if b is not None else 'absent')):
                return result
            continue
        if len(a) != len(b):
            if add(Difference(topic, None, 'message count', len(a), len(b))):
                return result
        worst = 0.0
        for i, ((ta, ma), (tb, mb)) in enumerate(zip(a, b)):
            if receive_time and ta != tb and add(Difference(topic, i, 'receive time (ns)', ta,
                                                            tb)):
                return result
            for (fa, va), (fb, vb) in zip(flatten(ma), flatten(mb)):
                if fa != fb:
                    if add(Difference(topic, i, fa, 'field layout', fb)):
                        return result
                    break
                if isinstance(va, (int, float)) and isinstance(vb, (int, float)) \
                        and not isinstance(va, bool):
                    if math.isnan(va) and math.isnan(vb):
                        continue
                    err = abs(va - vb)
                    worst = max(worst, err if math.isfinite(err) else math.inf)
                    if not err <= atol + rtol * abs(va):
                        if add(Difference(topic, i, fa, va, vb)):
                            return result
                elif va != vb:
                    if add(Difference(topic, i, fa, va, vb)):
                        return result
        result.max_abs_error[topic] = worst
    return result


def format_differences(cmp: Comparison, limit: int = 20) -> str:
    """Readable diff of a comparison (empty string when the bags agree)."""
    if cmp.equal:
        return ''
    lines = [f'{len(cmp.differences)} difference(s)'
             + (' (stopped at the limit)' if len(cmp.differences) >= limit else '') + ':']
    lines += [f'  {d}' for d in cmp.differences[:limit]]
    return '\n'.join(lines)
