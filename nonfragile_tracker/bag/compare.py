"""Compare two runs topic by topic, field by field: the one comparison engine.

Every message is flattened to its numeric and string leaves; two runs agree when every
compared topic has the same messages and every leaf agrees (numbers within
``atol + rtol * |expected|``, per topic and field by :class:`Tolerance` rules,
:func:`parse_tolerance`; strings exactly).  Messages are paired per topic by header stamp,
by index or by receive time (``align``, ``auto`` by default); :func:`format_differences`
prints a readable diff.

See doc/bags.md, section "``bag compare``" (the alignments, stamps and republished steps).
"""
from __future__ import annotations

import bisect
import fnmatch
import math
import os
from collections.abc import Callable, Iterable, Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .reader import open_reader, typestore_for
from .errors import BagError

__all__ = ['Difference', 'Comparison', 'TopicSummary', 'Tolerance', 'BagError',
           'flatten', 'parse_tolerance', 'compare_bags', 'compare_messages',
           'format_differences', 'read_topic_messages', 'ALIGNMENTS']

ALIGNMENTS = ('auto', 'stamp', 'index', 'time')
#: Message pairs in time alignment may be this far apart (s) unless told otherwise.
DEFAULT_TIME_TOLERANCE = 0.005

Message = tuple[int, Any]            # (receive time ns, deserialized message)


@dataclass(frozen=True)
class Tolerance:
    """Agreement of numbers: ``|got - expected| <= atol + rtol * |expected|``."""

    atol: float
    rtol: float = 0.0

    def ok(self, expected: float, got: float) -> bool:
        """Whether ``got`` is within ``atol + rtol |expected|`` of ``expected``.

        Parameters
        ----------
        expected, got : float
            The two values.

        Returns
        -------
        bool
        """
        return abs(got - expected) <= self.atol + self.rtol * abs(expected)


def parse_tolerance(spec: str) -> tuple[str, str, Tolerance]:
    """Parse ``TOPIC.FIELD=ABS[,REL]`` into ``(topic, field pattern, Tolerance)``.

    ``TOPIC`` is a topic name (leading ``/`` optional; topic names have no dots),
    ``FIELD`` a dotted field (``pose.pose.position.x``), a prefix of one
    (``pose.pose.position``) or a glob (``*.x``); without ``.FIELD`` the rule covers
    the whole topic, and ``*`` as topic covers every topic.

    Parameters
    ----------
    spec : str
        The rule, e.g. ``/odom.pose.pose.position.x=1e-3`` or ``cmd_vel=1e-6,1e-3``.

    Returns
    -------
    (topic, field, Tolerance)
        ``topic`` with a leading ``/`` (or ``*``); ``field`` is ``*`` for the whole
        topic.

    Raises
    ------
    BagError
        If the rule is malformed or a tolerance is not a finite number >= 0.
    """
    if not isinstance(spec, str) or '=' not in spec:
        raise BagError(f'tolerance {spec!r} is not TOPIC.FIELD=ABS[,REL] (e.g. '
                       '/odom.pose.pose.position.x=1e-3 or cmd_vel=1e-6,1e-3)')
    key, _, value = spec.partition('=')
    topic, _, fld = key.strip().partition('.')
    if not topic:
        raise BagError(f'tolerance {spec!r} names no topic (TOPIC.FIELD=ABS[,REL])')
    parts = [p.strip() for p in value.split(',')]
    try:
        nums = [float(p) for p in parts]
    except ValueError:
        raise BagError(f'tolerance {spec!r}: {value!r} is not ABS or ABS,REL (numbers '
                       '>= 0)') from None
    if len(nums) not in (1, 2) or not all(math.isfinite(n) and n >= 0 for n in nums):
        raise BagError(f'tolerance {spec!r}: give ABS or ABS,REL as finite numbers >= 0')
    if topic != '*' and not topic.startswith('/'):
        topic = '/' + topic
    return topic, fld or '*', Tolerance(nums[0], nums[1] if len(nums) == 2 else 0.0)


class _Rules:
    """Tolerance lookup: the most specific matching rule wins, else the default."""

    def __init__(self, default: Tolerance, rules: Iterable[tuple[str, str, Tolerance]]
                 ) -> None:
        self.default = default
        # more specific first: exact topic before '*', longer field pattern first
        self.rules = sorted(rules, key=lambda r: (r[0] == '*', -len(r[1].strip('*'))))
        self._cache: dict[tuple[str, str], Tolerance] = {}

    def get(self, topic: str, fld: str) -> Tolerance:
        key = (topic, fld)
        hit = self._cache.get(key)
        if hit is None:
            hit = self.default
            for t, f, tol in self.rules:
                if (t == '*' or t == topic) and (f == '*' or fnmatch.fnmatchcase(fld, f)
                                                 or fld.startswith(f + '.')):
                    hit = tol
                    break
            self._cache[key] = hit
        return hit


@dataclass(frozen=True)
class Difference:
    """One disagreement between the expected and the new run."""

    topic: str
    index: int | None          # message index within the topic (expected side); None: topic
    field: str
    expected: Any
    got: Any
    tolerance: Tolerance | None = None

    def __str__(self) -> str:
        where = self.topic if self.index is None else f'{self.topic}[{self.index}]'
        text = f'{where} {self.field}: expected {self.expected!r}, got {self.got!r}'
        if self.tolerance is not None and isinstance(self.expected, (int, float)) \
                and isinstance(self.got, (int, float)):
            err = abs(self.got - self.expected)
            text += (f' (|diff| {err:.3g} > atol {self.tolerance.atol:g}'
                     + (f' + rtol {self.tolerance.rtol:g}' if self.tolerance.rtol else '') + ')')
        return text


@dataclass
class TopicSummary:
    """Per-topic outcome: messages paired, messages with a difference, worst error."""

    align: str
    expected: int
    got: int
    paired: int = 0
    differing: int = 0               # paired messages with at least one field out of tolerance
    unpaired: int = 0                # expected messages with no partner (and extra ones)
    fields: set[str] = field(default_factory=set)
    max_abs_error: float = 0.0


@dataclass
class Comparison:
    """Result of :func:`compare_bags` / :func:`compare_messages`."""

    topics: list[str]
    messages: dict[str, int]                        # expected messages per topic
    differences: list[Difference] = field(default_factory=list)   # the first max_differences
    max_abs_error: dict[str, float] = field(default_factory=dict)
    repeats: dict[str, int] = field(default_factory=dict)   # repeated stamps dropped (new run)
    total_differences: int = 0
    summary: dict[str, TopicSummary] = field(default_factory=dict)
    max_differences: int = 50

    @property
    def equal(self) -> bool:
        """Whether the two bags agree everywhere (no difference found)."""
        return self.total_differences == 0


def flatten(msg: Any, prefix: str = '') -> Iterator[tuple[str, Any]]:
    """Yield ``(dotted.field, value)`` for every leaf of a deserialized message.

    Parameters
    ----------
    msg : object
        A rosbags message (a dataclass), a sequence, an array or a leaf value.
    prefix : str, optional
        The dotted path of ``msg`` itself (array items get ``[i]``).

    Yields
    ------
    (str, object)
    """
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


def _stamp(msg: Any) -> tuple[int, int] | None:
    header = getattr(msg, 'header', None)
    if header is None or not hasattr(header, 'stamp'):
        return None
    return int(header.stamp.sec), int(header.stamp.nanosec)


def read_topic_messages(path: str | os.PathLike[str], topics: Iterable[str] | None = None
                        ) -> tuple[dict[str, list[Message]], dict[str, int], int]:
    """Messages per topic in bag order, the repeats dropped, and the bag's first time (ns).

    A stamped message repeating a header stamp already seen on its topic is dropped
    and counted.  Types unknown to the Jazzy typestore are read with the definitions
    stored in the bag.

    Parameters
    ----------
    path : path-like
        A bag directory or an MCAP file.
    topics : iterable of str, optional
        Stored topic names to read (default: all).

    Returns
    -------
    messages : dict
        ``{topic: [(receive ns, message), ...]}``.
    repeats : dict
        ``{topic: number of dropped repeats}``.
    first : int
        The earliest receive time read [ns] (0 for none).

    Raises
    ------
    BagError
        If the bag cannot be opened or a message cannot be read.
    """
    out: dict[str, list[Message]] = {}
    repeats: dict[str, int] = {}
    seen: dict[str, set[tuple[int, int]]] = {}
    wanted = None if topics is None else set(topics)
    first = None
    reader = open_reader(path)
    try:
        ts = typestore_for(reader)
        conns = [c for c in reader.connections if wanted is None or c.topic in wanted]
        try:
            for conn, t, raw in reader.messages(connections=conns):
                first = t if first is None else min(first, t)
                msg = ts.deserialize_cdr(raw, conn.msgtype)
                stamp = _stamp(msg)
                if stamp is not None:
                    stamps = seen.setdefault(conn.topic, set())
                    if stamp in stamps:
                        repeats[conn.topic] = repeats.get(conn.topic, 0) + 1
                        continue
                    stamps.add(stamp)
                out.setdefault(conn.topic, []).append((t, msg))
        except (ValueError, IndexError, KeyError, AssertionError) as exc:
            raise BagError(f'{path}: a message cannot be read ({type(exc).__name__}: {exc}); '
                           'the bag is damaged - try `nonfragile_tracker bag repair`') from None
    finally:
        reader.close()
    return out, repeats, first if first is not None else 0


def _pairs(align: str, a: Sequence[Message], b: Sequence[Message], ta0: int, tb0: int,
           time_tol: float) -> tuple[list[tuple[int, int]], list[int], list[int]]:
    """Index pairs (i in a, j in b), unpaired indices of a, unpaired of b."""
    if align == 'index':
        n = min(len(a), len(b))
        return [(i, i) for i in range(n)], list(range(n, len(a))), list(range(n, len(b)))
    if align == 'stamp':
        where = {_stamp(m): j for j, (_, m) in enumerate(b)}
        pairs, lost = [], []
        for i, (_, m) in enumerate(a):
            j = where.pop(_stamp(m), None)
            (lost.append(i) if j is None else pairs.append((i, j)))
        return pairs, lost, sorted(where.values())
    # time: nearest unused partner within the tolerance, in order
    tb = [t - tb0 for t, _ in b]
    used = [False] * len(b)
    tol = int(round(time_tol * 1e9))
    pairs, lost = [], []
    for i, (t, _) in enumerate(a):
        t -= ta0
        k = bisect.bisect_left(tb, t - tol)
        best, dist = None, None
        while k < len(tb) and tb[k] <= t + tol:
            if not used[k] and (dist is None or abs(tb[k] - t) < dist):
                best, dist = k, abs(tb[k] - t)
            k += 1
        if best is None:
            lost.append(i)
        else:
            used[best] = True
            pairs.append((i, best))
    return pairs, lost, [j for j, u in enumerate(used) if not u]


def _auto(a: Sequence[Message], b: Sequence[Message]) -> str:
    sa = [_stamp(m) for _, m in a]
    if sa and all(s is not None for s in sa):
        sb = {_stamp(m) for _, m in b}
        if sum(1 for s in sa if s in sb) >= 0.5 * len(sa):
            return 'stamp'
    return 'index' if len(a) == len(b) else 'time'


def compare_messages(expected: Mapping[str, Sequence[Message]],
                     got: Mapping[str, Sequence[Message]], *,
                     topics: Iterable[str] | None = None, rtol: float = 0.0, atol: float = 1e-9,
                     tolerances: Iterable[tuple[str, str, Tolerance] | str] = (),
                     align: str | Mapping[str, str] = 'auto',
                     time_tolerance: float = DEFAULT_TIME_TOLERANCE,
                     expected_start_ns: int | None = None, got_start_ns: int | None = None,
                     receive_time: bool = False, max_differences: int = 50) -> Comparison:
    """The comparison engine: ``{topic: [(receive ns, message), ...]}`` on both sides.

    ``tolerances`` are rules from :func:`parse_tolerance` (or their strings); other
    fields use ``atol``/``rtol``.  ``align`` is one of ``ALIGNMENTS`` or a mapping
    topic -> alignment.  Differences beyond ``max_differences`` are counted, not kept.

    Parameters
    ----------
    expected, got : mapping
        ``{topic: [(receive ns, message), ...]}`` (:func:`read_topic_messages`).
    topics : iterable of str, optional
        Topics to compare (default: every topic of either side).
    rtol, atol : float, optional
        Default tolerance of numeric fields.
    tolerances : iterable of str or rule, optional
        Per topic/field rules ``TOPIC.FIELD=ABS[,REL]`` (:func:`parse_tolerance`).
    align : str or mapping, optional
        ``auto``, ``stamp``, ``index`` or ``time`` (per topic with a mapping).
    time_tolerance : float, optional
        Largest receive-time distance [s] of a pair in ``time`` alignment.
    expected_start_ns, got_start_ns : int, optional
        Time origin of each side [ns] (default: its first message).
    receive_time : bool, optional
        Also compare the receive times (stamp/index alignment).
    max_differences : int, optional
        Differences kept in ``Comparison.differences`` (all are counted).

    Returns
    -------
    Comparison

    Raises
    ------
    BagError
        For a bad ``max_differences``, ``time_tolerance`` or alignment.
        For a malformed tolerance rule.
    """
    rules = _Rules(Tolerance(atol, rtol), (parse_tolerance(r) if isinstance(r, str) else r
                                           for r in tolerances))
    if not isinstance(max_differences, int) or max_differences < 0:
        raise BagError(f'max_differences must be an integer >= 0, got {max_differences!r}')
    if not (math.isfinite(time_tolerance) and time_tolerance >= 0):
        raise BagError(f'time tolerance must be a finite number >= 0 s, got {time_tolerance!r}')
    names = sorted(topics) if topics is not None else sorted(set(expected) | set(got))
    ta0 = _first_ns(expected) if expected_start_ns is None else expected_start_ns
    tb0 = _first_ns(got) if got_start_ns is None else got_start_ns
    result = Comparison(topics=names, messages={k: len(v) for k, v in expected.items()},
                        max_differences=max_differences)

    def add(d: Difference) -> None:
        result.total_differences += 1
        if len(result.differences) < max_differences:
            result.differences.append(d)

    for topic in names:
        a, b = expected.get(topic), got.get(topic)
        if a is None or b is None:
            add(Difference(topic, None, 'topic', 'present' if a is not None else 'absent',
                           'present' if b is not None else 'absent'))
            continue
        how = _alignment(align, topic, a, b)
        summ = TopicSummary(how, len(a), len(b))
        result.summary[topic] = summ
        if len(a) != len(b):
            add(Difference(topic, None, 'message count', len(a), len(b)))
        pairs, lost, extra = _pairs(how, a, b, ta0, tb0, time_tolerance)
        summ.paired, summ.unpaired = len(pairs), len(lost) + len(extra)
        if how != 'index':
            for i in lost:
                add(Difference(topic, i, f'no partner ({how} alignment)',
                               _describe(how, a[i], ta0), 'missing'))
            for j in extra:
                add(Difference(topic, None, f'extra message ({how} alignment)', 'none',
                               _describe(how, b[j], tb0)))
        worst = 0.0
        for i, j in pairs:
            (ta, ma), (tb, mb) = a[i], b[j]
            bad = False
            if receive_time and how != 'time' and ta != tb:
                add(Difference(topic, i, 'receive time (ns)', ta, tb))
                bad = True
            differs, err = _compare_fields(topic, i, ma, mb, rules, summ, add)
            worst = max(worst, err)
            bad = bad or differs
            summ.differing += bad
        summ.max_abs_error = worst
        result.max_abs_error[topic] = worst
    return result


def _first_ns(side: Mapping[str, Sequence[Message]]) -> int:
    """The earliest receive time (ns) of a side's messages (0 if it has none)."""
    firsts = [msgs[0][0] for msgs in side.values() if msgs]
    return min(firsts) if firsts else 0


def _alignment(align: str | Mapping[str, str], topic: str, a: Sequence[Message],
               b: Sequence[Message]) -> str:
    """The alignment of ``topic`` (``auto`` resolved); :class:`BagError` for an unknown one."""
    how = align.get(topic, 'auto') if isinstance(align, Mapping) else align
    if how not in ALIGNMENTS:
        raise BagError(f'alignment {how!r} is not one of {", ".join(ALIGNMENTS)}')
    return _auto(a, b) if how == 'auto' else how


def _compare_fields(topic: str, i: int, ma: Any, mb: Any, rules: '_Rules',
                    summ: TopicSummary, add: Callable[[Difference], None]
                    ) -> tuple[bool, float]:
    """Compare two messages field by field; each difference to ``add``.

    Returns whether any field differs (beyond its tolerance, or the layouts), and the
    largest numeric difference of the fields compared (inf for a non-finite one).
    """
    worst, bad = 0.0, False
    for (fa, va), (fb, vb) in zip(flatten(ma), flatten(mb)):
        if fa != fb:
            add(Difference(topic, i, fa, 'field layout', fb))
            return True, worst
        if isinstance(va, (int, float)) and isinstance(vb, (int, float)) \
                and not isinstance(va, bool):
            if math.isnan(va) and math.isnan(vb):
                continue
            err = abs(va - vb)
            worst = max(worst, err if math.isfinite(err) else math.inf)
            tol = rules.get(topic, fa)
            if not tol.ok(va, vb):
                add(Difference(topic, i, fa, va, vb, tol))
                summ.fields.add(fa)
                bad = True
        elif va != vb:
            add(Difference(topic, i, fa, va, vb))
            summ.fields.add(fa)
            bad = True
    return bad, worst


def _describe(how: str, item: Message, t0: int) -> str:
    t, msg = item
    if how == 'stamp':
        s = _stamp(msg)
        return f'stamp {s[0]}.{s[1]:09d}' if s else 'unstamped'
    return f'at {(t - t0) * 1e-9:.6f} s'


def compare_bags(expected: str | os.PathLike[str], got: str | os.PathLike[str], *,
                 topics: Iterable[str] | None = None, rtol: float = 0.0, atol: float = 1e-9,
                 tolerances: Iterable[tuple[str, str, Tolerance] | str] = (),
                 align: str | Mapping[str, str] = 'auto',
                 time_tolerance: float = DEFAULT_TIME_TOLERANCE, receive_time: bool = False,
                 max_differences: int = 50) -> Comparison:
    """Compare the bag ``got`` with the bag ``expected`` (see the module docstring).

    Parameters
    ----------
    expected, got : path-like
        Bag directories (or single MCAP files without metadata.yaml).
    topics : iterable of str, optional
        Stored topic names to compare (default: every topic of either bag).
    rtol, atol : float
        Default tolerance of numeric fields.
    tolerances : iterable of str or rule
        Per topic/field rules ``TOPIC.FIELD=ABS[,REL]`` (:func:`parse_tolerance`).
    align : str or mapping
        ``auto``, ``stamp``, ``index`` or ``time`` (per topic with a mapping).
    time_tolerance : float
        Largest receive-time distance (s) of a pair in ``time`` alignment.
    receive_time : bool
        Also compare the bags' receive timestamps (stamp/index alignment).
    max_differences : int
        Differences kept in ``Comparison.differences`` (all are counted).

    Returns
    -------
    Comparison
        ``equal`` is True when nothing differs beyond the tolerances.

    Raises
    ------
    BagError
        A bag cannot be read (an :class:`~nonfragile_tracker.errors.InputError`, exit 2).
    """
    exp, _, t0a = read_topic_messages(expected, topics)
    new, repeats, t0b = read_topic_messages(got, topics)
    cmp = compare_messages(exp, new, topics=topics, rtol=rtol, atol=atol, tolerances=tolerances,
                           align=align, time_tolerance=time_tolerance, expected_start_ns=t0a,
                           got_start_ns=t0b, receive_time=receive_time,
                           max_differences=max_differences)
    cmp.repeats = repeats
    return cmp


def format_differences(cmp: Comparison, limit: int | None = None) -> str:
    """Readable diff of a comparison (empty string when the runs agree).

    The first ``limit`` differences (default: all that were kept), then one summary
    line per topic: alignment, messages, pairs, messages that differ, fields, worst error.

    Parameters
    ----------
    cmp : Comparison
        The comparison.
    limit : int, optional
        How many differences to list.

    Returns
    -------
    str
    """
    if cmp.equal:
        return ''
    limit = len(cmp.differences) if limit is None else limit
    shown = cmp.differences[:limit]
    lines = [f'{cmp.total_differences} difference(s); first {len(shown)}:']
    lines += [f'  {d}' for d in shown]
    if cmp.total_differences > len(shown):
        lines.append(f'  ... and {cmp.total_differences - len(shown)} more')
    lines.append('summary per topic:')
    for topic in cmp.topics:
        s = cmp.summary.get(topic)
        if s is None:
            lines.append(f'  {topic}: missing on one side')
            continue
        fields = ', '.join(sorted(s.fields)[:6]) + (' ...' if len(s.fields) > 6 else '')
        status = 'equal' if not (s.differing or s.unpaired or s.expected != s.got) else \
            f'{s.differing} of {s.paired} paired messages differ' \
            + (f' ({fields})' if fields else '') + (f', {s.unpaired} unpaired' if s.unpaired
                                                    else '')
        lines.append(f'  {topic} [{s.align}]: expected {s.expected}, got {s.got}; {status}; '
                     f'max |diff| {s.max_abs_error:.3g}')
    return '\n'.join(lines)
