"""Writing the export formats: :func:`export`, and the writers of the reports and the Kalibr file.

The formats themselves (name, consumer model, capabilities, where the writer is) are records
in :mod:`engine.formats.catalog`, which imports no writer. A new filter format (OpenVINS,
Basalt, VINS ...) is one module with a writer ``writer(fits, **options) -> str`` (and a reader
where one exists) that takes its numbers from the one datasheet table (:mod:`engine.units`),
plus one :func:`~engine.formats.catalog.register` call in the catalog.
"""

from __future__ import annotations

import dataclasses
import json
import os
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

from .._files import write_atomic
from ..fit import GMWMResult
from ..io.log import channel_axis
from ..units import ExportError
from .catalog import FORMATS, VALUE_KINDS, Format, register
from .common import source_text
from .datasheet import datasheet_csv, datasheet_table, datasheet_text
from .kalibr import KalibrImu, kalibr_imu
from .noise import FleetUnit, check_inflate, noise_for
from .report import curves_csv, fit_report
from .tails import log_tail_factors

if TYPE_CHECKING:  # pragma: no cover
    from ..inference import ParamInterval
    from ..io import ImuLog

__all__ = [
    "Format",
    "FORMATS",
    "VALUE_KINDS",
    "register",
    "export",
    "kalibr_text",
    "json_text",
    "curves_text",
    "datasheet_table_text",
    "datasheet_csv_text",
]


def kalibr_text(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    f = check_inflate(kw.get("inflate", 1.0))
    if (kw.get("projection") or "bound") == "fit":
        kal = kalibr_imu(
            fits,
            units=kw.get("units"),
            rostopic=kw.get("rostopic") or "/imu0",
            source=kw.get("source", ""),
            allow_partial=kw.get("allow_partial", False),
        )
        kal = dataclasses.replace(
            kal,
            values={k: v * f for k, v in kal.values.items()},
            per_axis={k: {a: v * f for a, v in d.items()} for k, d in kal.per_axis.items()},
            comments=[
                *kal.comments,
                "projection fit: the fit's own WN and RW terms (no projection, no bound)",
                f"inflate = {f!r}: every noise value below is the fitted value x {f!r}",
            ],
        )
        return kal.to_yaml()
    nz = noise_for(
        fits, "Kalibr imu.yaml", kw, allow_partial=kw.get("allow_partial", False), consumer="kalibr"
    )
    per_axis: dict[str, dict[str, float]] = {}
    chosen: dict[str, str] = {}
    values: dict[str, float] = {}
    for ch, p in nz.projections.items():
        kind = p.sensor or ""
        ax = channel_axis(ch)
        per_axis.setdefault(f"{kind}_noise_density", {})[ax] = nz.values[kind]["N"][ax]
        per_axis.setdefault(f"{kind}_random_walk", {})[ax] = nz.values[kind]["K"][ax]
    for key, axes in per_axis.items():
        ax = max(axes, key=lambda a: axes[a])
        values[key] = axes[ax]
        kind = key.split("_")[0]
        chosen[key] = next(
            c for c, p in nz.projections.items() if p.sensor == kind and channel_axis(c) == ax
        )
    kal = KalibrImu(
        values=values,
        chosen=chosen,
        per_axis=per_axis,
        sources={},
        update_rate=nz.rate,
        rostopic=kw.get("rostopic") or "/imu0",
        comments=nz.header,
        warnings=nz.warnings,
    )
    return kal.to_yaml()


def _no_inflate(kw: Mapping[str, Any], name: str) -> None:
    if check_inflate(kw.get("inflate", 1.0)) != 1.0:
        raise ExportError(
            f"inflate= is for filter formats; the {name} reports the fit itself (inflate 1)"
        )


def json_text(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    _no_inflate(kw, "JSON report")
    rep = fit_report(
        fits,
        intervals=kw.get("intervals"),
        log=kw.get("log"),
        units=kw.get("units"),
        source=kw.get("source", ""),
        consumers=kw.get("consumers"),
        projection=kw.get("projection") or "bound",
        filter_rate=kw.get("filter_rate"),
        horizon_s=kw.get("horizon_s"),
        band=kw.get("band"),
        confidence=kw.get("confidence"),
        ci=kw.get("ci", "asymptotic"),
        data=kw.get("data") or "low",
        tails=kw.get("tails"),
    )
    return json.dumps(rep, indent=1, allow_nan=False) + "\n"


def datasheet_table_text(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    _no_inflate(kw, "datasheet")
    return (
        datasheet_text(datasheet_table(fits, intervals=kw.get("intervals"), units=kw.get("units")))
        + "\n"
    )


def datasheet_csv_text(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    _no_inflate(kw, "datasheet")
    return datasheet_csv(
        datasheet_table(fits, intervals=kw.get("intervals"), units=kw.get("units"))
    )


def curves_text(fits: Mapping[str, GMWMResult], **kw: Any) -> str:
    _no_inflate(kw, "curves CSV")
    return curves_csv(fits)


def export(
    path: str | os.PathLike[str] | None,
    fits: Mapping[str, GMWMResult],
    fmt: str,
    *,
    intervals: Mapping[str, Sequence[ParamInterval]] | None = None,
    log: ImuLog | None = None,
    units: Mapping[str, str] | None = None,
    source: str | os.PathLike[str] = "",
    rostopic: str | None = None,
    allow_partial: bool = False,
    inflate: float = 1.0,
    filter_rate: float | None = None,
    projection: str = "bound",
    horizon_s: float | None = None,
    band: Sequence[float] | None = None,
    confidence: float | None = None,
    ci: str | None = "asymptotic",
    vehicle_id: int = 1,
    scale_factor_std_ppm: float | None = None,
    consumers: Sequence[str] | None = None,
    data: str = "low",
    tails: bool = True,
    fleet: Sequence[tuple[str, Mapping[str, GMWMResult], ImuLog | None]] = (),
) -> str:
    """Export fits in one format; writes ``path`` (unless None) and returns the text.

    Parameters
    ----------
    path : path or None
        Where to write the text.
    fits : mapping of channel name to GMWMResult
    fmt : str
        A name of :data:`FORMATS`: ``"kalibr"`` (Kalibr ``imu.yaml``), ``"json"`` (JSON
        report), ``"csv"`` (WV and implied curves), ``"datasheet"`` (readable datasheet
        table), ``"datasheet-csv"``, and the filter formats ``"openvins"``, ``"basalt"``,
        ``"orbslam3"``, ``"vins"``, ``"px4"``, ``"ardupilot"``, ``"matlab"``, ``"gazebo"``,
        ``"kf-gins"``, ``"ros-imu"`` (docs/fit-to-filter.md, "Export formats").
    intervals, log, units, source, rostopic, allow_partial
        Passed to the format's writer (parameter intervals per channel, the log for the JSON
        report, signal unit per channel, source name (a str or a path), Kalibr topic, partial
        Kalibr file). Every user-given string is written with its control characters escaped
        (:func:`engine.formats.common.clean_text`): a newline in a file name cannot add a line
        (a parameter, a key) to the file.
    inflate : float
        Filter formats: every noise value (density, random walk, bias std) is the fitted value
        times ``inflate`` (variances times ``inflate**2``), written in the file's header;
        the reports (json, csv, datasheet) refuse a factor other than 1. Default 1.
    rostopic : str, optional
        Kalibr/OpenVINS ``rostopic``; default: the bag's IMU topic when ``log`` came from a
        bag, else ``/imu0``.
    filter_rate : float, optional
        PX4/ArduPilot: the rate (Hz) the EKF predicts at (required by those formats); the
        other filter formats: the filter's step for the projection (default the log's rate).
    projection : {"bound", "plain", "fit"}
        Filter formats: ``"bound"`` (default) projects each fit onto the consumer's noise model
        and over-bounds it (:func:`engine.formats.projection.project`); ``"plain"`` the rule
        without the bound; ``"fit"`` the fit's own terms converted one by one (no projection).
    horizon_s, band, confidence, ci
        The bound's horizon (s, default the log length), its WV scales (s), the confidence of
        the fitted WV's upper limit to bound (default: the WV itself), the intervals
        (``"asymptotic"`` or None); :func:`engine.formats.projection.project`.
    vehicle_id : int
        PX4: the MAVLink system id of the ``.params`` lines (default 1).
    scale_factor_std_ppm : float, optional
        KF-GINS: ``gsstd``/``asstd`` (not identified by GMWM; default 1000 ppm).
    consumers : sequence of str, optional
        JSON report: the consumer models or filter formats each fit is projected onto, with
        each value's interval and factor (default ``("WN+RW",)``; ``projection="fit"``:
        none); the filter formats use their own consumer.
    data : {"low", "estimate", "high", "none"}
        Filter formats and the JSON report's projections: the bound also covers the
        empirical WV's lower interval limit (default), its estimate or its upper limit at the
        dyadic scales of the band, or only the fitted model (``"none"``);
        :func:`engine.formats.projection.project`.
    tails : bool
        Filter formats and the JSON report's projections, with a data bound and ``log``
        given: the data bound's variance at each dyadic scale times the channel's tail factor
        (:func:`engine.formats.tails.tail_factors` of ``log``'s channel: the least factor that
        makes the file's Gaussian 99.9 % quantile cover the data's Haar coefficients'), so
        that a sensor with heavier-than-Gaussian errors is not exported overconfident
        (docs/filters.md, "Tails"). Default True; False: the data bound alone.
    fleet : sequence of (source, fits, log or None)
        WN+RW and white-noise filter formats: more units of the same sensor model, with the
        same channels as ``fits`` (the first unit, from ``log`` and ``source``). The file is
        the **fleet file**: per axis the largest N and K of every unit's own export (each with
        its tail factors from its log), so that no unit is exported overconfident
        (:func:`engine.formats.noise.fleet_noise`; docs/filters.md, "One file for a fleet").
        Refused by the reports and the Gauss-Markov formats, and with ``projection="fit"``.

    Examples
    --------
    A Kalibr ``imu.yaml`` of one gyroscope axis (the simulated white noise is
    ``sqrt(1e-6 / 100 Hz) = 1e-4 rad/s/sqrt(Hz)``, the random walk
    ``sqrt(1e-12 * 100 Hz) = 1e-5 rad/s^2/sqrt(Hz)``):

    >>> import numpy as np
    >>> import engine as eg
    >>> m = eg.parse_model("WN(1e-6) + RW(1e-12)")
    >>> x = m.simulate(2**15, rng=np.random.default_rng(1))
    >>> fit = eg.fit_gmwm(eg.wavelet_variance(x, fs=100.0, unit="rad/s"), "WN + RW")
    >>> text = eg.export(None, {"gyro_x": fit}, "kalibr", allow_partial=True)
    >>> for line in text.splitlines():
    ...     if line.startswith(("gyroscope_noise_density:", "gyroscope_random_walk:")):
    ...         key, value = line.split("#")[0].split(":")
    ...         print(key, f"{float(value):.3e}")
    gyroscope_noise_density 9.906e-05
    gyroscope_random_walk 7.675e-06
    """
    f = FORMATS.get(fmt)
    if f is None:
        raise ExportError(f"unknown export format {fmt!r}: use one of {', '.join(FORMATS)}")

    def tail_map(log: ImuLog | None, fits: Mapping[str, GMWMResult]) -> Any:
        return (
            log_tail_factors(log, fits)
            if tails
            and log is not None
            and projection == "bound"
            and data != "none"
            # the formats whose projection has a data bound (not sensor_msgs/Imu's white part)
            and (f.consumer not in (None, "WN") or fmt == "json")
            else None
        )

    if fleet and (not f.is_filter or projection == "fit"):
        raise ExportError(
            f"a fleet file is a filter format's bounded numbers: {fmt!r} with projection "
            f"{projection!r} takes one unit's fits (export each unit on its own)"
        )
    units_more = [FleetUnit(str(src), fs_, tail_map(lg, fs_)) for src, fs_, lg in fleet]
    text = f.writer(
        fits,
        intervals=intervals,
        log=log,
        units=units,
        source=source_text(source),
        rostopic=rostopic or (log.meta.get("topic") if log is not None else None) or "/imu0",
        allow_partial=allow_partial,
        inflate=inflate,
        filter_rate=filter_rate,
        projection=projection,
        horizon_s=horizon_s,
        band=band,
        confidence=confidence,
        ci=ci,
        vehicle_id=vehicle_id,
        scale_factor_std_ppm=scale_factor_std_ppm,
        consumers=consumers,
        data=data,
        tails=tail_map(log, fits),
        **({"fleet": units_more} if units_more else {}),
    )
    if path is not None:
        write_atomic(path, text)  # the one write of every format (engine._files)
    return text
