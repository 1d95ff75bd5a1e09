"""Odometry as a real base delivers it: late, at a lower rate than the plant, noisy.

:class:`Odometer` is called by the plant
(:class:`~nonfragile_tracker.control.simulation.plant.UnicyclePlant`) once per step: every
``period``-th step it measures the true pose with seeded Gaussian noise, optionally
jittered in time, and releases the measurement ``latency`` steps later with the stamp of
its measurement time, as real odometry does.  Plain floats; no ROS.

See doc/ros-interface.md, section "plant" (the odometry parameters and model).
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass
from typing import Any, NamedTuple, cast

import numpy as np

from .batch_data import Settings
from .model import wrap

__all__ = ['OdometryModel', 'OdometrySample', 'Odometer', 'VectorOdometer']


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


# ---------------------------------------------------------------------------------------------
# The vector twin of Odometer: the same step for N cases at once
# (the batch; test/control/test_twins.py checks each pair)

class VectorOdometer:
    """:class:`.control.simulation.sensors.Odometer` for every case: rate, latency and noise.

    ``ideal``: every case measures the plant's own state at every step, without noise or
    latency (nothing is buffered).  Otherwise the measurements go into a ring of
    ``max(odom_latency) + 1`` steps (:meth:`measure`) from which :meth:`read` takes those
    published at a step.

    Parameters
    ----------
    s : control.simulation.batch_data.Settings
        The resolved per-case settings (period, latency, noise and seed of the odometry).
    """

    def __init__(self, s: Settings):
        n = s.n
        self.idx = np.arange(n)
        period, odom_d = self.period, self.odom_d = s.period, s.odom_d
        self.noise = s.noise
        self.noisy = np.any(s.noise != 0.0, axis=1)
        self.any_noise = bool(self.noisy.any())
        self.uniform = bool(np.all(period == period[0]) and np.all(odom_d == odom_d[0]))
        self.ideal = (self.uniform and period[0] == 1 and odom_d[0] == 0
                      and not self.any_noise)
        if not self.ideal:
            self.Ro = int(odom_d.max()) + 1
            self.obuf = np.zeros((self.Ro, 4, n))   # measured x, y, th, v by step % Ro
            if self.any_noise:
                self.rngs = {int(i): np.random.default_rng(int(s.seed[i]))
                             for i in np.flatnonzero(self.noisy)}
                self.blk = 256
                self.nbuf = np.zeros((n, self.blk, 3))
                self.ncount = np.zeros(n, dtype=np.int64)    # measurements taken per case

    def measure(self, k: int, pos: np.ndarray, th: np.ndarray, pv: np.ndarray) -> None:
        """Measure the plant's state at step ``k`` for every case whose period is due.

        Parameters
        ----------
        k : int
            The step.
        pos, th, pv : numpy.ndarray
            The plant's position (2, N), heading and speed.
        """
        take = (k % self.period) == 0
        if not take.any():
            return
        mx, my, mth = pos[0], pos[1], th
        if self.any_noise:
            nz = take & self.noisy
            if nz.any():
                blk, nbuf = self.blk, self.nbuf
                j = self.ncount % blk
                for i in np.flatnonzero(nz & (j == 0)):
                    nbuf[i] = self.rngs[int(i)].standard_normal((blk, 3))
                draw = nbuf[self.idx, j]
                sx, sy, sth = self.noise[:, 0], self.noise[:, 1], self.noise[:, 2]
                mx = np.where(nz, mx + sx * draw[:, 0], mx)
                my = np.where(nz, my + sy * draw[:, 1], my)
                mth = np.where(nz, wrap(th + sth * draw[:, 2]), th)
                self.ncount[nz] += 1
        slot = k % self.Ro
        sel = take if not take.all() else slice(None)
        obuf = self.obuf
        obuf[slot, 0, sel] = mx[sel]
        obuf[slot, 1, sel] = my[sel]
        obuf[slot, 2, sel] = mth[sel]
        obuf[slot, 3, sel] = pv[sel]

    def read(self, k: int) -> tuple[Any, Any, Any, Any, Any]:
        """``(due, position, heading, speed, measured step)`` of the odometry due at ``k``.

        ``due`` is True (every case), False (none: the rest is None) or a mask of cases.

        Parameters
        ----------
        k : int
            The step.

        Returns
        -------
        tuple
            ``(due, position (2, N), heading, speed, measured step)``.
        """
        ms = k - self.odom_d
        dmask = (ms >= 0) & ((ms % self.period) == 0)
        if self.uniform:
            due = bool(dmask[0])
        else:
            due = dmask if dmask.any() else False
        if due is False:
            return False, None, None, None, None
        slot = ms % self.Ro
        idx = self.idx
        mpos = self.obuf[slot, 0:2, idx].T
        mth, mv = self.obuf[slot, 2, idx], self.obuf[slot, 3, idx]
        return due, mpos, mth, mv, (ms if not self.uniform else int(ms[0]))
