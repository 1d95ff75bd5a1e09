"""Launch the tracking scenario: reference, plant and tracker (+ recorder, RViz optional).

    ros2 launch nonfragile_tracker tracking.launch.py
    ros2 launch nonfragile_tracker tracking.launch.py mode:=realtime record:=true bag:=runs/rt
    ros2 launch nonfragile_tracker tracking.launch.py trajectory:=/path/lap.csv \\
        namespace:=robot1 enable_stamped_cmd_vel:=true gains:=/path/to/gains.yaml

Arguments: mode (lockstep|realtime), record (true|false) and bag (directory to create),
record_all (true|false: in lockstep record every topic instead of the lean set - odom,
cmd_vel, run_done and the trajectory messages; real time always records every topic),
namespace, gains, scenario, trajectory (waypoint file; "" = the scenario's path),
enable_stamped_cmd_vel (true|false), rviz (true|false).  Standard launch/launch_ros API
(Jazzy).  In lockstep the plant publishes the global /clock: one lockstep system per
ROS domain (namespaces separate real-time systems).  The launch ends by itself when the
run is complete: when the plant exits (its ``duration``; a real-time recorder then
closes its bag on the shutdown's SIGINT), or in lockstep with ``record:=true`` when the
recorder has drained and closed the bag; Ctrl-C ends it earlier.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, GroupAction, RegisterEventHandler
from launch.conditions import IfCondition, UnlessCondition
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node, PushRosNamespace
from launch_ros.parameter_descriptions import ParameterValue

from nonfragile_tracker.interface.topics import LEAN_TOPICS, TYPES


def generate_launch_description():
    share = get_package_share_directory('nonfragile_tracker')
    config = os.path.join(share, 'config')
    mode = LaunchConfiguration('mode')
    record = LaunchConfiguration('record')
    scenario = LaunchConfiguration('scenario')
    gains = LaunchConfiguration('gains')
    trajectory = LaunchConfiguration('trajectory')
    stamped = LaunchConfiguration('enable_stamped_cmd_vel')
    lockstep = PythonExpression(["'", mode, "' == 'lockstep'"])
    # with a recorder every lockstep publisher waits for it too (runner.lockstep_handshake)
    subscribers = ParameterValue(PythonExpression(["2 if '", record, "' == 'true' else 0"]),
                                 value_type=int)
    lockstep_recording = PythonExpression(["'", record, "' == 'true' and '", mode,
                                           "' == 'lockstep'"])
    # real time with a recorder: the plant starts stepping once the recorder has announced
    # that its subscriptions matched (runner.realtime_handshake), so the bag has it all
    realtime_recording = PythonExpression(["'", record, "' == 'true' and '", mode,
                                           "' == 'realtime'"])
    # the tracker follows the trajectory message (in lockstep the reference publishes the
    # built-in path as one too); the reference's per-step samples have one subscriber to
    # wait for, the recorder
    follow_only = PythonExpression(["'", mode, "' == 'lockstep' or '", trajectory, "' != ''"])
    ref_subscribers = ParameterValue(PythonExpression(["1 if '", record, "' == 'true' else 0"]),
                                     value_type=int)
    # lockstep records the lean set unless record_all (runner.recorded_topics); the
    # reference publishes its per-step samples there only when they are recorded
    record_all = LaunchConfiguration('record_all')
    full = PythonExpression(["'", mode, "' == 'realtime' or '", record_all, "' == 'true'"])
    recorded = PythonExpression([f"{list(TYPES)!r} if ", full, f" else {list(LEAN_TOPICS)!r}"])
    samples = ParameterValue(PythonExpression(["'", mode, "' == 'realtime' or ('", record,
                                               "' == 'true' and '", record_all,
                                               "' == 'true')"]), value_type=bool)
    common = {'mode': ParameterValue(mode, value_type=str)}
    cmd = {'enable_stamped_cmd_vel': ParameterValue(stamped, value_type=bool)}
    plant = Node(package='nonfragile_tracker', executable='plant', name='plant',
                 parameters=[scenario, common, cmd, {
                     'lockstep_subscribers': ParameterValue(PythonExpression(
                         ["2 if '", record, "' == 'true' else 1"]), value_type=int),
                     'lockstep_recorder': ParameterValue(record, value_type=bool),
                     'realtime_recorder': ParameterValue(realtime_recording, value_type=bool)}],
                 output='screen')
    recorder = Node(package='nonfragile_tracker', executable='recorder', name='recorder',
                    condition=IfCondition(record),
                    parameters=[cmd, {'output': ParameterValue(LaunchConfiguration('bag'),
                                                               value_type=str),
                                      'use_sim_time': ParameterValue(lockstep, value_type=bool),
                                      'topics': recorded,
                                      'lockstep_gate': True}],          # in both modes
                    output='screen')
    return LaunchDescription([
        DeclareLaunchArgument('mode', default_value='lockstep', choices=['lockstep', 'realtime'],
                              description='lockstep (deterministic, sim time) or realtime'),
        DeclareLaunchArgument('record', default_value='false', choices=['true', 'false'],
                              description='record a rosbag2 (MCAP) bag with the recorder node'),
        DeclareLaunchArgument('record_all', default_value='false', choices=['true', 'false'],
                              description='lockstep: record every topic (also /clock, pose and '
                              'the reference samples) instead of odom, cmd_vel, run_done and '
                              'the trajectory messages'),
        DeclareLaunchArgument('bag', default_value='nonfragile_bag',
                              description='bag directory to create when record:=true'),
        DeclareLaunchArgument('namespace', default_value='',
                              description='namespace of all nodes and topics'),
        DeclareLaunchArgument('scenario', default_value=os.path.join(config, 'paper_scenario.yaml'),
                              description='parameter file of the three nodes'),
        DeclareLaunchArgument('gains', default_value=os.path.join(config, 'tracker_gains.yaml'),
                              description='tracker gain file (default: certified for command '
                              'latency up to 0.15 s through a 50 ms lag; after the bring-up '
                              'the file latency-design wrote for your base)'),
        DeclareLaunchArgument('trajectory', default_value='',
                              description='waypoint file (CSV/YAML: t, x, y[, yaw][, speed]) '
                              'to follow; "" = the path of the scenario'),
        DeclareLaunchArgument('enable_stamped_cmd_vel', default_value='false',
                              choices=['true', 'false'],
                              description='cmd_vel as TwistStamped (Nav2 name) instead of Twist'),
        DeclareLaunchArgument('rviz', default_value='false', choices=['true', 'false'],
                              description='start RViz2 with the package configuration'),
        GroupAction([
            PushRosNamespace(LaunchConfiguration('namespace')),
            Node(package='nonfragile_tracker', executable='reference', name='reference',
                 parameters=[scenario, common, {
                     'trajectory_file': ParameterValue(trajectory, value_type=str),
                     'publish_samples': samples,
                     'lockstep_subscribers': ref_subscribers}],
                 output='screen'),
            Node(package='nonfragile_tracker', executable='tracker', name='tracker',
                 parameters=[scenario, gains, common, cmd, {
                     'wait_for_trajectory': ParameterValue(follow_only, value_type=bool),
                     'lockstep_subscribers': subscribers}],
                 output='screen'),
            plant,
            recorder,
            Node(package='rviz2', executable='rviz2', name='rviz2',
                 condition=IfCondition(LaunchConfiguration('rviz')),
                 arguments=['-d', os.path.join(share, 'rviz', 'tracking.rviz')]),
            # the run is complete: end the launch (the reference and tracker would idle on)
            # (a lockstep recorder drains and closes the bag itself after run_done: wait for
            # it; in real time the shutdown's SIGINT closes the bag)
            RegisterEventHandler(OnProcessExit(target_action=plant, on_exit=[EmitEvent(
                event=Shutdown(reason='the plant has completed its run'))]),
                condition=UnlessCondition(lockstep_recording)),
            RegisterEventHandler(OnProcessExit(target_action=recorder, on_exit=[EmitEvent(
                event=Shutdown(reason='the recorder has closed the bag'))]),
                condition=IfCondition(lockstep_recording)),
        ]),
    ])
