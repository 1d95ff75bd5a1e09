"""Odometry as a real base delivers it: late, at a lower rate than the plant, noisy.

:class:`Odometer` is called by :class:`control.simulation.loop.UnicyclePlant` once per plant step
``k`` (in order).  At every ``period``-th step (``k % period == 0``) it takes a
measurement of the true state - pose plus Gaussian noise drawn from a seeded
``numpy.random.Generator`` (three draws ``x, y, yaw`` per measurement, always in that
order, so changing one standard deviation leaves the others' sequence alone) - and
releases it ``latency`` steps later.  The sample keeps the step (hence the stamp) of
the measurement time, as real odometry does: a message published at step
``k + latency`` carries the stamp of step ``k``.  With ``jitter_steps`` ``J`` the
``n``-th measurement is taken at step ``n period + o_n`` instead, ``o_n`` drawn uniformly
from the whole steps in ``[-J, J]`` (a generator of its own, seeded ``[seed, 2]``: the
noise's sequence is unchanged), its stamp that true time: odometry whose intervals jitter.
Plain floats; no ROS.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import NamedTuple, cast

import numpy as np

__all__ = ['OdometryModel', 'OdometrySample', 'Odometer']


@dataclass(frozen=True)
class OdometryModel:
    """Odometry timing and noise in plant steps (built and validated by ``PlantConfig``)."""

    latency_steps: int = 0             # a measurement of step k is published at step k + this
    period_steps: int = 1              # measure at every period-th step
    #: standard deviation of x (m), y (m), yaw (rad)
    noise: tuple[float, float, float] = (0.0, 0.0, 0.0)
    seed: int = 0
    jitter_steps: int = 0              # each measurement up to this many steps early or late

    @property
    def ideal(self) -> bool:
        """True for the paper's plant: every step, at once, exact."""
        return self.latency_steps == 0 and self.period_steps == 1 and not any(self.noise) \
            and not self.jitter_steps


class OdometrySample(NamedTuple):
    """One odometry measurement: taken at plant step ``step``; speeds are the actual ones."""

    step: int
    x: float
    y: float
    th: float
    v: float
    w: float


class Odometer:
    """Delay line, decimation and noise between the true state and the odometry messages.

    Parameters
    ----------
    model : OdometryModel
        Latency and period (in plant steps), noise and its seed.
    """

    def __init__(self, model: OdometryModel) -> None:
        self.model = model
        self._noisy = any(model.noise)
        self.reset()

    def reset(self) -> None:
        """Forget pending measurements and restart the noise from the seed."""
        self._pending: deque[OdometrySample] = deque()
        self._rng = np.random.default_rng(self.model.seed) if self._noisy else None
        m = self.model
        self._jitter_rng = (np.random.default_rng([int(m.seed), 2]) if m.jitter_steps
                            else None)
        self._nominal = 0                    # nominal step of the next measurement
        self._next = self._draw(0)           # step it is taken at

    def _draw(self, nominal: int) -> int:
        """The step the measurement due at ``nominal`` is taken at (jittered; never < 0)."""
        if self._jitter_rng is None:
            return nominal
        J = self.model.jitter_steps
        return max(0, nominal + int(self._jitter_rng.integers(-J, J + 1)))

    def measure(self, k: int, x: float, y: float, th: float, v: float, w: float) -> None:
        """Record the true state of step ``k`` (call once per step, in order).

        Parameters
        ----------
        k : int
            Plant step.
        x, y : float
            True position [m].
        th : float
            True heading [rad].
        v, w : float
            Actual speed [m/s] and angular rate [rad/s] (never noisy).
        """
        m = self.model
        pending = self._pending
        while pending and pending[0].step + m.latency_steps < k:
            pending.popleft()                    # released at an earlier step
        if self._jitter_rng is not None:
            if k != self._next:
                return
            self._nominal += m.period_steps
            self._next = self._draw(self._nominal)
        elif k % m.period_steps:
            return
        if self._noisy:
            nx, ny, nth = cast(np.random.Generator, self._rng).standard_normal(3)
            sx, sy, sth = m.noise
            x, y = x + sx * float(nx), y + sy * float(ny)
            th = math.remainder(th + sth * float(nth), math.tau)
        pending.append(OdometrySample(k, x, y, th, v, w))

    def due(self, k: int) -> OdometrySample | None:
        """The sample to publish at step ``k`` (measured at ``k - latency``), if any.

        Parameters
        ----------
        k : int
            Plant step (after :meth:`measure` of the same step).

        Returns
        -------
        OdometrySample or None
        """
        pending = self._pending
        if pending and pending[0].step + self.model.latency_steps == k:
            return pending[0]
        return None
