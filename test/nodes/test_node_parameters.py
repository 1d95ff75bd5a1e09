"""Node parameters: start-up refusal with exit code 2, runtime sets validated, old value kept."""
import subprocess
import sys

import pytest
import rclpy
from rclpy.parameter import Parameter

from nonfragile_tracker.nodes.common import StartupError
from nonfragile_tracker.nodes.plant import PlantNode
from nonfragile_tracker.nodes.reference import ReferenceNode
from nonfragile_tracker.nodes.tracker import TrackerNode

K_NF = [-4.4453, -4.8047, -1.4766, -1.5234, -1.4766, -1.5234, -4.4453, -4.8047]


@pytest.fixture(scope='module')
def context():
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=231)
    yield ctx
    rclpy.try_shutdown(context=ctx)


def make_tracker(context, **params):
    values = {'K': K_NF, **params}
    return TrackerNode(context=context,
                       parameter_overrides=[Parameter(k, value=v) for k, v in values.items()])


def test_runtime_gain_set_is_validated(context):
    node = make_tracker(context, F=[0.5] * 8)       # the paper's F (code default: zeros)
    try:
        old = node.tracker.config.K
        bad = [
            ([1.0] * 7, 'has 7 entries; a 2x4 gain needs 8'),
            ([float('nan')] + K_NF[1:], 'K[0][0] is nan'),
            ([1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0], 'does not stabilize the nominal loop'),
        ]
        for value, reason in bad:
            res = node.set_parameters([Parameter('K', value=value)])[0]
            assert not res.successful and reason in res.reason and 'keeping the old value' in res.reason
            assert node.tracker.config.K == old
        res = node.set_parameters([Parameter('K', value=[1, 0, 0, 0, 0, 0, 0, 0])])[0]
        assert not res.successful and node.tracker.config.K == old
        res = node.set_parameters([Parameter('max_angular_speed', value=-1.0)])[0]
        assert not res.successful
        new = [2 * k for k in K_NF]
        res = node.set_parameters([Parameter('K', value=new)])[0]
        assert res.successful
        assert node.tracker.config.K[0][0] == pytest.approx(2 * K_NF[0])
        res = node.set_parameters([Parameter('Delta', value=[1.0, 0.0, 0.0, 1.0])])[0]
        assert res.successful
        assert node.tracker.config.K_effective[0][0] == pytest.approx(2 * K_NF[0] + 0.5)
    finally:
        node.destroy_node()


@pytest.mark.parametrize('params, message', [
    ({'K': [1.0] * 6}, 'has 6 entries'),
    ({'K': [1.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 1.0]}, 'does not stabilize'),
    ({'mode': 'turbo'}, "parameter mode is 'turbo'"),
    ({'min_speed': 2.0}, 'min_speed (2.0) must be below max_linear_speed'),
    ({'E': [1.0, 0.0]}, 'E needs 4 doubles'),
])
def test_tracker_refuses_to_start(context, params, message):
    with pytest.raises(StartupError, match=message.replace('(', r'\(').replace(')', r'\)')):
        make_tracker(context, **params)


def test_plant_and_reference_refuse_bad_values(context):
    with pytest.raises(StartupError, match='A_tau needs 16 doubles'):
        PlantNode(context=context, parameter_overrides=[Parameter('A_tau', value=[0.0] * 4)])
    with pytest.raises(StartupError, match="unknown path 'square'"):
        ReferenceNode(context=context, parameter_overrides=[Parameter('path', value='square')])


def test_processes_exit_2_with_a_clear_message(tmp_path, ros_env):
    bad = tmp_path / 'gains.yaml'
    bad.write_text('tracker:\n  ros__parameters:\n    K: [1, 0, 0, 0, 0, 0, 0, 0]\n')
    cases = [
        (['nonfragile_tracker.nodes.tracker', '--ros-args', '--params-file', str(bad)],
         'Write doubles as 1.0, not 1'),
        (['nonfragile_tracker.nodes.tracker'], 'parameter K is not set'),
        (['nonfragile_tracker.nodes.plant', '--ros-args', '-p', 'dt:=-1.0'], 'dt'),
    ]
    for args, text in cases:
        out = subprocess.run([sys.executable, '-m', *args], capture_output=True, text=True,
                             env=ros_env, timeout=60)
        assert out.returncode == 2, (args, out.stderr)
        assert text in out.stderr and 'Traceback' not in out.stderr


def test_plant_rounds_a_delay_that_is_not_a_multiple_of_the_step(context):
    node = PlantNode(context=context, parameter_overrides=[Parameter('tau', value=0.2049),
                                                           Parameter('dt', value=0.01)])
    try:
        assert node.plant.N == 20                       # effective delay 0.2 s (logged)
        assert node.plant.N * node.dt == pytest.approx(0.2)
    finally:
        node.destroy_node()


def test_zero_or_negative_limits_refuse_to_start(context):
    from rclpy.exceptions import InvalidParameterValueException
    with pytest.raises(InvalidParameterValueException):
        make_tracker(context, max_linear_speed=0.0)
