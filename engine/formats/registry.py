"""Writing the export formats: :func:`export`, and the writers of the reports and the Kalibr file.

The formats themselves (name, consumer model, capabilities, where the writer is) are records
in :mod:`engine.formats.catalog`, which imports no writer. A new filter format (OpenVINS,
Basalt, VINS ...) is one module with a writer ``writer(fits, options) -> str`` (``options``
an :class:`~engine.formats.options.ExportOptions`), and a reader where one exists, that takes
its numbers from the one datasheet table (:mod:`engine.units`), plus one
:func:`~engine.formats.catalog.register` call in the catalog that names the options it reads.
"""

from __future__ import annotations

import dataclasses
import json
import os
import warnings
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
from .noise import FleetUnit, noise_for
from .options import ExportOptions
from .projection import Projection
from .report import curves_csv, fit_report
from .tails import log_tail_factors

if TYPE_CHECKING:  # pragma: no cover
    from ..io import ImuLog

__all__ = [
    "Format",
    "FORMATS",
    "VALUE_KINDS",
    "register",
    "export",
    "prepared_options",
    "projections",
    "kalibr_text",
    "json_text",
    "curves_text",
    "datasheet_table_text",
    "datasheet_csv_text",
]


def kalibr_text(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """Kalibr ``imu.yaml``: the bounded WN+RW projection (max over axes), or with
    ``projection="fit"`` the fit's own terms (:func:`~engine.formats.kalibr.kalibr_imu`)."""
    rostopic = o.rostopic or "/imu0"
    if o.projection == "fit":
        f = o.inflate
        kal = kalibr_imu(
            fits,
            units=o.units,
            rostopic=rostopic,
            source=o.source,
            allow_partial=o.allow_partial,
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
    nz = noise_for(fits, "Kalibr imu.yaml", o, allow_partial=o.allow_partial, consumer="kalibr")
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
        rostopic=rostopic,
        comments=nz.header,
        warnings=nz.warnings,
    )
    return kal.to_yaml()


def json_text(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """The JSON report (:func:`~engine.formats.report.fit_report`) of the options."""
    rep = fit_report(
        fits,
        intervals=o.intervals,
        log=o.log,
        units=o.units,
        source=o.source,
        consumers=o.consumers,
        projection=o.projection,
        filter_rate=o.filter_rate,
        horizon_s=o.horizon_s,
        band=o.band,
        confidence=o.confidence,
        ci=o.ci,
        data=o.data,
        tails=o.tail_factors,
    )
    return json.dumps(rep, indent=1, allow_nan=False) + "\n"


def datasheet_table_text(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """The readable datasheet table (:func:`~engine.formats.datasheet.datasheet_text`)."""
    return datasheet_text(datasheet_table(fits, intervals=o.intervals, units=o.units)) + "\n"


def datasheet_csv_text(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """The datasheet CSV (:func:`~engine.formats.datasheet.datasheet_csv`)."""
    return datasheet_csv(datasheet_table(fits, intervals=o.intervals, units=o.units))


def curves_text(fits: Mapping[str, GMWMResult], o: ExportOptions) -> str:
    """The CSV of the WV and implied curves (:func:`~engine.formats.report.curves_csv`)."""
    return curves_csv(fits)


def prepared_options(
    fits: Mapping[str, GMWMResult],
    fmt: str,
    *,
    fleet: Sequence[tuple[str, Mapping[str, GMWMResult], ImuLog | None]] = (),
    **options: Any,
) -> tuple[Format, ExportOptions]:
    """The format's record and the options its writer gets, as :func:`export` makes them:
    checked once (one :class:`~engine.errors.ExportError` naming a bad or unknown option, a
    fleet the record does not take, a missing filter rate; a :class:`UserWarning` naming an
    option the format does not read), with the context filled in (the rostopic, the tail
    factors of the logs, the fleet's units). Parameters as :func:`export`.
    """
    f = FORMATS.get(fmt)
    if f is None:
        raise ExportError(f"unknown export format {fmt!r}: use one of {', '.join(FORMATS)}")
    unknown = [k for k in options if k not in ExportOptions.names() or k == "fleet"]
    if unknown:
        raise ExportError(
            f"unknown export option(s) {', '.join(unknown)}: the options are "
            f"{', '.join(n for n in ExportOptions.names() if n != 'fleet')} and fleet"
        )
    if "source" in options:
        options["source"] = source_text(options["source"])
    o = ExportOptions(**options)
    if o.inflate != 1.0 and "inflate" not in f.options:
        raise ExportError(
            f"inflate= is for filter formats; the {f.description} reports the fit itself "
            "(inflate 1)"
        )
    if fleet and f.is_filter and not f.fleet_file:
        raise ExportError(
            f"{fmt}: a fleet file takes, per axis, the largest white noise and random walk of "
            f"the units (the formats {', '.join(n for n, g in FORMATS.items() if g.fleet_file)}"
            f"); the {f.consumer} consumer's Gauss-Markov bias has a correlation time per "
            "unit, which one value cannot bound: export each unit's own file (gmwm export LOG)"
        )
    if fleet and ("fleet" not in f.options or o.projection == "fit"):
        raise ExportError(
            f"a fleet file is a filter format's bounded numbers: {fmt!r} with projection "
            f"{o.projection!r} takes one unit's fits (export each unit on its own)"
        )
    if f.needs_filter_rate and o.filter_rate is None:
        raise ExportError(
            f"the {fmt} export needs the filter rate in Hz its EKF predicts at (filter_rate=...):"
            " its noise parameters are per filter step"
        )
    ignored = o.ignored_by(fmt, f.options)
    if ignored:
        warnings.warn(ignored, UserWarning, stacklevel=3)

    def tail_map(log: ImuLog | None, unit_fits: Mapping[str, GMWMResult]) -> Any:
        return (
            log_tail_factors(log, unit_fits)
            if o.tails
            and log is not None
            and o.projection == "bound"
            and o.data != "none"
            # the formats whose projection has a data bound (not sensor_msgs/Imu's white part)
            and (f.consumer not in (None, "WN") or fmt == "json")
            else None
        )

    topic = o.log.meta.get("topic") if o.log is not None else None
    o = dataclasses.replace(
        o,
        rostopic=o.rostopic or topic or "/imu0",
        tail_factors=tail_map(o.log, fits),
        fleet=tuple(FleetUnit(str(src), fs_, tail_map(lg, fs_)) for src, fs_, lg in fleet),
    )
    return f, o


def projections(fits: Mapping[str, GMWMResult], fmt: str, **options: Any) -> dict[str, Projection]:
    """The projection of each fit onto a filter format's consumer model, as :func:`export`
    computes the file's numbers with the same options (its checks, tail factors and the
    format's own numbers, :attr:`Format.noise`: KF-GINS's one ``T_c``), without writing the
    file: what the app's export preview shows.

    A file of one sensor is projected too (the file itself may need both). Empty for a report
    and for ``projection="fit"`` (the fit's own terms: nothing is projected).

    Parameters
    ----------
    fits : mapping of channel name to GMWMResult
    fmt : str
        A name of :data:`FORMATS`.
    **options
        As :func:`export` (the fields of :class:`~engine.formats.ExportOptions`).

    Returns
    -------
    dict of channel to Projection

    Raises
    ------
    ExportError
        As :func:`export`: a bad option, or a fit the consumer cannot take.
    """
    f = FORMATS.get(fmt)
    if f is not None and not f.is_filter:
        return {}
    f, o = prepared_options(fits, fmt, **options)
    if o.projection == "fit":
        return {}
    return dict(f.noise_of(fits, o, True).projections)


def export(
    path: str | os.PathLike[str] | None,
    fits: Mapping[str, GMWMResult],
    fmt: str,
    *,
    fleet: Sequence[tuple[str, Mapping[str, GMWMResult], ImuLog | None]] = (),
    **options: Any,
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
    fleet : sequence of (source, fits, log or None)
        WN+RW and white-noise filter formats: more units of the same sensor model, with the
        same channels as ``fits`` (the first unit, from ``log`` and ``source``). The file is
        the **fleet file**: per axis the largest N and K of every unit's own export (each with
        its tail factors from its log), so that no unit is exported overconfident
        (:func:`engine.formats.noise.fleet_noise`; docs/filters.md, "One file for a fleet").
        Refused by the reports, by the formats whose record says no
        (:attr:`Format.fleet_file`: the Gauss-Markov ones) and with ``projection="fit"``.
    **options
        The fields of :class:`engine.formats.ExportOptions`, each documented there with its
        unit and default: ``intervals``, ``log``, ``units``, ``source`` (what the fits are),
        ``rostopic``, ``allow_partial``, ``inflate``, ``filter_rate`` [Hz], ``projection``,
        ``horizon_s`` [s], ``band`` [s], ``confidence``, ``ci``, ``vehicle_id``,
        ``scale_factor_std_ppm``, ``consumers``, ``data``, ``tails``. They are checked once
        (a bad value, or an unknown name: one :class:`~engine.errors.ExportError` naming
        it); the format's record says which it uses (:attr:`Format.options`, listed by
        ``gmwm export --help``): one given that the format does not use is named in a
        :class:`UserWarning`, except ``inflate``, which the reports refuse. Every user-given
        string is written with its control characters escaped
        (:func:`engine.formats.common.clean_text`): a newline in a file name cannot add a line
        (a parameter, a key) to the file.

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
    f, o = prepared_options(fits, fmt, fleet=fleet, **options)
    text = f.writer(fits, o)
    if path is not None:
        write_atomic(path, text)  # the one write of every format (engine._files)
    return text
