"""Bags of tracking runs: write, read, report, compare, replay and repair (public API).

The modules :mod:`.writer`, :mod:`.reader`, :mod:`.report`, :mod:`.compare`,
:mod:`.replay` and :mod:`.repair`; a user's regression test needs only their public
functions (``compare_bags``, ``replay``, ``bag_report``, ``format_differences``, ...).
None of them imports rclpy; the ROS side is :mod:`nonfragile_tracker.nodes.recorder` and
:func:`nonfragile_tracker.workflows.dds_replay.replay_over_dds`.

See doc/bags.md, section "Bag regression for your own robot or scenario" (the API by
module, an example).
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
