"""Bring up the tracker on a new robot: ``nonfragile_tracker bringup`` from ``ros2 launch``.

    ros2 launch nonfragile_tracker bringup.launch.py robot:=robot.yaml box:=1.0

Drives a designed excitation within ``box`` m of the start pose, identifies the base,
designs a certified gain, verifies it in a short trial and writes the robot file, the gain
file and a report into a new folder under ``out`` (see the CLI's ``bringup``).  Ctrl-C
reaches the bring-up, which commands zero velocity and ends.
"""
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess
from launch.conditions import IfCondition, UnlessCondition
from launch.substitutions import LaunchConfiguration


def generate_launch_description():
    cmd = ['ros2', 'run', 'nonfragile_tracker', 'nonfragile_tracker', 'bringup',
           '--robot', LaunchConfiguration('robot'), '--box', LaunchConfiguration('box'),
           '--out', LaunchConfiguration('out'), '--truth', LaunchConfiguration('truth')]
    accel = LaunchConfiguration('accel_segment')
    return LaunchDescription([
        DeclareLaunchArgument('robot', default_value='',
                              description='robot file (topics, frames, Twist/TwistStamped, '
                              'limits); empty: odom, cmd_vel, Twist, no known limits'),
        DeclareLaunchArgument('box', default_value='1.0',
                              description='stay within this distance of the start pose (m)'),
        DeclareLaunchArgument('accel_segment', default_value='true',
                              choices=['true', 'false'],
                              description='allow steps faster than the base follows (its '
                              'acceleration limits are identified)'),
        DeclareLaunchArgument('truth', default_value='',
                              description='an external pose of the base (PoseStamped: motion '
                              'capture) recorded beside the odometry; its side slip is '
                              'identified and compensated; empty: none'),
        DeclareLaunchArgument('out', default_value='runs',
                              description='folder of the run folders'),
        ExecuteProcess(cmd=cmd + ['--accel-segment'], output='screen',
                       condition=IfCondition(accel)),
        ExecuteProcess(cmd=cmd + ['--no-accel-segment'], output='screen',
                       condition=UnlessCondition(accel)),
    ])
