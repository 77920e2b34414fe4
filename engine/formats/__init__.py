"""The export formats of GMWM fits (navigation filters, simulators, reports) and the projection.

``engine.export`` (:func:`.registry.export`) is the function users call; this package holds
the formats it writes.

* :mod:`.datasheet`: :func:`datasheet_table` (rows of the one datasheet table,
  :mod:`engine.units`), :func:`datasheet_text`, :func:`datasheet_csv`;
* :mod:`.kalibr`: Kalibr ``imu.yaml`` (:func:`kalibr_imu`, :func:`write_kalibr`,
  :func:`read_kalibr`, :func:`kalibr_models`);
* :mod:`.report`: :func:`fit_report`, :func:`write_report`, :func:`curves_csv`;
* :mod:`.noise`: :func:`imu_noise` (N, K, B and the GM numbers per sensor and axis, in SI,
  with the explicit ``inflate`` factor) for the filter formats:
* :mod:`.vio` (OpenVINS, Basalt, ORB-SLAM3, VINS), :mod:`.autopilot` (PX4 EKF2, ArduPilot
  EKF3), :mod:`.sim` (MATLAB, Gazebo/RotorS), :mod:`.ins` (KF-GINS, ``sensor_msgs/Imu``);
* :mod:`.projection`: :func:`project` (a fit onto a filter's noise model, over-bounded, with
  intervals), used by every filter format;
* :mod:`.tails`: :func:`~.tails.tail_factors` (per scale, the factor on the data bound's
  variance that makes the file's Gaussian quantile cover the data's);
* :mod:`.catalog`: the formats by name (:data:`FORMATS`), records of their consumer model,
  capabilities and the options their writer reads, importing no writer; :mod:`.options`:
  :class:`ExportOptions`, the typed options every writer takes; :mod:`.registry`:
  :func:`export` and :func:`projections` (what a filter file will assume, as the export
  computes it).

The names are imported on first use (PEP 562, :func:`engine._lazy.lazy_attributes`), so that a
module that needs one helper (``engine.formats.common``) does not load every writer.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from .._lazy import lazy_attributes

#: Each module (relative to this package; ``.units`` is ``engine.units``) and the public names
#: it defines.
_LAZY: dict[str, tuple[str, ...]] = {
    ".units": ("ExportError", "DatasheetRow", "si_factor", "BI_FACTOR"),
    "datasheet": ("datasheet_table", "datasheet_text", "datasheet_csv"),
    "kalibr": ("KalibrImu", "kalibr_imu", "write_kalibr", "kalibr_models"),
    ".io.kalibr": ("read_kalibr",),
    "report": ("fit_report", "write_report", "curves_csv"),
    "catalog": ("FORMATS", "Format", "register", "FORMAT_CONSUMERS"),
    "registry": ("export", "projections"),
    "options": ("ExportOptions", "DATA_BOUNDS"),
    "noise": ("ImuNoise", "imu_noise"),
    "projection": (
        "project",
        "Projection",
        "ProjectedParam",
        "MISFIT_SHARE",
        "misfit",
    ),
    "tails": ("TailFactors", "tail_factors", "log_tail_factors"),
}

if TYPE_CHECKING:  # pragma: no cover - for type checkers and IDEs (the names of _LAZY)
    from ..io.kalibr import read_kalibr  # noqa: F401
    from ..units import BI_FACTOR, DatasheetRow, ExportError, si_factor  # noqa: F401
    from .catalog import FORMAT_CONSUMERS, FORMATS, Format, register  # noqa: F401
    from .datasheet import datasheet_csv, datasheet_table, datasheet_text  # noqa: F401
    from .kalibr import KalibrImu, kalibr_imu, kalibr_models, write_kalibr  # noqa: F401
    from .noise import ImuNoise, imu_noise  # noqa: F401
    from .options import DATA_BOUNDS, ExportOptions  # noqa: F401
    from .projection import (  # noqa: F401
        MISFIT_SHARE,
        ProjectedParam,
        Projection,
        misfit,
        project,
    )
    from .registry import export, projections  # noqa: F401
    from .report import curves_csv, fit_report, write_report  # noqa: F401
    from .tails import TailFactors, log_tail_factors, tail_factors  # noqa: F401

__getattr__, __dir__, _lazy_names = lazy_attributes(__name__, _LAZY, globals())

__all__ = list(_lazy_names)  # the names of _LAZY, in its order
