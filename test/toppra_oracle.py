"""The time-optimal timing of a fitted path by the ``toppra`` package: the tests' oracle.

toppra (Pham and Pham's reference implementation of TOPP-RA, PyPI ``toppra==0.6.10``, a
test-only dependency) solves the same problem as :func:`control.simulation.limits.retime`
with its own discretization and its own LP solver (seidel), on the same geometry: the
path coordinate is the arc length itself (a 1-dof path ``q(s) = s``); the speed rows are a
varying velocity bound ``min(v_plan(s), v_max, w_max / |kappa(s)|)``; the accelerations a
second-order constraint ``w = (s'', kappa'(s) s'^2 + kappa(s) s'')`` with ``|w_1| <=
a_max`` and ``|w_2| <= alpha_max``.
"""
from __future__ import annotations

import logging

import numpy as np

from nonfragile_tracker.control.simulation.limits import Limits, PathFit, PathPiece

logging.getLogger('toppra').setLevel(logging.WARNING)


def piece_duration(piece: PathPiece, limits: Limits, span: tuple[float, float], *,
                   step: float = 0.004) -> float:
    """toppra's time-optimal duration (s) of a span of a piece, from and to the planned
    speeds at its ends."""
    import toppra as ta
    import toppra.algorithm as algo
    import toppra.constraint as constraint
    s0, L = span
    n = max(int(np.ceil((L - s0) / step)), 10)
    ss = np.linspace(s0, L, n + 1)
    path = ta.SplineInterpolator(ss, ss.reshape(-1, 1))

    def curvature(q):
        _, _, _, k, dk = piece.evaluate(np.atleast_1d(q[0]))
        return float(k[0]), float(dk[0])

    def vlim(s):
        v = float(piece.speed_cap(s))
        if limits.max_linear_speed > 0:
            v = min(v, limits.max_linear_speed)
        k = abs(curvature([s])[0])
        if limits.max_angular_speed > 0 and k > 0:
            v = min(v, limits.max_angular_speed / k)
        return np.array([[-v, v]])

    cons = [constraint.JointVelocityConstraintVarying(vlim)]
    rows, bounds = [], []
    if limits.max_linear_accel > 0:
        rows += [[1.0, 0.0], [-1.0, 0.0]]
        bounds += [limits.max_linear_accel] * 2
    if limits.max_angular_accel > 0:
        rows += [[0.0, 1.0], [0.0, -1.0]]
        bounds += [limits.max_angular_accel] * 2
    if rows:
        F, g = np.array(rows), np.array(bounds)

        def inv_dyn(q, qd, qdd):
            k, dk = curvature(q)
            return np.array([qdd[0], dk * qd[0] ** 2 + k * qdd[0]])

        cons.append(constraint.SecondOrderConstraint(inv_dyn, lambda q: F, lambda q: g, 1))
    inst = algo.TOPPRA(cons, path, gridpoints=ss, solver_wrapper='seidel')
    v0 = float(vlim(s0)[0, 1])
    v1 = float(vlim(L)[0, 1])
    _, sd, _ = inst.compute_parameterization(v0, v1)
    sd = np.asarray(sd, float)
    if not np.all(np.isfinite(sd)):
        raise RuntimeError('toppra found no parameterization')
    return float(np.sum(2 * np.diff(ss) / (sd[1:] + sd[:-1])))


def duration(path: PathFit, limits: Limits, *, step: float = 0.004) -> float:
    """toppra's time-optimal duration (s) of a fitted path (pieces and spans meet at rest)."""
    return sum(piece_duration(p, limits, span, step=step) for p in path.pieces
               for span in p.spans())
