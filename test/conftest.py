"""Shared fixtures: paths to the shipped configuration and the paper's data."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parent.parent
CONFIG = ROOT / 'config'


@pytest.fixture(scope='session')
def paper_problem():
    from nonfragile_tracker.control.problem import load_problem
    return load_problem(CONFIG / 'paper_problem.yaml')


@pytest.fixture(scope='session')
def paper_gains():
    import yaml
    data = yaml.safe_load((CONFIG / 'paper_gains.yaml').read_text())
    return {k: np.array(v, dtype=float) for k, v in data.items()}


@pytest.fixture
def ros_env(tmp_path):
    """Environment for ROS subprocesses: an isolated domain on localhost."""
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(1 + (os.getpid() * 7 + hash(tmp_path.name)) % 100 + 100)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['PYTHONPATH'] = str(ROOT) + os.pathsep + env.get('PYTHONPATH', '')
    return env
