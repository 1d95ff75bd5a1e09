"""Workarounds of upstream faults of the node processes, each with the condition to drop it.

The rclpy 7.1.6 wheels (ROS 2 Jazzy) with their Fast DDS 2.14; none of this is control
logic.  Lean at import (the standard library only, rclpy types for the type checker):
:mod:`nonfragile_tracker.nodes.entry` imports it before the heavy imports.

1. **The process leaves with** ``os._exit`` after its clean-up
   (:func:`exit_without_finalization`).  rclpy's EventsExecutor (experimental;
   ros2/rclpy#1391, in Jazzy since rclpy 7.1.4 through ros2/rclpy#1435) aborts in the
   destructor of its callback manager when callbacks are still registered ('Destroying
   callback manager with callbacks remaining', then ``abort()``), which the
   interpreter's finalization could reach after a signal right after start (about 1 in
   30 stops; also before this package handled signals).  No upstream issue for this
   abort was found.  Drop when the EventsExecutor unregisters its callbacks on
   destruction (or leaves ``rclpy.experimental``) in the rclpy the package pins, or
   when the nodes use the ``SingleThreadedExecutor`` (``NONFRAGILE_EXECUTOR=single``).
2. **The ended executors are kept alive** (:func:`end_executor`): the node is removed and
   the executor shut down while it lives, and it is never destroyed before the process
   leaves (the same abort, item 1).  Drop with item 1.
3. **The DDS tear-down has a deadline** (:func:`arm_exit_deadline`).  With Fast DDS 2.14,
   destroying the last node destroys the participant, whose ``set_listener(nullptr)``
   waits forever when a discovery callback (a peer removing an endpoint, e.g. every node
   of a launch file stopping at once) runs at that moment: a deadlock of two middleware
   threads, about once in a few hundred stops under load, that otherwise ends only with
   SIGKILL.  No upstream issue for this deadlock was found; eProsima/Fast-DDS#6193
   (deadlock on reader/writer destruction with several participants in one process) is
   the closest report.  Drop when the pinned Fast DDS destroys a participant without
   waiting on its discovery listener (a release whose notes name the fix, checked by
   ``make soak`` without a ``Timeout`` line in the node logs).
4. **The spin has a finite timeout** (:func:`spin_until`).  The EventsExecutor's
   ``spin_once()`` without a timeout does not return once the context is shut down from
   another thread (rclpy's signal thread does that on SIGINT): checked here with rclpy
   7.1.6, a ``try_shutdown()`` from a timer thread 1 s after the start left it spinning
   at most of a core until SIGKILL, where the ``SingleThreadedExecutor`` raised
   ``ExternalShutdownException`` at once.  With a timeout the loop also looks at its own
   end conditions between spins (a node's ``finished``, a stop signal rclpy's handlers
   did not act on).  No upstream issue found.  Drop the workaround part (keep a timeout
   for those checks) when the pinned rclpy's EventsExecutor returns from an untimed
   ``spin_once()`` on an external shutdown.
5. **A shutdown under a callback ends it quietly** (:func:`guard_shutdown_race`).
   rclpy's signal thread shuts the context down while the main thread runs a callback;
   whatever that callback then touches (a publish, a log to rosout) raises - rclpy 7.1
   races its own shutdown (ros2/rclpy#1352, fixed by ros2/rclpy#1353 after Jazzy's
   7.1.x; rcl's 'Failed to publish log message to rosout: publisher's context is
   invalid', ros2/rclcpp#812).  Drop when the pinned rclpy includes ros2/rclpy#1353 and
   a signal during a callback leaves no traceback in ``make soak``.
"""
from __future__ import annotations

import contextlib
import faulthandler
import os
import sys
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, NoReturn

if TYPE_CHECKING:
    from rclpy.context import Context
    from rclpy.executors import Executor
    from rclpy.node import Node

__all__ = ['TEARDOWN_DEADLINE_S', 'mark_node_process', 'arm_exit_deadline', 'flush_output',
           'exit_without_finalization', 'end_executor', 'spin_until', 'guard_shutdown_race']

#: Longest DDS tear-down (s) once a node has released its own resources (bag closed):
#: past it the process dumps its stacks and ends with its exit code (:func:`arm_exit_deadline`).
TEARDOWN_DEADLINE_S = 4.0

_node_process = False       # set by mark_node_process(): entry.main started this process
_ENDED_EXECUTORS: list[Executor] = []


def mark_node_process() -> None:
    """Mark this process as a node process started by :func:`nodes.entry.main`.

    Only then does :func:`arm_exit_deadline` arm its deadline (never in a test or an
    embedding process).
    """
    global _node_process
    _node_process = True


def flush_output() -> None:
    """Flush Python's stdout/stderr buffers (``os._exit`` and ``_exit`` would drop them)."""
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(OSError, ValueError):
            stream.flush()


def exit_without_finalization(code: int) -> NoReturn:
    """End the process with ``code`` without the interpreter's finalization (item 1).

    For a node that has closed its bag, destroyed itself and shut rclpy down.

    Parameters
    ----------
    code : int
        The exit code.
    """
    flush_output()
    os._exit(code)


def arm_exit_deadline(code: int, seconds: float | None = None) -> bool:
    """End this node process with ``code`` if it is still alive ``seconds`` from now (item 3).

    For the DDS tear-down after a node's own clean-up (bag closed, outputs flushed).  The
    deadline is a C timer (glibc ``timer_create`` with ``SIGEV_THREAD`` calling ``_exit``):
    it fires also while the main thread is blocked inside rcl with the GIL held, where no
    Python code can run.  Just before, faulthandler writes every thread's Python stack to
    stderr under ``Timeout (0:00:03.800000)!``.  Only in a process marked by
    :func:`mark_node_process`; returns whether the deadline is armed (False where glibc
    timers are unavailable).

    Parameters
    ----------
    code : int
        The exit code (its low byte).
    seconds : float, optional
        The deadline [s]; :data:`TEARDOWN_DEADLINE_S` (read at the call) when ``None``.

    Returns
    -------
    bool
        Whether the deadline is armed.
    """
    if not _node_process:
        return False
    if seconds is None:
        seconds = TEARDOWN_DEADLINE_S
    flush_output()
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


def end_executor(executor: Executor, node: Node | None) -> None:
    """Remove ``node`` from ``executor``, shut it down, and keep it alive (item 2).

    Idempotent after a context shutdown (which does the same).

    Parameters
    ----------
    executor : rclpy.executors.Executor
        The executor that spun the node.
    node : rclpy.node.Node or None
        The node, if it was built.
    """
    with contextlib.suppress(Exception):
        if node is not None:
            executor.remove_node(node)
        executor.shutdown()
    _ENDED_EXECUTORS.append(executor)


def spin_until(executor: Executor, done: Callable[[], bool], period: float = 0.1) -> None:
    """Spin with a finite timeout until ``done()`` (item 4).

    Parameters
    ----------
    executor : rclpy.executors.Executor
        With the nodes added.
    done : callable
        Ends the spin when it returns True (checked between spins).
    period : float, optional
        Timeout (s) of each spin.
    """
    while executor.context.ok() and not done():
        executor.spin_once(timeout_sec=period)


def guard_shutdown_race(context: Context,
                        callback: Callable[..., Any]) -> Callable[..., Any]:
    """``callback``, ending quietly when it fails because ``context`` was shut down (item 5).

    Parameters
    ----------
    context : rclpy.context.Context
        The node's context.
    callback : callable
        A subscription or timer callback.

    Returns
    -------
    callable
        The guarded callback.
    """
    def guarded(*args: Any) -> Any:
        try:
            return callback(*args)
        except Exception:
            if context.ok():
                raise
            return None           # the context was shut down under this callback: done
    return guarded
