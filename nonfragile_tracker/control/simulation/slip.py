"""A turning base's side slip: the lateral speed it slides at, and the pose it leaves behind.

A skid-steer (and, less, any base on soft tyres) slides outward in a turn: its body moves
sideways at ``v_y = -c(|w|) v w`` (m/s; ``c`` in s, the *side-slip coefficient*, a function
of the turn rate), which neither its encoders nor its gyro see, so its odometry drifts from
the true pose.  :func:`slip_coefficient` evaluates ``c`` from a table of turn rates
(piecewise linear, constant beyond the table's ends, :func:`hat_basis` the same as the
columns an identification fits), and :class:`SlideReckoner` integrates the slide the table
predicts from the measured speed, yaw rate and heading: the offset the tracker adds to the
odometry's position (``TrackerConfig.side_slip``).  Pure Python and numpy, no ROS.

See doc/theory.md, section "Side slip".
"""
from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from .errors import LoopConfigError

__all__ = ['slip_coefficient', 'hat_basis', 'check_slip_table', 'SlideReckoner']

#: Largest side-slip coefficient accepted (s): a lateral speed of 10 x v w.
MAX_COEFFICIENT = 10.0
#: Largest angle between heading and motion the tracker is told of (rad, 0.3 = 17 deg).
MAX_COURSE_OFFSET = 0.3


def check_slip_table(rates: Sequence[float], coefficients: Sequence[float]
                     ) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """The side-slip table as two tuples of floats, validated.

    Parameters
    ----------
    rates : sequence of float
        Turn rates ``|w|`` (rad/s) of the table: finite, >= 0, strictly increasing.
    coefficients : sequence of float
        ``c`` (s) at each rate: finite, within ``+-MAX_COEFFICIENT``.  Both empty: no slip.

    Returns
    -------
    (tuple, tuple)

    Raises
    ------
    LoopConfigError
        If the two differ in length or a value is out of range.
    """
    try:
        r = tuple(float(x) for x in rates)
        c = tuple(float(x) for x in coefficients)
    except (TypeError, ValueError):
        raise LoopConfigError(f'side_slip_rates and side_slip must be sequences of numbers, '
                              f'got {rates!r} and {coefficients!r}') from None
    if len(r) != len(c):
        raise LoopConfigError(f'side_slip has {len(c)} coefficients for {len(r)} '
                              'side_slip_rates; give one coefficient (s) per turn rate (rad/s)')
    if not all(math.isfinite(x) and x >= 0.0 for x in r) or \
            any(b <= a for a, b in zip(r, r[1:])):
        raise LoopConfigError(f'side_slip_rates must be finite, >= 0 and strictly increasing '
                              f'(rad/s), got {list(r)}')
    if not all(math.isfinite(x) and abs(x) <= MAX_COEFFICIENT for x in c):
        raise LoopConfigError(f'side_slip coefficients must be finite and within '
                              f'+-{MAX_COEFFICIENT} s, got {list(c)}')
    return r, c


def slip_coefficient(rates: Sequence[float], coefficients: Sequence[float], w: float) -> float:
    """``c(|w|)`` (s): linear between the table's rates, its end values beyond them.

    Parameters
    ----------
    rates, coefficients : sequence of float
        The table (:func:`check_slip_table`); empty: 0.
    w : float
        Yaw rate (rad/s).

    Returns
    -------
    float
    """
    if not rates:
        return 0.0
    return float(np.interp(abs(w), rates, coefficients))


def hat_basis(rates: Sequence[float], w: np.ndarray) -> np.ndarray:
    """The table's basis at ``|w|``: column ``j`` is ``c(|w|)`` for a unit coefficient ``j``.

    ``c(|w|) = hat_basis(rates, w) @ coefficients`` for every table on ``rates``.

    Parameters
    ----------
    rates : sequence of float
        Turn rates of the table (rad/s, increasing).
    w : numpy.ndarray
        Yaw rates (rad/s).

    Returns
    -------
    numpy.ndarray
        Shape ``(len(w), len(rates))``.
    """
    a = np.abs(np.asarray(w, dtype=float))
    eye = np.eye(len(rates))
    return np.column_stack([np.interp(a, rates, eye[j]) for j in range(len(rates))])


class SlideReckoner:
    """The slide a side-slip table predicts, integrated: an offset to add to the odometry.

    Each :meth:`update` adds the lateral displacement over the interval that passed,
    trapezoidal in the body-frame lateral speed ``-c(|w|) v w`` and in the heading, to
    :attr:`offset` (m, in the odometry frame).

    Parameters
    ----------
    rates, coefficients : sequence of float
        The side-slip table (:func:`check_slip_table`).
    """

    def __init__(self, rates: Sequence[float], coefficients: Sequence[float]) -> None:
        self.rates, self.coefficients = check_slip_table(rates, coefficients)
        #: The predicted slide so far (m, odometry frame): true position - odometry's.
        self.offset = (0.0, 0.0)
        #: The body-frame lateral speed now (m/s), from the last update.
        self.speed = 0.0
        self._last: tuple[float, float] | None = None

    def forget(self) -> None:
        """Start the next interval afresh (the offset stays: the slide has happened)."""
        self._last = None

    def lateral_speed(self, v: float, w: float) -> float:
        """Body-frame lateral speed (m/s): ``-c(|w|) v w``.

        Parameters
        ----------
        v, w : float
            Speed (m/s) and yaw rate (rad/s).

        Returns
        -------
        float
        """
        return -slip_coefficient(self.rates, self.coefficients, w) * v * w

    def course_offset(self, v: float | None) -> float:
        """The angle (rad) from the heading to the direction of motion at speed ``v`` (m/s).

        ``atan(v_y / v)`` with the lateral speed now (:attr:`speed`), within
        ``+-MAX_COURSE_OFFSET``; 0 for an unknown or zero speed.

        Parameters
        ----------
        v : float or None
            Measured speed (m/s).

        Returns
        -------
        float
        """
        if v is None or not math.isfinite(v) or v == 0.0:
            return 0.0
        off = math.atan(self.speed / v)
        return max(-MAX_COURSE_OFFSET, min(MAX_COURSE_OFFSET, off))

    def update(self, th: float, v: float, w: float, dt: float | None) -> tuple[float, float]:
        """Add the slide over the interval ``dt`` (s) that ended at this measurement.

        Parameters
        ----------
        th : float
            Measured heading (rad).
        v, w : float
            Measured speed (m/s) and yaw rate (rad/s); a non-finite one skips the interval.
        dt : float or None
            The interval (s) since the previous update; None or <= 0: nothing added.

        Returns
        -------
        (float, float)
            The offset (m) after the update.
        """
        if not (math.isfinite(th) and math.isfinite(v) and math.isfinite(w)):
            self._last = None
            return self.offset
        vy = self.speed = self.lateral_speed(v, w)
        last, self._last = self._last, (th, vy)
        if last is None or dt is None or not dt > 0.0:
            return self.offset
        th0, vy0 = last
        mid = th0 + 0.5 * math.remainder(th - th0, math.tau)
        lat = 0.5 * (vy0 + vy) * dt
        dx, dy = self.offset
        self.offset = (dx - lat * math.sin(mid), dy + lat * math.cos(mid))
        return self.offset
