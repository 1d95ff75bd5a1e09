"""Batch simulation's parts: pieces of the single run's state, vectorized over cases.

:func:`control.simulation.batch.simulate_batch` sets a run up from these parts, each
holding one piece of the single run's state for every case and stepping it with the
operations of the scalar step functions in the same order: the odometry
(:class:`Odometry`, as :class:`control.simulation.sensors.Odometer`), the tracker
(:class:`BatchTracker`, as :class:`control.simulation.loop.Tracker` with its delay
compensation; the law itself is :class:`control.simulation.law.VectorLaw`), the command
line (:class:`CommandLine`: command latency) and the plant
(:class:`BatchPlant`, as :class:`control.simulation.loop.UnicyclePlant`, with its actuator
and state delay), and the arithmetic they share with the batch's loops (heading wrap,
the arc's series and angle addition, sums of products in the plant's order).  The
public names of the batch are in :mod:`control.simulation.batch`; these parts are its
machinery (named without a leading underscore only because the batch imports them).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any, Callable

import numpy as np

from .law import VectorLaw
from .loop import PlantConfig, TrackerConfig, delay_steps

if TYPE_CHECKING:
    from .batch import Schedule, Settings

_PI = math.pi
_ATAN2 = np.frompyfunc(math.atan2, 2, 1)
_TAU = math.tau


def per_value(fn: Callable[[float], Any], values: np.ndarray, dtype: Any) -> np.ndarray:
    """``[fn(v) for v in values]`` evaluated once per distinct value (scalar functions).

    Parameters
    ----------
    fn : callable
        A function of one float.
    values : numpy.ndarray
        The values, one per case.
    dtype : numpy dtype
        Type of the result.

    Returns
    -------
    numpy.ndarray
    """
    uniq, inv = np.unique(values, return_inverse=True)
    return np.array([fn(float(v)) for v in uniq], dtype=dtype)[inv.reshape(-1)]


# ---------------------------------------------------------------------------------------------
# Vectorized step pieces (the same operations as the scalar functions)

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


def _first_order(s: np.ndarray, c: np.ndarray, T: np.ndarray, amax: np.ndarray,
                 em1: np.ndarray, has_lag: np.ndarray, has_lim: np.ndarray, h: float
                 ) -> tuple[np.ndarray, np.ndarray]:
    """:func:`control.simulation.actuator.first_order_step` element-wise: ``(end, mean)``."""
    d = c - s
    end = c.copy()
    mean = c.copy()
    if has_lag.any():
        lag = has_lag & (d != 0.0)
        e_end = c - d * (1.0 - em1)
        e_mean = c - d * T * em1 / h
        end = np.where(lag, e_end, end)
        mean = np.where(lag, e_mean, mean)
    if has_lim.any():
        ad = np.abs(d)
        ramp = has_lim & (ad > amax * T) & (d != 0.0)
        if ramp.any():
            with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
                sign = np.where(d > 0, 1.0, -1.0)
                t1 = (ad - amax * T) / amax
                full = t1 >= h
                f_end = s + sign * amax * h
                f_mean = 0.5 * (s + f_end)
                s1 = s + sign * amax * t1
                area = 0.5 * (s + s1) * t1
                rest = h - t1
                em1r = -np.expm1(-rest / T)
                p_end = np.where(T > 0.0, c + (s1 - c) * (1.0 - em1r), c)
                area = np.where(T > 0.0, area + (c * rest + (s1 - c) * T * em1r),
                                area + c * rest)
                p_mean = area / h
            end = np.where(ramp, np.where(full, f_end, p_end), end)
            mean = np.where(ramp, np.where(full, f_mean, p_mean), mean)
    return end, mean


class Odometry:
    """:class:`control.simulation.sensors.Odometer` for every case: rate, latency and noise.

    ``ideal``: every case measures the plant's own state at every step, without noise or
    latency (nothing is buffered).  Otherwise the measurements go into a ring of
    ``max(odom_latency) + 1`` steps (:meth:`measure`) from which :meth:`read` takes those
    published at a step.

    Parameters
    ----------
    s : control.simulation.batch.Settings
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


class BatchTracker:
    """:meth:`control.simulation.loop.Tracker.step` for every case, in the same order.

    Holds the tracker's state (its speed ``tv``, started cases, the gain in force, the
    compensation history) and the buffers of one step; :meth:`command` computes the
    command ``(v, w)`` of the cases whose odometry is due (with a command every step,
    straight into the metrics block ``cblk``).

    Parameters
    ----------
    s : control.simulation.batch.Settings
        The resolved per-case settings.
    tracker : TrackerConfig
        The shared tracker settings (limits, delay compensation).
    schedule : control.simulation.batch.Schedule
        The per-case gains and perturbations by segment.
    tdt : float or numpy.ndarray
        The tracker's step (s): shared, or one per case.
    cblk : numpy.ndarray
        The metrics' block of commands (``BLOCK``, 2, N).
    exact : bool
        The single run's operations (else cheaper forms of the same values).
    recur : bool
        The plant carries the heading's cosine and sine (:class:`BatchPlant`).
    ideal_odom : bool
        Odometry of the plant's own state every step (:class:`Odometry`).
    """

    def __init__(self, s: Settings, tracker: TrackerConfig, schedule: Schedule,
                 tdt: np.ndarray | float, cblk: np.ndarray, exact: bool, recur: bool,
                 ideal_odom: bool):
        n = s.n
        self.n, self.idx = n, np.arange(n)
        self.schedule = schedule
        self.seg = 0                                # segment_index(0, ...) is 0
        self.Kc = schedule.gain(0)                  # (2, 4, N)
        self.tv = np.zeros(n)
        self.started = np.zeros(n, dtype=bool)
        self.all_started = False
        self.tdt = tdt
        self.vmax, self.wmax = tracker.max_linear_speed, tracker.max_angular_speed
        self.vmin = tracker.min_speed
        self.exact, self.recur, self.ideal_odom, self.cblk = exact, recur, ideal_odom, cblk
        # the step from the odometry: no interval known at a case's first command, whose
        # speed is then the measured one (control.simulation.loop.Tracker)
        self.first_hold_zero = tracker.dt == 0
        self.comp = tracker.delay_compensation
        if self.comp:
            Atc = np.array(tracker.A_tau, dtype=float)
            self.cterms = [[(j, float(Atc[i, j])) for j in range(4)] for i in range(4)]
            self.Lc = s.comp_n
            self.cbuf_ref = np.zeros((int(self.Lc.max()), 8, n))
            self.ccount = np.zeros(n, dtype=np.int64)
        self.cs = np.empty((2, n))                  # cos, sin of the measured heading
        self.law = VectorLaw(n, self.vmax, self.wmax, self.vmin, ordered=True)
        self.epos = self.law.E[0::2]                # the position error (x, y)
        self.cmd_log = np.stack((s.v0, np.zeros(n)))    # the command in force: (v0, 0)

    def command(self, k: int, j: int, due: Any, mpos: np.ndarray, mth: np.ndarray,
                mv: np.ndarray, ref: tuple[Any, Any, Any]) -> np.ndarray:
        """The command ``(v, w)`` (2, N) at step ``k`` (block row ``j``) from odometry.

        Parameters
        ----------
        k, j : int
            The step and its row in the metrics block.
        due : bool or numpy.ndarray
            The cases whose odometry is due (True: every case).
        mpos, mth, mv : numpy.ndarray
            The measured position (2, N), heading and speed.
        ref : tuple
            The reference's position, velocity and acceleration.

        Returns
        -------
        numpy.ndarray
        """
        n = self.n
        qpos, qvel, qacc = ref
        vmax = self.vmax
        first = None
        if not self.all_started:
            new = ~self.started if due is True else (~self.started & due)
            if new.any():
                first = new if self.first_hold_zero else None
                v_init = np.where(np.isfinite(mv), mv, 0.0)
                v_init = np.maximum(-vmax, np.minimum(vmax, v_init))
                self.tv = np.where(new, v_init, self.tv)
                self.started = self.started | new
                self.all_started = bool(self.started.all())
        v = self.tv
        if self.exact:
            # yaw through the message's quaternion (its qx = qy = 0 terms add exact
            # zeros: left out), as the tracker node reads it
            # (libm's atan2 per element: numpy's SIMD arctan2 differs from it by an
            # ulp for about 3 % of arguments)
            qz, qw = np.sin(0.5 * mth), np.cos(0.5 * mth)
            mth = _ATAN2(2.0 * (qw * qz), qw * qw - qz * qz).astype(float)
        # (otherwise the yaw is used as measured: the same angle to round-off)
        cs = self.cs
        if not self.recur or k % _ANCHOR == 0:
            np.cos(mth, out=cs[0])
            np.sin(mth, out=cs[1])
        if self.comp:
            xdpos, xdvel, ud = _compensated(self.cbuf_ref, self.ccount, self.Lc, self.cterms,
                                            qpos, qvel, qacc, due, self.idx, n)
        else:
            xdpos, xdvel, ud = qpos, qvel, qacc
        sg = self.schedule.segment(k)
        if sg != self.seg:
            self.Kc = self.schedule.gain(sg)
            self.seg = sg
        # (v, w) sent; with a command every step, straight into the block
        cmd = self.cblk[j] if self.ideal_odom else np.empty((2, n))
        self.law.command(self.Kc, mpos, cs, v, xdpos, xdvel, ud, self.tdt, cmd)
        cv = cmd[0]
        v_next = cv.copy()
        cv += v
        if first is not None:                     # a first command: no ramp, the speed
            cv[first] = v[first] + v[first]
        cv *= 0.5                                 # (v + v_next) / 2
        w = cmd[1]
        # the sum is finite unless a value is nan (all are clipped)
        if math.isfinite(np.add.reduce(cmd, axis=None)):
            self.tv = v_next if due is True else np.where(due, v_next, self.tv)
        else:       # non-finite: stop, keep the compensator state
            ok = np.isfinite(w) & np.isfinite(v_next)
            self.tv = np.where(ok if due is True else ok & due, v_next, self.tv)
            cmd[...] = np.where(ok, cmd, 0.0)
        self.cmd_log = cmd if due is True else np.where(due, cmd, self.cmd_log)
        return cmd


class CommandLine:
    """:meth:`control.simulation.loop.UnicyclePlant.command` for every case: the command in force.

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


class _Actuator:
    """:func:`control.simulation.actuator.first_order_step` of ``v`` and ``w`` for every case."""

    def __init__(self, s: Settings, dt: float):
        self.dt = dt
        self.lag_v, self.lag_w = lag_v, lag_w = s.lag_v, s.lag_w
        self.alv, self.alw = alv, alw = s.max_linear_accel, s.max_angular_accel
        self.on = bool(np.any(lag_v) or np.any(lag_w) or np.any(alv) or np.any(alw))
        self.em1_v = per_value(lambda T: -math.expm1(-dt / T) if T > 0 else 0.0, lag_v, float)
        self.em1_w = per_value(lambda T: -math.expm1(-dt / T) if T > 0 else 0.0, lag_w, float)
        self.lagv_m, self.lagw_m, self.limv_m, self.limw_m = lag_v > 0, lag_w > 0, alv > 0, alw > 0

    def step(self, pv: np.ndarray, pw: np.ndarray, v: np.ndarray, w: np.ndarray
             ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """``(v_end, v_mean, w_end, w_mean)`` over a step from ``(pv, pw)`` towards ``(v, w)``."""
        v_end, v = _first_order(pv, v, self.lag_v, self.alv, self.em1_v, self.lagv_m,
                                self.limv_m, self.dt)
        w_end, w = _first_order(pw, w, self.lag_w, self.alw, self.em1_w, self.lagw_m,
                                self.limw_m, self.dt)
        return v_end, v, w_end, w


class _PlantDelay:
    """The plant's delayed-state term ``d = A_tau xi(t - tau)`` for every case.

    A history of the parts of ``xi = (x, x', y, y')`` that ``A_tau`` uses, by step
    ``% (Nd + 1)``; ``diag``: the paper's form ``d_x = a x(t - tau)``, ``d_y = b y(t - tau)``
    (one product for both).  :meth:`update` fills ``dpos`` and ``dvel`` for a step.
    """

    def __init__(self, plant: PlantConfig, pos: np.ndarray, pv: np.ndarray, th: np.ndarray):
        n = pv.size
        self.Nd = Nd = delay_steps(plant.tau, plant.dt)[0]
        At = np.array(plant.A_tau, dtype=float)
        terms = [[(j, float(At[i, j])) for j in range(4) if At[i, j] != 0.0] for i in range(4)]
        self.terms = terms
        self.on = any(terms)
        self.diag = self.need_vel = self.has_off = False
        self.ax = self.ay = 0.0
        if not self.on:
            return
        self.cols = cols = sorted({j for row in terms for j, _ in row})
        self.need_vel = 1 in cols or 3 in cols
        self.has_off = bool(terms[1] or terms[3])   # else the velocity offset stays 0
        self.hterms = [[(cols.index(j), a) for j, a in row] for row in terms]
        self.diag = (cols == [0, 2] and not self.has_off
                     and [len(r) for r in terms] == [1, 0, 1, 0]
                     and terms[0][0][0] == 0 and terms[2][0][0] == 2)
        if self.diag:
            self.ax, self.ay = terms[0][0][1], terms[2][0][1]
        xi0 = (pos[0], pv * np.cos(th), pos[1], pv * np.sin(th))
        self.hist = np.empty((Nd + 1, len(cols), n))
        self.hist[:] = np.array([xi0[j] for j in cols])[None]
        self.dbuf = np.zeros((4, n))
        self.dpos, self.dvel = self.dbuf[0::2], self.dbuf[1::2]

    def update(self, k: int, pos: np.ndarray, v: np.ndarray, csp: np.ndarray | None,
               off: np.ndarray) -> None:
        """``dpos``, ``dvel`` of step ``k``; the history takes the state of step ``k``."""
        Nd = self.Nd
        if self.diag and Nd > 0:
            old = self.hist[k % (Nd + 1)]               # (x, y) at step k - N
            np.multiply(self.ax, old[0], out=self.dpos[0])
            np.multiply(self.ay, old[1], out=self.dpos[1])
            old[...] = pos
            return
        xi: tuple[Any, Any, Any, Any]
        if self.need_vel:
            vel = v * csp
            if self.has_off:
                vel += off
            xi = (pos[0], vel[0], pos[1], vel[1])       # xi_now = (x, vel_x, y, vel_y)
        else:
            xi = (pos[0], None, pos[1], None)
        if Nd == 0:
            for i in range(4):
                _dot_terms(self.terms[i], xi, self.dbuf[i])
        else:
            old = self.hist[k % (Nd + 1)]               # the used parts of xi at step k - N
            for i in range(4):
                _dot_terms(self.hterms[i], old, self.dbuf[i])
            for r, j in enumerate(self.cols):
                old[r] = xi[j]


class BatchPlant:
    """:meth:`control.simulation.loop.UnicyclePlant.advance` for every case: pose, speed, delay.

    ``pos`` (2, N), ``th``, the speed and rate at the end of the last step ``pv``, ``pw``
    and the velocity offset ``off`` of the delay term.  Without ``exact`` the arc's sine
    and cosines come from series (``small_arc``, when ``|w| dt / 2 <= 0.01`` holds for
    every command) and, with ``recur``, the tracker's heading cosine and sine are carried
    to the next step by angle addition.

    Parameters
    ----------
    plant : PlantConfig
        The shared plant settings (step, state delay).
    s : control.simulation.batch.Settings
        The resolved per-case settings (initial state, actuator).
    exact : bool
        The single run's operations (else cheaper forms of the same values).
    ideal_odom : bool
        Odometry of the plant's own state every step (:class:`Odometry`).
    wmax : float
        The tracker's largest angular speed (rad/s).
    """

    def __init__(self, plant: PlantConfig, s: Settings, exact: bool, ideal_odom: bool,
                 wmax: float):
        n = s.n
        dt = self.dt = plant.dt
        self.hdt = 0.5 * dt
        self.pos = np.stack((s.x0, s.y0))           # (x, y) as (2, N)
        self.th, self.pv = s.th0.copy(), s.v0.copy()
        self.pw = np.zeros(n)
        self.off = np.zeros((2, n))                 # velocity offset (ox, oy)
        self.delay = _PlantDelay(plant, self.pos, self.pv, self.th)
        self.act = _Actuator(s, dt)
        self.exact, self.ideal_odom = exact, ideal_odom
        # |w| <= max_angular_speed for every command (clipped, held, or a mean of two
        # through the actuator): the arc's series applies at every step when
        # 0.5 wmax dt <= 0.01
        self.small_arc = not exact and 0.5 * wmax * dt <= _SERIES_MAX
        # the heading's cosine and sine carried from step to step by angle addition (the
        # tracker measures the plant's own heading), evaluated afresh every _ANCHOR steps
        self.recur = self.small_arc and ideal_odom
        # the heading moves at most wmax dt per step: after a look at max |th| = m the wrap
        # (|th| > pi) cannot be needed for (pi - m) / (wmax dt) steps
        self.wstep = wmax * dt * (1.0 + 1e-9)
        self.wrap_next = 0
        self.mid = np.empty((2, n))
        self.tmp = np.empty((2, n))
        self.arcbuf = np.empty((4, n))

    def advance(self, k: int, v: np.ndarray, w: np.ndarray, cs: np.ndarray) -> None:
        """Advance step ``k`` under the command ``(v, w)`` in force.

        ``cs``: the tracker's cosine and sine of the heading it measured (carried to the
        next step with ``recur``).

        Parameters
        ----------
        k : int
            The step.
        v, w : numpy.ndarray
            The command in force.
        cs : numpy.ndarray
            Cosine and sine of the measured heading (2, N).
        """
        dt = self.dt
        act, d = self.act, self.delay
        if act.on:
            v_end, v, w_end, w = act.step(self.pv, self.pw, v, w)
        if self.ideal_odom and not self.exact:      # the tracker measured this very heading
            csp: np.ndarray | None = cs
        elif d.on:
            csp = np.stack((np.cos(self.th), np.sin(self.th)))
        else:
            csp = None
        if d.on:
            d.update(k, self.pos, v, csp, self.off)
        half = w * self.hdt                         # = 0.5 w dt (halving is exact)
        mid = self.mid
        if self.small_arc and csp is not None:
            sinc, ch, sh = _arc_series(half, csp, mid, self.tmp, self.arcbuf)
            if self.recur:                          # cos, sin (th + 2 half) for the tracker
                _rotate(mid, ch, sh, cs, self.tmp)
        else:
            sinc = _arc_terms(self.th, half, csp, self.exact, mid)
        arc = v * dt
        arc *= sinc
        step = mid * arc
        if d.on:
            if d.has_off:
                step += (d.dpos + self.off) * dt
                step += 0.5 * d.dvel * dt * dt
                self.off = self.off + d.dvel * dt
            else:                                   # the velocity terms are exact zeros
                step += d.dpos * dt
        self.pos = self.pos + step
        th = self.th + w * dt
        if k >= self.wrap_next:
            th, self.wrap_next = wrap_due(th, k, self.wstep)
        self.th = th
        if act.on:
            self.pv, self.pw = v_end, w_end
        else:
            self.pv, self.pw = v, w


#: Steps per block of the metrics.
BLOCK = 16


def _compensated(buf: np.ndarray, count: np.ndarray, L: np.ndarray,
                 terms: list[list[tuple[int, float]]], qpos: Any, qvel: Any, qacc: Any,
                 due: Any, idx: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:meth:`control.simulation.loop.Tracker._compensated_reference` for every case that is due.

    ``buf`` holds per case the last ``L`` pairs ``(xi*, xi*')`` (8 rows) in a ring
    indexed by the case's call ``count``; returns ``xi*`` as position and velocity
    pairs and ``u*`` (each ``(2, N)``).
    """
    rx, ry = np.broadcast_to(qpos[0], (n,)), np.broadcast_to(qpos[1], (n,))
    vx, vy = np.broadcast_to(qvel[0], (n,)), np.broadcast_to(qvel[1], (n,))
    ax, ay = qacc[0], qacc[1]
    first = count == 0
    if due is not True:
        first = first & due
    if first.any():
        init = _stack((rx, vx, ry, vy, vx, 0.0 * vx, vy, 0.0 * vy), n)
        buf[:, :, first] = init[:, first][None]
    cs = count % L
    z = buf[cs, :, idx].T                           # (8, N): xi*, xi*' at t - tau
    d = [_dot4(terms[i], z[0:4]) for i in range(4)]
    dd = [_dot4(terms[i], z[4:8]) for i in range(4)]
    xs = (rx, vx - d[0], ry, vy - d[2])
    us = (ax - dd[0] - d[1], ay - dd[2] - d[3])
    row = _stack((xs[0], xs[1], xs[2], xs[3], vx, us[0] + d[1], vy, us[1] + d[3]), n)
    if due is True:
        buf[cs, :, idx] = row.T
        count += 1
    else:
        w_idx = np.flatnonzero(due)
        buf[cs[w_idx], :, w_idx] = row[:, w_idx].T
        count[w_idx] += 1
    return (_stack((xs[0], xs[2]), n), _stack((xs[1], xs[3]), n), _stack(us, n))


# Taylor coefficients of sin(h)/h and cos(h) in h^2 (to h^6; |h| <= 0.01: truncation < 1e-20)
S1, S2, S3 = -1.0 / 6.0, 1.0 / 120.0, -1.0 / 5040.0
_C1, _C2, _C3 = -1.0 / 2.0, 1.0 / 24.0, -1.0 / 720.0


#: Largest ``|half|`` (rad) for which the arc's series are used.
_SERIES_MAX = 1e-2
#: Steps between fresh evaluations of the heading's cosine and sine when they are carried
#: by angle addition (each step adds about an ulp; the fresh values bound the drift).
_ANCHOR = 16


def _arc_series(half: np.ndarray, cs: np.ndarray, mid: np.ndarray, tmp: np.ndarray,
                buf: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(sin(h)/h, cos h, sin h)`` of ``h = half`` from their series.

    ``mid`` receives ``cos, sin (th + half)`` from ``cs = (cos th, sin th)`` by angle
    addition.  The operations of the non-exact branch of :func:`_arc_terms` (the same values) into
    the rows of ``buf`` (4, N); for ``|half| <= _SERIES_MAX``.
    """
    h2, sinc, ch, sh = buf
    np.multiply(half, half, out=h2)
    for out, c3, c2, c1 in ((sinc, S3, S2, S1), (ch, _C3, _C2, _C1)):
        np.multiply(h2, c3, out=out)
        out += c2
        out *= h2
        out += c1
        out *= h2
        out += 1.0
    np.multiply(half, sinc, out=sh)
    _rotate(cs, ch, sh, mid, tmp)
    return sinc, ch, sh


def _rotate(cs: np.ndarray, ch: np.ndarray, sh: np.ndarray, out: np.ndarray,
            tmp: np.ndarray) -> None:
    """``out = (c ch - s sh, s ch + c sh)`` for ``cs = (c, s)`` (angle addition)."""
    c, s = cs
    t = tmp[0]
    np.multiply(c, ch, out=out[0])
    np.multiply(s, sh, out=t)
    out[0] -= t
    np.multiply(s, ch, out=out[1])
    np.multiply(c, sh, out=t)
    out[1] += t


def _arc_terms(th: np.ndarray, half: np.ndarray, cs: np.ndarray | None, exact: bool,
               mid: np.ndarray) -> np.ndarray:
    """``sin(half) / half`` of the exact arc; ``mid`` receives ``cos, sin (th + half)``.

    ``exact``: the plant's own operations.  Otherwise, for ``|half| <= 0.01``
    (``|w| dt <= 0.02``), ``sin(half) / half`` from its Taylor series (truncation below
    1e-20) and, given ``cs = (cos th, sin th)`` (else ``None``), the angle-addition
    formulas: up to three transcendental calls per step fewer, the same values to
    round-off.
    """
    if not exact and np.max(np.abs(half)) <= _SERIES_MAX:
        h2 = half * half
        sinc: np.ndarray = ((h2 * S3 + S2) * h2 + S1) * h2 + 1.0
        if cs is not None:
            sh = half * sinc
            ch = ((h2 * _C3 + _C2) * h2 + _C1) * h2 + 1.0
            c, s = cs[0], cs[1]
            np.subtract(c * ch, s * sh, out=mid[0])
            np.add(s * ch, c * sh, out=mid[1])
            return sinc
    else:
        big = np.abs(half) > 1e-8
        sinc = np.where(big, np.sin(half) / np.where(big, half, 1.0), 1.0 - half * half / 6.0)
    a = th + half
    np.cos(a, out=mid[0])
    np.sin(a, out=mid[1])
    return sinc


def _stack(values: Any, n: int) -> np.ndarray:
    """Rows of scalars or arrays of ``n`` as one ``(len(values), n)`` array."""
    return np.stack([np.broadcast_to(v, (n,)) for v in values])


def _dot_terms(terms: list[tuple[int, float]], xi: Any, out: np.ndarray) -> None:
    """``out = sum(a * xi[j])`` over the nonzero terms, left to right (as the plant).

    The plant starts from ``0.0``: that changes at most the sign of a zero.  Rows
    without terms are left as they are (zero).
    """
    if not terms:
        return
    j, a = terms[0]
    np.multiply(a, xi[j], out=out)
    for j, a in terms[1:]:
        out += a * xi[j]


def _dot4(terms: list[tuple[int, float]], z: Any) -> Any:
    """``sum(A[i][j] * z[j] for j in range(4))`` left to right (Python's ``sum`` from 0)."""
    out = 0
    for j, a in terms:
        out = out + a * z[j]
    return out
