"""``golden``: re-run the golden scenarios and print what changed (``--write`` replaces)."""
from __future__ import annotations

import argparse


def cmd_golden(args: argparse.Namespace) -> int:
    """Compare fresh runs with the golden bags; exit 1 when they differ (0 after --write)."""
    from ..golden import check_golden
    return check_golden(write=args.write)


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``golden``."""
    g = sub.add_parser('golden', help='re-run the golden scenarios, print what changed '
                       '(--write replaces test/data/golden_*)')
    g.add_argument('--write', action='store_true', help='replace the golden bags')
    g.set_defaults(func=cmd_golden)
