"""Track a trajectory on a real robot (or any simulator): tracker and reference only.

    ros2 launch nonfragile_tracker robot.launch.py trajectory:=/path/lap.csv \\
        cmd_vel:=/diff_drive_controller/cmd_vel odom:=/diff_drive_controller/odom \\
        enable_stamped_cmd_vel:=true

The robot's driver provides odometry (nav_msgs/Odometry in odom_frame) and takes
cmd_vel; both topics are remappable.  Real time (wall clock or the robot's clock with
use_sim_time).  Without a trajectory file the tracker follows a trajectory published
on the relay topic (e.g. a planner's nav_msgs/Path) or the scenario's path.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node, PushRosNamespace
from launch_ros.parameter_descriptions import ParameterValue


def generate_launch_description():
    config = os.path.join(get_package_share_directory('nonfragile_tracker'), 'config')
    trajectory = LaunchConfiguration('trajectory')
    relay = LaunchConfiguration('trajectory_topic')
    scenario = LaunchConfiguration('scenario')
    use_sim_time = ParameterValue(LaunchConfiguration('use_sim_time'), value_type=bool)
    frames = {'odom_frame': ParameterValue(LaunchConfiguration('odom_frame'), value_type=str)}
    own = PythonExpression(["'", trajectory, "' != '' or '", relay, "' != ''"])
    remap = [('cmd_vel', LaunchConfiguration('cmd_vel')), ('odom', LaunchConfiguration('odom'))]
    return LaunchDescription([
        DeclareLaunchArgument('cmd_vel', default_value='cmd_vel',
                              description='velocity command topic of the robot'),
        DeclareLaunchArgument('odom', default_value='odom',
                              description='odometry topic of the robot'),
        DeclareLaunchArgument('namespace', default_value='', description='namespace'),
        DeclareLaunchArgument('gains', default_value=os.path.join(config, 'tracker_gains.yaml'),
                              description='tracker gain file (default: certified for command '
                              'latency up to 0.15 s through a 50 ms lag; after the bring-up '
                              'the file latency-design wrote for your base)'),
        DeclareLaunchArgument('scenario', default_value=os.path.join(config, 'paper_scenario.yaml'),
                              description='parameter file (tracker and reference sections)'),
        DeclareLaunchArgument('trajectory', default_value='',
                              description='waypoint file to follow (CSV/YAML)'),
        DeclareLaunchArgument('trajectory_topic', default_value='',
                              description='relay nav_msgs/Path trajectories from this topic'),
        DeclareLaunchArgument('enable_stamped_cmd_vel', default_value='true',
                              choices=['true', 'false'],
                              description='TwistStamped (Jazzy diff_drive_controller) or Twist'),
        DeclareLaunchArgument('odom_frame', default_value='odom', description='odometry frame'),
        DeclareLaunchArgument('base_frame', default_value='base_link', description='body frame'),
        DeclareLaunchArgument('use_sim_time', default_value='false', choices=['true', 'false'],
                              description='use /clock (simulators)'),
        GroupAction([
            PushRosNamespace(LaunchConfiguration('namespace')),
            Node(package='nonfragile_tracker', executable='reference', name='reference',
                 parameters=[scenario, frames, {
                     'mode': 'realtime', 'use_sim_time': use_sim_time,
                     'trajectory_file': ParameterValue(trajectory, value_type=str),
                     'trajectory_topic': ParameterValue(relay, value_type=str)}],
                 output='screen'),
            Node(package='nonfragile_tracker', executable='tracker', name='tracker',
                 parameters=[scenario, LaunchConfiguration('gains'), frames, {
                     'mode': 'realtime', 'use_sim_time': use_sim_time,
                     'wait_for_trajectory': ParameterValue(own, value_type=bool),
                     'enable_stamped_cmd_vel': ParameterValue(
                         LaunchConfiguration('enable_stamped_cmd_vel'), value_type=bool),
                     'base_frame': ParameterValue(LaunchConfiguration('base_frame'),
                                                  value_type=str)}],
                 remappings=remap, output='screen'),
        ]),
    ])
