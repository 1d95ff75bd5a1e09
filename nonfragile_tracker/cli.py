"""``nonfragile_tracker``: the package's one command-line entry point (argparse only).

:func:`build_parser` collects every command module's sub-commands (:data:`COMMANDS`); the
top-level ``--help`` lists them all with a line each (:data:`DESCRIPTION`, :data:`EPILOG`),
and every command's ``--help`` shows each option's default.  :func:`main` maps errors to
the exit codes of :mod:`nonfragile_tracker.errors`.

See doc/cli.md (every command, the exit codes).
"""
from __future__ import annotations

import os
import sys

# The matrices here are small: BLAS threads only add contention (a 132x132 eigvals took
# 40x longer with threads on a busy 2-core machine, benchmarks/README.md).  Set before
# numpy is imported; an explicit OPENBLAS_NUM_THREADS from the caller wins.
os.environ.setdefault('OPENBLAS_NUM_THREADS', '1')

# Only the standard library and ``errors`` (no imports of its own) at the top: everything
# heavy (argparse, the command modules, numpy, cvxpy, rclpy) is imported inside main(),
# where Ctrl-C becomes exit 130 without a traceback (see main).
from .errors import EXIT_INTERRUPTED, NonfragileError, exit_code  # noqa: E402

TYPE_CHECKING = False            # typing.TYPE_CHECKING without importing typing (mypy: True)
if TYPE_CHECKING:
    import argparse

#: The top-level ``--help``: what the package does (plain text; the commands follow).
DESCRIPTION = ('Non-fragile trajectory tracking for differential-drive and car-like bases on '
               'ROS 2 Jazzy: design gains certified for gain perturbations and command '
               'latency, run the tracker, identify a base, and record, report, compare and '
               'replay runs.  Every command has its own --help.')
#: After the commands in the top-level ``--help``.
EPILOG = ('exit codes: 0 ok; 1 a check found differences or violations (golden, bag '
          'compare/replay, trajectory check) or an internal error; 2 bad input; 3 infeasible '
          'LMI; 4 solver or verification failure; 5 run failure; 130 interrupted')

#: The command modules (under ``nonfragile_tracker.commands``), in ``--help`` order; each
#: exposes ``register(subparsers)``.  Imported by :func:`build_parser`.
COMMANDS = ('synthesis', 'identify', 'latency_design', 'sweep', 'run', 'bringup', 'study',
            'trajectory', 'bag', 'reproduce', 'golden')


def build_parser() -> argparse.ArgumentParser:
    """The argument parser with every command module's sub-commands.

    Returns
    -------
    argparse.ArgumentParser
    """
    import argparse
    import importlib
    formatter = importlib.import_module(f'{__package__}.commands.common').HelpFormatter
    p = argparse.ArgumentParser(prog='nonfragile_tracker', description=DESCRIPTION,
                                epilog=EPILOG, formatter_class=formatter)
    sub = p.add_subparsers(dest='command', required=True, title='commands',
                           metavar='COMMAND')
    for name in COMMANDS:
        importlib.import_module(f'{__package__}.commands.{name}').register(sub)
    parsers = [p]
    while parsers:                  # every command's --help shows its options' defaults
        parser = parsers.pop()
        parser.formatter_class = formatter
        parsers += [c for a in parser._actions if isinstance(a, argparse._SubParsersAction)
                    for c in a.choices.values()]
    return p


def main(argv: list[str] | None = None) -> int:
    """Parse ``argv``, run the command, map its errors to an exit code (no traceback).

    ``NonfragileError`` and ``OSError`` print ``error: <message>`` and exit with
    :func:`.errors.exit_code` (2 for bad input); anything else is a bug: one
    ``internal error`` line with the exception type, exit 1, and the traceback only
    when ``NONFRAGILE_DEBUG=1``.  Usage errors exit 2 from argparse.

    Ctrl-C (SIGINT) anywhere in here - while the command modules and numpy/cvxpy are
    imported, while parsing, while the command runs or reports an error - returns 130
    (also when Python wrapped the KeyboardInterrupt, e.g. into the RuntimeError of a
    ``__set_name__`` interrupted while a dataclass was created)
    (128 + SIGINT, what a shell reports for an interrupted program) without a traceback.
    Before main() is entered only the interpreter's start, this package's ``__init__``
    and ``errors`` (no imports) run: a SIGINT that early ends the process by the signal
    itself (status -2 / 130 in a shell) or, once Python's handler is installed, with a
    short KeyboardInterrupt traceback.

    A SIGINT can also reach Python inside C code that replaces the KeyboardInterrupt by
    an error of its own (numpy's C extension, interrupted while it imports ``datetime``,
    raises ImportError): main() notes every SIGINT (its handler, installed for the call
    where Python's own is, raises KeyboardInterrupt just the same), and any error after
    one is the interruption, 130.

    Parameters
    ----------
    argv : list of str, optional
        The arguments after the program name (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        The exit code (``errors.EXIT_*``).
    """
    import signal
    noted: list[int] = []

    def on_sigint(signum: int, frame: object) -> None:
        noted.append(signum)
        raise KeyboardInterrupt

    previous = signal.getsignal(signal.SIGINT)
    ours = previous is signal.default_int_handler
    if ours:
        try:
            signal.signal(signal.SIGINT, on_sigint)
        except ValueError:           # not the main thread: Python's handler stays
            ours = False
    try:
        try:
            args = build_parser().parse_args(argv)
            return int(args.func(args) or 0)
        except (NonfragileError, OSError) as exc:
            if noted:
                return EXIT_INTERRUPTED
            print(f'error: {exc}', file=sys.stderr)
            return exit_code(exc)
        except Exception as exc:  # noqa: BLE001 - a bug: one line, the traceback on request
            cause: BaseException | None = exc
            while cause is not None and not isinstance(cause, KeyboardInterrupt):
                cause = cause.__cause__ or cause.__context__
            if cause is not None or noted:   # Ctrl-C wrapped or replaced (see above)
                return EXIT_INTERRUPTED
            if os.environ.get('NONFRAGILE_DEBUG') == '1':
                raise
            print(f'internal error: {type(exc).__name__}: {exc} (this is a bug; re-run with '
                  'NONFRAGILE_DEBUG=1 for the traceback and report it)', file=sys.stderr)
            return exit_code(exc)
    except KeyboardInterrupt:
        return EXIT_INTERRUPTED
    finally:
        if ours:
            signal.signal(signal.SIGINT, previous)


if __name__ == '__main__':
    sys.exit(main())
