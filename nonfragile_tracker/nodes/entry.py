"""Import-light entry points of the node processes (console scripts, ``python -m``).

A node module imports rclpy, numpy and the message packages (a few hundred ms) before
its ``main`` reaches :func:`common.run`, which switches Python's KeyboardInterrupt off
first thing.  A Ctrl-C in that window - the terminal signals every process of ``ros2
launch`` or of ``nonfragile_tracker run`` at once, perhaps while the nodes still start -
would end the node with a KeyboardInterrupt traceback and exit code 1.  These wrappers
import the node module themselves, so a Ctrl-C during the import is what it is while
spinning: a clean end, exit 0, no output.  Only the standard library is imported here.

``python -m nonfragile_tracker.nodes.entry NODE [--ros-args ...]`` starts ``NODE``
(``reference``, ``plant``, ``tracker``, ``recorder``, ``replayer``) the same way.
"""
from __future__ import annotations

import importlib
import os
import sys

#: The node modules (in this package) that have a ``main(args) -> int``.
NODES = ('reference', 'plant', 'tracker', 'recorder', 'replayer')


def _interrupted(exc: BaseException | None) -> bool:
    """True if ``exc`` is, or was caused by, a KeyboardInterrupt.

    Python wraps one raised in ``__set_name__`` while a class is created into a RuntimeError.
    """
    while exc is not None:
        if isinstance(exc, KeyboardInterrupt):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def _exit_now(code: int) -> None:
    """Flush and leave at once.

    CPython would otherwise end by re-raising SIGINT (status -2, what ``ros2 launch``
    reports as a died process) when the KeyboardInterrupt passed through code an extension
    module ran while importing, even though it was caught.
    """
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


def start(name: str, args: list[str] | None = None) -> int:
    """Import node module ``name`` and run its ``main(args)`` (a process entry point).

    A Ctrl-C before :func:`common.run` has switched KeyboardInterrupt off - while the
    node module imports - ends the process at once with 0: nothing has started yet.
    """
    if name not in NODES:
        print(f'error: unknown node {name!r}; one of {", ".join(NODES)}', file=sys.stderr)
        return 2
    try:
        module = importlib.import_module(f'{__package__}.{name}')
        return int(module.main(args))
    except KeyboardInterrupt:
        _exit_now(0)
    except Exception as exc:
        if _interrupted(exc):
            _exit_now(0)
        raise
    return 0                                        # not reached: _exit_now does not return


def reference() -> int:
    """Console script ``reference``."""
    return start('reference')


def plant() -> int:
    """Console script ``plant``."""
    return start('plant')


def tracker() -> int:
    """Console script ``tracker``."""
    return start('tracker')


def recorder() -> int:
    """Console script ``recorder``."""
    return start('recorder')


if __name__ == '__main__':
    if len(sys.argv) < 2:
        print(f'usage: python -m {__package__}.entry NODE [--ros-args ...]; NODE one of '
              f'{", ".join(NODES)}', file=sys.stderr)
        sys.exit(2)
    sys.exit(start(sys.argv[1]))
