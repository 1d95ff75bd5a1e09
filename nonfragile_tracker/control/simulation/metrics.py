"""Tracking metrics from sampled runs (simulation arrays or a bag).

See doc/bags.md, section "``bag report``".
"""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any, Sequence

import numpy as np
from numpy.typing import ArrayLike

__all__ = ['TrackingMetrics', 'tracking_metrics']


@dataclass(frozen=True)
class TrackingMetrics:
    """Summary of a tracking run; distances in m, times in s, rates in rad/s."""

    duration: float
    steps: int
    final_error: float
    rms_error: float                 # over the whole run
    rms_error_settled: float         # after settling_time (nan if it never settles)
    max_error_settled: float
    first_within: float              # first time the error is <= tolerance (nan: never)
    settling_time: float             # time after which it stays <= tolerance (nan: never)
    tolerance: float
    peak_abs_v: float
    peak_abs_w: float

    def as_dict(self) -> dict[str, Any]:
        """The fields as a JSON-ready dict."""
        return asdict(self)


def tracking_metrics(t: ArrayLike, x: ArrayLike, y: ArrayLike, xd: ArrayLike, yd: ArrayLike,
                     v: Sequence[float] | np.ndarray | None = None,
                     w: Sequence[float] | np.ndarray | None = None, *,
                     tolerance: float = 0.01) -> TrackingMetrics:
    """Metrics of the position error ``|(x, y) - (x_d, y_d)|`` sampled at times ``t``.

    Parameters
    ----------
    t : array_like, shape (N,)
        Sample times [s], increasing.
    x, y : array_like, shape (N,)
        Robot position [m].
    xd, yd : array_like, shape (N,)
        Desired position [m].
    v, w : array_like, shape (N,), optional
        Commanded speed [m/s] and angular rate [rad/s], for the peaks (``nan`` if
        absent or empty).
    tolerance : float, optional
        Error [m] within which the robot counts as tracking (settling).

    Returns
    -------
    TrackingMetrics

    Raises
    ------
    ValueError
        If there are no samples.
    """
    t = np.asarray(t, float)
    err = np.hypot(np.asarray(x, float) - np.asarray(xd, float),
                   np.asarray(y, float) - np.asarray(yd, float))
    if t.size == 0:
        raise ValueError('tracking_metrics: empty run (no samples)')
    within = err <= tolerance
    first = float(t[np.argmax(within)]) if within.any() else math.nan
    if within[-1]:
        outside = np.flatnonzero(~within)
        idx = 0 if outside.size == 0 else outside[-1] + 1
        settle = float(t[idx])
        settled = err[idx:]
        rms_s, max_s = float(np.sqrt(np.mean(settled ** 2))), float(settled.max())
    else:
        settle, rms_s, max_s = math.nan, math.nan, math.nan
    peak_v = float(np.max(np.abs(v))) if v is not None and len(v) else math.nan
    peak_w = float(np.max(np.abs(w))) if w is not None and len(w) else math.nan
    return TrackingMetrics(duration=float(t[-1] - t[0]), steps=int(t.size),
                           final_error=float(err[-1]), rms_error=float(np.sqrt(np.mean(err ** 2))),
                           rms_error_settled=rms_s, max_error_settled=max_s, first_within=first,
                           settling_time=settle, tolerance=tolerance, peak_abs_v=peak_v,
                           peak_abs_w=peak_w)
