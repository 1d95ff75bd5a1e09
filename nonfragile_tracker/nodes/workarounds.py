"""Workarounds of upstream faults of the node processes, each with the condition to drop it.

For the rclpy 7.1.6 wheels (ROS 2 Jazzy) with their Fast DDS 2.14; none of this is control
logic: the exit without finalization (:func:`exit_without_finalization`), the kept
executors (:func:`end_executor`), the tear-down deadline (:func:`arm_exit_deadline`), the
finite spin timeout (:func:`spin_until`) and the shutdown race under a callback
(:func:`guard_shutdown_race`).  Lean at import (the standard library only):
:mod:`nonfragile_tracker.nodes.entry` imports it before the heavy imports.

See doc/safety.md, "Workarounds of upstream faults": each fault, its upstream report and
the condition to drop its workaround.
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
    """Mark this process as a node process started by :func:`.nodes.entry.main`.

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
