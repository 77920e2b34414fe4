"""Loading and saving IMU logs, ROS bags, time-column checks (sessions: :mod:`engine.session`).

* :mod:`engine.io.log`: :class:`ImuLog`, :class:`LoadError`, :func:`pick_channel`.
* :mod:`engine.io.load`: :func:`load_log` (format sniffing and dispatch; :func:`log_of`: a path
  loaded or a log as it is) over the readers
  :mod:`~engine.io.text`, :mod:`~engine.io.npy`, :mod:`~engine.io.hdf5` (WV summaries:
  :mod:`~engine.io.summary`) and :mod:`~engine.io.rosbag`, which share the column checks of
  :mod:`engine.io._assemble`.
* Flight logs: :mod:`~engine.io.ulog` (PX4 ULog, extra ``px4``) and :mod:`~engine.io.dataflash`
  (ArduPilot DataFlash, extra ``ardupilot``); :mod:`engine.io.timecols`: the roles of a table's
  columns (time, instance, temperature, counters) and the converters' CSV profiles;
  :mod:`engine.io.segments`: the still segments of a flight log.
* :mod:`engine.io.save`: :func:`save_log`.
* :mod:`engine.io.timecheck`: gaps, duplicates and jitter of time stamps.
* :mod:`engine.io.qualify`: is the log fit to calibrate from (warm-up, shocks, motion,
  saturation, quantisation, lines, slow trend, timing), checked before every fit.

Numerics (:mod:`engine.wv`, :mod:`engine.models`, the fit) never import this package.
"""

from __future__ import annotations

from .._limits import available_memory
from .load import load_log, log_of
from .log import ImuLog, LoadError, pick_channel
from .npy import npy_sidecar_path, read_npy_sidecar, write_npy_sidecar
from .qualify import Finding, Qualification, drop_warmup, qualify_log, qualify_signal
from .rosbag import IMU_CHANNELS, ImuBag, imu_topics, mcap_profile, read_imu_bag, write_imu_bag
from .save import save_log
from .timecheck import GAP_FACTOR, TimeEvent, TimeReport, as_seconds, check_time, segment_fs

__all__ = [
    "available_memory",  # what the loaders' size checks compare a log with
    "ImuLog",
    "LoadError",
    "load_log",
    "log_of",
    "save_log",
    "pick_channel",
    "npy_sidecar_path",
    "read_npy_sidecar",
    "write_npy_sidecar",
    "ImuBag",
    "IMU_CHANNELS",
    "read_imu_bag",
    "imu_topics",
    "write_imu_bag",
    "mcap_profile",
    "TimeEvent",
    "TimeReport",
    "check_time",
    "segment_fs",
    "as_seconds",
    "GAP_FACTOR",
    "Finding",
    "Qualification",
    "qualify_log",
    "qualify_signal",
    "drop_warmup",
]
