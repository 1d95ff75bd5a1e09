"""ament_python setup for nonfragile_tracker.

The executables are console scripts (the ament_python convention), installed into
``lib/nonfragile_tracker`` by setup.cfg so that ``ros2 run``/``ros2 launch`` find them.
Under ``colcon build`` (``setup.py install``/``develop``) setuptools writes them as
*easy-install* wrappers with the right interpreter in the shebang under every setuptools
colcon accepts (68.1.2, Ubuntu 24.04's, to 79.x; plain ``scripts=`` got the wheel
placeholder ``#!python`` from setuptools 79's ``build_scripts``, so ``ros2 run`` failed
with FileNotFoundError).  Those wrappers import ``importlib.metadata`` and scan the
installed distributions (0.1 s or more) before any package code runs: a Ctrl-C in that
window printed a KeyboardInterrupt traceback.  :class:`_NodeWrappers` therefore writes the
node wrappers as pip does for a wheel - the shebang setuptools chose, then one import of
the cheap :mod:`nonfragile_tracker.nodes.entry` (which notes SIGINT/SIGTERM at once) and
its entry function.  ``test/package/test_colcon_setuptools.py`` builds the package with
colcon under both setuptools versions and execs every installed executable.
"""
from glob import glob

from setuptools import find_packages, setup
from setuptools.command.develop import develop
from setuptools.command.install_scripts import install_scripts

package_name = 'nonfragile_tracker'
#: The node executables (``nonfragile_tracker.nodes.entry.NODES``), one console script each.
NODES = ('reference', 'plant', 'tracker', 'recorder', 'bringup')


def lean_wrapper(script_name, contents):
    """The wrapper of a node executable: setuptools' shebang, then the entry function.

    Other scripts (the CLI) and non-text contents (Windows launchers) are returned as they
    are.
    """
    if script_name not in NODES or not isinstance(contents, str):
        return contents
    shebang = contents.splitlines()[0]
    if not shebang.startswith('#!'):
        return contents
    return (f'{shebang}\n'
            f'# ros2 run {package_name} {script_name}: written by setup.py (lean_wrapper)\n'
            'import sys\n'
            f'from {package_name}.nodes.entry import {script_name}_main\n'
            f'sys.exit({script_name}_main())\n')


class _NodeWrappers:
    """Mix-in for the commands that write console scripts (install_scripts, develop)."""

    def write_script(self, script_name, contents, *args, **kwargs):  # noqa: D102
        return super().write_script(script_name, lean_wrapper(script_name, contents),
                                    *args, **kwargs)


class InstallScripts(_NodeWrappers, install_scripts):
    """``setup.py install`` (colcon build): lean node wrappers."""


class Develop(_NodeWrappers, develop):
    """``setup.py develop`` (colcon build --symlink-install): lean node wrappers."""


if __name__ == '__main__':       # colcon, pip and setuptools run it as __main__
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
            # the physics plant's MJCF bases (control/simulation/physics.py) and their scenarios
            ('share/' + package_name + '/config/bases', glob('config/bases/*.xml')
             + glob('config/bases/*.yaml')),
            ('share/' + package_name + '/rviz', glob('rviz/*.rviz')),
        ],
        install_requires=['setuptools'],
        zip_safe=True,
        maintainer='nonfragile_tracker maintainers',
        maintainer_email='maintainers@nonfragile-tracker.org',
        description=('Non-fragile LMI trajectory tracking of delayed wheeled mobile robots '
                     '(ROS 2 Jazzy).'),
        license='Apache-2.0',
        tests_require=['pytest'],
        entry_points={
            'console_scripts': [
                'nonfragile_tracker = nonfragile_tracker.cli:main',
                *(f'{node} = {package_name}.nodes.entry:{node}_main' for node in NODES),
            ],
        },
        cmdclass={'install_scripts': InstallScripts, 'develop': Develop},
    )
