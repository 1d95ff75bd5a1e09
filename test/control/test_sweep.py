"""control.synthesis.sweep and parallel: the grid, one design's record, the front, executors (local, Dask)."""
import json
import sys
from concurrent.futures import Executor, Future

import numpy as np
import pytest

from conftest import DI_PROBLEM

from nonfragile_tracker.cli import main
from nonfragile_tracker.control.synthesis.input_delay import certify_input_delay
from nonfragile_tracker.control.synthesis.latency_design import lagged_problem
from nonfragile_tracker.control.synthesis.problem import Problem
from nonfragile_tracker.control.synthesis.sweep import (SweepPoint, design_point, pareto_front,
                                                        run_sweep, sweep_points, sweep_table)
from nonfragile_tracker.errors import InputError
from nonfragile_tracker.parallel import map_tasks, open_executor

#: Depends on linear algebra: make test runs it again under a second BLAS kernel (Makefile).
pytestmark = pytest.mark.numerical


def di_problem():
    return Problem(A=np.array([[0.0, 1.0], [0.0, 0.0]]), B=np.array([[0.0], [1.0]]),
                   A_tau=np.zeros((2, 2)), tau=0.1, E=np.eye(1), F=np.array([[0.2, 0.2]]),
                   name='di', perturbations={'minus': -np.eye(1), 'plus': np.eye(1)},
                   options={'gain_bound': 3.0})


def strip(records):
    return [{k: v for k, v in r.items() if k != 'seconds'} for r in records]


# two designs of the double integrator: about 1 s each on an idle core
POINTS = sweep_points([(0.0, 0.03)], lags=[0.0, 0.05], gain_bounds=[3.0], predictors=[False])


@pytest.fixture(scope='module')
def serial():
    return run_sweep(di_problem(), POINTS, workers=1)


def test_grid_is_every_combination_in_order():
    pts = sweep_points([(0.0, 0.03), (0.1, 0.15)], lags=[0.0, 0.05], gain_bounds=[3.0, 5.0],
                       objectives=['decay', 'max-delay'], predictors=[False, True])
    # [0, 0.03]: the predictor removes nothing, one design without it; [0.1, 0.15]: both
    assert len(pts) == 2 * 2 * 2 * 1 + 2 * 2 * 2 * 2
    assert pts[0] == SweepPoint((0.0, 0.03), 0.0, 3.0, 'decay', False)
    assert pts[1] == SweepPoint((0.0, 0.03), 0.0, 3.0, 'max-delay', False)
    assert pts[8] == SweepPoint((0.1, 0.15), 0.0, 3.0, 'decay', False)
    assert pts[9] == SweepPoint((0.1, 0.15), 0.0, 3.0, 'decay', True)
    assert pts[-1] == SweepPoint((0.1, 0.15), 0.05, 5.0, 'max-delay', True)
    assert sweep_points([(0.0, 0.1)], predictors=[True]) == [
        SweepPoint((0.0, 0.1), 0.0, None, 'decay', True)]
    for bad in ([(0.2, 0.1)], [(0.0, float('nan'))], [(0.0,)], [(True, 0.1)]):
        with pytest.raises(InputError):
            sweep_points(bad)
    with pytest.raises(InputError, match='objective'):
        sweep_points([(0, 0.1)], objectives=['fast'])
    with pytest.raises(InputError, match='no lag'):
        sweep_points([(0, 0.1)], lags=[])


def test_each_design_is_certified_and_its_record_is_exact(serial):
    p = di_problem()
    plain, lagged = serial
    assert [r['status'] for r in serial] == ['ok', 'ok']
    for r in serial:
        assert r['delay_interval'] == pytest.approx([0.0, 0.05])    # [L_lo, L_hi + T]
        assert r['verified'] and r['gain_norm'] <= 3.0 * (1 + 1e-9) and r['decay_rate'] > 0
        # certified command latency = H - T without the predictor
        assert r['certified_command_latency'] == pytest.approx(r['certified_h_max'] - 0.02)
        assert r['true_delay_margin'] > r['certified_h_max']
    # the lagged design's figure is a real certificate of the lagged loop, and not beyond
    K = np.array(lagged['K'])
    lp = lagged_problem(p, 0.05)
    K_aug = np.hstack([K, np.zeros((1, 1))])
    c = certify_input_delay(lp, K_aug, 0.0, lagged['certified_h_max'])
    assert c.certified and c.verification.ok
    assert not certify_input_delay(lp, K_aug, 0.0, lagged['certified_h_max'] + 0.01).certified
    # the lag costs certified latency
    assert lagged['certified_h_max'] < plain['certified_h_max']


def test_with_the_predictor_the_residual_is_certified_and_the_latency_counted_from_L_lo():
    r = design_point(di_problem(), SweepPoint((0.2, 0.22), 0.0, 3.0, 'decay', True))
    assert r['status'] == 'ok' and r['delay_interval'] == pytest.approx([0.0, 0.04])
    assert r['certified_command_latency'] == pytest.approx(0.2 + r['certified_h_max'] - 0.02)
    bad = design_point(di_problem(), SweepPoint((0.2, 3.0), 0.0, 3.0, 'decay', False))
    assert bad['status'] == 'infeasible' and 'infeasible' in bad['message'] and 'K' not in bad


def test_pareto_front_is_per_lag_and_keeps_only_undominated():
    def rec(lag, lat, decay, norm):
        return {'status': 'ok', 'lag': lag, 'certified_command_latency': lat,
                'decay_rate': decay, 'gain_norm': norm}
    records = [rec(0.0, 0.2, 1.0, 5.0), rec(0.0, 0.1, 0.9, 6.0),     # 1 dominated by 0
               rec(0.0, 0.3, 0.5, 5.0), rec(0.05, 0.05, 0.2, 9.0),   # 3: only one of its lag
               {'status': 'infeasible', 'lag': 0.0}]
    assert pareto_front(records) == [0, 2, 3]


def test_two_local_workers_give_the_same_records(serial):
    two = run_sweep(di_problem(), POINTS, workers=2)
    assert strip(two) == strip(serial)
    assert 'Pareto' not in sweep_table(serial) and sweep_table(serial).count('\n') == 2


def test_dask_local_cluster_gives_the_same_records(serial):
    import distributed          # pinned in requirements.txt: the suite runs the Dask path
    with distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                  dashboard_address=None) as cluster, \
            distributed.Client(cluster) as client:
        got = run_sweep(di_problem(), POINTS, executor=client.get_executor())
    assert strip(got) == strip(serial)


class _Recording(Executor):
    """Runs each task at once, in this thread, and records the order it was handed out."""

    def __init__(self):
        self.order = []

    def submit(self, fn, /, *args, **kwargs):
        self.order.append(args[0])
        fut = Future()
        fut.set_result(fn(*args, **kwargs))
        return fut


def test_tasks_are_handed_out_longest_first_and_results_kept_in_order():
    ex = _Recording()
    tasks = [1, -5, 3, -2, 4, 2]
    got = map_tasks(abs, tasks, executor=ex, cost=abs)
    assert got == [1, 5, 3, 2, 4, 2]
    assert ex.order == [-5, 4, 3, -2, 2, 1]          # stable: -2 before 2 (equal cost)
    ex = _Recording()
    assert map_tasks(abs, tasks, executor=ex) == [1, 5, 3, 2, 4, 2]
    assert ex.order == tasks                         # no cost: the tasks' order
    # a sweep hands the lagged designs out first, the records stay in the points' order
    ex = _Recording()
    pts = [SweepPoint((0.0, 0.03), 0.0, None, 'decay', False),
           SweepPoint((0.0, 0.03), 0.05, None, 'decay', False),
           SweepPoint((0.0, 0.08), 0.0, None, 'decay', True)]
    recs = run_sweep(di_problem(), pts, executor=ex)
    assert [t[1] for t in ex.order] == [pts[1], pts[2], pts[0]]
    assert [(r['lag'], r['latency']) for r in recs] == [(0.0, [0.0, 0.03]),
                                                        (0.05, [0.0, 0.03]),
                                                        (0.0, [0.0, 0.08])]


def test_executor_arguments_are_checked(monkeypatch):
    assert map_tasks(abs, [-1, 2, -3], workers=1) == [1, 2, 3]
    assert map_tasks(abs, []) == []
    with pytest.raises(InputError, match='executor must be one of'):
        map_tasks(abs, [1], executor='ray')
    with pytest.raises(InputError, match='workers'):
        map_tasks(abs, [1, 2], workers=0)
    with pytest.raises(InputError, match='dask only'):
        with open_executor('local', scheduler='tcp://x:1'):
            pass
    monkeypatch.setitem(sys.modules, 'distributed', None)     # Dask not installed
    with pytest.raises(InputError, match='pip install dask'):
        with open_executor('dask', workers=1):
            pass


def test_cli_sweep_writes_json_and_plot(tmp_path, capsys):
    prob = tmp_path / 'di.yaml'
    prob.write_text(DI_PROBLEM)
    out, png = tmp_path / 's.json', tmp_path / 's.png'
    assert main(['sweep', str(prob), '--latency', '0', '0.03', '--predictor', 'off',
                 '--workers', '1', '--json', str(out), '--plot', str(png)]) == 0
    text = capsys.readouterr().out
    assert '1 of 1 designs certified' in text and 'wrote' in text
    data = json.loads(out.read_text())
    (d,) = data['designs']
    assert d['status'] == 'ok' and d['pareto'] and len(d['K']) == 1 and d['verified']
    assert png.stat().st_size > 10_000
    assert main(['sweep', str(prob), '--json', str(out)]) == 2          # never overwrites
    assert 'pass --force' in capsys.readouterr().err
    assert main(['sweep', str(prob), '--latency', '0.2', '0.1']) == 2
    assert 'LO <= HI' in capsys.readouterr().err
