"""The robot file (issue 30, item 2): the shipped config/robot.yaml, its loader and writer
(nonfragile_tracker.interface.robot), the tracker taking its topics from it, and the docs including
the very file the tests load - so that the file, the docs and the code cannot drift."""
from __future__ import annotations

import re

import pytest
import yaml

from conftest import ROOT
from nonfragile_tracker.errors import InputError
from nonfragile_tracker.interface.robot import (KEYS, RobotConfig, RobotFileError, identified_limits,
                                      load_robot_file, robot_file, update_robot_file)

SHIPPED = ROOT / 'config' / 'robot.yaml'


def test_the_shipped_file_is_the_one_the_loader_finds_and_holds_every_key():
    assert robot_file() == SHIPPED
    cfg = load_robot_file()
    assert cfg.source == str(SHIPPED)
    params = yaml.safe_load(SHIPPED.read_text())['/**/tracker']['ros__parameters']
    assert list(params) == [k.name for k in KEYS]        # complete, in the documented order
    assert cfg.parameters() == params
    assert cfg.enable_stamped_cmd_vel is True             # Jazzy diff_drive_controller
    assert (cfg.max_linear_accel, cfg.max_angular_accel, cfg.min_turning_radius) == (0, 0, 0)
    # commented line by line: every key's line says what it is
    for line in SHIPPED.read_text().splitlines():
        if re.match(r'^    \w+:', line):
            assert '#' in line, line
    # a key that means "unknown" / "none" at 0 says so in its comment
    text = SHIPPED.read_text()
    for k in KEYS:
        if k.zero:
            assert re.search(rf'^    {k.name}: .*# .*0 = {k.zero}', text, re.MULTILINE), k.name


def test_no_paper_simulation_parameter_in_the_robot_file():
    params = yaml.safe_load(SHIPPED.read_text())['/**/tracker']['ros__parameters']
    paper = yaml.safe_load((ROOT / 'config' / 'paper_scenario.yaml').read_text())
    sim_only = set(paper['/**/tracker']['ros__parameters']) - {k.name for k in KEYS}
    assert sim_only >= {'tau', 'A_tau', 'E', 'F', 'Delta', 'delay_compensation', 'dt'}
    assert not sim_only & set(params)
    assert 'dt' not in params                  # the step comes from the odometry (issue 30)


@pytest.mark.ros
def test_every_key_is_a_declared_tracker_parameter_with_its_default_and_range():
    from nonfragile_tracker.nodes.tracker import PARAMS
    declared = {p.name: p for p in PARAMS}
    assert RobotConfig().parameters() == {k.name: k.default for k in KEYS}
    for k in KEYS:
        assert k.name in declared, k.name
        p = declared[k.name]
        assert p.default == k.default and type(p.default) is k.kind, k.name
        if k.kind is float:
            assert (p.low, p.high) == (k.low, k.high), k.name


def test_the_docs_include_the_very_file_the_tests_load():
    page = (ROOT / 'doc' / 'ros-interface.md').read_text()
    assert '```{literalinclude} ../config/robot.yaml\n:language: yaml\n```' in page
    readme = (ROOT / 'README.md').read_text()
    section = readme.split('\n## In a ROS 2 system\n', 1)[1].split('\n## ', 1)[0]
    assert '[config/robot.yaml](config/robot.yaml)' in section      # linked, not copied
    assert 'robot.launch.py robot:=my_robot.yaml gains:=g.yaml' in section


def write(tmp_path, text: str, name: str = 'robot.yaml'):
    p = tmp_path / name
    p.write_text(text)
    return p


def section(**params) -> str:
    return yaml.safe_dump({'/**/tracker': {'ros__parameters': params}})


@pytest.mark.parametrize('params, words', [
    ({'max_speed': 1.0}, 'unknown key(s) max_speed; a robot file knows odom_topic, '
     'cmd_vel_topic, enable_stamped_cmd_vel'),
    ({'dt': 0.02}, 'unknown key(s) dt'),
    ({'max_linear_speed': 1}, 'max_linear_speed is 1: write 1.0 (ROS refuses an integer'),
    ({'max_linear_accel': -1.0}, 'max_linear_accel is -1.0: it must be at least 0 and at '
     'most 1000 (|dv/dt| limit (m/s^2); 0 = unknown)'),
    ({'max_linear_speed': 0.0}, 'max_linear_speed is 0.0: it must be above 0'),
    ({'input_timeout': float('nan')}, 'input_timeout is nan'),
    ({'enable_stamped_cmd_vel': 'yes'}, "enable_stamped_cmd_vel is 'yes': write true or false"),
    ({'odom_topic': '/diff drive/odom'}, "odom_topic is '/diff drive/odom': a ROS 2 topic "
     'name is needed'),
    ({'cmd_vel_topic': '2cmd'}, "cmd_vel_topic is '2cmd'"),
    ({'base_frame': '/base_link'}, "base_frame is '/base_link': a tf2 frame id is needed "
     '(no leading /'),
    ({'max_angular_speed': '2.0'}, "max_angular_speed is '2.0': a number is needed"),
])
def test_bad_values_are_refused_naming_the_key_and_what_to_write(tmp_path, params, words):
    p = write(tmp_path, section(**params))
    with pytest.raises(RobotFileError) as exc:
        load_robot_file(p)
    assert str(exc.value).startswith(f'{p}: ') and words in str(exc.value), str(exc.value)
    assert isinstance(exc.value, InputError)          # exit code 2 through the CLI


@pytest.mark.parametrize('text, words', [
    ('tracker: {ros__parameters: {}}\nreference: {ros__parameters: {}}\n',
     'section(s) reference not allowed: a robot file has one section'),
    ('/**/tracker: {max_linear_speed: 1.0}\n', 'must hold ros__parameters'),
    ('- 1\n', 'expected a YAML mapping (robot file), got a list'),
    ('/**/tracker: {ros__parameters: [1]}\n', 'must hold ros__parameters'),
    ('a: [\n', 'not valid YAML'),
])
def test_bad_layouts_are_refused(tmp_path, text, words):
    with pytest.raises(RobotFileError, match=re.escape(words)):
        load_robot_file(write(tmp_path, text))


def test_missing_file_and_partial_files(tmp_path):
    with pytest.raises(RobotFileError, match='cannot read robot file'):
        load_robot_file(tmp_path / 'none.yaml')
    # a key left out takes the tracker's default; /tracker and tracker are the same node
    for key in ('tracker', '/tracker', '/**/tracker', '/robot1/tracker'):
        p = write(tmp_path, yaml.safe_dump({key: {'ros__parameters': {
            'odom_topic': '/diff_drive_controller/odom', 'max_linear_accel': 0.8}}}))
        cfg = load_robot_file(p)
        assert cfg == RobotConfig(odom_topic='/diff_drive_controller/odom',
                                  max_linear_accel=0.8, source=str(p))
        assert cfg.parameters()['max_angular_speed'] == 2.0
        assert cfg.parameters()['enable_stamped_cmd_vel'] is False


def test_update_keeps_every_other_line_and_comment(tmp_path):
    p = tmp_path / 'my_robot.yaml'
    changes = update_robot_file(p, {'max_linear_accel': 1.002, 'max_angular_accel': 3.0},
                                note='identified from runs/a/bag')
    assert [str(c) for c in changes] == ['max_linear_accel: 0.0 -> 1.002',
                                         'max_angular_accel: 0.0 -> 3.0']
    before, after = SHIPPED.read_text().splitlines(), p.read_text().splitlines()
    assert len(before) == len(after)
    differ = [(b, a) for b, a in zip(before, after) if b != a]
    assert len(differ) == 2
    for b, a in differ:
        assert a.startswith(b.split(':')[0]) and a.endswith('[identified from runs/a/bag]')
        assert b.split('#', 1)[1] in a                     # the comment kept
    cfg = load_robot_file(p)
    assert (cfg.max_linear_accel, cfg.max_angular_accel) == (1.002, 3.0)
    # a second identification replaces the value and the note, adds no second note
    changes = update_robot_file(p, {'max_linear_accel': 0.9, 'max_angular_accel': 3.0},
                                note='identified from runs/b/bag')
    assert [str(c) for c in changes] == ['max_linear_accel: 1.002 -> 0.9']
    line = [x for x in p.read_text().splitlines() if 'max_linear_accel:' in x][0]
    assert line.count('[') == 1 and line.endswith('[identified from runs/b/bag]')
    assert 'max_angular_accel: 3.0' in p.read_text() and 'runs/a/bag' in p.read_text()
    # only_unknown: a value the file knows stays, an unknown (0) one is filled in
    update_robot_file(p, {'max_angular_accel': 0.0}, note='by hand')
    changes = update_robot_file(p, {'max_linear_accel': 2.0, 'max_angular_accel': 2.0,
                                    'min_turning_radius': 0.5}, only_unknown=True)
    assert [str(c) for c in changes] == ['max_angular_accel: 0.0 -> 2.0',
                                         'min_turning_radius: 0.0 -> 0.5']
    assert load_robot_file(p).max_linear_accel == 0.9


def test_update_of_a_user_file_appends_a_missing_key_and_refuses_bad_input(tmp_path):
    p = write(tmp_path, '# my base\ntracker:\n  ros__parameters:\n'
                        '    odom_topic: /base/odom   # the driver\n')
    update_robot_file(p, {'max_angular_accel': 2.5}, note='identified')
    text = p.read_text()
    assert text.startswith('# my base\n') and '/base/odom   # the driver' in text
    assert load_robot_file(p).max_angular_accel == 2.5
    assert 'max_angular_accel: 2.5' in text and '[identified]' in text
    with pytest.raises(RobotFileError, match='max_linear_accel is -2.0'):
        update_robot_file(p, {'max_linear_accel': -2.0})
    with pytest.raises(RobotFileError, match='unknown key'):
        update_robot_file(p, {'tau': 0.2})
    assert p.read_text() == text                          # untouched on a refusal
    bad = write(tmp_path, section(max_speed=1.0), 'bad.yaml')
    with pytest.raises(RobotFileError, match='unknown key'):
        update_robot_file(bad, {'max_linear_accel': 1.0})
    assert [f.name for f in tmp_path.iterdir() if f.name.startswith('.')] == []


def test_identified_limits_only_where_the_recording_shows_them():
    from nonfragile_tracker.control.identification.identify import Identification
    base = Identification(0.1, 0.09, 0.11, 0.05, 0.04, 0.06, 0.05, 0.04, 0.06, 50.0, 1000,
                          1e-3, 1e-3)
    from dataclasses import replace
    assert identified_limits(base) == {}
    assert identified_limits(replace(base, max_linear_accel=1.00234)) == \
        {'max_linear_accel': 1.002}
    assert identified_limits(replace(base, max_linear_accel=1.0, max_angular_accel=3.0)) == \
        {'max_linear_accel': 1.0, 'max_angular_accel': 3.0}


@pytest.mark.ros
def test_the_tracker_takes_its_topics_from_the_robot_file_and_remapping_still_applies():
    import rclpy
    from rclpy.parameter import Parameter

    from conftest import unique_domain_id
    from nonfragile_tracker.nodes.common import StartupError
    from nonfragile_tracker.nodes.tracker import TrackerNode
    from nonfragile_tracker.interface.scenario import node_parameters
    gains = node_parameters('tracker', ROOT / 'config' / 'tracker_gains.yaml')
    robot = RobotConfig(odom_topic='/diff_drive_controller/odom',
                        cmd_vel_topic='/diff_drive_controller/cmd_vel',
                        enable_stamped_cmd_vel=True, max_linear_accel=1.0)
    ctx = rclpy.Context()
    rclpy.init(context=ctx, domain_id=unique_domain_id('robot_file'))

    def make(values, args=None):
        return TrackerNode(context=ctx, cli_args=args, parameter_overrides=[
            Parameter(k, value=v) for k, v in {**values, **gains}.items()])
    try:
        node = make({**robot.parameters(), 'mode': 'realtime'})
        try:
            subs = {s.topic_name for s in node.subscriptions}
            assert '/diff_drive_controller/odom' in subs and '/odom' not in subs
            assert node.pub_cmd.topic_name == '/diff_drive_controller/cmd_vel'
            assert type(node._cmd_msg).__name__ == 'TwistStamped'
            assert node.tracker.config.max_linear_accel == 1.0
        finally:
            node.destroy_node()
        node = make({}, ['--ros-args', '-r', 'odom:=/base/odom', '-r', 'cmd_vel:=/base/cmd'])
        try:                                   # defaults odom, cmd_vel: remapped as before
            assert '/base/odom' in {s.topic_name for s in node.subscriptions}
            assert node.pub_cmd.topic_name == '/base/cmd'
        finally:
            node.destroy_node()
        with pytest.raises(StartupError, match="odom_topic is 'odom//x'"):
            make({'odom_topic': 'odom//x'})
    finally:
        rclpy.try_shutdown(context=ctx)
