"""Track a trajectory on a real robot (or any simulator): tracker and reference only.

    ros2 launch nonfragile_tracker robot.launch.py robot:=my_robot.yaml gains:=g.yaml \\
        trajectory:=/path/lap.csv

The robot file (a copy of config/robot.yaml, commented, edited for the base) gives the
odometry and command topics, the frames, Twist or TwistStamped, the speed and
acceleration limits, the minimum turning radius and the input timeout; it is read and
checked when the launch starts (nonfragile_tracker.robot: a bad key stops the launch with
its name and what to write) and its values go to the tracker, before the gain file (whose
tracker section may add the identified predictor settings and limits).  Nothing of the
paper's simulation (config/paper_scenario.yaml) is loaded.  Real time (wall clock, or the
robot's clock with use_sim_time).  With trajectory:= the reference publishes that file,
with trajectory_topic:= it relays a planner's nav_msgs/Path; with neither no reference is
started and the tracker waits at rest for a trajectory on its trajectory topics.
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node, PushRosNamespace


def robot_nodes(context):
    """The tracker (and the reference) with the robot file's values, read at launch time."""
    from nonfragile_tracker.robot import load_robot_file
    robot = load_robot_file(LaunchConfiguration('robot').perform(context))
    trajectory = LaunchConfiguration('trajectory').perform(context)
    relay = LaunchConfiguration('trajectory_topic').perform(context)
    common = {'mode': 'realtime',
              'use_sim_time': LaunchConfiguration('use_sim_time').perform(context) == 'true'}
    nodes = [PushRosNamespace(LaunchConfiguration('namespace'))]
    if trajectory or relay:
        nodes.append(Node(
            package='nonfragile_tracker', executable='reference', name='reference',
            parameters=[{**common, 'odom_frame': robot.odom_frame,
                         'trajectory_file': trajectory, 'trajectory_topic': relay}],
            output='screen'))
    nodes.append(Node(
        package='nonfragile_tracker', executable='tracker', name='tracker',
        parameters=[robot.parameters(), LaunchConfiguration('gains'),
                    {**common, 'wait_for_trajectory': True}],
        output='screen'))
    return [GroupAction(nodes)]


def generate_launch_description():
    config = os.path.join(get_package_share_directory('nonfragile_tracker'), 'config')
    return LaunchDescription([
        DeclareLaunchArgument('robot', default_value=os.path.join(config, 'robot.yaml'),
                              description='robot file: topics, frames, Twist or TwistStamped, '
                              'limits, timeout (copy the shipped one and edit it)'),
        DeclareLaunchArgument('gains', default_value=os.path.join(config, 'tracker_gains.yaml'),
                              description='tracker gain file (default: certified for command '
                              'latency up to 0.15 s through a 50 ms lag; after the bring-up '
                              'the file latency-design wrote for your base)'),
        DeclareLaunchArgument('trajectory', default_value='',
                              description='waypoint file to follow (CSV/YAML)'),
        DeclareLaunchArgument('trajectory_topic', default_value='',
                              description='relay nav_msgs/Path trajectories from this topic'),
        DeclareLaunchArgument('namespace', default_value='', description='namespace'),
        DeclareLaunchArgument('use_sim_time', default_value='false', choices=['true', 'false'],
                              description='use /clock (simulators)'),
        OpaqueFunction(function=robot_nodes),
    ])
