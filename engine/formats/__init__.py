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
* :mod:`.registry`: the formats by name (:data:`FORMATS`) and :func:`export`.
"""

from __future__ import annotations

from ..io.kalibr import read_kalibr
from ..units import BI_FACTOR, DatasheetRow, ExportError, si_factor
from .datasheet import datasheet_csv, datasheet_table, datasheet_text
from .kalibr import KalibrImu, kalibr_imu, kalibr_models, write_kalibr
from .noise import ImuNoise, imu_noise
from .projection import (
    DATA_BOUNDS,
    FORMAT_CONSUMERS,
    MISFIT_SHARE,
    ProjectedParam,
    Projection,
    misfit,
    project,
)
from .registry import FORMATS, Format, export, register
from .report import curves_csv, fit_report, write_report
from .tails import TailFactors, log_tail_factors, tail_factors

__all__ = [
    "ExportError",
    "DatasheetRow",
    "si_factor",
    "datasheet_table",
    "datasheet_text",
    "datasheet_csv",
    "KalibrImu",
    "kalibr_imu",
    "write_kalibr",
    "read_kalibr",
    "kalibr_models",
    "fit_report",
    "write_report",
    "curves_csv",
    "export",
    "FORMATS",
    "Format",
    "register",
    "BI_FACTOR",
    "ImuNoise",
    "imu_noise",
    "project",
    "Projection",
    "ProjectedParam",
    "FORMAT_CONSUMERS",
    "DATA_BOUNDS",
    "MISFIT_SHARE",
    "misfit",
    "TailFactors",
    "tail_factors",
    "log_tail_factors",
]
