"""Reference paths: position, velocity, acceleration and tangent heading at time t.

The paper's circle is ``x_d = 0.5 cos(0.01 t)``, ``y_d = 0.5 sin(0.01 t)``.  Its
``theta_d(t) = t`` is not the heading of that circle (the tangent heading is
``0.01 t + pi/2``); the linearized law does not use ``theta_d`` at all, and here
the heading is always the tangent of the path (``atan2(y_d', x_d')``).

See doc/theory.md, section "What the numbers say".
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Mapping, NamedTuple

from ..validate import as_finite_float
from .errors import PathError

__all__ = ['RefSample', 'Path', 'circle', 'figure_eight', 'make_path', 'PATHS', 'PathError']


class RefSample(NamedTuple):
    """Desired state at time ``t`` (SI units, ``odom`` frame)."""

    t: float
    x: float
    y: float
    vx: float
    vy: float
    ax: float
    ay: float
    heading: float

    @property
    def xi(self) -> tuple[float, float, float, float]:
        """Desired linearized state ``xi_d = [x, x', y, y']``."""
        return (self.x, self.vx, self.y, self.vy)


@dataclass(frozen=True)
class Path:
    """A named path ``t -> RefSample`` with its parameters."""

    name: str
    params: Mapping[str, float]
    _fn: Callable[[float], tuple[float, float, float, float, float, float]]
    _heading0: float
    #: Highest multiple of ``rate`` among the path's harmonics (sampling density).
    harmonic: int = 1

    def kinematics(self, t: float) -> tuple[float, float, float, float, float, float]:
        """``(x, y, vx, vy, ax, ay)`` at time ``t`` [s]: :meth:`sample` without the heading.

        Parameters
        ----------
        t : float
            Time [s].

        Returns
        -------
        tuple of 6 float
        """
        return self._fn(t)

    @property
    def rest_heading(self) -> float:
        """Heading [rad] where the path is at rest (the parameterization's tangent)."""
        return self._heading0

    def sample(self, t: float) -> RefSample:
        """Position, velocity, acceleration and heading of the path at time ``t``.

        Parameters
        ----------
        t : float
            Time [s] (the path's own clock: 0 at its start).

        Returns
        -------
        RefSample
        """
        x, y, vx, vy, ax, ay = self._fn(t)
        if vx * vx + vy * vy > 1e-24:
            heading = math.atan2(vy, vx)
        else:  # at rest: keep the tangent direction of the parameterization
            heading = self._heading0
        return RefSample(t, x, y, vx, vy, ax, ay, heading)


def _finite(name: str, value: Any) -> float:
    return as_finite_float(value, f'path parameter {name}', error=PathError)


def _path_params(radius: Any, rate: Any, center_x: Any, center_y: Any, phase: Any
                 ) -> tuple[float, float, float, float, float]:
    r = _finite('radius', radius)
    if r <= 0:
        raise PathError(f'path parameter radius must be > 0 m, got {r}')
    return (r, _finite('rate', rate), _finite('center_x', center_x),
            _finite('center_y', center_y), _finite('phase', phase))


def circle(radius: float = 0.5, rate: float = 0.01, center_x: float = 0.0,
           center_y: float = 0.0, phase: float = 0.0) -> Path:
    """Circle ``c + r [cos(W t + phase), sin(W t + phase)]`` (paper: r = 0.5, W = 0.01).

    Parameters
    ----------
    radius : float, optional
        ``r`` [m], > 0.
    rate : float, optional
        ``W`` [rad/s]; negative runs clockwise.
    center_x, center_y : float, optional
        ``c`` [m].
    phase : float, optional
        Angle at ``t = 0`` [rad].

    Returns
    -------
    Path

    Raises
    ------
    PathError
        For a non-finite parameter or ``radius <= 0``.
    """
    r, w, cx, cy, ph = _path_params(radius, rate, center_x, center_y, phase)

    def fn(t: float) -> tuple[float, float, float, float, float, float]:
        a = w * t + ph
        c, s = math.cos(a), math.sin(a)
        return (cx + r * c, cy + r * s, -r * w * s, r * w * c, -r * w * w * c, -r * w * w * s)

    h0 = ph + (math.pi / 2 if w >= 0 else -math.pi / 2)
    return Path('circle', dict(radius=r, rate=w, center_x=cx, center_y=cy, phase=ph), fn, h0)


def figure_eight(radius: float = 0.5, rate: float = 0.01, center_x: float = 0.0,
                 center_y: float = 0.0, phase: float = 0.0) -> Path:
    """Lemniscate of Gerono: ``x = c_x + r sin(a)``, ``y = c_y + (r/2) sin(2a)``.

    The parameter is ``a = W t + phase`` (``W`` = ``rate``).

    Parameters
    ----------
    radius : float, optional
        ``r`` [m], > 0.
    rate : float, optional
        ``W`` [rad/s].
    center_x, center_y : float, optional
        ``c`` [m].
    phase : float, optional
        Parameter at ``t = 0`` [rad].

    Returns
    -------
    Path

    Raises
    ------
    PathError
        For a non-finite parameter or ``radius <= 0``.
    """
    r, w, cx, cy, ph = _path_params(radius, rate, center_x, center_y, phase)

    def fn(t: float) -> tuple[float, float, float, float, float, float]:
        a = w * t + ph
        s1, c1 = math.sin(a), math.cos(a)
        s2, c2 = math.sin(2 * a), math.cos(2 * a)
        return (cx + r * s1, cy + 0.5 * r * s2, r * w * c1, r * w * c2,
                -r * w * w * s1, -2 * r * w * w * s2)

    h0 = math.atan2(math.cos(2 * ph), math.cos(ph)) if w >= 0 else \
        math.atan2(-math.cos(2 * ph), -math.cos(ph))
    return Path('figure_eight', dict(radius=r, rate=w, center_x=cx, center_y=cy, phase=ph),
                fn, h0, harmonic=2)


PATHS: dict[str, Callable[..., Path]] = {'circle': circle, 'figure_eight': figure_eight}


def make_path(name: str, **params: float) -> Path:
    """Build a path by name (``circle`` or ``figure_eight``).

    Parameters
    ----------
    name : str
        A key of ``PATHS``.
    **params
        The path function's parameters (:func:`circle`, :func:`figure_eight`).

    Returns
    -------
    Path

    Raises
    ------
    PathError
        For an unknown name or an invalid parameter value.
    """
    try:
        factory = PATHS[name]
    except KeyError:
        raise PathError(f'unknown path {name!r}; choose one of {", ".join(sorted(PATHS))}') \
            from None
    return factory(**params)
