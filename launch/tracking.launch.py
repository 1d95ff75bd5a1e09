"""Launch the paper's tracking scenario: reference, plant and tracker (lockstep, sim time).

    ros2 launch nonfragile_tracker tracking.launch.py
    ros2 launch nonfragile_tracker tracking.launch.py gains:=/path/to/gains.yaml
"""
import os

from ament_index_python.packages import get_package_share_directory
from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node


def generate_launch_description():
    config = os.path.join(get_package_share_directory('nonfragile_tracker'), 'config')
    scenario = LaunchConfiguration('scenario')
    gains = LaunchConfiguration('gains')
    return LaunchDescription([
        DeclareLaunchArgument('scenario', default_value=os.path.join(config, 'paper_scenario.yaml'),
                              description='parameter file of the three nodes'),
        DeclareLaunchArgument('gains', default_value=os.path.join(config, 'tracker_gains.yaml'),
                              description='tracker gain file (nonfragile_tracker synthesize)'),
        Node(package='nonfragile_tracker', executable='reference', name='reference',
             parameters=[scenario], output='screen'),
        Node(package='nonfragile_tracker', executable='tracker', name='tracker',
             parameters=[scenario, gains], output='screen'),
        Node(package='nonfragile_tracker', executable='plant', name='plant',
             parameters=[scenario], output='screen'),
    ])
