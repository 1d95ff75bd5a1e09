"""The package is a valid ament_python package: colcon builds and installs it."""
import ast
import os
import subprocess
import sys
from pathlib import Path


from conftest import ROOT

COLCON = Path(sys.executable).parent / 'colcon'
EXECUTABLES = {'reference', 'plant', 'tracker', 'recorder', 'bringup', 'nonfragile_tracker'}


def test_package_xml_is_valid_for_catkin_pkg():
    from catkin_pkg.package import parse_package
    pkg = parse_package(str(ROOT / 'package.xml'))
    pkg.validate()                                    # raises on an invalid maintainer email
    assert pkg.name == 'nonfragile_tracker' and pkg.package_format == 3
    assert pkg.get_build_type() == 'ament_python'
    exec_deps = {d.name for d in pkg.exec_depends}
    assert {'rclpy', 'geometry_msgs', 'nav_msgs', 'rosgraph_msgs', 'launch_ros'} <= exec_deps


def test_setup_installs_the_cli_and_one_console_script_per_node():
    """ament_python's convention: console scripts; setup.py writes the node wrappers lean."""
    import runpy
    from nonfragile_tracker.nodes import entry
    setup_py = runpy.run_path(str(ROOT / 'setup.py'), run_name='not_main')
    assert set(setup_py['NODES']) == set(entry.NODES)
    assert set(entry.NODES) | {'nonfragile_tracker'} == EXECUTABLES
    for node in entry.NODES:
        assert callable(getattr(entry, f'{node}_main')), node
        assert (ROOT / 'nonfragile_tracker' / 'nodes' / f'{node}.py').is_file(), node
        wrapper = setup_py['lean_wrapper'](node, '#!/usr/bin/python3\n# EASY-INSTALL ...\n')
        assert wrapper.splitlines()[0] == '#!/usr/bin/python3'
        assert f'from nonfragile_tracker.nodes.entry import {node}_main' in wrapper
        assert 'importlib' not in wrapper
    assert setup_py['lean_wrapper']('nonfragile_tracker', 'x') == 'x'   # the CLI: as written


def test_launch_file_is_idiomatic_python():
    src = (ROOT / 'launch' / 'tracking.launch.py').read_text()
    tree = ast.parse(src)
    funcs = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert 'generate_launch_description' in funcs
    assert "from launch_ros.actions import Node" in src
    for exe in ('reference', 'plant', 'tracker'):
        assert f"executable='{exe}'" in src


def test_colcon_build_installs_executables_launch_and_config(tmp_path):
    env = dict(os.environ, PYTHONDONTWRITEBYTECODE='1')
    listing = subprocess.run([str(COLCON), 'list', '--paths', str(ROOT)], capture_output=True,
                             text=True, env=env, cwd=tmp_path, timeout=120)
    assert '(ros.ament_python)' in listing.stdout, listing.stdout + listing.stderr
    proc = subprocess.run(
        [str(COLCON), '--log-base', str(tmp_path / 'log'), 'build', '--paths', str(ROOT),
         '--build-base', str(tmp_path / 'build'), '--install-base', str(tmp_path / 'install')],
        capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    prefix = tmp_path / 'install' / 'nonfragile_tracker'
    lib = prefix / 'lib' / 'nonfragile_tracker'
    assert {p.name for p in lib.iterdir()} >= EXECUTABLES
    assert all(os.access(lib / e, os.X_OK) for e in EXECUTABLES)
    share = prefix / 'share' / 'nonfragile_tracker'
    assert (share / 'launch' / 'tracking.launch.py').is_file()
    for cfg in ('paper_problem.yaml', 'paper_scenario.yaml', 'tracker_gains.yaml',
                'max_decay_gains.yaml', 'paper_gains.yaml', 'paper_gains_tracker.yaml'):
        assert (share / 'config' / cfg).is_file(), cfg
    assert (prefix / 'share' / 'ament_index' / 'resource_index' / 'packages'
            / 'nonfragile_tracker').is_file()
    # the installed CLI runs from the install space and finds its config via the ament index
    out = subprocess.run([str(lib / 'nonfragile_tracker'), 'synthesize',
                          str(share / 'config' / 'paper_problem.yaml')],
                         capture_output=True, text=True, timeout=120,
                         env=dict(env, AMENT_PREFIX_PATH=str(prefix), PYTHONPATH=str(
                             next((prefix / 'lib').glob('python3*/site-packages')))))
    assert out.returncode == 0 and 'feasible' in out.stdout, out.stderr
