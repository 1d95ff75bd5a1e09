"""Shared ROS plumbing of the nodes: QoS, parameters with descriptors, message conversion,
spinning and the Jazzy shutdown pattern.  No control math lives here."""
from __future__ import annotations

import os
import signal
import sys
from dataclasses import dataclass
from typing import Any, Callable, Iterable

import rclpy
from rcl_interfaces.msg import FloatingPointRange, ParameterDescriptor, ParameterType
from rclpy.exceptions import InvalidParameterTypeException, ParameterException
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

from .. import topics

from ..errors import InputError
# message conversions and the parameter -> config mapping are ROS-free (bag replay uses them)
from ..msgconv import (fill_pose, fill_reference, ns_to_stamp,  # noqa: F401
                      pose_from_odom, reference_from_msgs, stamp_ns)

__all__ = ['DATA_QOS', 'LATCHED_QOS', 'Param', 'declare', 'stamp_ns', 'ns_to_stamp',
           'pose_from_odom', 'fill_pose', 'reference_from_msgs', 'fill_reference',
           'make_executor', 'run', 'StartupError']

DATA_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=topics.DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

MODES = ('lockstep', 'realtime')


class StartupError(InputError):
    """A node cannot start with its parameters; the message says which and why."""


@dataclass(frozen=True)
class Param:
    """A parameter declaration: name, default, description and optional range."""

    name: str
    default: Any
    description: str
    type: int | None = None
    low: float | None = None
    high: float | None = None
    read_only: bool = False


_TYPES = {bool: ParameterType.PARAMETER_BOOL, int: ParameterType.PARAMETER_INTEGER,
          float: ParameterType.PARAMETER_DOUBLE, str: ParameterType.PARAMETER_STRING}


def declare(node: Node, params: Iterable[Param]) -> None:
    """Declare parameters with descriptors (type, description, range, read-only)."""
    for p in params:
        ptype = p.type
        if ptype is None:
            if isinstance(p.default, list):
                inner = type(p.default[0]) if p.default else float
                ptype = {float: ParameterType.PARAMETER_DOUBLE_ARRAY,
                         int: ParameterType.PARAMETER_INTEGER_ARRAY,
                         str: ParameterType.PARAMETER_STRING_ARRAY}[inner]
            else:
                ptype = _TYPES[type(p.default)]
        desc = ParameterDescriptor(description=p.description, type=ptype, read_only=p.read_only)
        if p.low is not None and ptype == ParameterType.PARAMETER_DOUBLE:
            desc.floating_point_range = [FloatingPointRange(
                from_value=float(p.low), to_value=float(p.high if p.high is not None else 1e300),
                step=0.0)]
        node.declare_parameter(p.name, p.default, desc)


def get(node: Node, name: str) -> Any:
    return node.get_parameter(name).value


def check_mode(value: str, node_name: str) -> str:
    if value not in MODES:
        raise StartupError(f'{node_name}: parameter mode is {value!r}; use one of {MODES}')
    return value


def make_executor(context=None):
    """EventsExecutor (about 2x faster here) unless NONFRAGILE_EXECUTOR=single."""
    if os.environ.get('NONFRAGILE_EXECUTOR', 'events') == 'single':
        return rclpy.executors.SingleThreadedExecutor(context=context)
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


def spin_until(executor, done: Callable[[], bool], period: float = 0.1) -> None:
    """Spin with a finite timeout (the EventsExecutor needs one) until ``done()``."""
    while rclpy.ok() and not done():
        executor.spin_once(timeout_sec=period)


def _on_signal(signum, frame) -> None:            # noqa: ARG001
    """Python-level SIGINT/SIGTERM handler: no exception in the middle of a callback.

    Installed *before* ``rclpy.init`` so rclpy's own handler (which shuts the
    context down and wakes the executor) chains to it; the node is then closed
    in :func:`run`'s ``finally`` between callbacks (the recorder closes its bag).
    """
    rclpy.try_shutdown()


def run(factory: Callable[[], Node], args: list[str] | None = None) -> int:
    """Node main: init, build, spin until the node is finished, Jazzy-style shutdown.

    SIGINT and SIGTERM end the spin cleanly (``close()`` and ``destroy_node()`` run).
    Returns the process exit code: 0, the node's ``exit_code`` attribute if set,
    or 2 when the node refuses to start (:class:`StartupError`, ``ValueError``, a
    bad parameter or arguments rcl cannot parse).
    """
    previous = {s: signal.signal(s, _on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        return _run(factory, args)
    finally:
        for s, h in previous.items():
            signal.signal(s, h)


def _run(factory: Callable[[], Node], args: list[str] | None) -> int:
    try:
        rclpy.init(args=args)
    except Exception as exc:  # noqa: BLE001 - rcl reports bad arguments/params files so
        print(f'[FATAL] cannot start: {exc}'.split(', at /')[0], file=sys.stderr)
        return 2
    node = None
    try:
        try:
            node = factory()
        except (StartupError, ValueError) as exc:
            print(f'[FATAL] {exc}', file=sys.stderr)
            return 2
        except ParameterException as exc:
            hint = (' Write doubles as 1.0, not 1, in parameter files.'
                    if isinstance(exc, InvalidParameterTypeException) else '')
            print(f'[FATAL] invalid parameter: {exc}.{hint}', file=sys.stderr)
            return 2
        executor = make_executor()
        executor.add_node(node)
        spin_until(executor, lambda: getattr(node, 'finished', False))
        return int(getattr(node, 'exit_code', 0) or 0)
    except (KeyboardInterrupt, ExternalShutdownException):
        return int(getattr(node, 'exit_code', 0) or 0)
    finally:
        if node is not None:
            close = getattr(node, 'close', None)
            if close is not None:
                close()
            node.destroy_node()
        rclpy.try_shutdown()
