"""Process entry points of the nodes: a stop signal is honoured from the first line on.

``ros2 run``/``ros2 launch`` start the scripts ``reference``, ``plant``, ``tracker`` and
``recorder`` (``scripts/`` of the source tree, installed into ``lib/nonfragile_tracker``),
which call :func:`main` (``python -m nonfragile_tracker.nodes.entry NAME [--ros-args
...]`` does the same).  This module
imports nothing heavy: before anything else it notes SIGINT and SIGTERM in a flag
instead of Python's default actions (KeyboardInterrupt with a traceback, or death by
SIGTERM), then imports the node module (numpy, rclpy, rosbags: a second or more on a
busy machine) and runs it.  A signal that arrives while the process is still importing
or initialising - Ctrl-C on ``ros2 launch`` right after start, ``systemctl stop`` during
boot - ends it with exit code 0 and no traceback, like a signal during the run
(:func:`nonfragile_tracker.nodes.common.run`).  Without this, a SIGINT in the window
before rclpy installs its handlers was either a traceback or lost (a recorder that never
ended).  What remains is the interpreter's own start-up (tens of ms) before this module runs.
"""
from __future__ import annotations

import contextlib
import faulthandler
import importlib
import os
import signal
import sys

#: The node modules a process can run.
NODES = ('reference', 'plant', 'tracker', 'recorder')

_received: list[int] = []


def _note(signum: int, frame: object) -> None:
    _received.append(signum)


def catch_stop_signals() -> None:
    """Note SIGINT/SIGTERM in a flag (:func:`stop_requested`); main thread only.

    rclpy's own handlers, installed later by ``rclpy.init``, chain to this one, so the
    flag is also set for a signal during the run.
    """
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, _note)


def ignore_stop_signals() -> None:
    """The process is ending: ignore further SIGINT/SIGTERM (main thread only).

    ``ros2 launch`` forwards a second SIGINT right after the terminal's.  Python resets
    a signal with a Python handler to its default action while the interpreter
    finalizes, so a repeated signal during the last clean-up (DDS teardown) would kill
    the process (exit -2) instead of letting it end with 0.  A hang still ends by
    launch's SIGKILL escalation.
    """
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, signal.SIG_IGN)


def dump_stacks_on_sigusr1() -> None:
    """Make SIGUSR1 write the Python stack of every thread to stderr (the node's log).

    It has no other effect on the run.  For a node that does not end after a stop
    signal: :func:`nonfragile_tracker.runner.run_processes` sends SIGUSR1 before its
    SIGKILL, so the log tells where the node hung (``kill -USR1 PID`` does the same by
    hand).  The dump is written from C, also while the main thread is blocked inside rcl
    or DDS.
    """
    with contextlib.suppress(AttributeError, ValueError, OSError, RuntimeError):
        faulthandler.register(signal.SIGUSR1, all_threads=True, chain=False)


def stop_requested() -> bool:
    """Whether SIGINT or SIGTERM arrived since :func:`catch_stop_signals`."""
    return bool(_received)


def main(name: str, args: list[str] | None = None) -> int:
    """Run node ``name`` (one of :data:`NODES`) with ROS arguments ``args``; its exit code."""
    catch_stop_signals()
    dump_stacks_on_sigusr1()
    if name not in NODES:
        print(f'[FATAL] unknown node {name!r}; one of {", ".join(NODES)}', file=sys.stderr)
        return 2
    module = importlib.import_module(f'nonfragile_tracker.nodes.{name}')
    if stop_requested():
        ignore_stop_signals()
        return 0
    code = int(module.main(args) or 0)
    ignore_stop_signals()
    # the node has closed its bag, destroyed itself and shut rclpy down: leave without the
    # interpreter's finalization, in which the experimental EventsExecutor of rclpy 7.1.6
    # can abort in its destructor ('Destroying callback manager with callbacks
    # remaining', seen about once in 30 stops right after start)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code)


if __name__ == '__main__':
    catch_stop_signals()
    if len(sys.argv) < 2:
        print('usage: python -m nonfragile_tracker.nodes.entry NODE [--ros-args ...]',
              file=sys.stderr)
        sys.exit(2)
    sys.exit(main(sys.argv[1], [sys.argv[0], *sys.argv[2:]]))
