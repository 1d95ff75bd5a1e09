"""Trajectories within a base's limits (control.simulation.limits): check, margins, re-timing.

The line-arc lap (straights joined by 0.4 m arcs, 0.4 m/s) exceeds each limit when the
limit is set below its peak; the check names the limit, the time and the value, the
re-timed trajectory is within the limits and never faster than the plan, and a path
tighter than the minimum turning radius is refused with the place and the curvature.
"""
import math

import numpy as np
import pytest

from conftest import CONFIG
from nonfragile_tracker.control.simulation.limits import (ACCEL_FRACTION, LIMIT_NAMES,
                                                          PATH_TOLERANCE, TOLERANCE, Limits,
                                                          check, retime, within_limits)
from nonfragile_tracker.control.simulation.trajectory import TrajectoryError, load_waypoints

LINE_ARC = CONFIG / 'trajectories' / 'line_arc_lap.csv'
#: One limit below the lap's peak at a time (peaks: 0.403 m/s, 0.45 m/s^2, 1.14 rad/s,
#: 5.4 rad/s^2, radius 0.351 m)
BELOW = {'max_linear_speed': 0.3, 'max_linear_accel': 0.3, 'max_angular_speed': 0.9,
         'max_angular_accel': 3.0}


@pytest.fixture(scope='module')
def lap():
    """The line-arc lap as its waypoint file gives it."""
    return load_waypoints(LINE_ARC)


def test_the_lap_is_straights_and_0_4_m_arcs_at_0_4_m_per_s(lap):
    """The shipped lap is what the benchmark says: 0.4 m/s cruise, turns of ~0.4 m."""
    r = check(lap, Limits())
    assert r['max_linear_speed'].peak == pytest.approx(0.4, abs=0.01)
    assert 0.34 < r['min_turning_radius'].peak < 0.41
    assert r['max_angular_speed'].peak == pytest.approx(1.0, abs=0.15)
    assert lap.t_end == pytest.approx(21.78, abs=0.01)


def test_within_the_limits_nothing_changes(lap):
    """Limits above every peak: margins positive, the trajectory passes unchanged."""
    lim = Limits(1.0, 1.0, 2.0, 10.0, 0.3)
    r = check(lap, lim)
    assert r.ok and all(rep.margin > 0 for rep in r.reports)
    assert within_limits(lap, lim) == (lap, '')


def test_a_trajectory_takes_its_share_of_the_acceleration_limits(lap):
    """A trajectory may use ACCEL_FRACTION (80 %) of each acceleration limit, the rest is
    the feedback's: the lap (peaks 0.449 m/s^2, 5.43 rad/s^2) is left alone within the
    whole of 0.5 m/s^2 and 6 rad/s^2 but re-timed to its share by default, the speeds
    unscaled; given again, the re-timed lap is left as it is (judged to the re-timing's
    accuracy, TOLERANCE)."""
    lim = Limits(max_linear_speed=0.41, max_linear_accel=0.5, max_angular_accel=6.0)
    assert within_limits(lap, lim, 1.0) == (lap, '')
    assert ACCEL_FRACTION == 0.8
    new, note = within_limits(lap, lim)
    assert 'the acceleration limits at 80 % (trajectory_accel_fraction' in note
    after = check(new, lim.accel_share(ACCEL_FRACTION), tolerance=TOLERANCE)
    assert after.ok
    assert 0.36 < after['max_linear_accel'].peak <= 0.4 * (1 + TOLERANCE)       # 90-101 %
    assert after['max_angular_accel'].peak <= 4.8 * (1 + TOLERANCE)
    assert after['max_linear_speed'].peak <= 0.41 and new.t_end > lap.t_end
    assert within_limits(new, lim) == (new, '')
    share = lim.accel_share(0.5)
    assert (share.max_linear_speed, share.max_linear_accel, share.max_angular_accel) == \
        (0.41, 0.25, 3.0)
    for bad in (0.0, 0.01, -0.1, 1.5, math.nan, True):
        with pytest.raises(TrajectoryError, match=r'trajectory_accel_fraction must be'):
            within_limits(lap, lim, bad)


@pytest.mark.parametrize('name', list(BELOW))
def test_each_limit_is_checked_and_re_timed(lap, name):
    """The violated limit is named with the time and value; the re-timed lap is within it,
    follows the same path and is nowhere faster than the plan."""
    lim = Limits(**{name: BELOW[name]})
    r = check(lap, lim)
    assert [v.name for v in r.violations] == [name]
    v = r[name]
    assert v.violated_value > BELOW[name] and lap.t_start <= v.violated_at < lap.t_end
    text = v.describe()
    assert f'VIOLATES {name} = {BELOW[name]:g}' in text
    assert f'first at t = {v.violated_at:.3f} s' in text
    rt = retime(lap, lim)
    assert rt.changed and rt.after.ok and rt.duration_after > rt.duration_before
    assert rt.after[name].peak <= BELOW[name] * 1.01
    new = rt.trajectory
    # the same path: every waypoint lies within PATH_TOLERANCE (1 mm) of the re-timed
    # curve (sampled every 0.1 mm at most: 40,001 samples of ~22 s at <= 0.4 m/s)
    from scipy.spatial import cKDTree
    s = new.evaluate(np.linspace(new.t_start, new.t_end, 40001))
    pts = lap.evaluate(lap.knots)
    d, _ = cKDTree(np.column_stack([s.x, s.y])).query(np.column_stack([pts.x, pts.y]))
    assert float(d.max()) <= PATH_TOLERANCE + 1e-4
    assert float(np.hypot(s.vx, s.vy).max()) <= 0.4035         # never faster than the plan


def test_line_arc_junctions_get_a_continuous_turn_rate(lap):
    """max_angular_accel 3 rad/s^2: the turn rate changes by at most 3 rad/s^2 x 20 ms per
    command period of a 50 Hz base (it stepped 0 -> 1 rad/s within ~0.2 s before)."""
    rt = retime(lap, Limits(1.0, 1.0, 2.0, 3.0))
    new = rt.trajectory
    ts = np.arange(new.t_start, new.t_end, 0.02)
    s = new.evaluate(ts)
    sp = np.hypot(s.vx, s.vy)
    w = np.where(sp > 1e-3, (s.vx * s.ay - s.vy * s.ax) / np.maximum(sp, 1e-3) ** 2, 0.0)
    assert float(np.abs(np.diff(w)).max()) <= 3.0 * 0.02 * 1.01
    assert float(np.abs(np.diff(np.hypot(s.vx, s.vy))).max()) <= 1.0 * 0.02 * 1.01


def test_a_path_tighter_than_the_turning_radius_is_refused(lap):
    """No timing fixes a curvature: refused with the place, the time and the curvature -
    the path's (0.4 m arcs: 2.5 1/m, within 5 % after the 1 mm smoothing), not the
    spline's between the waypoints (2.8 1/m)."""
    import re
    with pytest.raises(TrajectoryError) as exc:
        within_limits(lap, Limits(min_turning_radius=0.5))
    msg = str(exc.value)
    assert 'min_turning_radius = 0.5 m' in msg
    curvature = float(re.search(r'curvature ([0-9.]+) 1/m', msg).group(1))
    assert curvature == pytest.approx(2.5, rel=0.05)
    assert ' at (' in msg and ', t = ' in msg


def test_bad_limits_are_refused():
    """Negative or non-finite limits name the parameter."""
    for bad in (-1.0, math.nan):
        with pytest.raises(TrajectoryError, match='max_angular_accel'):
            Limits(max_angular_accel=bad)
    assert set(LIMIT_NAMES) == {f for f in Limits.__dataclass_fields__}


@pytest.mark.parametrize('name', list(BELOW) + ['min_turning_radius'])
def test_cli_trajectory_check_names_the_limit_time_and_value(capsys, lap, name):
    """`trajectory check FILE --limits NAME=VALUE` prints every margin, the violation
    (limit, time, value) and what re-timing changes; exit 1 when a limit is exceeded."""
    from nonfragile_tracker.cli import main
    value = BELOW.get(name, 0.5)
    assert main(['trajectory', 'check', str(LINE_ARC), '--limits', f'{name}={value}']) == 1
    out = capsys.readouterr().out
    # judged as the tracker judges it: an acceleration against its share of the limit
    # (ACCEL_FRACTION, the rest is the feedback's), to the re-timing's accuracy (TOLERANCE)
    share = Limits(**{name: value}).accel_share(ACCEL_FRACTION)
    v = check(lap, share, tolerance=TOLERANCE)[name]
    line = next(ln for ln in out.splitlines() if 'VIOLATES' in ln)
    assert f'VIOLATES {name} = {getattr(share, name):g}' in line
    assert ('80 % of the acceleration limits' in out) is (ACCEL_FRACTION == 0.8)
    assert f'first at t = {v.violated_at:.3f} s' in line
    if name == 'min_turning_radius':
        assert 'refused: ' in out and 'curvature' in out
    else:
        assert f'{v.violated_value:.4g}' in line
        assert 're-timed for ' + name in out and 'after re-timing' in out


def test_cli_limits_margins_and_bad_limit_names(capsys, tmp_path):
    """Within the limits: margins and exit 0; -o writes the re-timed waypoints; a wrong
    name exits 2 naming the accepted ones."""
    from nonfragile_tracker.cli import main
    out_csv = tmp_path / 'timed.csv'
    assert main(['trajectory', 'check', str(LINE_ARC), '--limits', 'max_linear_speed=1',
                 'max_angular_speed=2', '-o', str(out_csv)]) == 0
    out = capsys.readouterr().out
    assert 'margin 0.597' in out and 'within the limits: timing unchanged' in out
    assert load_waypoints(out_csv).t_end == pytest.approx(21.78, abs=0.03)
    with pytest.raises(SystemExit) as exc:
        main(['trajectory', 'check', str(LINE_ARC), '--limits', 'max_speed=1'])
    assert exc.value.code == 2
    assert 'max_linear_speed' in capsys.readouterr().err
