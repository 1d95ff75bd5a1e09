"""Bags of tracking runs: write, read, report, compare, replay and repair (public API).

* :mod:`.writer` - :class:`BagWriter` (raw CDR in, chunked flushes), :func:`new_run_dir`,
  QoS helpers and the :class:`BagError` hierarchy (an ``InputError``: exit 2);
* :mod:`.reader` - :func:`read_bag` (numpy arrays of a run), :func:`read_messages`;
* :mod:`.report` - :func:`bag_report` (metrics, real-time timing, gaps, PNG plots),
  :func:`format_report`;
* :mod:`.compare` - :func:`compare_bags` (per topic/field tolerances, stamp/index/time
  alignment), :func:`format_differences`;
* :mod:`.replay` - :func:`replay` (recorded inputs into a fresh tracker, commands
  compared), :func:`format_replay`;
* :mod:`.repair` - :func:`repair_bag` for a bag whose recorder was killed or an MCAP
  without metadata.yaml.

A user's regression test needs only these, e.g.::

    from nonfragile_tracker.bag import compare_bags, format_differences, replay
    res = replay('my_robot_run', gains='new_gains.yaml')
    assert res.comparison.equal, format_differences(res.comparison)

None of these import rclpy; the ROS side is :mod:`nonfragile_tracker.nodes.recorder` and
:func:`nonfragile_tracker.replayer.replay_over_dds`.
"""
from __future__ import annotations

from .compare import (Comparison, Difference, Tolerance, compare_bags, compare_messages,
                      format_differences, parse_tolerance)
from .errors import BagError, BagExistsError, BagNotFoundError, MissingTopicsError
from .reader import (BagData, CommandSeries, PoseSeries, ReferenceSeries, RunData, read_bag,
                     read_messages)
from .repair import RepairResult, repair_bag
from .replay import ReplayResult, format_replay, replay
from .report import Report, TimingMetrics, bag_report, format_report
from .writer import BagWriter, default_qos, make_qos, new_run_dir

__all__ = ['BagError', 'BagExistsError', 'BagNotFoundError', 'MissingTopicsError', 'BagWriter',
           'new_run_dir', 'make_qos', 'default_qos', 'BagData', 'RunData', 'PoseSeries',
           'ReferenceSeries', 'CommandSeries', 'read_bag', 'read_messages', 'RepairResult',
           'repair_bag', 'Report', 'TimingMetrics', 'bag_report', 'format_report', 'Comparison',
           'Difference', 'Tolerance', 'compare_bags', 'compare_messages', 'format_differences',
           'parse_tolerance', 'ReplayResult', 'replay', 'format_replay']
