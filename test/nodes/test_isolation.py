"""No hidden global state: a run's ROS domain is reserved for it (ids ROS calls safe on Linux,
never shared by concurrent runs), a composed run leaves this process's environment as it was,
and a programming error in a node's start-up is not reported as a bad parameter."""
import os

import pytest
import rclpy

from nonfragile_tracker.errors import InputError
from nonfragile_tracker.nodes.common import AdapterNode, Param
from nonfragile_tracker.nodes.errors import StartupError
from nonfragile_tracker.workflows.runner import reserved_domain, run_composed, scenario_parameters

from conftest import CONFIG, unique_domain_id


def test_a_run_reserves_a_safe_domain_of_its_own(monkeypatch):
    monkeypatch.delenv('ROS_DOMAIN_ID', raising=False)
    with reserved_domain() as a, reserved_domain() as b:
        ids = int(a['ROS_DOMAIN_ID']), int(b['ROS_DOMAIN_ID'])
        assert ids[0] != ids[1]                          # concurrent runs never share one
        assert all(1 <= i <= 100 for i in ids)           # within ROS's safe range on Linux
        assert 'ROS_DOMAIN_ID' not in os.environ         # and the caller's env is untouched
    with reserved_domain() as c:                         # freed at the end of the block
        assert int(c['ROS_DOMAIN_ID']) in ids
    with reserved_domain({'ROS_DOMAIN_ID': '42'}) as d:  # a domain set by the caller is kept
        assert d['ROS_DOMAIN_ID'] == '42'


def test_a_composed_run_leaves_the_environment_as_it_was(monkeypatch):
    monkeypatch.setenv('ROS_DOMAIN_ID', str(unique_domain_id('composed-env')))
    monkeypatch.delenv('ROS_AUTOMATIC_DISCOVERY_RANGE', raising=False)
    before = dict(os.environ)
    params = scenario_parameters(CONFIG / 'paper_scenario.yaml', CONFIG / 'tracker_gains.yaml',
                                 {'plant': {'ros__parameters': {'duration': 0.5}}})
    res = run_composed(params, None, record=False)
    assert res.exit_codes['plant'] == 0
    assert dict(os.environ) == before


class _Node(AdapterNode[dict]):
    def __init__(self, configure, **kw):
        super().__init__('isolation_probe', **kw)
        self.config = self.bind_parameters([Param('x', 1.0, 'a value')], configure)


def _bad_input(values):
    raise InputError('x must be positive')


def _bug(values):
    raise ValueError('a bug: math domain error')


def test_a_programming_error_at_start_up_is_not_a_bad_parameter():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('isolation'))
    try:
        with pytest.raises(StartupError, match='x must be positive'):
            _Node(_bad_input, context=ctx)
        with pytest.raises(ValueError, match='a bug') as err:
            _Node(_bug, context=ctx)
        assert not isinstance(err.value, StartupError)   # it keeps its traceback (exit 1)
    finally:
        rclpy.try_shutdown(context=ctx)
