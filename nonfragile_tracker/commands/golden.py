"""``nonfragile_tracker golden``: re-run golden scenarios, show what changed, replace them.

See doc/cli.md, section "golden", and doc/bags.md, section "Recording and golden bags".
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..errors import EXIT_DIFFERENT, EXIT_OK
from .common import Subparsers

__all__ = ['register', 'cmd_golden']


def cmd_golden(args: argparse.Namespace) -> int:
    """Re-run the golden scenarios; exit 1 if a bag differs or is new (unless ``--write``).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``golden``.
    """
    from ..workflows import golden
    if args.scenario:
        scenarios = [golden.scenario_from_file(p, args.gains) for p in args.scenario]
    else:
        scenarios = list(golden.SCENARIOS.values())
    changed = golden.check_golden(scenarios, out=Path(args.out) if args.out else None,
                                  write=args.write, duration=args.duration)
    if changed and not args.write:
        print('golden bags differ or are new; re-run with --write to replace them',
              file=sys.stderr)
        return EXIT_DIFFERENT
    return EXIT_OK


def register(subparsers: Subparsers) -> None:
    """Add ``golden`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``); ``golden`` is added to them.
    """
    from ..workflows.golden import DURATION
    g = subparsers.add_parser(
        'golden', help='re-run golden scenarios (the package\'s, or your --scenario files) in '
        'lockstep and print what changed against their golden bags (--write replaces them)')
    g.add_argument('--scenario', action='append', metavar='FILE',
                   help='your scenario parameter file (plant/reference/tracker sections; '
                   'repeatable); its golden bag is <out>/golden_<file stem> (default: the '
                   "package's own scenarios, paper and delta2, whose golden bags are in the "
                   "source tree's test/data)")
    g.add_argument('--gains', help='gain file for --scenario (default config/tracker_gains.yaml)')
    g.add_argument('--out', help='directory of the golden bags (default: the source tree\'s '
                   'test/data, only for the package\'s own scenarios)')
    g.add_argument('--duration', type=float, default=DURATION,
                   help=f'simulated seconds per scenario (default {DURATION})')
    g.add_argument('--write', action='store_true', help='write new or changed golden bags')
    g.set_defaults(func=cmd_golden)
