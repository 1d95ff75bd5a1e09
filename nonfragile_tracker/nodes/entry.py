"""Process entry points of the nodes: a stop signal is honoured from the first line on.

The console scripts ``reference``, ``plant``, ``tracker`` and ``recorder`` (see
``setup.py``) call :func:`reference_main` ... :func:`recorder_main`, which call
:func:`main` (as does ``python -m nonfragile_tracker.nodes.entry NAME [--ros-args ...]``).
This module imports nothing heavy: it notes SIGINT and SIGTERM in a flag first, then
imports the node module and runs it, so a signal during the imports or the start-up ends
the process with 0 and no traceback, like one during the run
(:func:`.nodes.common.run`).

See doc/safety.md, section "Stopping: Ctrl-C, ros2 launch, systemd".
"""
from __future__ import annotations

import contextlib
import faulthandler
import importlib
import os
import signal
import sys
from typing import Any, Sequence

from . import workarounds         # (lean: the standard library only)

#: The node modules a process can run.
NODES = ('reference', 'plant', 'tracker', 'recorder', 'bringup')

_received: list[int] = []


def _note(signum: int, frame: object) -> None:
    _received.append(signum)


class _StopImport(BaseException):
    """A stop signal while the node module is imported (:func:`_import_node`).

    A BaseException, like KeyboardInterrupt: an ``except Exception`` in the imported
    libraries' own import-time code does not swallow it.
    """


def _stop_import(signum: int, frame: object) -> None:
    _received.append(signum)
    raise _StopImport


def _import_node(name: str) -> Any:
    """The node module, or None when a stop signal came before or during its import.

    Importing numpy, rclpy, scipy, rosbags takes 0.3-0.5 s on a quiet machine and several
    seconds on a busy one (``ros2 launch`` starts every node at once); a signal only
    noted meanwhile was acted on after the whole import (the nodes ended 3-8 s after
    Ctrl-C).  During the import SIGINT and SIGTERM raise instead: Python runs the
    handler between two bytecodes of whatever module is being imported, so the import
    stops there.  Nothing outside the process exists yet (no rclpy, no file), and the
    caller leaves with ``os._exit`` without the interpreter's finalization of the
    half-imported modules.
    """
    if stop_requested():
        return None
    unraisable = sys.unraisablehook
    try:
        try:
            # (inside the try: a signal may be handled as soon as its handler is set)
            for sig in (signal.SIGINT, signal.SIGTERM):
                signal.signal(sig, _stop_import)
            # a signal that lands in code whose exceptions Python cannot raise (a weakref
            # callback such as importlib's module-lock one, a __del__) is "Exception ignored
            # in ...", with a traceback on stderr, and the import goes on: the stop is noted
            # all the same (seen once in a suite run of Ctrl-C 0.2 s after launch), so that
            # report is not printed
            sys.unraisablehook = lambda u: None if isinstance(u.exc_value, _StopImport) \
                else unraisable(u)
            return importlib.import_module(f'nonfragile_tracker.nodes.{name}')
        finally:
            sys.unraisablehook = unraisable
            catch_stop_signals()            # only noted again from here on
    except BaseException:
        # _StopImport (also from a signal handled while the handlers are swapped), or what
        # an extension module's initialisation made of it (an ImportError or SystemError
        # around it): any failure once a stop was requested
        if stop_requested():
            return None
        raise


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
    signal: :func:`nonfragile_tracker.workflows.runner.kill_with_stacks` sends SIGUSR1 before its
    SIGKILL, so the log tells where the node hung (``kill -USR1 PID`` does the same by
    hand).  The dump is written from C, also while the main thread is blocked inside rcl
    or DDS.
    """
    with contextlib.suppress(AttributeError, ValueError, OSError, RuntimeError):
        faulthandler.register(signal.SIGUSR1, all_threads=True, chain=False)


def stop_requested() -> bool:
    """Whether SIGINT or SIGTERM arrived since :func:`catch_stop_signals`."""
    return bool(_received)


def main(name: str, args: list[str] | None = None, noted: Sequence[int] = ()) -> int:
    """Run node ``name`` (one of :data:`NODES`) with ROS arguments ``args``; its exit code.

    Parameters
    ----------
    name : str
        The node, one of :data:`NODES`.
    args : list of str, optional
        Command-line arguments as ``sys.argv`` holds them (program name first, then
        ``--ros-args ...``); ``sys.argv`` when ``None``.
    noted : sequence of int, optional
        Stop signals a caller noted before (``python -m``'s ``__main__`` copy of this
        module, while it imported this one).

    Returns
    -------
    int
        2 for an unknown node; otherwise the process ends with the node's exit code
        (``os._exit``; 0 when stopped before the node started) and does not return.
    """
    catch_stop_signals()
    _received.extend(noted)
    dump_stacks_on_sigusr1()
    workarounds.mark_node_process()
    if name not in NODES:
        print(f'[FATAL] unknown node {name!r}; one of {", ".join(NODES)}', file=sys.stderr)
        return 2
    module = _import_node(name)
    if module is None or stop_requested():
        ignore_stop_signals()
        workarounds.flush_output()
        os._exit(0)                         # (no finalization of a half-done import)
    code = int(module.main(args) or 0)
    ignore_stop_signals()
    # the node has closed its bag, destroyed itself and shut rclpy down
    workarounds.exit_without_finalization(code)


def reference_main() -> int:
    """Console script ``reference``: :func:`main` of the reference node."""
    return main('reference')


def plant_main() -> int:
    """Console script ``plant``: :func:`main` of the plant node."""
    return main('plant')


def tracker_main() -> int:
    """Console script ``tracker``: :func:`main` of the tracker node."""
    return main('tracker')


def recorder_main() -> int:
    """Console script ``recorder``: :func:`main` of the recorder node."""
    return main('recorder')


def bringup_main() -> int:
    """Console script ``bringup``: :func:`main` of the bring-up node."""
    return main('bringup')


if __name__ == '__main__':
    catch_stop_signals()
    if len(sys.argv) < 2:
        print('usage: python -m nonfragile_tracker.nodes.entry NODE [--ros-args ...]',
              file=sys.stderr)
        sys.exit(2)
    # run the importable module's main, not this __main__ copy: the node modules import
    # nonfragile_tracker.nodes.entry, whose state (the stop flag) must be the one main() sets
    from nonfragile_tracker.nodes import entry as _entry
    sys.exit(_entry.main(sys.argv[1], [sys.argv[0], *sys.argv[2:]], noted=_received))
