"""The command line: what happens to a command between the tracker and the base's motors.

A command received at step ``k`` acts from a later step: a constant latency, a latency that
changes on a schedule, a latency drawn per command (jitter, in order), and stalls during which
the base ignores its commands.  :class:`CommandLine` is that part of a simulated plant, apart
from the motion model, so any plant (:class:`~.interfaces.Plant`) can put it in front of its
actuators; :class:`~.plant.UnicyclePlant` does, from :class:`~.plant.PlantConfig`'s
``cmd_latency``, ``cmd_latency_schedule``, ``cmd_latency_jitter``, ``stalls`` and ``noise_seed``.

See doc/ros-interface.md, section "plant" (the latency parameters).
"""
from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import Any

import numpy as np

__all__ = ['CommandLine', 'VectorCommandLine']


class CommandLine:
    """Latency, latency schedule, jitter and stalls between a command and the base.

    :meth:`send` takes the command received at step ``k``; :meth:`in_force` is the command
    the base applies over step ``k`` (zero while a stall lasts: the base brakes to rest
    through its actuator, then applies the newest command received).  A command that would
    act no later than one received before it replaces the queued ones (a latency drop skips
    them, as a transport that delivers the newest does); with jitter, commands stay in order.

    Parameters
    ----------
    latency : int
        Command latency (steps) before the schedule's first change.
    schedule : sequence of (int, int), optional
        ``(first step, latency in steps)`` changes, steps increasing.
    jitter : int, optional
        Each command's latency is drawn from ``latency .. latency + jitter`` steps.
    stalls : sequence of (int, int), optional
        ``[first, end)`` steps during which the base ignores its commands.
    seed : int, optional
        Seed of the jitter's generator (a generator of its own).
    v0 : float, optional
        Speed (m/s) in force before the first command.
    """

    def __init__(self, latency: int, schedule: Sequence[tuple[int, int]] = (), jitter: int = 0,
                 stalls: Sequence[tuple[int, int]] = (), seed: int = 0, v0: float = 0.0):
        self.latency = int(latency)
        self._schedule = tuple(schedule)
        self._jitter = int(jitter)
        self._stalls = tuple(stalls)
        self.seed = int(seed)
        self.reset(float(v0))

    def reset(self, v0: float = 0.0) -> None:
        """Nothing queued; the command in force is ``(v0, 0)``.

        Parameters
        ----------
        v0 : float
            Speed (m/s) in force before the first command.
        """
        self._queue: deque[tuple[int, float, float]] = deque()    # (first step it acts, v, w)
        self.cmd = (v0, 0.0)            # command in force
        self.cmd_delay = self.latency
        self._next_change = 0           # index of the next schedule entry
        # a generator of its own (not the odometry noise's): jitter leaves the noise alone
        self._jitter_rng = (np.random.default_rng([self.seed, 1])
                            if self._jitter else None)
        self._last_act = -1
        self.last_act_step = -1         # step the newest command acts from (-1: none yet)

    def send(self, k: int, v: float, w: float) -> None:
        """Receive ``(v, w)`` at step ``k``: it acts from ``k`` plus the latency then in force.

        Parameters
        ----------
        k : int
            The step the command is received at.
        v, w : float
            Commanded speed (m/s) and yaw rate (rad/s).
        """
        if self._schedule:
            sch = self._schedule
            while self._next_change < len(sch) and sch[self._next_change][0] <= k:
                self.cmd_delay = sch[self._next_change][1]
                self._next_change += 1
            act = k + self.cmd_delay
            while self._queue and self._queue[-1][0] >= act:
                self._queue.pop()
        if self._jitter_rng is not None:
            d = self.cmd_delay + int(self._jitter_rng.integers(0, self._jitter + 1))
            act = max(k + d, self._last_act)        # in order: never before an earlier one
            self._last_act = act
            self._queue.append((act, v, w))
        elif self.cmd_delay == 0 and not self._queue:
            self.cmd = (v, w)
            act = k
        else:
            act = k + self.cmd_delay
            self._queue.append((act, v, w))
        self.last_act_step = act

    def in_force(self, k: int) -> tuple[float, float]:
        """The command the base applies over step ``k`` (``(0, 0)`` while stalled).

        Parameters
        ----------
        k : int
            The step about to be applied.

        Returns
        -------
        (float, float)
            Speed (m/s) and yaw rate (rad/s).
        """
        queue = self._queue
        while queue and queue[0][0] <= k:
            _, cv, cw = queue.popleft()
            self.cmd = (cv, cw)
        if self._stalls and any(a <= k < b for a, b in self._stalls):
            return 0.0, 0.0                     # stalled: commands ignored, braking to rest
        return self.cmd


# ---------------------------------------------------------------------------------------------
# The vector twin of CommandLine: the same step for N cases at once
# (the batch; test/control/test_twins.py checks each pair)

class VectorCommandLine:
    """:meth:`.control.simulation.plant.UnicyclePlant.command` for every case: the command in force.

    A command sent at step ``k`` acts from ``k + cmd_latency`` steps; until a case's first
    one arrives its plant holds ``(v0, 0)``.  ``queue`` (a command every step for every
    case): a ring of steps each command is put into at the slot its step reads; otherwise
    a ring of the commands sent and their steps.

    Parameters
    ----------
    cmd_d : numpy.ndarray
        Command latency (steps) of each case.
    v0 : numpy.ndarray
        Initial speed of each case (the command in force before the first).
    queue : bool
        Every case sends a command every step.
    """

    def __init__(self, cmd_d: np.ndarray, v0: np.ndarray, queue: bool):
        n = cmd_d.size
        self.idx = np.arange(n)
        self.cmd_d = cmd_d
        self.force_v, self.force_w = v0.copy(), np.zeros(n)     # command in force
        self.delayed = bool(np.any(cmd_d))
        if self.delayed:
            self.R = int(cmd_d.max()) + 1
            self.cbuf = np.zeros((self.R, 2, n))
            self.cstep = np.full((self.R, n), np.iinfo(np.int64).min, dtype=np.int64)
        self.queue = queue
        if queue:
            # a command every step: the one sent at k is put where step k + d reads it, a
            # ring of Rq steps whose slots hold the initial command in force, (v0, 0), until
            # then (one slot more than the longest delay: the slot read at k is not written
            # at k + 1)
            Rq = self.Rq = int(cmd_d.max()) + 2
            self.cq = cq = np.empty((Rq, 2, n))
            cq[:, 0] = self.force_v
            cq[:, 1] = self.force_w
            self.cq_flat = cq.reshape(-1)
            slots = (np.arange(Rq)[:, None] + cmd_d[None, :]) % Rq               # (Rq, N)
            self.put_idx = (slots[:, None, :] * (2 * n) + np.arange(2)[None, :, None] * n
                            + np.arange(n)[None, None, :])                       # (Rq, 2, N)

    def send(self, k: int, cmd: np.ndarray, due: Any) -> None:
        """The commands ``cmd`` (2, N) sent at step ``k`` by the cases ``due``.

        Parameters
        ----------
        k : int
            The step.
        cmd : numpy.ndarray
            The commands ``(v, w)`` (2, N).
        due : bool or numpy.ndarray
            The cases that sent one (True: every case).
        """
        if self.queue:
            np.put(self.cq_flat, self.put_idx[k % self.Rq], cmd)
        elif self.delayed:
            slot = k % self.R
            if due is True:
                self.cbuf[slot] = cmd
                self.cstep[slot] = k
            else:
                self.cbuf[slot] = np.where(due, cmd, self.cbuf[slot])
                self.cstep[slot] = np.where(due, k, self.cstep[slot])
        elif due is True:
            self.force_v, self.force_w = cmd[0], cmd[1]
        else:
            self.force_v = np.where(due, cmd[0], self.force_v)
            self.force_w = np.where(due, cmd[1], self.force_w)

    def in_force(self, k: int) -> tuple[np.ndarray, np.ndarray]:
        """The command ``(v, w)`` each plant acts on over step ``k``.

        Parameters
        ----------
        k : int
            The step.

        Returns
        -------
        (numpy.ndarray, numpy.ndarray)
        """
        if self.queue:                      # the command sent at k - d, or (v0, 0)
            self.force_v, self.force_w = self.cq[k % self.Rq]
        elif self.delayed:
            ks = k - self.cmd_d
            slot = ks % self.R
            idx = self.idx
            hit = self.cstep[slot, idx] == ks
            if hit.any():
                self.force_v = np.where(hit, self.cbuf[slot, 0, idx], self.force_v)
                self.force_w = np.where(hit, self.cbuf[slot, 1, idx], self.force_w)
        return self.force_v, self.force_w
