"""The two seams of the tracking loop: what a controller is and what a plant is.

A :class:`Controller` turns a measured pose and a reference sample into a command; our law
(:class:`~.tracker.Tracker`) is one, a peer's law (WPILib's, Nav2's) another.  A :class:`Plant`
takes commands and gives odometry, one step at a time; the kinematic
:class:`~.plant.UnicyclePlant` is one, a physics base another.  Whatever runs a loop - the
in-process simulation (:func:`~.simulate.run_loop`), the :class:`~.follow.Follower`, the
tracker's input rules that the node and the bag replay feed, the bring-up - takes any
implementation, named ``module:callable`` as Nav2 names its plugins (:func:`load_factory`):
nothing is registered by hand.  See doc/developing.md, "The two seams".
"""
from __future__ import annotations

import importlib
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Protocol, runtime_checkable

from .errors import LoopConfigError

if TYPE_CHECKING:   # pragma: no cover - types only (loop imports nothing from here at run time)
    from .tracker import Command, TrackerConfig
    from .plant import PlantConfig
    from .reference import RefSample
    from .sensors import OdometrySample
    from .timing import PeriodEstimator

__all__ = ['Controller', 'Plant', 'ControllerFactory', 'PlantFactory', 'DEFAULT_CONTROLLER',
           'DEFAULT_PLANT', 'load_factory', 'make_controller', 'make_plant']

#: Our tracking law, the controller a tracker runs unless told otherwise.
DEFAULT_CONTROLLER = 'nonfragile_tracker.control.simulation.tracker:Tracker'
#: The kinematic unicycle with latency, lag and odometry models.
DEFAULT_PLANT = 'nonfragile_tracker.control.simulation.plant:UnicyclePlant'


@runtime_checkable
class Controller(Protocol):
    """A tracking law: a command from a measured pose and a reference sample.

    ``timing`` measures the odometry period from the stamps the law is given (the input
    rules feed it stamps while no step is due); ``horizon`` (s) is how far ahead of the
    measurement the law wants its reference sampled (0: at the measurement's time; a
    latency predictor's horizon otherwise).
    """

    @property
    def timing(self) -> PeriodEstimator:
        """The period estimate of the odometry stamps the law is given."""
        ...   # pragma: no cover - protocol

    @property
    def horizon(self) -> float:
        """Time (s) ahead of the measurement at which the reference is sampled."""
        ...   # pragma: no cover - protocol

    def reset(self, v: float | None = None) -> None:
        """Forget the law's state.

        Parameters
        ----------
        v : float, optional
            Speed (m/s) to start from (default: the next measured one).
        """
        ...   # pragma: no cover - protocol

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
        """One command for the pose ``(x, y, th)`` measured at ``stamp`` (default ``ref.t``).

        Parameters
        ----------
        x, y, th : float
            Measured pose (m, m, rad).
        ref : RefSample
            The reference sample (of the time ``stamp + horizon``, or extrapolated to it).
        measured_speed : float, optional
            Measured speed (m/s).
        stamp : float, optional
            Measurement time (s).
        stamp_ns : int, optional
            The same time in integer nanoseconds (the message's stamp).
        measured_rate : float, optional
            Measured yaw rate (rad/s, the odometry's ``twist.angular.z``).

        Returns
        -------
        Command
        """
        ...   # pragma: no cover - protocol


@runtime_checkable
class Plant(Protocol):
    """A simulated base stepped in lockstep: commands in, odometry out, one step ``dt``.

    ``x, y, th, v`` are the true pose and speed (for scoring, never for the controller);
    ``cmd`` is the command in force; ``k`` the current step (its time is ``k dt``).  Per
    step: :meth:`odometry` (the sample due now, if any), :meth:`command` (what the
    controller sent, if it sent one), :meth:`advance`.
    """

    x: float
    y: float
    th: float
    v: float
    k: int

    @property
    def cmd(self) -> tuple[float, float]:
        """The command in force (m/s, rad/s)."""
        ...   # pragma: no cover - protocol

    @property
    def dt(self) -> float:
        """The plant's step (s)."""
        ...   # pragma: no cover - protocol

    def reset(self) -> None:
        """Back to the initial state (step 0, nothing queued)."""
        ...   # pragma: no cover - protocol

    def command(self, v: float, w: float) -> None:
        """Receive a command at the current step.

        Parameters
        ----------
        v, w : float
            Speed (m/s) and yaw rate (rad/s).
        """
        ...   # pragma: no cover - protocol

    def advance(self) -> None:
        """Advance one step ``dt``."""
        ...   # pragma: no cover - protocol

    def odometry(self) -> OdometrySample | None:
        """The odometry sample to publish at the current step, if one is due."""
        ...   # pragma: no cover - protocol


#: Makes a controller from the tracker's settings (limits, ``dt``; our law also its gain).
ControllerFactory = Callable[['TrackerConfig'], Controller]
#: Makes a plant from the plant settings (step, initial pose, latency, odometry).
PlantFactory = Callable[['PlantConfig'], Plant]


def load_factory(spec: str, kind: str = 'controller') -> Callable[..., Any]:
    """The callable named by ``spec``, ``'package.module:name'`` (a class or a function).

    Parameters
    ----------
    spec : str
        ``module:attribute``, e.g. :data:`DEFAULT_CONTROLLER`.
    kind : str
        What it is for, in the error message (``'controller'`` or ``'plant'``).

    Returns
    -------
    callable

    Raises
    ------
    LoopConfigError
        If ``spec`` is not of that form, the module cannot be imported or has no such
        callable.
    """
    if not isinstance(spec, str) or spec.count(':') != 1 or not all(spec.split(':')):
        default = DEFAULT_CONTROLLER if kind == 'controller' else DEFAULT_PLANT
        raise LoopConfigError(f'{kind} must be named as "package.module:name", got {spec!r} '
                              f'(the default is {default!r})')
    module_name, attr = spec.split(':')
    try:
        module = importlib.import_module(module_name)
    except ImportError as exc:
        raise LoopConfigError(f'{kind} {spec!r}: module {module_name!r} cannot be imported '
                              f'({exc}); install it or put it on PYTHONPATH') from None
    factory = getattr(module, attr, None)
    if not callable(factory):
        raise LoopConfigError(f'{kind} {spec!r}: {module_name} has no callable {attr!r}')
    return factory    # type: ignore[no-any-return]


def make_controller(config: TrackerConfig, spec: str | ControllerFactory | None = None
                    ) -> Controller:
    """A controller for ``config``: our law by default, else the one ``spec`` names.

    Parameters
    ----------
    config : TrackerConfig
        The tracker's settings, handed to the factory.
    spec : str or callable, optional
        ``module:name`` (:func:`load_factory`) or a factory; default ``config.controller``,
        else :data:`DEFAULT_CONTROLLER`.

    Returns
    -------
    Controller

    Raises
    ------
    LoopConfigError
        If the factory cannot be loaded or does not make a :class:`Controller`.
    """
    spec = spec or config.controller or DEFAULT_CONTROLLER
    factory = load_factory(spec) if isinstance(spec, str) else spec
    controller = factory(config)
    if not isinstance(controller, Controller):
        raise LoopConfigError(f'controller {spec!r} made a {type(controller).__name__}, which '
                              'lacks timing, horizon, reset or step (see Controller)')
    return controller


def make_plant(config: PlantConfig, spec: str | PlantFactory | None = None) -> Plant:
    """A plant for ``config``: the kinematic unicycle by default, else the one ``spec`` names.

    Parameters
    ----------
    config : PlantConfig
        The plant settings, handed to the factory.
    spec : str or callable, optional
        ``module:name`` (:func:`load_factory`) or a factory; default :data:`DEFAULT_PLANT`.

    Returns
    -------
    Plant

    Raises
    ------
    LoopConfigError
        If the factory cannot be loaded or does not make a :class:`Plant`.
    """
    spec = spec or DEFAULT_PLANT
    factory = load_factory(spec, 'plant') if isinstance(spec, str) else spec
    plant = factory(config)
    if not isinstance(plant, Plant):
        raise LoopConfigError(f'plant {spec!r} made a {type(plant).__name__}, which lacks '
                              'x, y, th, v, cmd, dt, reset, command, advance or odometry '
                              '(see Plant)')
    return plant
