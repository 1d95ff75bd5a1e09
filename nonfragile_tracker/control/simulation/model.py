"""Unicycle model, its exact linearization by dynamic extension, and eq. (4).

The unicycle (paper eq. 2) with the dynamic extension ``v' = a`` becomes, in
``xi = [x, v cos th, y, v sin th]``, the pair of double integrators of eq. (4); the map back
from ``u`` to ``(a, w)`` cannot be inverted at ``v = 0``, where :func:`inputs_from_u` raises
:class:`~nonfragile_tracker.errors.InputError` instead of dividing by zero.  Plain numpy /
math; no ROS.

See doc/theory.md, section "Model".
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError
from ..validate import StateInputShape

__all__ = ['LinearizedModel', 'double_integrator_model', 'xi_from_state', 'u_from_inputs',
           'inputs_from_u', 'wrap', 'wrap_due', 'yaw_to_quaternion', 'quaternion_to_yaw']


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


_PI, _TAU = math.pi, math.tau


def wrap_due(th: np.ndarray, k: int, wstep: float) -> tuple[np.ndarray, int]:
    """Wrap the headings ``th`` into [-pi, pi] if any left it; the next step to look again.

    ``wstep`` bounds the heading change per step, so no heading can leave [-pi, pi]
    before the returned step; a non-finite heading (nan) is looked at every step.

    Parameters
    ----------
    th : numpy.ndarray
        Headings (rad), one per case.
    k : int
        The current step.
    wstep : float
        Bound of the heading change per step (rad).

    Returns
    -------
    (numpy.ndarray, int)
        The headings (wrapped or as given) and the next step to look again.
    """
    m = float(np.abs(th).max())
    if m > _PI:
        th = wrap(th)
        m = float(np.abs(th).max())
    return th, (k + 1 + int((_PI - m) / wstep) if m <= _PI else k + 1)


def wrap(x: np.ndarray) -> np.ndarray:
    """``math.remainder(x, tau)`` element-wise (exact: one subtraction, Sterbenz).

    Parameters
    ----------
    x : numpy.ndarray
        Angles (rad).

    Returns
    -------
    numpy.ndarray
        The angles in [-pi, pi] (``x`` itself when none left it).
    """
    ax = np.abs(x)
    over = ax > _PI
    if not over.any():
        return x
    out = np.where(over, x - np.copysign(_TAU, x), x)
    far = ax >= 3.0 * _PI
    if far.any():
        for i in np.flatnonzero(far):
            out[i] = math.remainder(float(x[i]), _TAU)
    return out


def yaw_to_quaternion(th: float) -> tuple[float, float, float, float]:
    """Quaternion (x, y, z, w) of a rotation by ``th`` about z (REP-103).

    Parameters
    ----------
    th : float
        Yaw (rad).

    Returns
    -------
    (float, float, float, float)
    """
    return (0.0, 0.0, math.sin(0.5 * th), math.cos(0.5 * th))


def quaternion_to_yaw(qx: float, qy: float, qz: float, qw: float) -> float:
    """Yaw (rotation about z) of a quaternion; valid for any non-zero norm.

    Parameters
    ----------
    qx, qy, qz, qw : float
        The quaternion.

    Returns
    -------
    float
        Yaw (rad) in ``[-pi, pi]``.
    """
    return math.atan2(2.0 * (qw * qz + qx * qy), qw * qw + qx * qx - qy * qy - qz * qz)
