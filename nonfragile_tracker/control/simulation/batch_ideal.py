"""Batch simulation's fast path: the tracking loop with ideal odometry, fewer operations a step.

:func:`control.simulation.batch.simulate_batch` runs :func:`ideal_loop` instead of its
general loop when, without ``exact``, every case measures the plant's own state at every
step (no odometry latency, rate or noise), the tracker has no delay compensation, the
plant no actuator lag or acceleration limit, and the state delay is none or the paper's
diagonal one; any command latency and perturbation schedule.  It is the same step as the
general loop (the law is :class:`control.simulation.law.VectorLaw`, with ``K e`` summed
first), the same values to round-off (``test/control/test_batch_ideal.py`` checks
it against single runs and the exact mode), with about 50 whole-array operations a step
instead of about 64 (``doc/study.md``).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from .batch_parts import BLOCK, S1, S2, S3, wrap, wrap_due
from .law import VectorLaw
from .loop import step_time_ns

if TYPE_CHECKING:
    from .batch import Metrics, Reference, Schedule

_PI = math.pi


@dataclass(frozen=True)
class IdealRun:
    """What :func:`ideal_loop` runs (besides the initial state and the metrics).

    ``limits`` is ``(max_linear_speed, max_angular_speed, min_speed)`` of the tracker
    (at the shared period ``tdt``), ``delay`` ``None`` or ``(Nd, ax, ay)``
    (``d = (ax x, ay y)(t - tau)``), ``cmd_d`` the command latencies in steps (``None``:
    none); ``first_hold_zero``: the tracker takes its step from the odometry, so its first
    command (step 0) has no ramp (the measured speed).
    """

    steps: int
    dt: float
    tdt: float
    ref: Reference
    schedule: Schedule
    limits: tuple[float, float, float]
    delay: tuple[int, float, float] | None
    cmd_d: np.ndarray | None
    first_hold_zero: bool = False


def ideal_loop(run: IdealRun, pos0: np.ndarray, th0: np.ndarray, v0: np.ndarray,
                metrics: Metrics, trace: dict[str, np.ndarray] | None
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`simulate_batch`'s loop for the ideal odometry case (fewer operations per step).

    Without ``exact``, for odometry of the plant's own state at every step, no delay
    compensation and no actuator dynamics.

    The same step as the general loop with fewer whole-array operations (at about 1,000
    cases their count sets the time): the law (:class:`control.simulation.law.VectorLaw`)
    sums ``K e`` first; one reduction checks ``|v| >= min_speed`` and
    finiteness, the commanded speed is kept as ``v + v_next`` (twice the mean: halving is
    exact), the arc's series is a polynomial in ``w**2`` (``dt sin(h) / (2h)``,
    ``h = w dt / 2``; ``cos h = sqrt(1 - sin(h)**2)``), the next heading's cosine and sine
    are ``2 cos(h) mid - (cos, sin)(th)`` from the midpoint direction ``mid`` (one
    rotation per step), the new position is written into the ring of delayed
    positions over the oldest one, constants are 0-d arrays (no conversion per call);
    without a trace the heading advances once per metrics block by the sum of its rows of
    ``w dt`` (its one use is the fresh cosine and sine at the block's start).  The
    squared error is a sum of products (``einsum``: one pass).  ``run`` holds the
    settings (:class:`IdealRun`), ``pos0``, ``th0``, ``v0`` the initial state.  Returns
    the final position, heading and squared error (a row of ``metrics``).

    Parameters
    ----------
    run : IdealRun
        The run's settings.
    pos0, th0, v0 : numpy.ndarray
        Initial position (2, N), heading and speed.
    metrics : control.simulation.batch.Metrics
        The metrics, updated block by block.
    trace : dict or None
        The per-step arrays to fill (``record=True``).

    Returns
    -------
    (numpy.ndarray, numpy.ndarray, numpy.ndarray)
    """
    n = pos0.shape[1]
    steps, dt, tdt, ref, delay, cmd_d = run.steps, run.dt, run.tdt, run.ref, run.delay, run.cmd_d
    schedule = run.schedule
    S = schedule.segments
    vmax, wmax, vmin = run.limits
    hdt = 0.5 * dt
    mul, add, sub = np.multiply, np.add, np.subtract
    absolute = np.absolute
    minred, addred = np.minimum.reduce, np.add.reduce
    cos, sin = np.cos, np.sin
    c0 = np.array                                   # 0-d constants
    tdt_, dt_ = c0(float(tdt)), c0(float(dt))
    ref_rows = ref.rows if ref.table is not None else None
    ref_at = ref.at
    # positions: a ring of the delayed ones (the new position replaces the oldest)
    if delay is not None:
        Nd, ax, ay = delay
        L = Nd + 2
        ring = np.empty((L, 2, n))
        ring[:] = pos0[None]
        axdt, aydt = c0(ax * dt), c0(ay * dt)
        dtmp = np.empty((2, n))
        pos = ring[0]
    else:
        pos = pos0.copy()
    th = th0.copy()
    cs = np.empty((2, n))
    mid = np.empty((2, n))
    cs0, cs1 = cs
    mid0, mid1 = mid
    sqrt = np.sqrt
    # tracker
    law = VectorLaw(n, vmax, wmax, vmin, ordered=False)
    command = law.command
    epos = law.E[0::2]
    einsum = np.einsum
    uc = np.empty((2, n))
    uc0, uc1 = uc
    absx = np.empty((2, n))
    tv = np.maximum(-vmax, np.minimum(vmax, np.where(np.isfinite(v0), v0, 0.0)))
    tvn = np.empty(n)
    careful = not (float(minred(np.abs(tv))) >= vmin)
    seg = 0                                         # Schedule.segment(0) is 0
    Kc = schedule.gain(seg)                         # (2, 4, N)
    # plant: the arc's series in w**2: Q = hdt sin(h) / h (sin h = w Q); ch = cos h
    W2 = np.empty(n)
    hh = hdt * hdt
    q3, q2, q1, q0 = (c0(hdt * c * hh ** i) for i, c in ((3, S3), (2, S2), (1, S1), (0, 1.0)))
    one = c0(1.0)
    Q = np.empty(n)
    ch = np.empty(n)
    sh = np.empty(n)
    arc = np.empty(n)
    tmp = np.empty((2, n))
    thstep = np.empty(n)
    queue = cmd_d is not None
    if cmd_d is not None:
        # the command sent at k is row k % Rq of a ring (a contiguous copy); case i reads
        # row (k - d_i) % Rq (a gather), which holds the initial command in force, (v0, 0),
        # until k = d_i; rows of the commands in force by block row (w: the heading's rows)
        Rq = int(cmd_d.max()) + 1
        cq = np.empty((Rq, 2, n))                   # (v + v_next, w) sent, by step
        cq[:, 0] = 2.0 * v0
        cq[:, 1] = 0.0
        cq_flat = cq.reshape(-1)
        slots = (np.arange(Rq)[:, None] - cmd_d[None, :]) % Rq
        take_idx = (slots[:, None, :] * (2 * n) + np.arange(2)[None, :, None] * n
                    + np.arange(n)[None, None, :])
        fblk = np.empty((BLOCK, 2, n))
        take = np.take
    # metrics
    cblk, eblk = metrics.cblk, metrics.eblk
    flush = metrics.flush
    wstep = wmax * dt * (1.0 + 1e-9)
    wrap_next = 0
    pv = v0.copy()
    # without a trace the heading advances once per block (the rows of w summed), the only
    # use of it being the fresh cosine and sine at the block's start
    lazy = trace is None
    if lazy:
        wblk = fblk[:, 1] if queue else cblk[:, 1]
        maxred = np.maximum.reduce
    j = 0
    for k in range(steps + 1):
        j = k % BLOCK
        rpos, rvel, racc = ref_rows[k] if ref_rows is not None else ref_at(k)
        v = tv
        if j == 0:                                  # fresh cosine and sine every block
            cos(th, out=cs[0])
            sin(th, out=cs[1])
        sg = schedule.segment(k) if S > 1 else 0
        if sg != seg:
            Kc = schedule.gain(sg)                  # (2, 4, N)
            seg = sg
        X = cblk[j]                                 # (v_next, w), then (v + v_next, w)
        command(Kc, pos, cs, v, rpos, rvel, racc, tdt_, X, careful)
        cv, w = X
        absolute(X, out=absx)
        mv, mw = minred(absx, axis=1).tolist()      # nan if any is nan
        tvn[...] = cv
        cv += v
        if k == 0 and run.first_hold_zero:         # the first command: no ramp
            add(v, v, out=cv)
        if mv == mv and mw == mw:
            tv, tvn = tvn, tv
            careful = not (mv >= vmin)
        else:       # non-finite: stop, keep the speed of those cases
            ok = np.isfinite(w) & np.isfinite(tvn)
            tv = np.where(ok, tvn, v)
            tvn = np.empty(n)
            X[...] = np.where(ok, X, 0.0)
            careful = True
        if queue:
            r = k % Rq
            cq[r] = X
            take(cq_flat, take_idx[r], out=fblk[j], mode='clip')   # (indices are in range)
            sv, w = fblk[j]
        else:
            sv = cv
        # ---- log row k and metrics (the squared error)
        einsum('in,in->n', epos, epos, out=eblk[j])
        if j == BLOCK - 1 or k == steps:
            flush(k - j, j + 1)
            if lazy:                                # the heading after the block's advances
                rows = j + 1 if k < steps else j
                addred(wblk[:rows], axis=0, out=thstep)
                thstep *= dt_
                th += thstep
                if float(maxred(absolute(th, out=thstep))) > _PI:
                    th = wrap(th)
        if trace is not None:
            row = (step_time_ns(k, dt) * 1e-9, pos[0], pos[1], th, pv, rpos[0], rpos[1],
                   0.5 * X[0], X[1], 1.0)
            for name, val in zip(trace, row):
                trace[name][k] = val
        if k == steps:
            break
        # ---- UnicyclePlant.advance
        mul(w, w, out=W2)
        mul(W2, q3, out=Q)
        Q += q2
        Q *= W2
        Q += q1
        Q *= W2
        Q += q0
        mul(w, Q, out=sh)                           # sin h
        mul(sv, Q, out=arc)                         # (v + v_next) hdt sin(h) / h
        mul(sh, sh, out=ch)                         # cos h = sqrt(1 - sin(h)**2), |h| <= 0.01
        sub(one, ch, out=ch)
        sqrt(ch, out=ch)
        mul(cs0, ch, out=mid0)                      # cos, sin (th + h) (_rotate)
        mul(cs1, sh, out=uc0)
        mid0 -= uc0
        mul(cs1, ch, out=mid1)
        mul(cs0, sh, out=uc0)
        mid1 += uc0
        add(ch, ch, out=ch)                         # cos, sin (th + 2 h) = 2 cos(h) mid - cs
        mul(mid0, ch, out=uc0)
        sub(uc0, cs0, out=cs0)
        mul(mid1, ch, out=uc1)
        sub(uc1, cs1, out=cs1)
        mul(mid, arc, out=tmp)
        if delay is not None:
            old = ring[(k + 1) % L]                 # (x, y) at step k - Nd - 1
            mul(old[0], axdt, out=dtmp[0])
            mul(old[1], aydt, out=dtmp[1])
            tmp += dtmp
            add(pos, tmp, out=old)
            pos = old
        else:
            pos += tmp
        if not lazy:
            mul(w, dt_, out=thstep)
            th += thstep
            if k >= wrap_next:
                th, wrap_next = wrap_due(th, k, wstep)
            pv = 0.5 * sv
    metrics.peak[0] *= 0.5
    return pos, th, eblk[j]
