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

Numerics (:mod:`engine.wv`, :mod:`engine.models`, the fit) never import this package. The names
are imported on first use (PEP 562, :func:`engine._lazy.lazy_attributes`): reading a Kalibr
file (:mod:`engine.io.kalibr`) loads no log reader.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes

#: Each module (relative to this package; ``._limits`` is ``engine._limits``) and the public
#: names it defines.
_LAZY: dict[str, tuple[str, ...]] = {
    "._limits": ("available_memory",),
    "load": ("load_log", "log_of"),
    "log": ("ImuLog", "LoadError", "pick_channel"),
    "npy": ("npy_sidecar_path", "read_npy_sidecar", "write_npy_sidecar"),
    "qualify": ("Finding", "Qualification", "drop_warmup", "qualify_log", "qualify_signal"),
    "rosbag": (
        "IMU_CHANNELS",
        "ImuBag",
        "imu_topics",
        "mcap_profile",
        "read_imu_bag",
        "write_imu_bag",
    ),
    "save": ("save_log",),
    "segments": ("still_segments", "with_segments"),
    "timecheck": (
        "GAP_FACTOR",
        "TimeEvent",
        "TimeReport",
        "as_seconds",
        "check_time",
        "segment_fs",
    ),
}

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs (the names of _LAZY)
    from .._limits import available_memory  # noqa: F401
    from .load import load_log, log_of  # noqa: F401
    from .log import ImuLog, LoadError, pick_channel  # noqa: F401
    from .npy import npy_sidecar_path, read_npy_sidecar, write_npy_sidecar  # noqa: F401
    from .qualify import (  # noqa: F401
        Finding,
        Qualification,
        drop_warmup,
        qualify_log,
        qualify_signal,
    )
    from .rosbag import (  # noqa: F401
        IMU_CHANNELS,
        ImuBag,
        imu_topics,
        mcap_profile,
        read_imu_bag,
        write_imu_bag,
    )
    from .save import save_log  # noqa: F401
    from .segments import still_segments, with_segments  # noqa: F401
    from .timecheck import (  # noqa: F401
        GAP_FACTOR,
        TimeEvent,
        TimeReport,
        as_seconds,
        check_time,
        segment_fs,
    )

__getattr__, __dir__, _lazy_names = lazy_attributes(__name__, _LAZY, globals())

__all__ = list(_lazy_names)  # the names of _LAZY, in its order
