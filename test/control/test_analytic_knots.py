"""The built-in paths as trajectory knots: the quintic Hermite interpolant the tracker
rebuilds from them is the exact path to round-off (analytic_knots)."""
import numpy as np
import pytest

from nonfragile_tracker.control.simulation.reference import make_path
from nonfragile_tracker.control.simulation.trajectory import (KNOT_ANGLE, TrajectoryError,
                                                              analytic_knots, from_states)


def rebuilt(path, horizon):
    t_ns, s = analytic_knots(path, horizon)
    return t_ns, from_states(t_ns * 1e-9, s.x, s.y, s.vx, s.vy, s.ax, s.ay, yaw=s.heading)


def worst(path, traj, times):
    exact = np.array([path.sample(float(t)) for t in times])
    got = np.array([traj.sample(float(t)) for t in times])
    return np.abs(exact - got).max(axis=0)        # t, x, y, vx, vy, ax, ay, heading


@pytest.mark.parametrize('name', ['circle', 'figure_eight'])
def test_paper_rate_over_an_hour_is_exact_to_round_off(name):
    path = make_path(name, radius=0.5, rate=0.01)
    t_ns, traj = rebuilt(path, 3600.0)
    step = np.diff(t_ns)
    assert np.all(step == step[0]) and t_ns[0] == 0 and t_ns[-1] >= 3600 * 10**9
    assert step[0] == int(KNOT_ANGLE / (0.01 * path.harmonic) * 1e9)
    times = np.concatenate([np.arange(0.0, 60.0, 0.01),          # a run's stamps
                            np.random.default_rng(1).uniform(0.0, 3600.0, 3000)])
    err = worst(path, traj, times)
    assert err[1] < 1e-13 and err[2] < 1e-13           # position (m): the 1e-12 target
    assert err[3] < 1e-13 and err[4] < 1e-13           # velocity (m/s, path speed 5 mm/s)
    assert err[5] < 1e-13 and err[6] < 1e-13           # acceleration (m/s^2)
    assert err[7] < 1e-10                              # heading (rad) = atan2 of the velocity


def test_fast_path_keeps_the_same_angle_per_knot():
    path = make_path('figure_eight', radius=0.5, rate=0.5)
    t_ns, traj = rebuilt(path, 60.0)
    assert len(t_ns) == int(np.ceil(60.0 / (KNOT_ANGLE / 1.0))) + 1
    err = worst(path, traj, np.random.default_rng(2).uniform(0.0, 60.0, 3000))
    assert max(err[1], err[2]) < 1e-13


def test_resting_path_and_limits():
    path = make_path('circle', radius=0.5, rate=0.0)
    t_ns, traj = rebuilt(path, 10.0)
    assert t_ns.tolist() == [0, 10 * 10**9]
    s = traj.sample(5.0)
    assert (s.x, s.y, s.vx, s.vy) == pytest.approx((0.5, 0.0, 0.0, 0.0), abs=1e-15)
    with pytest.raises(TrajectoryError,
                       match='33333335 knots needed for a horizon of 1000000.0 s'):
        analytic_knots(make_path('circle', rate=1.0), 1e6)
    with pytest.raises(TrajectoryError, match='horizon must be a finite time'):
        analytic_knots(path, float('nan'))


@pytest.mark.parametrize('accelerations', [True, False])
def test_hermite_pieces_are_scipys_to_round_off(accelerations):
    """from_states builds the Hermite pieces in closed form (no scipy.interpolate import):
    the polynomials of scipy's BPoly.from_derivatives, evaluated alike (PPoly) with every
    derivative, on uneven knots of very different lengths."""
    from scipy.interpolate import BPoly, PPoly
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.01, 2.0, 60))
    x, vx, ax, y, vy, ay = rng.normal(size=(6, 60))
    traj = from_states(t, x, y, vx, vy, ax if accelerations else None,
                       ay if accelerations else None)
    times = np.concatenate([t, rng.uniform(t[0] - 1.0, t[-1] + 1.0, 2000)])
    for p, v, a, col in ((x, vx, ax, 0), (y, vy, ay, 1)):
        ys = np.column_stack([p, v, a] if accelerations else [p, v])
        ref = PPoly.from_bernstein_basis(BPoly.from_derivatives(t, ys))
        scale = np.abs(ref.c).max(axis=0) + 1.0
        assert np.all(np.abs(traj._pp.c[..., col] - ref.c) <= 1e-12 * scale)
        for nu in range(4):                       # limits.py reads the jerk (nu = 3)
            want = ref(times, nu)
            assert np.allclose(traj._pp(times, nu)[:, col], want, rtol=1e-11,
                               atol=1e-11 * np.abs(want).max())
