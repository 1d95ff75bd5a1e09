"""``reproduce``: the paper's Section IV into an output directory (and ``doc/reproduction/``).

See doc/cli.md, section "reproduce".
"""
from __future__ import annotations

import argparse
from pathlib import Path

from ..errors import InputError
from .argtypes import positive_float
from .common import Subparsers

__all__ = ['register', 'cmd_reproduce']


def _docs_dir(value: str | None) -> Path:
    """Where ``--docs`` writes: the given directory, else ``doc/reproduction/`` of a checkout.

    Raises
    ------
    InputError
        ``--docs`` without a directory when the package runs from an install (the
        installed package is never written into).
    """
    from ..interface.resources import source_root
    if value:
        return Path(value)
    root = source_root()
    if root is None:
        raise InputError('--docs without a directory needs a source checkout (the installed '
                         'package is never written into); give one: --docs DIR')
    return root / 'doc' / 'reproduction'


def cmd_reproduce(args: argparse.Namespace) -> int:
    """Compute the report into ``--out`` (and copy it into the ``--docs`` directory).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line of ``reproduce``.
    """
    from ..workflows import reproduce
    from ..interface.resources import config_dir
    docs = _docs_dir(args.docs) if args.docs is not None else None
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise InputError(f'--out {out} exists and is not a directory')
    if out.exists() and any(out.iterdir()) and not args.force:
        raise InputError(f'{out} exists and is not empty; pass --force or another --out')
    res = reproduce.compute(config_dir(), out, ros_duration=args.duration, ros=not args.no_ros)
    md = reproduce.write_report(res, out)
    if docs is not None:
        reproduce.write_docs(res, out, docs)
    print(md)
    print(f'wrote {out}' + (f' and {docs}' if docs is not None else '')
          + f' in {res["wall_time"]:.1f} s')
    return 0


def register(subparsers: Subparsers) -> None:
    """Add ``reproduce`` to the CLI.

    Parameters
    ----------
    subparsers : argparse._SubParsersAction
        The CLI's sub-commands (``cli.build_parser``); ``reproduce`` is added to them.
    """
    r = subparsers.add_parser('reproduce', help="the paper's Section IV: gains, Figs. 2-6, report")
    r.add_argument('--out', default='runs/reproduction', help='output directory')
    r.add_argument('--force', action='store_true', help='write into a non-empty --out')
    r.add_argument('--docs', nargs='?', const='', default=None, metavar='DIR',
                   help='also refresh DIR/paper_reproduction.* (default DIR: doc/reproduction/ '
                   'of the source checkout; required when the package is installed)')
    r.add_argument('--duration', type=positive_float, default=60.0,
                   help='simulated s of the ROS run')
    r.add_argument('--no-ros', action='store_true', help='skip the ROS run (no Fig. 6)')
    r.set_defaults(func=cmd_reproduce)
