"""Track a trajectory on a real robot (or any simulator): tracker and reference only.

    ros2 launch nonfragile_tracker robot.launch.py robot:=my_robot.yaml gains:=g.yaml \\
        trajectory:=/path/lap.csv

The robot file (a copy of config/robot.yaml, commented, edited for the base) gives the
odometry and command topics, the frames, Twist or TwistStamped, the speed and
acceleration limits, the minimum turning radius and the input timeout; it is read and
checked when the launch starts (nonfragile_tracker.interface.robot: a bad key stops the launch with
its name and what to write) and its values go to the tracker, before the gain file (whose
tracker section may add the identified predictor settings and limits).  Nothing of the
paper's simulation (config/paper_scenario.yaml) is loaded.  Real time (wall clock, or the
robot's clock with use_sim_time).  With trajectory:= the reference publishes that file,
with trajectory_topic:= it relays a planner's nav_msgs/Path; with neither no reference is
started and the tracker waits at rest for a trajectory on its trajectory topics.

In a Nav2 system (doc/nav2.md) nav2:=true remaps the tracker's cmd_vel to cmd_vel_nav (Nav2's
collision_monitor or velocity_smoother publishes cmd_vel) and its trajectory to Nav2's plan,
and watches for commands overridden downstream (override_tolerance 0.1 m/s); the tracker is a
managed node, configured and activated at once unless autostart:=false (then a lifecycle
manager, nav2_lifecycle_manager with 'tracker' in its node_names, brings it up):

    ros2 launch nonfragile_tracker robot.launch.py robot:=my_robot.yaml nav2:=true \\
        autostart:=false
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, GroupAction, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node, PushRosNamespace


def robot_nodes(context):
    """The tracker (and the reference) with the robot file's values, read at launch time."""
    from nonfragile_tracker.interface.robot import load_robot_file
    robot = load_robot_file(LaunchConfiguration('robot').perform(context))
    trajectory = LaunchConfiguration('trajectory').perform(context)
    relay = LaunchConfiguration('trajectory_topic').perform(context)
    from nonfragile_tracker.interface.topics import CMD_VEL, CMD_VEL_NAV, NAV2_PLAN, TRAJECTORY
    common = {'mode': 'realtime',
              'use_sim_time': LaunchConfiguration('use_sim_time').perform(context) == 'true'}
    own = {**common, 'wait_for_trajectory': True}
    extra = {}
    if LaunchConfiguration('autostart').perform(context) != 'true':
        own['autostart'] = False               # a lifecycle manager configures, activates
    if LaunchConfiguration('nav2').perform(context) == 'true':
        own['override_tolerance'] = 0.1        # collision_monitor slows or stops the base
        extra['remappings'] = [(CMD_VEL, CMD_VEL_NAV), (TRAJECTORY, NAV2_PLAN)]
    nodes = [PushRosNamespace(LaunchConfiguration('namespace'))]
    if trajectory or relay:
        nodes.append(Node(
            package='nonfragile_tracker', executable='reference', name='reference',
            parameters=[{**common, 'odom_frame': robot.odom_frame,
                         'trajectory_file': trajectory, 'trajectory_topic': relay}],
            output='screen'))
    nodes.append(Node(
        package='nonfragile_tracker', executable='tracker', name='tracker',
        parameters=[robot.parameters(), LaunchConfiguration('gains'), own],
        output='screen', **extra))
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
        DeclareLaunchArgument('autostart', default_value='true', choices=['true', 'false'],
                              description='configure and activate the tracker (a managed node) '
                              'at once; false: a lifecycle manager (nav2_lifecycle_manager) '
                              'does'),
        DeclareLaunchArgument('nav2', default_value='false', choices=['true', 'false'],
                              description='in a Nav2 system: publish cmd_vel_nav (for '
                              'collision_monitor), follow Nav2\'s plan, watch for commands '
                              'overridden downstream'),
        OpaqueFunction(function=robot_nodes),
    ])
