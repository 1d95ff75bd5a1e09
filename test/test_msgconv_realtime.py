"""The message conversions on the tracker's real-time path (each field read once)."""
from __future__ import annotations

import math
from types import SimpleNamespace as NS

import pytest

from nonfragile_tracker.control.simulation.model import quaternion_to_yaw, yaw_to_quaternion
from nonfragile_tracker.control.simulation.reference import RefSample
from nonfragile_tracker.interface.msgconv import pose_from_odom, reference_from_msgs


def pose(x, y, q):
    return NS(position=NS(x=x, y=y, z=0.0), orientation=NS(x=q[0], y=q[1], z=q[2], w=q[3]))


def ref_msgs(x, y, th, v, a):
    return (NS(pose=pose(x, y, yaw_to_quaternion(th))),
            NS(twist=NS(linear=NS(x=v[0], y=v[1], z=0.0))),
            NS(accel=NS(linear=NS(x=a[0], y=a[1], z=0.0))))


@pytest.mark.parametrize('th', [0.0, 0.3, -2.9, math.pi, 1e-9])
def test_pose_is_the_exact_yaw_of_the_quaternion(th):
    q = yaw_to_quaternion(th)
    assert pose_from_odom(pose(1.25, -0.5, q)) == (1.25, -0.5, quaternion_to_yaw(*q))


@pytest.mark.parametrize('i', range(6))
@pytest.mark.parametrize('bad', [math.nan, math.inf, -math.inf])
def test_any_non_finite_field_is_named(i, bad):
    vals = [0.5, 0.25, 0.0, 0.0, 0.0, 1.0]
    vals[i] = bad
    reason = pose_from_odom(pose(vals[0], vals[1], vals[2:]))
    assert reason == f'non-finite pose {tuple(vals)}'


def test_quaternion_norm_is_checked():
    assert pose_from_odom(pose(0.0, 0.0, (0.0, 0.0, 0.0, 1.01))) == \
        'quaternion norm 1.01 is not 1'
    assert isinstance(pose_from_odom(pose(0.0, 0.0, (0.0, 0.0, 0.0, 1.0009))), tuple)


def test_reference_sample_from_the_three_messages():
    ref = reference_from_msgs(2.5, *ref_msgs(1.0, 2.0, 0.7, (0.3, -0.2), (0.01, 0.02)))
    assert ref == RefSample(2.5, 1.0, 2.0, 0.3, -0.2, 0.01, 0.02,
                            quaternion_to_yaw(*yaw_to_quaternion(0.7)))


@pytest.mark.parametrize('i', range(4))
def test_non_finite_reference_rates_are_named(i):
    vals = [0.3, -0.2, 0.01, 0.02]
    vals[i] = math.nan
    msgs = ref_msgs(1.0, 2.0, 0.7, vals[:2], vals[2:])
    assert reference_from_msgs(0.0, *msgs) == \
        f'reference twist/accel not finite: {tuple(vals)}'
    bad_pose = ref_msgs(math.inf, 2.0, 0.7, (0.0, 0.0), (0.0, 0.0))
    assert reference_from_msgs(0.0, *bad_pose).startswith('reference/pose: non-finite pose')
