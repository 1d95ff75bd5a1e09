"""Launch files (launch/launch_ros are not installable here): they compile, declare the
arguments a ROS user expects, use every argument they declare and only those, and
the RViz configuration they start is installed."""
import ast

import pytest
import yaml

from conftest import ROOT

LAUNCH = ROOT / 'launch'


def calls(tree, name):
    return [n for n in ast.walk(tree) if isinstance(n, ast.Call)
            and getattr(n.func, 'id', getattr(n.func, 'attr', None)) == name]


def first_str(call):
    return call.args[0].value if call.args and isinstance(call.args[0], ast.Constant) else None


def arguments(path):
    src = path.read_text()
    tree = ast.parse(src)
    compile(src, str(path), 'exec')
    declared = {first_str(c) for c in calls(tree, 'DeclareLaunchArgument')}
    used = {first_str(c) for c in calls(tree, 'LaunchConfiguration')}
    return tree, declared, used


@pytest.mark.parametrize('name,expected', [
    ('tracking.launch.py', {'mode', 'record', 'record_all', 'bag', 'namespace', 'gains',
                            'scenario',
                            'trajectory', 'enable_stamped_cmd_vel', 'rviz'}),
    ('robot.launch.py', {'cmd_vel', 'odom', 'namespace', 'gains', 'scenario', 'trajectory',
                         'trajectory_topic', 'enable_stamped_cmd_vel', 'odom_frame',
                         'base_frame', 'use_sim_time'}),
    ('bringup.launch.py', {'robot', 'box', 'accel_segment', 'out'}),
])
def test_launch_arguments(name, expected):
    tree, declared, used = arguments(LAUNCH / name)
    assert declared == expected
    assert used == declared                       # nothing declared and unused, or undeclared
    funcs = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert 'generate_launch_description' in funcs


def test_tracking_launch_modes_and_nodes():
    tree, _, _ = arguments(LAUNCH / 'tracking.launch.py')
    decl = {first_str(c): c for c in calls(tree, 'DeclareLaunchArgument')}
    choices = {kw.arg: ast.literal_eval(kw.value) for kw in decl['mode'].keywords
               if kw.arg in ('choices', 'default_value')}
    assert choices == {'choices': ['lockstep', 'realtime'], 'default_value': 'lockstep'}
    exes = {kw.value.value for c in calls(tree, 'Node') for kw in c.keywords
            if kw.arg == 'executable'}
    assert exes == {'reference', 'tracker', 'plant', 'recorder', 'rviz2'}
    assert calls(tree, 'PushRosNamespace')
    # the launch ends when the run is complete: on the plant's exit, or the recorder's
    # (bag closed) when recording in lockstep - one handler each, on one condition
    handlers = calls(tree, 'RegisterEventHandler')
    targets = sorted(kw.value.id for h in handlers for c in calls(h, 'OnProcessExit')
                     for kw in c.keywords if kw.arg == 'target_action')
    conditions = sorted(kw.value.func.id for h in handlers for kw in h.keywords
                        if kw.arg == 'condition')
    assert targets == ['plant', 'recorder'] and conditions == ['IfCondition', 'UnlessCondition']
    assert {kw.value.args[0].id for h in handlers for kw in h.keywords
            if kw.arg == 'condition'} == {'lockstep_recording'}
    assert all(calls(h, 'Shutdown') for h in handlers)


def test_tracking_launch_gates_the_start_on_the_recorder_in_both_modes():
    """The handshake of runner.lockstep_handshake/realtime_handshake: the recorder announces
    its matched subscriptions (lockstep_gate, in both modes) and the plant waits for it
    (lockstep_recorder in lockstep, realtime_recorder in real time) when recording."""
    from nonfragile_tracker.runner import realtime_handshake
    text = (LAUNCH / 'tracking.launch.py').read_text()
    hand = realtime_handshake(True)
    assert hand['plant']['realtime_recorder'] and hand['recorder']['lockstep_gate']
    assert "'realtime_recorder': ParameterValue(realtime_recording, value_type=bool)" in text
    assert "'lockstep_gate': True}" in text
    assert '''realtime_recording = PythonExpression(["'", record, "' == 'true' and '", mode,
                                           "' == 'realtime'"])''' in text


def test_robot_launch_starts_tracker_and_reference_with_remappable_topics():
    tree, _, _ = arguments(LAUNCH / 'robot.launch.py')
    exes = {kw.value.value for c in calls(tree, 'Node') for kw in c.keywords
            if kw.arg == 'executable'}
    assert exes == {'reference', 'tracker'}
    remaps = [t for t in ast.walk(tree) if isinstance(t, ast.Tuple) and len(t.elts) == 2
              and isinstance(t.elts[0], ast.Constant) and t.elts[0].value in ('cmd_vel', 'odom')]
    assert {t.elts[0].value for t in remaps} == {'cmd_vel', 'odom'}


def test_bringup_launch_runs_the_cli_command():
    """The launch file is the CLI's ``bringup`` (one implementation, its safety included),
    with ``--accel-segment`` only when asked."""
    tree, _, _ = arguments(LAUNCH / 'bringup.launch.py')
    runs = calls(tree, 'ExecuteProcess')
    assert len(runs) == 2
    text = (LAUNCH / 'bringup.launch.py').read_text()
    assert "'nonfragile_tracker', 'nonfragile_tracker', 'bringup'" in text
    assert sorted(kw.value.func.id for c in runs for kw in c.keywords
                  if kw.arg == 'condition') == ['IfCondition', 'UnlessCondition']


def test_rviz_config_is_installed_and_shows_the_topics():
    cfg = yaml.safe_load((ROOT / 'rviz' / 'tracking.rviz').read_text())
    vm = cfg['Visualization Manager']
    assert vm['Global Options']['Fixed Frame'] == 'odom'
    topics = {d['Topic']['Value'] for d in vm['Displays'] if 'Topic' in d}
    assert topics == {'reference/path', 'tracker/path', 'odom', 'tracker/reference_marker'}
    setup = (ROOT / 'setup.py').read_text()
    assert "'/rviz', glob('rviz/*.rviz')" in setup
    assert "'/config/trajectories', glob('config/trajectories/*')" in setup
