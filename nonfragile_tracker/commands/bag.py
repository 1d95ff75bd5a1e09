"""``nonfragile_tracker bag ...``: report, compare, replay and repair recorded runs.

Each function takes the parsed ``args`` and returns the exit code; errors
(:class:`~nonfragile_tracker.errors.InputError` for an unreadable bag, exit 2) reach
the user through ``cli.main``.

See doc/cli.md, section "Bags", and doc/bags.md.
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import EXIT_DIFFERENT, EXIT_OK
from .common import Subparsers

__all__ = ['register', 'cmd_report', 'cmd_compare', 'cmd_replay', 'cmd_repair']


def _overrides(args: argparse.Namespace) -> dict[str, str]:
    out: dict[str, str] = {}
    if getattr(args, 'odom', None):
        out['odom'] = args.odom
    if getattr(args, 'cmd', None):
        out['cmd_vel'] = args.cmd
    return out


def cmd_report(args: argparse.Namespace) -> int:
    """Print the report of a recorded run (plots into ``--out``) and its certificate check.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``bag report``.
    """
    from ..bag.report import bag_report, format_report
    rep = bag_report(Path(args.bag), Path(args.out) if args.out else None,
                     overwrite=args.force, plots=not args.no_plots, tolerance=args.tolerance,
                     topic_overrides=_overrides(args), late_threshold=args.late)
    print(format_report(rep))
    from ..bag.report import certificate_check, certificate_source, format_certificate
    found = certificate_source(Path(args.bag), args.gains)
    if found is not None:
        cert, params, source = found
        print(format_certificate(certificate_check(Path(args.bag), cert, params,
                                                   source=source)))
    return EXIT_OK


def cmd_repair(args: argparse.Namespace) -> int:
    """Write a closed copy of a bag that was not closed and print what was recovered.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``bag repair``.
    """
    from ..bag.repair import repair_bag
    res = repair_bag(Path(args.bag), Path(args.out) if args.out else None)
    print(res.summary())
    return EXIT_OK


def cmd_compare(args: argparse.Namespace) -> int:
    """Compare two runs field by field: exit 0 when equal within tolerance, else 1.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``bag compare``.
    """
    from ..bag.compare import compare_bags, format_differences
    cmp = compare_bags(Path(args.expected), Path(args.actual), atol=args.atol, rtol=args.rtol,
                       tolerances=args.tol or (), align=args.align,
                       time_tolerance=args.time_tol, max_differences=args.max_diffs,
                       topics=args.topic or None)
    if cmp.equal:
        n = sum(s.paired for s in cmp.summary.values())
        print(f'equal within tolerance: {len(cmp.topics)} topic(s), {n} message pairs')
        return EXIT_OK
    print(format_differences(cmp))
    return EXIT_DIFFERENT


def cmd_replay(args: argparse.Namespace) -> int:
    """Replay a bag's inputs into a fresh tracker; exit 1 if its commands differ.

    In process, or through a tracker node with ``--ros``; the commands are compared with
    the recorded ones (or ``--expected``'s).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``bag replay``.
    """
    from ..bag.replay import format_replay, replay
    kw = dict(gains=Path(args.gains) if args.gains else None,
              params=Path(args.params) if args.params else None,
              expected=Path(args.expected) if args.expected else None,
              atol=args.atol, rtol=args.rtol, max_differences=args.max_diffs)
    if args.ros:
        from ..workflows.dds_replay import replay_over_dds
        res = replay_over_dds(Path(args.bag), **kw)
    else:
        res = replay(Path(args.bag), **kw)
    print(format_replay(res))
    return EXIT_OK if res.comparison.equal else EXIT_DIFFERENT


def _tolerance_args(p: argparse.ArgumentParser, atol: float) -> None:
    p.add_argument('--atol', type=float, default=atol,
                   help=f'default absolute tolerance of numeric fields (default {atol:g})')
    p.add_argument('--rtol', type=float, default=0.0,
                   help='default relative tolerance (default 0)')
    p.add_argument('--max-diffs', type=int, default=20, metavar='N',
                   help='differences listed (all are counted; default 20)')


def register(subparsers: Subparsers) -> None:
    """Add ``bag report|compare|replay|repair`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``);
        ``bag`` with ``report``, ``compare``, ``replay`` and ``repair`` is added to them.
    """
    b = subparsers.add_parser('bag', help='bag tools: report, compare, replay, repair')
    bs = b.add_subparsers(dest='bag_command', required=True)

    rep = bs.add_parser('report', help='metrics, timing and PNG plots of a recorded run '
                        '(lockstep or real time, ours or another system\'s)')
    rep.add_argument('bag', help='rosbag2 bag directory or MCAP file of a run')
    rep.add_argument('--out', help='directory for the plots (default: <bag>_report)')
    rep.add_argument('--force', action='store_true', help='replace existing plots')
    rep.add_argument('--no-plots', action='store_true', help='text report only')
    rep.add_argument('--tolerance', type=float, default=0.01,
                     help='position tolerance for settling (m, default 0.01)')
    rep.add_argument('--odom', help='odometry topic (nav_msgs/Odometry) if not found by name')
    rep.add_argument('--cmd', help='command topic (Twist or TwistStamped) if not found by name')
    rep.add_argument('--gains', metavar='FILE',
                     help='check the run against this gain file\'s certificate (its '
                     'gain_design record and tracker section): the latency estimate over the '
                     'run and the fraction of time inside the certified interval; default: '
                     'the certified_* parameters recorded in the run directory\'s params.yaml')
    rep.add_argument('--late', type=float,
                     help='latency (s) above which a command is late (default: median odom step)')
    rep.set_defaults(func=cmd_report)

    cmp = bs.add_parser('compare', help='compare two runs field by field (exit 0 equal, '
                        '1 different, 2 unreadable)')
    cmp.add_argument('expected', help='the reference bag (e.g. a golden bag)')
    cmp.add_argument('actual', help='the bag to check against it')
    cmp.add_argument('--tol', action='append', metavar='TOPIC.FIELD=ABS[,REL]',
                     help='tolerance of a topic, field, field prefix or glob (repeatable), '
                     'e.g. /odom.pose.pose.position=1e-3 or cmd_vel=1e-6,1e-3')
    cmp.add_argument('--align', choices=['auto', 'stamp', 'index', 'time'], default='auto',
                     help='pair messages by header stamp, index or receive time (default auto)')
    cmp.add_argument('--time-tol', type=float, default=0.005,
                     help='time alignment: largest receive-time distance of a pair (s)')
    cmp.add_argument('--topic', action='append', help='compare only this topic (repeatable)')
    _tolerance_args(cmp, 1e-9)
    cmp.set_defaults(func=cmd_compare)

    rp = bs.add_parser('replay', help='feed the recorded odometry and reference to a fresh '
                       'tracker and compare its commands with the recorded ones')
    rp.add_argument('bag', help='a recorded run (a real-time bag, or a lockstep one)')
    rp.add_argument('--gains', help='tracker gain file (default config/tracker_gains.yaml)')
    rp.add_argument('--params', help='scenario/parameter file with a tracker section '
                    '(default config/paper_scenario.yaml)')
    rp.add_argument('--expected', help='compare with the commands of this bag instead')
    rp.add_argument('--ros', action='store_true',
                    help='through a real tracker node over DDS instead of in process')
    _tolerance_args(rp, 1e-9)
    rp.set_defaults(func=cmd_replay)

    rr = bs.add_parser('repair', help='recover a bag whose recorder died without closing it, '
                       'or an MCAP from another recorder without metadata.yaml')
    rr.add_argument('bag', help='the bag directory or .mcap file to recover')
    rr.add_argument('--out', help='repaired bag directory (default <bag>_repaired)')
    rr.set_defaults(func=cmd_repair)
