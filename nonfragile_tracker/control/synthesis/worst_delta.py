"""The worst constant perturbation ``Delta`` over the unit ball, for the exact figures.

The exact figures (true delay margin, worst spectral abscissa) are the worst over every
constant ``||Delta||_2 <= 1``, not over a few listed matrices.  :func:`extreme_deltas` gives
the extreme points of the unit spectral-norm ball for the structure at hand (every singular
value 1): rotations and reflections for a square ``2 x 2`` ``Delta``, unit directions for a
rank-one (``q x 1`` or ``1 x r``) ``Delta``, sign-diagonal and random partial isometries
otherwise; :func:`worst_delta` evaluates them and refines the best by a projected
coordinate search on the ball (interior maxima included).  A search, so a lower bound of
the true worst case: it can refute a certificate, never confirm one.

See doc/theory.md, section "Synthesis choices" (the exact figures' Delta).
"""
from __future__ import annotations

import math
from typing import Callable

import numpy as np

__all__ = ['extreme_deltas', 'project_to_ball', 'worst_delta']

#: Angles of the grids on the extreme points (rotations, reflections, unit directions).
SAMPLES = 16
#: Most evaluations of the local refinement.
REFINE_EVALUATIONS = 48


def project_to_ball(D: np.ndarray) -> np.ndarray:
    """Nearest point of the unit spectral-norm ball (singular values clipped at 1).

    Parameters
    ----------
    D : numpy.ndarray, shape (q, r)
        Any matrix.

    Returns
    -------
    numpy.ndarray, shape (q, r)
    """
    U, S, Vt = np.linalg.svd(D, full_matrices=False)
    return np.asarray((U * np.minimum(S, 1.0)) @ Vt)


def _unit_vectors(k: int, samples: int, rng: np.random.Generator) -> list[np.ndarray]:
    if k == 1:
        return [np.ones(1), -np.ones(1)]
    if k == 2:
        return [np.array([math.cos(a), math.sin(a)])
                for a in np.linspace(0.0, 2 * math.pi, samples, endpoint=False)]
    out = [s * e for e in np.eye(k) for s in (1.0, -1.0)]
    for _ in range(samples):
        v = rng.standard_normal(k)
        out.append(v / np.linalg.norm(v))
    return out


def extreme_deltas(q: int, r: int, *, samples: int = SAMPLES, seed: int = 0
                   ) -> list[np.ndarray]:
    """Extreme points of ``{||Delta||_2 <= 1}`` in ``R^(q x r)`` (a grid or a sample of them).

    Parameters
    ----------
    q, r : int
        The shape of ``Delta`` (``E`` is ``m x q``, ``F`` is ``r x n``).
    samples : int
        Grid size: angles of the rotations and of the reflections (``2 x 2``), of the unit
        directions (rank one, a dimension 2), or random ones (otherwise).
    seed : int
        Seed of the random samples.

    Returns
    -------
    list of numpy.ndarray, shape (q, r)
        Each with every singular value 1.
    """
    rng = np.random.default_rng(seed)
    p = min(q, r)
    out: list[np.ndarray] = []
    if p == 1:
        vecs = _unit_vectors(max(q, r), samples, rng)
        return [v.reshape(q, r) for v in vecs]
    if q == r == 2:
        for a in np.linspace(0.0, 2 * math.pi, samples, endpoint=False):
            c, s = math.cos(a), math.sin(a)
            out.append(np.array([[c, -s], [s, c]]))       # rotation
            out.append(np.array([[c, s], [s, -c]]))       # reflection
        return out
    if p <= 4:
        for signs in range(2 ** p):
            M = np.zeros((q, r))
            M[:p, :p] = np.diag([1.0 if (signs >> i) & 1 else -1.0 for i in range(p)])
            out.append(M)
    for _ in range(samples):
        U, _, Vt = np.linalg.svd(rng.standard_normal((q, r)), full_matrices=False)
        out.append(U @ Vt)
    return out


def worst_delta(f: Callable[[np.ndarray], float], q: int, r: int, *,
                extra: list[np.ndarray] | None = None, samples: int = SAMPLES,
                evaluations: int = REFINE_EVALUATIONS, seed: int = 0
                ) -> tuple[float, np.ndarray]:
    """Largest ``f(Delta)`` found over ``||Delta||_2 <= 1`` (see module text).

    Parameters
    ----------
    f : callable
        ``Delta -> float`` to maximize (e.g. a spectral abscissa, or minus a margin).
    q, r : int
        The shape of ``Delta``.
    extra : list of numpy.ndarray, optional
        Further candidates (e.g. ``0`` and the problem's listed perturbations).
    samples : int
        Grid size of :func:`extreme_deltas`.
    evaluations : int
        Most evaluations of the refinement.
    seed : int
        Seed of the random candidates.

    Returns
    -------
    value : float
        The largest value found.
    Delta : numpy.ndarray, shape (q, r)
        Its maximizer (``||Delta||_2 <= 1``).
    """
    pool = [np.asarray(D, float) for D in (extra or [])] + extreme_deltas(q, r, samples=samples,
                                                                          seed=seed)
    vals = [f(D) for D in pool]
    i = int(np.argmax(vals))
    best, D = float(vals[i]), pool[i]
    step = math.pi / samples if q * r <= 4 else 0.25
    used = 0
    while used < evaluations and step > 1e-4:
        improved = False
        for k in range(q * r):
            for sign in (1.0, -1.0):
                C = D.copy().ravel()
                C[k] += sign * step
                C = project_to_ball(C.reshape(q, r))
                v = f(C)
                used += 1
                if v > best:
                    best, D, improved = float(v), C, True
                    break
            if used >= evaluations:
                break
        if not improved:
            step *= 0.5
    return best, D
