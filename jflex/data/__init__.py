"""The data layer: measured logs read into one record type and conditioned before any analysis.

Readers (CSV logs, ROS 2 bags / MCAP and UFF58 FRF files, read as a plain :class:`LogMap` says;
NPZ archives) give a :class:`Record`: arrays in SI units, per-channel metadata (:class:`Channel`: unit, source column,
scale, offset, quality flags) and a ``conditioning`` report. The conditioning steps
(:mod:`jflex.data._condition`) make stamps uniform, merge files on time, name dead, stuck, flat,
saturated and few-level channels, count spikes, choose a low-pass cutoff per record and turn motor
currents into joint torques. Beyond them: the signal tools (:mod:`jflex.data._signal`: noise
estimates, the motion's band, zero-phase filters, spectral and filtered derivatives), the checks of
arrays and of each kind of data set's fields, the processing of angle-only torque logs
(:mod:`jflex.data._angle_log`) and of response sets, and peak picking on FRFs.
``jflex.identify`` and ``jflex.gap`` read their data through it.

The folder also holds the demo case shipped with the library (``demo_case/``, ``demo_truth.json``).
"""

from ._condition import (
    CUTOFF_LIMIT as CUTOFF_LIMIT,
    EXCLUDE_FLAGS as EXCLUDE_FLAGS,
    channel_quality as channel_quality,
    choose_cutoff as choose_cutoff,
    clean_stamps as clean_stamps,
    condition_torque as condition_torque,
    currents_to_torque as currents_to_torque,
    find_spikes as find_spikes,
    merge_on_time as merge_on_time,
    resample_uniform as resample_uniform,
)
from ._csv import Table as Table, csv_arrays as csv_arrays, read_csv as read_csv
from ._log_map import LogMap as LogMap
from ._npz import load_npz_fields as load_npz_fields, read_npz as read_npz
from ._posture import yaml_posture as yaml_posture
from ._record import Channel as Channel, Record as Record
from ._rosbag import read_rosbag as read_rosbag, rosbag_arrays as rosbag_arrays
from ._uff import UFF58 as UFF58, read_uff58 as read_uff58, uff_arrays as uff_arrays, write_uff58 as write_uff58
