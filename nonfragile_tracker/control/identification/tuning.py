"""Online tuning of the tracker's predictor: the latency and lags it assumes, from its own data.

The certificate monitor (:mod:`.monitor`) estimates the command-to-motion latency and the
actuator lags from the tracker's commands and the odometry twist over a sliding window.
:class:`Tuned` wraps our law and, every ``period`` seconds of stamp time, moves the law's
predictor to that estimate (:func:`tuned_prediction`: the latency less its uncertainty, so
that what is left is a delay, the certified side; the lags within ``max_lag``, a lag beyond
it predicted as latency, a channel never excited taking the other's lag), so that a
tracker started on a base it has not been told about compensates the latency and lag it
measures.  Deterministic: it runs on the stamps, synchronously, in process and in the node.
See doc/theory.md, section "Latency monitor".
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

from ..simulation.predictor import LatencyPredictor
from ..simulation.tracker import Command, Tracker, TrackerConfig
from ..simulation.reference import RefSample
from ..simulation.timing import MAX_INTERVAL, PeriodEstimator
from ..simulation.wrappers import measurement_time
from .errors import MonitorError
from .monitor import LatencyEstimate, MonitorSettings, MonitorWorker

__all__ = ['TuningSettings', 'tuned_prediction', 'Tuned', 'parse_script', 'format_script']


@dataclass(frozen=True)
class TuningSettings:
    """How the predictor follows the estimate (SI units); validated on construction.

    Parameters
    ----------
    period : float
        Stamp time between estimates (s).
    max_latency : float
        Largest latency the predictor is moved to (s).
    max_lag : float
        Largest lag the predictor assumes and inverts (s): the lag the gain is certified
        through.
    step : float
        Smallest change of the latency or a lag that is applied (s): no chatter.
    script : tuple of (int, float, float, float), optional
        Retunes to apply instead of estimating: ``(stamp_ns, latency, lag_v, lag_w)``, each
        at the first step stamped at or after its stamp (a replay applies those a tracker
        published, :data:`~nonfragile_tracker.interface.topics.TUNING`); empty: estimate.
    """

    period: float = 1.0
    max_latency: float = 0.5
    max_lag: float = 0.05
    step: float = 0.005
    script: tuple[tuple[int, float, float, float], ...] = ()

    def __post_init__(self) -> None:
        for entry in self.script:
            if len(entry) != 4 or isinstance(entry[0], bool) or not isinstance(entry[0], int) \
                    or not all(isinstance(x, (int, float)) and not isinstance(x, bool)
                               and math.isfinite(x) and x >= 0 for x in entry[1:]):
                raise MonitorError('a tuning script entry must be (stamp_ns, latency, lag_v, '
                                   f'lag_w): an integer and three finite numbers >= 0 s, got '
                                   f'{entry!r}')
        for name in ('period', 'max_latency', 'max_lag', 'step'):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) \
                    or v < 0 or (name == 'period' and v == 0):
                raise MonitorError(f'tuning {name} must be a finite number '
                                   f'{">" if name == "period" else ">="} 0 s, got {v!r}')


def parse_script(text: str) -> tuple[tuple[int, float, float, float], ...]:
    """A tuning script from its text (the ``tuning_schedule`` parameter).

    Entries are separated by ``;``, each ``stamp_ns latency lag_v lag_w`` (integer
    nanoseconds, seconds); blank: none.

    Parameters
    ----------
    text : str
        The script (:func:`format_script` writes it).

    Returns
    -------
    tuple of (int, float, float, float)

    Raises
    ------
    MonitorError
        For an entry that is not four numbers (stamp an integer, the rest finite >= 0).
    """
    entries = []
    for part in str(text).split(';'):
        if not part.strip():
            continue
        words = part.split()
        try:
            if len(words) != 4:
                raise ValueError(part)
            entries.append((int(words[0]), float(words[1]), float(words[2]), float(words[3])))
        except ValueError:
            raise MonitorError(f'tuning_schedule entry {part.strip()!r} is not '
                               '"stamp_ns latency lag_v lag_w" (an integer stamp in ns, three '
                               'numbers in s); entries are separated by ";"') from None
    TuningSettings(script=tuple(entries))        # the ranges
    return tuple(entries)


def format_script(entries: Iterable[tuple[int, float, float, float]]) -> str:
    """The text of a tuning script (:func:`parse_script` reads it back exactly).

    Parameters
    ----------
    entries : iterable of (int, float, float, float)
        ``(stamp_ns, latency, lag_v, lag_w)``.

    Returns
    -------
    str
    """
    return '; '.join(f'{int(s)} {float(p)!r} {float(lv)!r} {float(lw)!r}'
                     for s, p, lv, lw in entries)


def tuned_prediction(est: LatencyEstimate, current: tuple[float, float, float],
                     settings: TuningSettings = TuningSettings(),
                     tolerance: float = MonitorSettings().tolerance,
                     measured: tuple[bool, bool] = (True, True)
                     ) -> tuple[float, float, float] | None:
    """The predictor's latency and lags for an estimate, or None to keep ``current``.

    ``P = L + e - u`` (``u`` half the estimate's interval, at least ``tolerance``; ``e`` the
    lag the predictor cannot invert, the smaller over the channels estimated of
    ``lag - max_lag``, at least 0: a first-order lag is a delay of its time constant at low
    frequency, so a lag beyond ``max_lag`` is predicted as latency), at least 0 and at most
    ``max_latency``; each lag the estimate's within ``[0, max_lag]``.  A channel without a
    lag keeps ``current``'s if it was ever ``measured``, else takes the other channel's (a
    differential drive's v and w come from the same wheels: a straight at constant speed
    never excites v).  None when the estimate is not valid or nothing moves by ``step``.

    Parameters
    ----------
    est : LatencyEstimate
        The monitor's estimate.
    current : (float, float, float)
        The predictor's latency and lags (v, w) now (s).
    settings : TuningSettings
        Limits and the smallest change.
    tolerance : float
        Least uncertainty of the latency (s; the monitor's estimator precision).
    measured : (bool, bool)
        Whether the lag of v, of w has been estimated before (default: both).

    Returns
    -------
    (float, float, float) or None
    """
    if not est.valid or not math.isfinite(est.latency):
        return None
    u = max(tolerance, 0.5 * (est.interval[1] - est.interval[0]))
    raw = [lag for lag in (est.lag_v, est.lag_w) if math.isfinite(lag)]
    excess = max(min(raw) - settings.max_lag, 0.0) if raw else 0.0
    P = min(max(est.latency + excess - u, 0.0), settings.max_latency)
    lags = []
    for c, (lag, other) in enumerate(((est.lag_v, est.lag_w), (est.lag_w, est.lag_v))):
        if not math.isfinite(lag) and not measured[c]:
            lag = other               # never measured: the other channel's (the same wheels)
        lags.append(min(max(lag, 0.0), settings.max_lag) if math.isfinite(lag)
                    else current[1 + c])
    new = (P, lags[0], lags[1])
    if all(abs(a - b) < settings.step for a, b in zip(new, current)):
        return None
    return (float(new[0]), float(new[1]), float(new[2]))


class Tuned:
    """Our law whose predictor follows the latency and lags it measures (a Controller).

    Each step records the odometry twist (at its stamp) and, after the law, the command
    (at the tracker's *now*, the stamp plus the assumed odometry latency, as the monitor
    records it); every ``settings.period`` of stamp time the monitor's estimate moves the
    law's predictor (:meth:`~nonfragile_tracker.control.simulation.tracker.Tracker.retune`),
    or a ``settings.script`` entry does at its stamp (no estimate); :attr:`last_change` is
    the last retune with the stamp it took effect at.  ``config`` and ``predictor`` are the
    law's.  A copy (``copy.deepcopy``, pickle: a
    replay's trial runs) carries the window, the estimate and the tuned prediction, with a
    lock of its own and no thread.

    Parameters
    ----------
    tracker : Tracker
        Our law (its predictor, if any, is the starting point).
    monitor : MonitorSettings, optional
        The estimator's settings (window, search limits, gating).
    settings : TuningSettings, optional
        The period, limits and smallest change of the tuning.
    """

    def __init__(self, tracker: Tracker, monitor: MonitorSettings | None = None,
                 settings: TuningSettings | None = None):
        self.tracker = tracker
        self.settings = settings if settings is not None else TuningSettings()
        self.worker = MonitorWorker(monitor if monitor is not None else MonitorSettings(),
                                    self.settings.period)
        self.latest: LatencyEstimate | None = None
        self.changes = 0
        self.measured = [False, False]        # a lag of v / w estimated yet
        #: ``(stamp_ns, latency, lag_v, lag_w)`` of the last retune (None before one): the
        #: step's stamp (ns; the stamp in s rounded when the step had none).
        self.last_change: tuple[int, float, float, float] | None = None
        self._next: float | None = None
        #: The time of the previous step (s): a jump back or beyond MAX_INTERVAL is a new
        #: time base.
        self._last_t: float | None = None
        self._script = sorted(self.settings.script)
        # the estimator's scipy.signal import (0.3 s, seconds under load) paid here, at the
        # node's configure, not in the first estimate inside an odometry callback
        import scipy.signal  # noqa: F401

    @property
    def config(self) -> TrackerConfig:
        """The law's settings (its prediction as tuned now); set: the law's."""
        return self.tracker.config

    @config.setter
    def config(self, config: TrackerConfig) -> None:
        self.tracker.config = config

    @property
    def predictor(self) -> LatencyPredictor | None:
        """The law's latency predictor (None until it has one)."""
        return self.tracker.predictor

    @property
    def timing(self) -> PeriodEstimator:
        """The law's period estimate."""
        return self.tracker.timing

    @property
    def horizon(self) -> float:
        """The law's horizon (its predictor's, as tuned now) (s)."""
        return self.tracker.horizon

    def reset(self, v: float | None = None) -> None:
        """Reset the law (the tuning and its window are kept: they are the base's).

        Parameters
        ----------
        v : float, optional
            Compensator speed (m/s) to start from.
        """
        self.tracker.reset(v)

    def _retune(self, stamp_ns: int, new: tuple[float, float, float]) -> None:
        self.tracker.retune(*new)
        self.changes += 1
        self.last_change = (stamp_ns, *new)

    def _tune(self, t: float, stamp_ns: int) -> None:
        if self.settings.script:
            due = None
            while self._script and self._script[0][0] <= stamp_ns:
                due = self._script.pop(0)[1:]
            if due is not None:                 # (retunes of the same step: the last)
                self._retune(stamp_ns, due)
            return
        if self._next is None:
            self._next = t + self.settings.period
        if t < self._next:
            return
        self._next = t + self.settings.period
        self.latest = est = self.worker.update()
        c = self.tracker.config
        new = tuned_prediction(est, (c.predict_latency, c.predict_lag_v, c.predict_lag_w),
                               self.settings, self.worker.settings.tolerance,
                               (self.measured[0], self.measured[1]))
        if est.valid:
            self.measured = [m or math.isfinite(lag)
                             for m, lag in zip(self.measured, (est.lag_v, est.lag_w))]
        if new is not None:
            self._retune(stamp_ns, new)

    def step(self, x: float, y: float, th: float, ref: RefSample,
             measured_speed: float | None = None, stamp: float | None = None,
             stamp_ns: int | None = None, measured_rate: float | None = None) -> Command:
        """Record the measurement, tune if due, run the law, record its command.

        Parameters
        ----------
        x, y, th : float
            Measured pose (m, m, rad).
        ref : RefSample
            The reference sample.
        measured_speed, measured_rate : float, optional
            The odometry's twist (m/s, rad/s); without them nothing is recorded.
        stamp : float, optional
            Measurement time (s; default ``ref.t``).
        stamp_ns : int, optional
            The same in integer nanoseconds.

        Returns
        -------
        Command
        """
        t = measurement_time(ref, stamp, stamp_ns)
        window = self.worker.window
        last, self._last_t = self._last_t, t
        if last is not None and math.isfinite(t) and not 0.0 <= t - last <= MAX_INTERVAL:
            # another time base (steps on reference samples by odometry stamp, then a
            # followed trajectory's own time): the window and the tuning clock start again;
            # the prediction tuned so far stays
            window.clear()
            self._next = None
        if measured_speed is not None and measured_rate is not None and math.isfinite(t):
            window.add_odometry(t, measured_speed, measured_rate)
            self._tune(t, stamp_ns if stamp_ns is not None else int(round(t * 1e9)))
        cmd = self.tracker.step(x, y, th, ref, measured_speed, stamp, stamp_ns, measured_rate)
        if math.isfinite(t):
            window.add_command(t + self.tracker.config.predict_odom_latency, cmd.v, cmd.w)
        return cmd
