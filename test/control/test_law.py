"""The tracking law's two forms (control/simulation/law.py): the vector form equals the scalar
form case by case - bit for bit in the scalar order, to round-off with ``K e`` summed first -
with the speed floor, the limits and non-finite inputs as the tracker has them."""
from __future__ import annotations

import math

import numpy as np
import pytest

from nonfragile_tracker.control.simulation.law import VectorLaw, feedback

VMAX, WMAX, VMIN = 1.0, 2.0, 0.05


def cases(n=400, seed=3):
    """Random poses, speeds (some below the floor, +-0.0, one nan) and gains."""
    rng = np.random.default_rng(seed)
    pos = rng.normal(0.0, 1.0, (2, n))
    th = rng.uniform(-math.pi, math.pi, n)
    v = rng.uniform(-1.2, 1.2, n)
    v[:40] = rng.uniform(-VMIN, VMIN, 40)
    v[40], v[41], v[42] = 0.0, -0.0, math.nan
    K = rng.normal(0.0, 3.0, (2, 4, n))
    xpos, xvel, ud = rng.normal(0.0, 1.0, (3, 2, n))
    return pos, np.stack((np.cos(th), np.sin(th))), v, K, xpos, xvel, ud


def scalar(i, pos, cs, v, K, xpos, xvel, ud, h):
    """The scalar law with the tracker's clipping, case i: (v_next, w)."""
    xd = (xpos[0, i], xvel[0, i], xpos[1, i], xvel[1, i])
    Ki = [[float(K[r, c, i]) for c in range(4)] for r in range(2)]
    _, _, _, a, w, _ = feedback(pos[0, i], pos[1, i], cs[0, i], cs[1, i], float(v[i]), xd,
                                (ud[0, i], ud[1, i]), Ki, VMIN)
    w = max(-WMAX, min(WMAX, w)) if w == w else w
    vn = float(v[i]) + a * h
    vn = max(-VMAX, min(VMAX, vn)) if vn == vn else vn
    return vn, w


@pytest.mark.parametrize('floor', [None, True])
def test_the_ordered_vector_law_is_the_scalar_law_bit_for_bit(floor):
    pos, cs, v, K, xpos, xvel, ud = cases()
    n, h = v.size, 0.02
    out = np.empty((2, n))
    VectorLaw(n, VMAX, WMAX, VMIN, ordered=True).command(K, pos, cs, v, xpos, xvel, ud, h,
                                                         out, floor)
    want = np.array([scalar(i, pos, cs, v, K, xpos, xvel, ud, h) for i in range(n)]).T
    assert np.array_equal(out, want, equal_nan=True)
    assert np.isnan(out[:, 42]).all()               # a nan speed gives nan, not a number
    assert np.all(np.abs(out[0, ~np.isnan(v)]) <= VMAX)
    assert np.all(np.abs(out[1, ~np.isnan(v)]) <= WMAX)


def test_the_einsum_form_agrees_to_round_off():
    pos, cs, v, K, xpos, xvel, ud = cases(seed=4)
    n, h = v.size, 0.01
    a, b = np.empty((2, n)), np.empty((2, n))
    VectorLaw(n, VMAX, WMAX, VMIN, ordered=True).command(K, pos, cs, v, xpos, xvel, ud, h, a)
    VectorLaw(n, VMAX, WMAX, VMIN, ordered=False).command(K, pos, cs, v, xpos, xvel, ud, h, b)
    ok = ~np.isnan(v)
    # |u| is at most about 40 here and w divides by v_f >= 0.05: a few 1e-12 at the most
    assert np.max(np.abs(a[:, ok] - b[:, ok])) < 1e-11
    assert np.count_nonzero(a[:, ok] != b[:, ok]) > 0   # the sums' orders do differ


def test_the_speed_floor_keeps_the_sign_and_plus_at_zero():
    law = VectorLaw(5, VMAX, WMAX, VMIN, ordered=True)
    v = np.array([0.0, -0.0, 0.01, -0.01, -0.3])
    assert law.floored(v).tolist() == [VMIN, VMIN, VMIN, -VMIN, -0.3]
