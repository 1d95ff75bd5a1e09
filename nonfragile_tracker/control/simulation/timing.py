"""The tracker's step from the odometry stamps: the interval that passed and the period.

A controller that integrates with a constant it was told, instead of the time that
passed, tracks badly when the constant is wrong and nothing says so.
:class:`PeriodEstimator` takes the odometry stamp of each step and gives the interval since
the previous step (in whole nanoseconds), a period robust to jitter, dropped and bunched
messages (the lower median of the last :data:`WINDOW` intervals, gaps above
:data:`GAP_FACTOR` periods left out) and a report when it moves by more than
:data:`CHANGE`; :func:`period_disagreement` compares a period set by hand.  Stamps only,
never a clock; plain floats; no ROS.

See doc/ros-interface.md, section "tracker" (the "Timing" parameters and the estimate).
"""
from __future__ import annotations

import math
from collections import deque

__all__ = ['step_time_ns', 'step_time', 'WINDOW', 'CHANGE', 'MAX_INTERVAL', 'GAP_FACTOR',
           'PeriodEstimator', 'period_disagreement']

#: Number of recent intervals whose median is the period.
WINDOW = 9
#: An interval above this many periods is a gap, not counted in the period.
GAP_FACTOR = 4.0
#: Intervals longer than this (s) are garbage, not a period (ignored).
MAX_INTERVAL = 1e6
#: Relative change of the period (or disagreement with a set one) that is reported.
CHANGE = 0.2


def step_time_ns(k: int, dt: float) -> int:
    """Stamp of step ``k`` in integer nanoseconds (``k * round(dt * 1e9)``).

    Parameters
    ----------
    k : int
        Step index.
    dt : float
        Step (s).

    Returns
    -------
    int
    """
    return k * int(round(dt * 1e9))


def step_time(k: int, dt: float) -> float:
    """Time of step ``k`` in seconds, computed exactly as a ROS node reads a stamp.

    Parameters
    ----------
    k : int
        Step index.
    dt : float
        Step (s).

    Returns
    -------
    float
    """
    return step_time_ns(k, dt) * 1e-9


class PeriodEstimator:
    """Interval since the previous step and the robust period of a stream of stamps.

    Parameters
    ----------
    window : int
        Number of recent intervals whose (lower) median is the period.
    """

    def __init__(self, window: int = WINDOW):
        if isinstance(window, bool) or not isinstance(window, int) or window < 1:
            raise ValueError(f'window must be an integer >= 1, got {window!r}')
        self.window = window
        self.reset()

    def reset(self) -> None:
        """Forget the stamps and intervals seen."""
        self._last: int | None = None          # ns
        self._intervals: deque[int] = deque(maxlen=self.window)
        self._gaps: list[int] = []             # gaps in a row (not counted yet)
        self._period_ns = 0
        self._reported_ns = 0

    def observe(self, t: float) -> float | None:
        """Take the time ``t`` (s) of a step; the interval since the previous one (s).

        :meth:`observe_ns` of ``t`` in whole nanoseconds (non-finite or absurd times are
        ignored: None).  A stamp of a ROS message is better given as its integer
        nanoseconds: at today's epoch a time in float seconds is only good to 0.24 us.

        Parameters
        ----------
        t : float
            Time of the step (s; the odometry stamp).

        Returns
        -------
        float or None
        """
        if not (math.isfinite(t) and abs(t) < 1e12):
            return None
        return self.observe_ns(int(round(t * 1e9)))

    def observe_ns(self, t_ns: int) -> float | None:
        """Take the time ``t_ns`` (ns) of a step; the interval since the previous one (s).

        A repeated time (a message in the same nanosecond) returns 0.0; the first call (or
        the first after :meth:`reset`), an earlier time or one more than
        :data:`MAX_INTERVAL` later (another time base: a new trajectory's time) return None
        and restart the intervals from ``t_ns``; neither counts for the period, which stays.

        Parameters
        ----------
        t_ns : int
            Time of the step (ns; the odometry stamp).

        Returns
        -------
        float or None
        """
        last = self._last
        self._last = t_ns
        if last is None:
            return None
        n = t_ns - last
        if n == 0:
            return 0.0
        if n < 0 or n > MAX_INTERVAL * 1e9:
            return None                        # a new time base: the period stays
        iv = self._intervals
        if self._period_ns and n > GAP_FACTOR * self._period_ns:
            self._gaps.append(n)
            if len(self._gaps) <= self.window // 2:
                return n * 1e-9                # a gap: passed, not a period
            iv.clear()                         # the rate dropped: these are its intervals
            iv.extend(self._gaps)
        else:
            iv.append(n)
        self._gaps.clear()
        self._period_ns = sorted(iv)[(len(iv) - 1) // 2]
        if not self._reported_ns and len(iv) == self.window:
            self._reported_ns = self._period_ns
        return n * 1e-9

    @property
    def last_ns(self) -> int | None:
        """The time (ns) of the last observation; None before the first (or after a reset)."""
        return self._last

    @property
    def period(self) -> float | None:
        """The period (s): lower median of the recent intervals; None before the first."""
        return self._period_ns * 1e-9 if self._period_ns else None

    @property
    def settled(self) -> bool:
        """True once a whole window of intervals has been seen."""
        return len(self._intervals) == self.window

    def rate_change(self, tol: float = CHANGE) -> tuple[float, float] | None:
        """``(before, now)`` (s) once the period moved by more than ``tol`` from the last report.

        The first settled period is the reference; a change is reported once (the new
        period becomes the reference).

        Parameters
        ----------
        tol : float
            Relative change reported.

        Returns
        -------
        (float, float) or None
        """
        ref, now = self._reported_ns, self._period_ns
        if not ref or not self.settled or abs(now - ref) <= tol * ref:
            return None
        self._reported_ns = now
        return ref * 1e-9, now * 1e-9


def period_disagreement(set_dt: float, measured: float | None, tol: float = CHANGE
                        ) -> str | None:
    """What is wrong when a step set by hand disagrees with the measured period, else None.

    Parameters
    ----------
    set_dt : float
        The step set by hand (s; 0: none, nothing to compare).
    measured : float or None
        The measured odometry period (s; None: not known yet).
    tol : float
        Relative disagreement reported.

    Returns
    -------
    str or None
    """
    if not set_dt or not measured or abs(set_dt - measured) <= tol * measured:
        return None
    return (f'dt = {set_dt:g} s is set but the odometry period is {measured:.4f} s '
            f'({1.0 / measured:.1f} Hz): the compensator integrates over the wrong step; '
            'set dt to 0 (the step from the odometry stamps)')
