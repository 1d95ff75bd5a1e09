"""Launch files (launch/launch_ros are not installable here): they compile, declare the
arguments a ROS user expects, use every argument they declare and only those, and
the RViz configuration they start is installed."""
import ast
import sys

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
    ('robot.launch.py', {'robot', 'gains', 'trajectory', 'trajectory_topic', 'namespace',
                         'use_sim_time', 'autostart', 'nav2'}),
    ('bringup.launch.py', {'robot', 'box', 'accel_segment', 'out', 'truth'}),
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
    from nonfragile_tracker.workflows.runner import realtime_handshake
    text = (LAUNCH / 'tracking.launch.py').read_text()
    hand = realtime_handshake(True)
    assert hand['plant']['realtime_recorder'] and hand['recorder']['lockstep_gate']
    assert "'realtime_recorder': ParameterValue(realtime_recording, value_type=bool)" in text
    assert "'lockstep_gate': True}" in text
    assert '''realtime_recording = PythonExpression(["'", record, "' == 'true' and '", mode,
                                           "' == 'realtime'"])''' in text


class _Action:
    """Stand-in for a launch / launch_ros class: keeps what it was made with."""

    def __init__(self, *args, **kwargs):
        self.args, self.kwargs = args, kwargs


class _LaunchConfiguration(_Action):
    def perform(self, context):
        return context[self.args[0]]


def _stub_launch(monkeypatch):
    """launch, launch_ros and ament_index as stand-ins (not installable here): enough to run
    a launch file's Python and see the nodes and parameters it makes."""
    import types
    names = {'launch': {'LaunchDescription': _Action},
             'launch.actions': {n: _Action for n in ('DeclareLaunchArgument', 'GroupAction',
                                                     'OpaqueFunction')},
             'launch.substitutions': {'LaunchConfiguration': _LaunchConfiguration},
             'launch_ros': {}, 'launch_ros.actions': {'Node': _Action, 'PushRosNamespace': _Action},
             'ament_index_python': {},
             'ament_index_python.packages': {'get_package_share_directory': lambda _: str(ROOT)}}
    for name, attrs in names.items():
        monkeypatch.setitem(sys.modules, name, types.SimpleNamespace(**attrs))


def robot_launch(monkeypatch, **arguments):
    """Run robot.launch.py with the stand-ins: (tracker Node, reference Node or None)."""
    import runpy
    _stub_launch(monkeypatch)
    desc = runpy.run_path(str(LAUNCH / 'robot.launch.py'))['generate_launch_description']()
    actions = desc.args[0]
    context = {a.args[0]: a.kwargs['default_value'] for a in actions
               if 'default_value' in a.kwargs}
    context.update(arguments)
    opaque = [a for a in actions if 'function' in a.kwargs]
    assert len(opaque) == 1
    (group,) = opaque[0].kwargs['function'](context)
    made = {a.kwargs.get('executable'): a for a in group.args[0] if 'executable' in a.kwargs}
    assert set(made) <= {'tracker', 'reference'}
    return made['tracker'], made.get('reference')


def test_robot_launch_gives_the_tracker_the_robot_file_and_no_paper_scenario(monkeypatch):
    from nonfragile_tracker.interface.robot import load_robot_file
    tree = ast.parse((LAUNCH / 'robot.launch.py').read_text())
    doc = ast.get_docstring(tree, clean=False)
    strings = [n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
               and isinstance(n.value, str) and n.value != doc]
    assert 'robot.yaml' in strings and not [t for t in strings if 'paper' in t or 'scenario' in t]
    tracker, reference = robot_launch(monkeypatch)
    assert reference is None                      # no trajectory source: the tracker waits
    robot, gains, own = tracker.kwargs['parameters']
    assert robot == load_robot_file(ROOT / 'config' / 'robot.yaml').parameters()
    assert gains.args == ('gains',)               # the gain file, after the robot file
    assert own == {'mode': 'realtime', 'use_sim_time': False, 'wait_for_trajectory': True}
    assert 'remappings' not in tracker.kwargs     # the topics are the robot file's
    # nothing of the paper's simulation reaches a robot launch
    sim = yaml.safe_load((ROOT / 'config' / 'paper_scenario.yaml').read_text())
    sim_only = {k for sec in sim.values() for k in sec['ros__parameters']} - set(robot) - {
        'mode', 'max_linear_speed', 'max_angular_speed'}
    assert {'tau', 'A_tau', 'E', 'F', 'radius', 'rate', 'path', 'dt', 'min_speed'} <= sim_only
    assert not sim_only & (set(robot) | set(own))


def test_robot_launch_with_a_users_robot_file_and_a_trajectory(monkeypatch, tmp_path):
    from nonfragile_tracker.interface.robot import RobotFileError
    mine = tmp_path / 'my_robot.yaml'
    mine.write_text('/**/tracker:\n  ros__parameters:\n    odom_frame: world\n'
                    '    odom_topic: /diff_drive_controller/odom\n')
    tracker, reference = robot_launch(monkeypatch, robot=str(mine), trajectory='lap.csv',
                                      use_sim_time='true')
    robot, _, own = tracker.kwargs['parameters']
    assert robot['odom_frame'] == 'world' and robot['odom_topic'] == '/diff_drive_controller/odom'
    assert robot['cmd_vel_topic'] == 'cmd_vel' and own['use_sim_time'] is True
    assert reference.kwargs['parameters'] == [{
        'mode': 'realtime', 'use_sim_time': True, 'odom_frame': 'world',
        'trajectory_file': 'lap.csv', 'trajectory_topic': ''}]
    _, reference = robot_launch(monkeypatch, robot=str(mine), trajectory_topic='/plan')
    assert reference.kwargs['parameters'][0]['trajectory_topic'] == '/plan'
    mine.write_text('/**/tracker:\n  ros__parameters:\n    max_linear_speed: 1\n')
    with pytest.raises(RobotFileError, match='max_linear_speed is 1: write 1.0'):
        robot_launch(monkeypatch, robot=str(mine))


def test_robot_launch_in_a_nav2_system(monkeypatch):
    """nav2:=true: cmd_vel -> cmd_vel_nav (collision_monitor), trajectory -> Nav2's plan,
    overrides watched; autostart:=false leaves the bring-up to a lifecycle manager."""
    tracker, reference = robot_launch(monkeypatch, nav2='true', autostart='false')
    assert reference is None
    assert tracker.kwargs['remappings'] == [('cmd_vel', 'cmd_vel_nav'), ('trajectory', 'plan')]
    own = tracker.kwargs['parameters'][2]
    assert own['autostart'] is False and own['override_tolerance'] == 0.1
    tracker, _ = robot_launch(monkeypatch, nav2='true')
    assert 'autostart' not in tracker.kwargs['parameters'][2]    # the default: at once


def test_bringup_launch_runs_the_cli_command():
    """The launch file is the CLI's ``bringup`` (one implementation, its safety included),
    with ``--no-accel-segment`` only when asked."""
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
