"""Unicycle model, its exact linearization by dynamic extension, and eq. (4).

The unicycle (paper eq. 2) with the dynamic extension ``v' = a`` has state
``(x, y, th, v)`` and inputs ``(a, w)``.  With ``xi = [x, v cos th, y, v sin th]``
and ``u = [a cos th - w v sin th, a sin th + w v cos th]`` it becomes the pair
of double integrators ``xi' = A xi + B u`` of eq. (4) (Oriolo, De Luca,
Vendittelli, IEEE TCST 10(6), 2002).  The map ``(a, w) -> u`` has the decoupling
matrix ``[[cos th, -v sin th], [sin th, v cos th]]`` whose determinant is ``v``:
it cannot be inverted at ``v = 0``; :func:`inputs_from_u` raises
:class:`InputError` there instead of dividing by zero.

Everything here is plain numpy / math; no ROS.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ..validate import StateInputShape

__all__ = [
    'LinearizedModel', 'double_integrator_model',
    'xi_from_state', 'u_from_inputs', 'inputs_from_u',
]


@dataclass(frozen=True)
class LinearizedModel(StateInputShape):
    """Matrices of eq. (4): ``xi' = A xi + B u``, ``y = C xi``."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray


def double_integrator_model(axes: int = 2) -> LinearizedModel:
    """Return eq. (4): ``axes`` decoupled double integrators (the paper: 2).

    State order per axis is (position, velocity), so for two axes
    ``xi = [x, x', y, y']`` exactly as in the paper.

    Parameters
    ----------
    axes : int, optional
        Number of double integrators (>= 1).

    Returns
    -------
    LinearizedModel
        ``A`` of shape ``(2 axes, 2 axes)``, ``B`` ``(2 axes, axes)``, ``C`` ``(axes, 2 axes)``.

    Raises
    ------
    ValueError
        If ``axes < 1``.
    """
    if axes < 1:
        raise ValueError(f'axes must be >= 1, got {axes}')
    a1 = np.array([[0.0, 1.0], [0.0, 0.0]])
    b1 = np.array([[0.0], [1.0]])
    c1 = np.array([[1.0, 0.0]])
    eye = np.eye(axes)
    return LinearizedModel(np.kron(eye, a1), np.kron(eye, b1), np.kron(eye, c1))


def xi_from_state(x: float, y: float, th: float, v: float) -> tuple[float, float, float, float]:
    """Linearizing coordinates ``xi = [x, v cos th, y, v sin th]``.

    Parameters
    ----------
    x, y : float
        Position [m].
    th : float
        Heading [rad].
    v : float
        Forward speed [m/s].

    Returns
    -------
    tuple of 4 float
        ``xi`` [m, m/s, m, m/s].
    """
    return (x, v * math.cos(th), y, v * math.sin(th))


def u_from_inputs(th: float, v: float, a: float, w: float) -> tuple[float, float]:
    """Map unicycle inputs ``(a, w)`` to the linear model's ``u`` (paper, below eq. 3).

    Parameters
    ----------
    th : float
        Heading [rad].
    v : float
        Forward speed [m/s].
    a : float
        Forward acceleration [m/s^2].
    w : float
        Angular rate [rad/s].

    Returns
    -------
    tuple of 2 float
        ``u`` [m/s^2].
    """
    c, s = math.cos(th), math.sin(th)
    return (a * c - w * v * s, a * s + w * v * c)


def inputs_from_u(th: float, v: float, u1: float, u2: float,
                  min_speed: float = 0.0) -> tuple[float, float]:
    """Invert :func:`u_from_inputs`.

    ``a = u1 cos th + u2 sin th``, ``w = (u2 cos th - u1 sin th) / v``.

    Parameters
    ----------
    th : float
        Heading [rad].
    v : float
        Forward speed [m/s].
    u1, u2 : float
        The linear model's input [m/s^2].
    min_speed : float, optional
        Smallest ``|v|`` accepted [m/s].

    Returns
    -------
    a : float
        Forward acceleration [m/s^2].
    w : float
        Angular rate [rad/s].

    Raises
    ------
    InputError
        When ``|v| <= min_speed`` (and always at ``v = 0``); the tracker applies its
        documented speed floor before calling.
    """
    if not abs(v) > min_speed:
        raise InputError(
            f'linearizing map is singular: |v| = {abs(v):.3g} m/s <= {min_speed:.3g} m/s; '
            'the decoupling matrix has determinant v. Apply a speed floor or start with v != 0.')
    c, s = math.cos(th), math.sin(th)
    return (u1 * c + u2 * s, (u2 * c - u1 * s) / v)
