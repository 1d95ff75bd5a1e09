"""The documented user regression example runs and its checks bite."""
from __future__ import annotations

import importlib.util

import pytest

from conftest import ROOT, unique_domain_id


def _example():
    spec = importlib.util.spec_from_file_location(
        'user_regression_example', ROOT / 'doc' / 'user_regression_example.py')
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_example_without_ros_passes_and_fails_on_another_gain(tmp_path):
    ex = _example()
    ex.test_new_gain_keeps_the_recorded_behaviour()
    ex.test_recorded_run_meets_the_tracking_requirements()
    # a different gain must make the replay test fail, with the diff in the message
    from nonfragile_tracker.control.simulation.gains import read_gain_file, write_gain_file
    write_gain_file(tmp_path / 'k11.yaml', read_gain_file(ex.MY_GAINS) * 1.1)
    ex.MY_GAINS = tmp_path / 'k11.yaml'
    # (the first command is the measured speed whatever the gain: they part at the second)
    with pytest.raises(AssertionError, match=r'(?s)commands differ:.*cmd_vel\[1\] linear.x'):
        ex.test_new_gain_keeps_the_recorded_behaviour()


@pytest.mark.ros
def test_example_with_ros(tmp_path, monkeypatch):
    monkeypatch.setenv('ROS_DOMAIN_ID', str(unique_domain_id('user_example')))
    ex = _example()
    ex.test_my_scenario_reproduces_its_golden_bag(tmp_path / 'a')
    # against another golden bag (Delta_2 injected) the same test fails with a diff
    ex.MY_GOLDEN = ex._DATA / 'golden_delta2'
    # a domain of its own: the first run's participants may linger in the graph for a while
    monkeypatch.setenv('ROS_DOMAIN_ID', str(unique_domain_id('user_example_b')))
    with pytest.raises(AssertionError, match=r'/cmd_vel\[1\] linear.x: expected'):
        ex.test_my_scenario_reproduces_its_golden_bag(tmp_path / 'b')
