"""Bag-based regression tests for YOUR robot or scenario, with nonfragile_tracker's public API.

Copy this file into your own test directory and point the four paths below at your files
(environment variables, or edit the defaults).  As shipped it runs against the package's
own paper scenario and golden bag, so ``pytest doc/user_regression_example.py`` works in a
source checkout.

* ``MY_ROBOT_BAG`` - a bag of a run (your robot in real time, or a lockstep simulation);
* ``MY_GAINS``     - the gain file you want to try (``nonfragile_tracker synthesize -o``);
* ``MY_SCENARIO``  - your scenario parameter file (plant / reference / tracker sections);
* ``MY_GOLDEN``    - the golden bag of that scenario, made once with
  ``nonfragile_tracker golden --scenario MY_SCENARIO --out DIR --write``.

The first two tests need no ROS; the third starts the three nodes (lockstep).
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from nonfragile_tracker.bag import (bag_report, compare_bags, format_differences,
                                    format_replay, replay)
from nonfragile_tracker.workflows.golden import golden_gains, run_scenario, scenario_from_file
from nonfragile_tracker.interface.resources import config_dir

_DATA = Path(__file__).resolve().parent.parent / 'test' / 'data'
MY_ROBOT_BAG = Path(os.environ.get('MY_ROBOT_BAG', _DATA / 'golden_paper'))
MY_GAINS = Path(os.environ.get('MY_GAINS', golden_gains()))   # the package's: the pinned gain
MY_SCENARIO = Path(os.environ.get('MY_SCENARIO', config_dir() / 'paper_scenario.yaml'))
MY_GOLDEN = Path(os.environ.get('MY_GOLDEN', _DATA / 'golden_paper'))


def test_new_gain_keeps_the_recorded_behaviour():
    """Replay the recorded odometry and reference into a tracker with MY_GAINS: its commands
    must be the recorded ones (tighten or loosen atol to what 'the same' means for you)."""
    res = replay(MY_ROBOT_BAG, gains=MY_GAINS, atol=1e-9)
    assert res.comparison.equal, format_replay(res)


def test_recorded_run_meets_the_tracking_requirements():
    """Metrics of the recorded run (real-time bags also get timing)."""
    rep = bag_report(MY_ROBOT_BAG, plots=False, tolerance=0.05)
    assert rep.metrics is not None, rep.notes
    assert rep.metrics.final_error < 0.05                 # m
    assert rep.metrics.peak_abs_v <= 1.0                  # m/s, the robot's limit
    if rep.mode == 'realtime':
        assert rep.timing.missing_commands == 0, rep.timing
        assert rep.timing.latency_p95 < 0.02              # s


@pytest.mark.ros
def test_my_scenario_reproduces_its_golden_bag(tmp_path):
    """Re-run MY_SCENARIO through the nodes (lockstep, 2.5 s) and compare with MY_GOLDEN:
    positions within 1 um, everything else within 1e-9."""
    new = run_scenario(scenario_from_file(MY_SCENARIO, MY_GAINS), tmp_path / 'run')
    cmp = compare_bags(MY_GOLDEN, new, tolerances=['*.pose.pose.position=1e-6'])
    assert cmp.equal, format_differences(cmp)
