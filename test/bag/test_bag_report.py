"""bag_report: metrics equal tracking_metrics of the simulation, gaps, plots and errors."""
from __future__ import annotations

import math

import numpy as np

import pytest
from test_bag_writer_reader import RUN, simulated_run, write_run_bag

from nonfragile_tracker.bag.reader import MissingTopicsError
from nonfragile_tracker.bag.report import PLOTS, bag_report, format_report
from nonfragile_tracker.control.simulation.metrics import tracking_metrics


@pytest.fixture(scope='module')
def sim():
    return simulated_run(600)


def _same_metrics(a, b, tol=1e-12):
    for key, va in a.as_dict().items():
        vb = b.as_dict()[key]
        if isinstance(va, float) and math.isnan(va):
            assert math.isnan(vb), key
        else:
            assert abs(va - vb) <= tol, (key, va, vb)


def test_report_metrics_and_plots(tmp_path, sim):
    run, path = sim
    write_run_bag(tmp_path / 'bag', run, path)
    rep = bag_report(tmp_path / 'bag')
    expected = tracking_metrics(run.t, run.x, run.y, run.xd, run.yd, run.cmd_v, run.cmd_w,
                                tolerance=0.01)
    _same_metrics(rep.metrics, expected)
    assert rep.metrics.steps == run.t.size == rep.matched
    assert not math.isnan(rep.metrics.settling_time)           # the run settles within 1 cm
    assert rep.counts == {t: run.t.size for t in RUN}
    assert rep.gaps == () and rep.median_step == pytest.approx(0.01)
    assert rep.out_dir == tmp_path / 'bag_report'
    assert sorted(rep.plots) == sorted(PLOTS)
    for name in PLOTS:
        png = rep.out_dir / name
        assert png.stat().st_size > 10_000
        assert png.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    text = format_report(rep)
    for needle in ('final position error', 'RMS position error', 'enters and stays within 1 cm',
                   'peak |v|', 'peak |w|', '/odom', 'nav_msgs/msg/Odometry', 'gaps on /odom: none',
                   f'{rep.metrics.final_error:.4g} m'):
        assert needle in text, needle


def test_report_tolerance_gaps_and_pose_fallback(tmp_path, sim):
    run, path = sim
    missing = {(t, k) for t in ('/odom', '/pose') for k in (100, 101, 102, 400)}
    write_run_bag(tmp_path / 'g', run, path, topics_=[t for t in RUN if t != '/odom'],
                  skip=missing)
    rep = bag_report(tmp_path / 'g', plots=False, tolerance=0.02)
    assert rep.pose_topic == '/pose' and rep.plots == {}
    keep = [k for k in range(run.t.size) if k not in (100, 101, 102, 400)]
    expected = tracking_metrics(run.t[keep], run.x[keep], run.y[keep], run.xd[keep],
                                run.yd[keep], run.cmd_v, run.cmd_w, tolerance=0.02)
    _same_metrics(rep.metrics, expected)
    assert [(round(g.t_before, 6), round(g.t_after, 6), g.missing_samples) for g in rep.gaps] == \
        [(0.99, 1.03, 3), (3.99, 4.01, 1)]
    assert '~3 samples missing' in format_report(rep)


def test_report_says_what_is_missing_and_reports_the_rest(tmp_path, sim):
    run, path = sim
    write_run_bag(tmp_path / 'nocmd', run, path, topics_=[t for t in RUN if t != '/cmd_vel'])
    rep = bag_report(tmp_path / 'nocmd', plots=False)
    assert rep.command_samples == 0 and rep.metrics is not None
    assert any('no commands (cmd_vel)' in n for n in rep.notes)
    assert 'note: no commands (cmd_vel)' in format_report(rep)
    write_run_bag(tmp_path / 'noref', run, path, topics_=['/odom', '/cmd_vel'])
    rep = bag_report(tmp_path / 'noref')
    assert rep.metrics is None and rep.timing.odom_count == run.t.size
    assert any('reference/pose + reference/twist + reference/accel' in n and
               'timing and the path only' in n for n in rep.notes)
    assert sorted(rep.plots) == ['commands.png', 'xy.png']
    assert rep.path_length == pytest.approx(np.sum(np.hypot(np.diff(run.x), np.diff(run.y))))
    write_run_bag(tmp_path / 'nopose', run, path, topics_=['/reference/pose', '/reference/twist',
                                                            '/reference/accel', '/cmd_vel'])
    rep = bag_report(tmp_path / 'nopose', plots=False)
    assert rep.metrics is None and rep.timing is None and rep.command_samples == run.t.size
    assert any(n.startswith('no odometry (odom or pose)') for n in rep.notes)
    write_run_bag(tmp_path / 'refonly', run, path, topics_=['/reference/pose'])
    with pytest.raises(MissingTopicsError, match=r'no odometry .* and no commands') as exc:
        bag_report(tmp_path / 'refonly')
    assert exc.value.missing == ('odom', 'cmd_vel')
    with pytest.raises(ValueError, match='tolerance'):
        bag_report(tmp_path / 'nopose', tolerance=0.0)
