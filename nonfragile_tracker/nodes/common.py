"""Shared ROS plumbing of the nodes.

QoS, parameters with descriptors, message conversion (re-exported from
:mod:`.msgconv`), the nodes' base class (constructor shape, parameter flow) and the Jazzy
shutdown pattern.  No control math lives here.

See doc/developing.md, section "Node shape", and doc/safety.md, section "Stopping: Ctrl-C,
ros2 launch, systemd".
"""
from __future__ import annotations

import gc
import os
import sys
import time
import traceback
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, fields
from typing import TYPE_CHECKING, Any, Generic, TypeVar

import rclpy
from rcl_interfaces.msg import (FloatingPointRange, ParameterDescriptor, ParameterType,
                                SetParametersResult)
from rclpy.exceptions import InvalidParameterTypeException, ParameterException
from rclpy.context import Context
from rclpy.executors import Executor, ExternalShutdownException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.subscription import Subscription
from rclpy.timer import Timer

from ..interface import topics
from ..errors import InputError
from ..interface.tracker_inputs import MODES as TRACKER_MODES
# message conversions and the parameter -> config mapping are ROS-free (bag replay uses them)
from .entry import catch_stop_signals, ignore_stop_signals, stop_requested
# the workarounds of rclpy 7.1.6 / Fast DDS 2.14 faults, each with the condition to drop it
from .workarounds import arm_exit_deadline, end_executor, guard_shutdown_race, spin_until
# the nodes' errors (nodes/errors.py, ROS-free), where the nodes have always imported them
from .errors import StartupError, StartupStopped
from ..interface.msgconv import (fill_pose, fill_reference, ns_to_stamp,  # noqa: F401
                      pose_from_odom, reference_from_msgs, stamp_ns)

__all__ = ['DATA_QOS', 'LATCHED_QOS', 'Param', 'declare', 'stamp_ns', 'ns_to_stamp',
           'pose_from_odom', 'fill_pose', 'reference_from_msgs', 'fill_reference',
           'make_executor', 'freeze_startup_objects', 'run', 'StartupError', 'AdapterNode',
           'overrides', 'check_mode', 'settings_from', 'require_at_least']

DATA_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=topics.DEPTH,
                      reliability=ReliabilityPolicy.RELIABLE,
                      durability=DurabilityPolicy.VOLATILE)
LATCHED_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1,
                         reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)

if TYPE_CHECKING:
    from _typeshed import DataclassInstance

#: The nodes' modes (the tracker's input rules define them).
MODES = TRACKER_MODES
#: A settings dataclass (:func:`settings_from`).
S = TypeVar('S', bound='DataclassInstance')


@dataclass(frozen=True)
class Param:
    """A parameter declaration: name, default, description and optional range.

    ``default=None`` (with ``type``) declares a parameter without a value (read as ``None``).
    """

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
    """Declare parameters with descriptors (type, description, range, read-only).

    Parameters
    ----------
    node : rclpy.node.Node
        The node that declares them.
    params : iterable of Param
        The declarations.
    """
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
        # no default: a statically typed parameter that must come from a file or -p
        node.declare_parameter(p.name, Parameter.Type(ptype) if p.default is None else p.default,
                               desc)


def get(node: Node, name: str) -> Any:
    """The value of parameter ``name`` of ``node``.

    Parameters
    ----------
    node : rclpy.node.Node
        A node that declared it.
    name : str
        The parameter.

    Returns
    -------
    object
    """
    return node.get_parameter(name).value


def settings_from(settings_class: type[S], values: Mapping[str, Any], /, **given: Any) -> S:
    """A node's settings dataclass from its parameter values.

    Each field named in ``given`` takes that value (a validated or derived one, or a
    parameter of another name); every other field the value of the parameter of its name
    (a field with a default keeps it when ``values`` lacks the name).

    Parameters
    ----------
    settings_class : dataclass type
        The settings class (e.g. ``TrackerSettings``).
    values : mapping
        The node's parameter values by name.
    **given
        Fields set here rather than from the parameter of the same name.

    Returns
    -------
    settings_class
    """
    names = {f.name for f in fields(settings_class)} - given.keys()
    return settings_class(**given, **{n: values[n] for n in names if n in values})


def require_at_least(values: Mapping[str, Any], name: str, low: int) -> None:
    """Refuse (:class:`.StartupError`) an integer parameter below ``low``.

    Parameters
    ----------
    values : mapping
        The node's parameter values by name.
    name : str
        The parameter.
    low : int
        Its smallest allowed value.
    """
    if values[name] < low:
        raise StartupError(f'{name} must be at least {low}, got {values[name]}')


def check_mode(value: str, node_name: str | None = None) -> str:
    """``value`` if it is one of :data:`MODES`, else :class:`.StartupError`.

    Parameters
    ----------
    value : str
        The ``mode`` parameter.
    node_name : str, optional
        Prefixed to the error message.

    Returns
    -------
    str
    """
    if value not in MODES:
        prefix = f'{node_name}: ' if node_name else ''
        raise StartupError(f'{prefix}parameter mode is {value!r}; use one of {MODES}')
    return value


def make_executor(context: Context | None = None) -> Executor:
    """EventsExecutor (about 2x faster here) unless NONFRAGILE_EXECUTOR=single.

    Parameters
    ----------
    context : rclpy.context.Context, optional
        Default: rclpy's default context.

    Returns
    -------
    rclpy.executors.Executor
    """
    if os.environ.get('NONFRAGILE_EXECUTOR', 'events') == 'single':
        return rclpy.executors.SingleThreadedExecutor(context=context)
    from rclpy.experimental import EventsExecutor
    return EventsExecutor(context=context)


def freeze_startup_objects() -> None:
    """Take the objects made at start-up out of Python's cyclic garbage collector.

    Modules, messages, the node and its parameters (some 40,000 objects) would otherwise be
    walked by every full collection - about 13 ms here, and a collection of the middle
    generation soon after start-up about 1 ms - stalls that land on a real-time callback.
    Collected once now, then frozen (``gc.freeze``); objects made later are collected as
    usual.
    """
    gc.collect()
    gc.freeze()


def overrides(**values: Any) -> list[Parameter]:
    """Parameter overrides from values: ``XNode(parameter_overrides=overrides(dt=0.02))``.

    Parameters
    ----------
    **values
        Parameter values by name.

    Returns
    -------
    list of rclpy.parameter.Parameter
    """
    return [Parameter(k, value=v) for k, v in values.items()]


#: A node's configuration type (``AdapterNode[XConfig]``, :attr:`AdapterNode.config`).
C = TypeVar('C')


class AdapterNode(Node, Generic[C]):
    """Base of the package's nodes: one constructor shape, one parameter flow, one way to end.

    Every node is built the same way (rclpy ``Node`` keyword arguments pass through)::

        class XNode(AdapterNode[XConfig]):
            def __init__(self, node_name: str = 'x', **node_kwargs):
                super().__init__(node_name, **node_kwargs)
                self.config = self.bind_parameters(PARAMS, x_config)   # declare, read, validate
                ...                                                     # then create interfaces

    ``x_config(values) -> XConfig`` is a plain function of the parameter values (a dict by
    name) that validates them and raises :class:`~nonfragile_tracker.errors.InputError`.
    :meth:`bind_parameters` uses it three times: at start-up (a refusal is a
    :class:`.StartupError`, exit code 2), in the *on-set* callback to validate a proposed
    runtime change (a refusal keeps the old values and says why), and in the *post-set*
    callback to apply an accepted change (``self.config`` is replaced, then
    :meth:`apply_config` runs) - the ros2 demos' split of validation and side effects.

    Run protocol (used by :func:`run`): ``finished`` ends the spin, ``exit_code`` is the
    process exit code, :meth:`drain` runs after a finished spin (blocking work such as
    waiting for acknowledgements belongs there, never in a callback), :meth:`close`
    releases resources on every path (also from :meth:`destroy_node`).

    Callbacks registered with :meth:`create_subscription` and :meth:`create_timer` are
    guarded: if a signal shuts the context down while one runs (rclpy does that from its
    own thread), whatever fails in it because of the shutdown (a publish, a count of
    matched endpoints) ends that callback quietly instead of raising out of the executor.
    """

    config: C        #: the validated configuration (replaced when a runtime change is applied)

    def __init__(self, node_name: str, **node_kwargs: Any):
        """Make the rclpy node.

        Parameters
        ----------
        node_name : str
            The node's name.
        **node_kwargs
            rclpy ``Node`` keyword arguments (``context``, ``parameter_overrides`` ...).
        """
        super().__init__(node_name, **node_kwargs)
        self.finished = False
        self.exit_code = 0

    # ------------------------------------------------------------------ parameters
    def bind_parameters(self, params: Sequence[Param],
                        configure: Callable[[dict[str, Any]], C]) -> C:
        """Declare ``params``, build the node's configuration, validate/apply runtime sets.

        Returns ``configure(values)``; raises :class:`.StartupError` (``'<node>: why'``) if
        the values are refused.  Afterwards a set of a writable parameter is validated by
        ``configure`` with the proposed values (on-set callback) and applied (post-set
        callback: ``self.config = configure(values)``, then :meth:`apply_config`).

        Parameters
        ----------
        params : sequence of Param
            The node's parameters.
        configure : callable
            ``configure(values) -> config``: validates the values (by name), raises
            :class:`~nonfragile_tracker.errors.InputError` if they are bad.

        Returns
        -------
        C
            The configuration at start-up.
        """
        self.declare_bound(params, configure)
        return self.configure_from_parameters()

    def declare_bound(self, params: Sequence[Param],
                      configure: Callable[[dict[str, Any]], C]) -> None:
        """Declare ``params`` and route runtime sets through ``configure``; validate nothing yet.

        The first half of :meth:`bind_parameters`, for a managed node that validates its
        parameters in its configure transition (:meth:`configure_from_parameters`) rather
        than in its constructor.  While :attr:`configured` is false a runtime set is only
        checked by the descriptors (the configure transition validates the whole set).

        Parameters
        ----------
        params : sequence of Param
            The node's parameters.
        configure : callable
            ``configure(values) -> config`` (as for :meth:`bind_parameters`).
        """
        params = list(params)
        declare(self, params)
        self._bound = {p.name for p in params}
        self._configure = configure
        self.add_on_set_parameters_callback(self._validate_parameters)
        self.add_post_set_parameters_callback(self._apply_parameters)

    def configure_from_parameters(self) -> C:
        """The configuration of the current parameter values; :class:`.StartupError` if refused.

        The message is ``'<node>: why'`` (the refused key named by the validator).

        Returns
        -------
        C
        """
        try:
            return self._configure(self.parameter_values())
        except InputError as exc:       # bad input only: a programming error keeps its traceback
            raise StartupError(f'{self.get_name()}: {exc}') from None

    @property
    def configured(self) -> bool:
        """Whether :attr:`config` is in force.

        Always, except for a managed node before its configure transition and after its
        clean-up.
        """
        return True

    def parameter_values(self, changes: Mapping[str, Any] | None = None) -> dict[str, Any]:
        """Current values of the bound parameters (``None`` if unset), updated by ``changes``.

        Parameters
        ----------
        changes : mapping, optional
            Proposed values by name.

        Returns
        -------
        dict
        """
        values = {n: self.get_parameter_or(n).value for n in self._bound}
        values.update(changes or {})
        return values

    def _validate_parameters(self, params: list[Parameter]) -> SetParametersResult:
        changes = {p.name: p.value for p in params if p.name in self._bound}
        if not changes or not self.configured:     # unconfigured: configure validates
            return SetParametersResult(successful=True)
        try:
            self._configure(self.parameter_values(changes))
        except InputError as exc:
            reason = f'{exc}; keeping the old value'
            self.log('error', f'rejected parameter set: {reason}')
            return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def _apply_parameters(self, params: list[Parameter]) -> None:
        changed = sorted(p.name for p in params if p.name in self._bound)
        if not changed or not self.configured:
            return
        old, self.config = self.config, self._configure(self.parameter_values())
        self.apply_config(old, self.config)
        self.log('info', f'accepted parameter set: {changed}')

    def apply_config(self, old: C, new: C) -> None:
        """Hook: make derived state follow an accepted runtime change (default: nothing).

        Parameters
        ----------
        old, new : C
            The configuration before and after the change.
        """

    # ------------------------------------------------------------------ guarded callbacks
    def create_subscription(self, msg_type: Any, topic: str, callback: Callable[..., Any],
                            *args: Any, **kwargs: Any) -> Subscription:
        """rclpy's, with the callback guarded against a shutdown under it.

        Parameters
        ----------
        msg_type : type
            The message class.
        topic : str
            The topic name.
        callback : callable
            Called with each message.
        *args, **kwargs
            Passed on to :meth:`rclpy.node.Node.create_subscription` (QoS ...).

        Returns
        -------
        rclpy.subscription.Subscription
        """
        return super().create_subscription(msg_type, topic,
                                           guard_shutdown_race(self.context, callback),
                                           *args, **kwargs)

    def create_timer(self, timer_period_sec: float, callback: Callable[..., Any],
                     *args: Any, **kwargs: Any) -> Timer:
        """rclpy's, with the callback guarded against a shutdown under it.

        Parameters
        ----------
        timer_period_sec : float
            The period (s).
        callback : callable
            Called at each period.
        *args, **kwargs
            Passed on to :meth:`rclpy.node.Node.create_timer` (clock ...).

        Returns
        -------
        rclpy.timer.Timer
        """
        return super().create_timer(timer_period_sec,
                                    guard_shutdown_race(self.context, callback), *args, **kwargs)

    # ------------------------------------------------------------------ logging
    @property
    def stopping(self) -> bool:
        """Whether the node is being stopped: a stop signal came or the context is down."""
        return stop_requested() or not self.context.ok()

    def log(self, level: str, text: str) -> None:
        """Log ``text`` at ``level`` ('info', 'warn' or 'error'), guarded against shutdown.

        Through the node's logger while the context is up and no stop signal came; to
        stderr in the same form after.  rclpy's signal thread shuts the context down while
        the main thread runs on; a node log then ends in rcl's 'Failed to publish log
        message to rosout: publisher's context is invalid'.  Callbacks, the start-up line
        and the nodes' ``close`` all log here, so only a signal landing during the log call
        itself (microseconds) is left.

        Parameters
        ----------
        level : str
            ``info``, ``warn`` or ``error`` (anything else: error).
        text : str
            The message.
        """
        if not self.stopping:
            logger = Node.get_logger(self)          # (rclpy's, untyped)
            # one call site per severity: rclpy refuses a severity change at one site
            if level == 'info':
                logger.info(text)
            elif level == 'warn':
                logger.warning(text)
            else:
                logger.error(text)
        else:
            ns = time.time_ns()                     # rcutils' console format
            print(f'[{level.upper()}] [{ns // 10**9}.{ns % 10**9:09d}] [{self.get_name()}]: '
                  f'{text}', file=sys.stderr)

    def check_stop(self) -> None:
        """Raise :class:`.StartupStopped` if a stop signal came (or the context is down).

        For long start-up work (the constructor runs before the spin, where nothing else
        acts on a signal): called between its pieces, each well under a second, so the
        node ends within a second of SIGINT/SIGTERM at any moment of its start-up
        (:func:`run` ends the process with 0).
        """
        if self.stopping:
            raise StartupStopped(f'{self.get_name()}: stop signal during start-up')

    # ------------------------------------------------------------------ ending
    def drain(self) -> None:
        """Hook: blocking work after the spin ended because the node finished (not on a signal)."""

    def close(self) -> None:
        """Hook: release resources (idempotent); called on every way out."""

    def destroy_node(self) -> None:
        """Close (:meth:`close`), then destroy the rclpy node."""
        self.close()
        Node.destroy_node(self)                     # (rclpy's, untyped)


def _tear_down(context: Context, node: AdapterNode[Any] | None,
               executor: Executor | None) -> None:
    """Executor, node and rclpy shut down (after the node's own clean-up)."""
    if executor is not None:
        end_executor(executor, node)                # (workarounds: kept alive)
    if node is not None:
        node.destroy_node()                         # (close() again: a no-op)
    try:
        rclpy.try_shutdown()
    except Exception:  # noqa: BLE001 - rclpy's signal thread shut it down meanwhile
        if context.ok():
            raise


def _fatal(text: str) -> int:
    print(f'[FATAL] {text}', file=sys.stderr)
    return 2


class _MissedStop:
    """Spin-loop check for a stop signal that rclpy's handlers did not act on.

    A SIGINT/SIGTERM normally reaches rclpy's handlers too: rclpy's signal thread shuts
    the context down (tearing the executor down from there) and the spin ends with
    ``ExternalShutdownException`` - the spin must go on until then, since ending it
    while that thread still works races the executor's teardown (an EventsExecutor
    aborts).  A signal that came before ``rclpy.init`` installed those handlers only set
    the flag: after :data:`GRACE` s with the context still up, the context is shut down
    here, in the main thread (nothing else is shutting it down then).
    """

    GRACE = 0.5

    def __init__(self, context: Context):
        self.context = context
        self.since: float | None = None

    def __call__(self) -> bool:
        if not stop_requested():
            return False
        now = time.monotonic()
        if self.since is None:
            self.since = now
        if now - self.since < self.GRACE or not self.context.ok():
            return False
        self.context.try_shutdown()
        return True


def run(node_class: Callable[[], AdapterNode[Any]], args: list[str] | None = None) -> int:
    """Process main of a node: the Jazzy pattern (init, spin, destroy, try_shutdown).

    Exit code: 0 after SIGINT/SIGTERM or a normal end, the node's ``exit_code`` if it set
    one (5: lockstep abort), 2 when it refuses to start (a :class:`.StartupError` or other
    ``ValueError``, a bad parameter, arguments rcl cannot parse) with a ``[FATAL]`` line, 1
    after an unexpected error (its traceback printed before the tear-down).  The same code
    ends the process if the DDS tear-down hangs (:func:`.workarounds.arm_exit_deadline`).

    Signals: rclpy's own handlers (installed by ``rclpy.init`` for SIGINT and SIGTERM)
    shut the context down from rclpy's signal thread; the executor then raises
    ``ExternalShutdownException`` between callbacks and the node is destroyed (the
    recorder closes its bag).  Python's KeyboardInterrupt is switched off first: SIGINT
    and SIGTERM only set a flag (:func:`.entry.catch_stop_signals`, to which rclpy's
    handlers chain).  A KeyboardInterrupt would be raised wherever the interpreter
    happens to be - in a callback writing the bag, or in the clean-up when ``ros2
    launch`` forwards a second SIGINT after the terminal's - and print a traceback, so
    repeated signals during the clean-up are harmless.  The flag also covers the window
    before ``rclpy.init`` has installed its handlers (and, through the console scripts of
    :mod:`.entry`, the imports): a signal there ends the process with 0 before or right
    after the node is built, instead of being lost.
    Exceptions that are only the consequence of the shutdown racing the main thread
    (rclpy 7.1: ros2/rclpy#1352, see :mod:`.workarounds`) are not reported.

    Parameters
    ----------
    node_class : callable
        Makes the node (an :class:`AdapterNode`), e.g. ``TrackerNode``.
    args : list of str, optional
        Command-line arguments for ``rclpy.init`` (``--ros-args ...``).

    Returns
    -------
    int
        The exit code.
    """
    catch_stop_signals()
    if stop_requested():
        ignore_stop_signals()
        return 0                                    # a signal while importing
    try:
        rclpy.init(args=args)
    except Exception as exc:  # noqa: BLE001 - rcl reports bad arguments/params files so
        return _fatal(f'cannot start: {exc}'.split(', at /')[0])
    context = rclpy.get_default_context()
    node = None
    executor = None
    failed: int | None = None                       # 2: refused to start, 1: an error
    try:
        try:
            node = node_class()
        except Exception as exc:  # noqa: BLE001
            if not context.ok() or stop_requested():
                return 0                            # a signal during start-up
            if isinstance(exc, ParameterException):
                hint = (' Write doubles as 1.0, not 1, in parameter files.'
                        if isinstance(exc, InvalidParameterTypeException) else '')
                failed = _fatal(f'invalid parameter: {exc}.{hint}')
            elif isinstance(exc, ValueError):       # StartupError, InputError
                failed = _fatal(str(exc))
            else:
                raise
            return failed
        executor = make_executor()
        executor.add_node(node)
        freeze_startup_objects()
        node.log('info', 'started; SIGINT (Ctrl-C) or SIGTERM ends it cleanly')
        missed = _MissedStop(context)
        spin_until(executor, lambda: node.finished or missed())
        if node.finished and not node.stopping:
            node.drain()
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except Exception:
        if context.ok():                            # else the shutdown racing the main thread
            # a real error: said now, before the tear-down (which may end the process at
            # its deadline), and the exit code 1 a traceback would have given
            traceback.print_exc()
            failed = 1
    finally:
        ignore_stop_signals()                       # ending: a repeated signal changes nothing
        try:
            if node is not None:
                node.close()                        # own resources first: the recorder's bag
        finally:
            code = failed if failed is not None else \
                int(node.exit_code or 0) if node is not None else 0
            # the DDS tear-down below can deadlock inside Fast DDS 2.14 (see
            # workarounds.arm_exit_deadline): past the deadline the process ends with this code
            arm_exit_deadline(code)
            _tear_down(context, node, executor)
    return code
