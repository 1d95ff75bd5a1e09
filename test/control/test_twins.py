"""Every step the batch vectorizes has its scalar twin in the same module: one test per pair.

Each test drives the scalar step (one instance per case) and its vector twin (all cases
at once) with the same inputs and asserts that case ``i`` of the twin equals the scalar
step of case ``i`` (bit for bit where the operations are the same, else to round-off).
The tracker and plant pairs (``tracker.Tracker`` / ``tracker.VectorTracker``,
``plant.UnicyclePlant`` / ``plant.VectorPlant``) need the loop around them: test_batch.py's
``*_equal_single_runs`` compare every traced field of each case step by step (commands,
poses, speeds; exact mode within 1e-12, over paper, latency, lag, limit, decimated and
noisy-odometry cases).
"""
from __future__ import annotations

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.actuator import ActuatorModel, VectorActuator, actuate
from nonfragile_tracker.control.simulation.batch_data import Settings
from nonfragile_tracker.control.simulation.command_line import CommandLine, VectorCommandLine
from nonfragile_tracker.control.simulation.law import VectorLaw, feedback
from nonfragile_tracker.control.simulation.sensors import (Odometer, OdometryModel,
                                                           VectorOdometer)

N = 7
RNG = np.random.default_rng(20261202)


def _settings(**vals: np.ndarray) -> Settings:
    """A batch's per-case settings with the fields the twins read (the rest neutral)."""
    n = N
    base = dict(period=np.ones(n, dtype=np.int64), odom_d=np.zeros(n, dtype=np.int64),
                noise=np.zeros((n, 3)), seed=np.arange(n))
    named = {k: vals.pop(k) for k in list(vals) if k in base}
    base.update(named)
    return Settings(n=n, K=np.zeros((n, 2, 4)), P=np.zeros((n, 1, 2, 4)), hold_ns=1,
                    vals=vals, cmd_d=np.zeros(n, dtype=np.int64), tdt=np.full(n, 0.01),
                    comp_n=np.ones(n, dtype=np.int64), **base)


def test_law_twins():
    """``law.feedback`` and ``law.VectorLaw`` (ordered): the same command, bit for bit."""
    K = RNG.normal(size=(N, 2, 4))
    pos, th = RNG.normal(size=(2, N)), RNG.uniform(-3, 3, N)
    v = RNG.uniform(-0.5, 1.0, N)
    xd = RNG.normal(size=(4, N))
    ud = RNG.normal(size=(2, N))
    law = VectorLaw(N, 1.0, 2.0, 1e-3, ordered=True)
    out = np.empty((2, N))
    cs = np.stack((np.cos(th), np.sin(th)))
    law.command(np.moveaxis(K, 0, -1), pos, cs, v, xd[0::2], xd[1::2], ud, 0.01, out)
    for i in range(N):
        e, u1, u2, a, w, _ = feedback(pos[0, i], pos[1, i], cs[0, i], cs[1, i], v[i],
                                      xd[:, i], ud[:, i], K[i], 1e-3)
        v_next = min(1.0, max(-1.0, v[i] + a * 0.01))
        assert (out[0, i], out[1, i]) == (v_next, min(2.0, max(-2.0, w))), i


def test_actuator_twins():
    """``actuator.actuate`` and ``actuator.VectorActuator``: lags, limits, none, both."""
    dt = 0.01
    lag_v, lag_w = RNG.choice([0.0, 0.05, 0.2], N), RNG.choice([0.0, 0.03], N)
    alv, alw = RNG.choice([0.0, 0.5, 3.0], N), RNG.choice([0.0, 2.0], N)
    twin = VectorActuator(_settings(lag_v=lag_v, lag_w=lag_w, max_linear_accel=alv,
                                    max_angular_accel=alw), dt)
    pv, pw = RNG.uniform(-1, 1, N), RNG.uniform(-2, 2, N)
    for _ in range(50):
        v, w = RNG.uniform(-1, 1, N), RNG.uniform(-2, 2, N)
        v_end, v_mean, w_end, w_mean = twin.step(pv, pw, v, w)
        for i in range(N):
            model = ActuatorModel(lag_v=lag_v[i], lag_w=lag_w[i], max_linear_accel=alv[i],
                                  max_angular_accel=alw[i])
            want = actuate(model, pv[i], pw[i], v[i], w[i], dt)
            got = (v_end[i], w_end[i], v_mean[i], w_mean[i])
            np.testing.assert_allclose(got, want, rtol=1e-13, atol=1e-15, err_msg=str(i))
        pv, pw = v_end, w_end


def test_odometer_twins():
    """``sensors.Odometer`` and ``sensors.VectorOdometer``: latency, decimation, noise."""
    period = RNG.choice([1, 2, 3], N).astype(np.int64)
    odom_d = RNG.choice([0, 1, 4], N).astype(np.int64)
    noise = np.where(RNG.random((N, 1)) < 0.5, 0.0, [[1e-3, 2e-3, 1e-2]])
    twin = VectorOdometer(_settings(period=period, odom_d=odom_d, noise=noise,
                                    seed=np.arange(N) + 3))
    scalars = [Odometer(OdometryModel(latency_steps=int(odom_d[i]),
                                      period_steps=int(period[i]),
                                      noise=tuple(noise[i]), seed=i + 3)) for i in range(N)]
    pos, th, v = np.zeros((2, N)), RNG.uniform(-3, 3, N), RNG.uniform(0, 1, N)
    seen = 0
    for k in range(80):
        twin.measure(k, pos, th, v)
        for i, odo in enumerate(scalars):
            odo.measure(k, pos[0, i], pos[1, i], th[i], v[i], 0.0)
        due, mpos, mth, mv, mstep = twin.read(k)
        for i, odo in enumerate(scalars):
            sample = odo.due(k)
            hit = due is True or (due is not False and bool(due[i]))
            assert hit == (sample is not None), (k, i)
            if sample is not None:
                step = mstep if np.ndim(mstep) == 0 else mstep[i]
                assert int(step) == sample.step
                np.testing.assert_allclose((mpos[0, i], mpos[1, i], mth[i], mv[i]),
                                           (sample.x, sample.y, sample.th, sample.v),
                                           rtol=0, atol=1e-15, err_msg=f'{k} {i}')
                seen += 1
        pos = pos + RNG.normal(scale=0.01, size=(2, N))
        th = np.remainder(th + RNG.normal(scale=0.05, size=N) + np.pi, 2 * np.pi) - np.pi
        v = v + RNG.normal(scale=0.01, size=N)
    assert seen > 80                     # every kind of case published many samples


@pytest.mark.parametrize('queue', [False, True])
def test_command_line_twins(queue):
    """``command_line.CommandLine`` and ``VectorCommandLine``: the command in force."""
    cmd_d = RNG.choice([0, 1, 5], N).astype(np.int64) if not queue else \
        np.full(N, 3, dtype=np.int64)
    v0 = RNG.uniform(0, 1, N)
    twin = VectorCommandLine(cmd_d, v0, queue)
    scalars = [CommandLine(int(cmd_d[i]), v0=float(v0[i])) for i in range(N)]
    for k in range(60):
        due = True if queue else RNG.random(N) < 0.6
        cmd = RNG.uniform(-1, 1, (2, N))
        sent = due if due is True else (due if due.any() else False)
        if sent is not False:
            twin.send(k, cmd, sent)
        for i, line in enumerate(scalars):
            if due is True or due[i]:
                line.send(k, cmd[0, i], cmd[1, i])
        fv, fw = twin.in_force(k)
        for i, line in enumerate(scalars):
            assert (fv[i], fw[i]) == line.in_force(k), (k, i)
