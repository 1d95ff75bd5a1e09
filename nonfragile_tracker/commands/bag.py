"""``bag report`` and ``bag repair``."""
from __future__ import annotations

import argparse
from pathlib import Path


def cmd_bag_report(args: argparse.Namespace) -> int:
    """Metrics and plots of a recorded run (a bad bag is ``BagError``: exit 2)."""
    from ..bag.report import bag_report, format_report
    rep = bag_report(Path(args.bag), Path(args.out) if args.out else None, overwrite=args.force)
    print(format_report(rep))
    return 0


def cmd_bag_repair(args: argparse.Namespace) -> int:
    """Recover a bag whose recorder died without closing it."""
    from ..bag.repair import repair_bag
    res = repair_bag(Path(args.bag), Path(args.out) if args.out else None)
    print(res.summary())
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    """Add ``bag report`` and ``bag repair``."""
    b = sub.add_parser('bag', help='bag tools: report, repair')
    bs = b.add_subparsers(dest='bag_command', required=True)
    rep = bs.add_parser('report', help='metrics and PNG plots of a recorded run')
    rep.add_argument('bag')
    rep.add_argument('--out', help='directory for the plots (default: <bag>_report)')
    rep.add_argument('--force', action='store_true', help='replace existing plots')
    rep.set_defaults(func=cmd_bag_report)
    rp = bs.add_parser('repair', help='recover a bag whose recorder died without closing it')
    rp.add_argument('bag')
    rp.add_argument('--out', help='repaired bag directory (default <bag>_repaired)')
    rp.set_defaults(func=cmd_bag_repair)
