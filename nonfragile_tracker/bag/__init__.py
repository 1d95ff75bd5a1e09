"""Bags of tracking runs: write (rosbag2 v9 / MCAP), read, repair and report.

* :mod:`.writer` - :class:`BagWriter` (raw CDR in, chunked flushes), :func:`new_run_dir`,
  QoS helpers and the :class:`BagError` hierarchy;
* :mod:`.reader` - :func:`read_bag` (numpy arrays of a run), :func:`read_messages`;
* :mod:`.repair` - :func:`repair_bag` for a bag whose recorder was killed;
* :mod:`.report` - :func:`bag_report` (metrics, gaps, PNG plots), :func:`format_report`.

None of these import rclpy; the ROS side is :mod:`nonfragile_tracker.nodes.recorder`.
"""
from __future__ import annotations

from .reader import (BagData, BagNotFoundError, BagTruncatedError, CommandSeries,
                     MissingTopicsError, NotABagError, PoseSeries, ReferenceSeries, RunData,
                     read_bag, read_messages)
from .repair import NothingToRepairError, RepairError, RepairResult, repair_bag
from .report import Report, bag_report, format_report
from .writer import (BagError, BagExistsError, BagWriter, InvalidRunNameError, default_qos,
                     make_qos, new_run_dir)

__all__ = ['BagError', 'BagExistsError', 'BagNotFoundError', 'BagTruncatedError',
           'InvalidRunNameError', 'MissingTopicsError', 'NotABagError', 'RepairError',
           'NothingToRepairError', 'BagWriter', 'new_run_dir', 'make_qos', 'default_qos',
           'BagData', 'RunData', 'PoseSeries', 'ReferenceSeries', 'CommandSeries', 'read_bag',
           'read_messages', 'RepairResult', 'repair_bag', 'Report', 'bag_report',
           'format_report']
