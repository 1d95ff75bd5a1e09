"""Shared checks of the batch simulation against single runs (``test/control/test_batch*``).

A case of a batch must be the single run (``control.simulation.simulate.simulate_tracking``) with
that case's configuration: these helpers run the single runs, measure the largest
difference of the logged fields and compare the metrics.
"""
from __future__ import annotations

import numpy as np
import pytest

from conftest import CONFIG
from nonfragile_tracker.control.simulation.batch import (PathBatch, perturbation_schedule,
                                                         sample_deltas)
from nonfragile_tracker.control.simulation.gains import read_gain_file
from nonfragile_tracker.control.synthesis.problem import load_problem
from nonfragile_tracker.control.simulation.simulate import simulate_tracking

#: The per-step fields a batch trace logs, as the single run's attributes.
FIELDS = ('x', 'y', 'th', 'speed', 'cmd_v', 'cmd_w', 'commanded')


def gain():
    """The shipped tracker gain."""
    return read_gain_file(CONFIG / 'tracker_gains.yaml')


def perturbations(rng, n, segments=1):
    """``n`` random ``E Delta F`` schedules of the paper's problem, ``segments`` each."""
    p = load_problem(CONFIG / 'paper_problem.yaml')
    return perturbation_schedule(p.E, p.F, sample_deltas(rng, n, segments, (2, 2)))


def single_runs(plant, tracker, path, steps, cases):
    """``(i, run)``: the single run of every case of ``cases``."""
    for i in range(cases.n):
        pci, tci = cases.configs(i, plant, tracker)
        p = path.path(i) if isinstance(path, PathBatch) else path
        yield i, simulate_tracking(pci, tci, p, steps)


def trace_deviation(run, batch, i) -> float:
    """Largest |single run - case ``i`` of a recorded batch| over :data:`FIELDS`."""
    return max(float(np.max(np.abs(getattr(run, name) - batch.trace[name][:, i])))
               for name in FIELDS)


def assert_metrics_equal(run, batch, i, *, first_within: bool = False) -> None:
    """Every metric of case ``i`` equals the single run's within 1e-12."""
    m = run.metrics(tolerance=batch.tolerance)
    assert m.settling_time == pytest.approx(batch.settling_time[i], abs=1e-12, nan_ok=True)
    if first_within:
        assert m.first_within == pytest.approx(batch.first_within[i], abs=1e-12, nan_ok=True)
    assert m.final_error == pytest.approx(batch.final_error[i], abs=1e-12)
    assert m.rms_error == pytest.approx(batch.rms_error[i], abs=1e-12)
    assert m.peak_abs_v == pytest.approx(batch.peak_abs_v[i], abs=1e-12)
    assert m.peak_abs_w == pytest.approx(batch.peak_abs_w[i], abs=1e-12)
    window = run.t >= batch.steady_from - 1e-12
    assert run.error[window].max() == pytest.approx(batch.steady_error[i], abs=1e-12)
