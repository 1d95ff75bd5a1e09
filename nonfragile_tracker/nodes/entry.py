"""Process entry points of the nodes: a stop signal is honoured from the first line on.

``ros2 run``/``ros2 launch`` start the executables ``reference``, ``plant``, ``tracker``
and ``recorder`` (console scripts installed into ``lib/nonfragile_tracker``; their
wrappers import only this module and call :func:`reference_main` ... :func:`recorder_main`,
see ``setup.py``), which call :func:`main` (``python -m nonfragile_tracker.nodes.entry
NAME [--ros-args ...]`` does the same).  This module
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
from typing import Sequence

#: The node modules a process can run.
NODES = ('reference', 'plant', 'tracker', 'recorder', 'bringup')
#: Longest DDS tear-down (s) once a node has released its own resources (bag closed):
#: past it the process dumps its stacks and ends with its exit code (:func:`arm_exit_deadline`).
TEARDOWN_DEADLINE_S = 4.0

_received: list[int] = []
_node_process = False        # set by main(): this process is a node started through it


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
    signal: :func:`nonfragile_tracker.runner.kill_with_stacks` sends SIGUSR1 before its
    SIGKILL, so the log tells where the node hung (``kill -USR1 PID`` does the same by
    hand).  The dump is written from C, also while the main thread is blocked inside rcl
    or DDS.
    """
    with contextlib.suppress(AttributeError, ValueError, OSError, RuntimeError):
        faulthandler.register(signal.SIGUSR1, all_threads=True, chain=False)


def arm_exit_deadline(code: int, seconds: float | None = None) -> bool:
    """End this node process with ``code`` if it is still alive ``seconds`` from now.

    ``seconds`` defaults to :data:`TEARDOWN_DEADLINE_S` (read at the call).

    For the DDS tear-down after a node's own clean-up (bag closed, outputs flushed): with
    the Fast DDS 2.14 of the rclpy 7.1.6 wheels, destroying the last node destroys the
    participant, whose ``set_listener(nullptr)`` waits forever when a discovery callback
    (a peer removing an endpoint, e.g. every node of a launch file stopping at once) is
    running at that moment - a deadlock of two middleware threads, seen about once in a
    few hundred stops under load, that otherwise ends only with SIGKILL.  The deadline
    is a C timer (glibc ``timer_create`` with ``SIGEV_THREAD`` calling ``_exit``): it
    fires also while the main thread is blocked inside rcl with the GIL held, where no
    Python code can run.  Just before, faulthandler writes every thread's Python stack
    to stderr under ``Timeout (0:00:03.800000)!``.  Only in a process started by :func:`main`
    (never in a test or an embedding process); returns whether the deadline is armed
    (False where glibc timers are unavailable).

    Parameters
    ----------
    code : int
        The exit code (its low byte).
    seconds : float, optional
        The deadline [s]; :data:`TEARDOWN_DEADLINE_S` when ``None``.

    Returns
    -------
    bool
        Whether the deadline is armed.
    """
    if not _node_process:
        return False
    if seconds is None:
        seconds = TEARDOWN_DEADLINE_S
    _flush_output()
    try:
        import ctypes

        class _Thread(ctypes.Structure):
            _fields_ = [('function', ctypes.c_void_p), ('attribute', ctypes.c_void_p)]

        class _Union(ctypes.Union):
            _fields_ = [('pad', ctypes.c_int * 12), ('tid', ctypes.c_int), ('thread', _Thread)]

        class _Sigevent(ctypes.Structure):         # struct sigevent (Linux, 64 bytes)
            _fields_ = [('value', ctypes.c_void_p), ('signo', ctypes.c_int),
                        ('notify', ctypes.c_int), ('un', _Union)]

        class _Timespec(ctypes.Structure):
            _fields_ = [('sec', ctypes.c_long), ('nsec', ctypes.c_long)]

        class _Itimerspec(ctypes.Structure):
            _fields_ = [('interval', _Timespec), ('value', _Timespec)]

        libc = ctypes.CDLL(None, use_errno=True)
        event = _Sigevent(value=int(code) & 0xFF, notify=2)      # SIGEV_THREAD
        # the notify function gets the sigval (in the first argument register): _exit(code)
        event.un.thread.function = ctypes.cast(libc._exit, ctypes.c_void_p).value
        timer = ctypes.c_void_p()
        if libc.timer_create(1, ctypes.byref(event), ctypes.byref(timer)) != 0:  # MONOTONIC
            return False
        whole = int(seconds)
        spec = _Itimerspec(value=_Timespec(whole, int((seconds - whole) * 1e9)))
        if libc.timer_settime(timer, 0, ctypes.byref(spec), None) != 0:
            return False
    except (OSError, AttributeError, TypeError, ValueError):
        return False
    faulthandler.dump_traceback_later(max(seconds - 0.2, 0.1), exit=False)
    return True


def _flush_output() -> None:
    """Flush Python's stdout/stderr buffers (``os._exit`` and ``_exit`` would drop them)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()


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
        2 for an unknown node, 0 when stopped before the node started; otherwise the
        process ends with the node's exit code (``os._exit``) and does not return.
    """
    global _node_process
    catch_stop_signals()
    _received.extend(noted)
    dump_stacks_on_sigusr1()
    _node_process = True
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
    _flush_output()
    os._exit(code)


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
    # nonfragile_tracker.nodes.entry, whose state (the stop flag, the node-process mark of
    # arm_exit_deadline) must be the one main() sets
    from nonfragile_tracker.nodes import entry as _entry
    sys.exit(_entry.main(sys.argv[1], [sys.argv[0], *sys.argv[2:]], noted=_received))
