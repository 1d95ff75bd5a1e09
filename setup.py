"""ament_python setup for nonfragile_tracker."""
from glob import glob

from setuptools import find_packages, setup

package_name = 'nonfragile_tracker'

setup(
    name=package_name,
    version='0.1.0',
    packages=find_packages(exclude=['test', 'test.*', 'benchmarks']),
    data_files=[
        ('share/ament_index/resource_index/packages', ['resource/' + package_name]),
        ('share/' + package_name, ['package.xml']),
        ('share/' + package_name + '/launch', glob('launch/*.launch.py')),
        ('share/' + package_name + '/config', glob('config/*.yaml')),
        ('share/' + package_name + '/config/trajectories', glob('config/trajectories/*')),
        ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
    ],
    install_requires=['setuptools'],
    zip_safe=True,
    maintainer='nonfragile_tracker maintainers',
    maintainer_email='maintainers@nonfragile-tracker.org',
    description='Non-fragile LMI trajectory tracking of delayed wheeled mobile robots (ROS 2 Jazzy).',
    license='Apache-2.0',
    tests_require=['pytest'],
    entry_points={
        'console_scripts': [
            'nonfragile_tracker = nonfragile_tracker.cli:main',
            'reference = nonfragile_tracker.nodes.entry:reference',
            'plant = nonfragile_tracker.nodes.entry:plant',
            'tracker = nonfragile_tracker.nodes.entry:tracker',
            'recorder = nonfragile_tracker.nodes.entry:recorder',
        ],
    },
)
