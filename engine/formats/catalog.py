"""The export formats as records (:class:`Format`, :data:`FORMATS`): what each writes, for
which consumer noise model, with which capabilities, and where its writer is.

A record names its writer (``"vio:openvins_yaml"``, a function of a module of this package)
instead of holding it, so that reading the formats (the ``gmwm export`` options and help, the
app's format menus, the consumer of a format name in the projection) imports no writer; the
writer's module is imported when a file is written (:func:`engine.formats.registry.export`).
A new format is one writer ``writer(fits, options) -> str`` (``options`` an
:class:`~engine.formats.options.ExportOptions`) in a module of this package and one
:func:`register` call below, which names the options the writer reads.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from .options import CONTEXT, ExportOptions

__all__ = [
    "Format",
    "FORMATS",
    "FORMAT_CONSUMERS",
    "CONSUMER_PARAMS",
    "FLEET_CONSUMERS",
    "VALUE_KINDS",
    "FILTER_OPTIONS",
    "register",
]

#: Consumer noise models and the parameters they take.
CONSUMER_PARAMS: dict[str, tuple[str, ...]] = {
    "WN+RW": ("N", "K"),
    "WN+GM": ("N", "sigma_b", "T_c"),
    "WN": ("N",),
}

#: The consumer models a fleet file can be written for (:attr:`Format.fleet_file`): their WV
#: grows with each of their parameters, so per axis the largest N and K over the units bound
#: every unit. Not a Gauss-Markov bias: its T_c differs per unit, and the largest sigma_b at
#: another unit's T_c does not bound (docs/filters.md, "One file for a fleet").
FLEET_CONSUMERS = ("WN+RW", "WN")

#: The values of :attr:`Format.values`: how a filter format's numbers relate to a rate.
VALUE_KINDS = {
    "density": "continuous-time densities (rate-free); the consumer's rate is written",
    "per-sample": "per-sample standard deviations or variances at the consumer's IMU rate",
    "per-step": "standard deviations per filter step at the filter's prediction rate",
}


#: The options every filter format reads (its projection, bound and file values):
#: :class:`~engine.formats.options.ExportOptions` fields.
FILTER_OPTIONS = (
    "inflate",
    "filter_rate",
    "projection",
    "horizon_s",
    "band",
    "confidence",
    "ci",
    "data",
    "tails",
    "fleet",
)


#: A writer: the fits (channel to :class:`~engine.fit.GMWMResult`) and the options -> the text.
Writer = Callable[[Mapping[str, Any], ExportOptions], str]


def _resolve(ref: Callable[..., Any] | str) -> Callable[..., Any]:
    if not isinstance(ref, str):
        return ref
    module, _, name = ref.partition(":")
    func: Callable[..., Any] = getattr(importlib.import_module(f".{module}", __package__), name)
    return func


@dataclass(frozen=True)
class Format:
    """An export format: ``writer(fits, options) -> text``; ``reader(path or text)``.

    The writer takes the fits (channel to :class:`~engine.fit.GMWMResult`) and one
    :class:`~engine.formats.options.ExportOptions`, and reads only the fields its record names
    in :attr:`options` (and the context: intervals, log, units, source).

    The capabilities of a filter format are declared here once and read by the writers'
    callers, the CLI and the app:

    Attributes
    ----------
    name : str
        What the user names (``gmwm export --format NAME``, ``eg.export(..., fmt=NAME)``).
    description : str
        One line: the consumer and the file.
    write, read : callable or str
        The writer and the reader (None: no reader), or where they are: ``"MODULE:FUNCTION"``
        in this package, imported on first use (:attr:`writer`, :attr:`reader`).
    suffix : str
        The file's suffix (``".yaml"``).
    consumer : str or None
        The consumer's noise model (``"WN+RW"``, ``"WN+GM"``, ``"WN"``;
        :data:`CONSUMER_PARAMS`); None for the reports.
    values : str or None
        A key of :data:`VALUE_KINDS` (None for the reports).
    needs_filter_rate : bool
        The file is wrong without the filter's rate (``filter_rate`` required).
    fleet_file : bool
        (Read from the consumer model.) One file can be written for a fleet of units
        (:data:`FLEET_CONSUMERS`).
    partial : bool
        The writer writes a partial file (one sensor) without being asked: the fits of a
        gyroscope alone (or an accelerometer alone) give a file whose other sensor is left
        out or marked not fitted (``matlab``, ``ros-imu``). False: a filter file needs a
        gyroscope and an accelerometer, unless the format takes ``allow_partial`` and it is
        given (``kalibr``; :attr:`needs_both_sensors`).
    bias : str
        The consumer's bias model in words (``"random walk"``, ``"Gauss-Markov, one T_c per
        file"`` ...); ``""`` for none.
    options : tuple of str
        The :class:`~engine.formats.options.ExportOptions` fields the writer reads besides the
        context (``intervals``, ``log``, ``units``, ``source``): what ``gmwm export --help``
        lists for the format; an option given that is not here is named in one warning.
    noise : callable or str or None
        A filter format's numbers: ``noise(fits, options, allow_partial) ->``
        :class:`~engine.formats.noise.ImuNoise`, whose ``projections`` are what the file
        writes (:func:`engine.formats.projections`, the app's preview); None: the one call
        most filter writers make, :func:`~engine.formats.noise.noise_for` with the format's
        name as the consumer. Or where it is (``"MODULE:FUNCTION"``; :attr:`noise_of`).
    """

    name: str
    description: str
    write: Writer | str
    read: Callable[[Any], Any] | str | None = None
    suffix: str = ".txt"
    consumer: str | None = None
    values: str | None = None
    needs_filter_rate: bool = False
    partial: bool = False
    bias: str = ""
    options: tuple[str, ...] = ()
    noise: Callable[..., Any] | str | None = None

    @property
    def writer(self) -> Writer:
        """The writer ``writer(fits, options) -> str`` (its module imported on first use)."""
        return _resolve(self.write)

    @property
    def reader(self) -> Callable[[Any], Any] | None:
        """The reader of the format's files, or None (its module imported on first use)."""
        return None if self.read is None else _resolve(self.read)

    @property
    def noise_of(self) -> Callable[..., Any]:
        """:attr:`noise` as a function ``(fits, options, allow_partial) -> ImuNoise`` (its
        module imported on first use)."""
        if self.noise is not None:
            return _resolve(self.noise)
        noise_for = _resolve("noise:noise_for")
        return lambda fits, o, allow_partial: noise_for(
            fits, self.description, o, allow_partial=allow_partial, consumer=self.name
        )

    def takes(self, option: str) -> bool:
        """The writer reads ``option`` (an :class:`~engine.formats.options.ExportOptions`
        field): one of :attr:`options` or of the context every format accepts."""
        return option in self.options or option in CONTEXT

    @property
    def fleet_file(self) -> bool:
        """The format can be written for a fleet (``export(..., fleet=...)``, ``gmwm batch
        --export``): a filter format whose consumer model is one of :data:`FLEET_CONSUMERS`."""
        return self.consumer in FLEET_CONSUMERS

    @property
    def needs_both_sensors(self) -> bool:
        """A filter format that writes no file of one sensor, whatever the options: it neither
        writes a partial file (:attr:`partial`) nor takes ``allow_partial``."""
        return self.is_filter and not self.partial and not self.takes("allow_partial")

    @property
    def is_filter(self) -> bool:
        """A filter or simulator format (it has a consumer noise model)."""
        return self.consumer is not None


#: Registered formats by name, in registration order.
FORMATS: dict[str, Format] = {}

#: The consumer model of each filter format: an index that :func:`register` fills from each
#: :class:`Format`'s ``consumer`` (declared there, once).
FORMAT_CONSUMERS: dict[str, str] = {}


def register(fmt: Format) -> Format:
    """Add (or replace) a format; returns it. A filter format's consumer model is indexed in
    :data:`FORMAT_CONSUMERS` (what the projection's ``consumer_of`` reads)."""
    if fmt.consumer is not None and fmt.consumer not in CONSUMER_PARAMS:
        raise ValueError(f"format {fmt.name!r}: unknown consumer model {fmt.consumer!r}")
    if fmt.values is not None and fmt.values not in VALUE_KINDS:
        raise ValueError(f"format {fmt.name!r}: values must be one of {', '.join(VALUE_KINDS)}")
    unknown = [o for o in fmt.options if o not in ExportOptions.names() or o in CONTEXT]
    if unknown:
        raise ValueError(f"format {fmt.name!r}: unknown options {unknown} (ExportOptions fields)")
    FORMATS[fmt.name] = fmt
    if fmt.consumer is not None:
        FORMAT_CONSUMERS[fmt.name] = fmt.consumer
    else:
        FORMAT_CONSUMERS.pop(fmt.name, None)
    return fmt


_RW, _GM = "random walk (one K per axis or per sensor)", "Gauss-Markov (T_c, sigma_b)"
for _fmt in (
    Format(
        "kalibr",
        "Kalibr imu.yaml",
        "registry:kalibr_text",
        ".io.kalibr:read_kalibr",
        ".yaml",
        "WN+RW",
        "density",
        bias=_RW,
        options=(*FILTER_OPTIONS, "rostopic", "allow_partial"),
    ),
    Format(
        "json",
        "JSON report",
        "registry:json_text",
        None,
        ".json",
        options=(*(o for o in FILTER_OPTIONS if o not in ("inflate", "fleet")), "consumers"),
    ),
    Format("csv", "CSV of the WV and implied curves", "registry:curves_text", None, ".csv"),
    Format("datasheet", "readable datasheet table", "registry:datasheet_table_text", None),
    Format("datasheet-csv", "datasheet CSV", "registry:datasheet_csv_text", None, ".csv"),
    Format(
        "openvins",
        "OpenVINS kalibr_imu_chain.yaml",
        "vio:openvins_yaml",
        None,
        ".yaml",
        "WN+RW",
        "density",
        bias=_RW,
        options=(*FILTER_OPTIONS, "rostopic"),
    ),
    Format(
        "basalt",
        "Basalt calibration JSON (IMU noise)",
        "vio:basalt_json",
        None,
        ".json",
        "WN+RW",
        "density",
        bias=_RW,
        options=FILTER_OPTIONS,
    ),
    Format(
        "orbslam3",
        "ORB-SLAM3 settings IMU.* keys",
        "vio:orbslam3_yaml",
        None,
        ".yaml",
        "WN+RW",
        "density",
        bias=_RW,
        options=FILTER_OPTIONS,
    ),
    Format(
        "px4",
        "PX4 EKF2 noise parameters (.params)",
        "autopilot:px4_params",
        None,
        ".params",
        "WN+RW",
        "per-step",
        needs_filter_rate=True,
        bias=_RW,
        options=(*FILTER_OPTIONS, "vehicle_id"),
    ),
    Format(
        "ardupilot",
        "ArduPilot EKF3 noise parameters (.param)",
        "autopilot:ardupilot_params",
        None,
        ".param",
        "WN+RW",
        "per-step",
        needs_filter_rate=True,
        bias=_RW,
        options=FILTER_OPTIONS,
    ),
    Format(
        "matlab",
        "MATLAB gyroparams/accelparams .m",
        "sim:matlab_m",
        None,
        ".m",
        "WN+RW",
        "density",
        partial=True,
        bias=_RW,
        options=FILTER_OPTIONS,
    ),
    Format(
        "gazebo",
        "Gazebo classic PX4/RotorS IMU plugin (GM bias)",
        "sim:gazebo_xml",
        None,
        ".xml",
        "WN+GM",
        "density",
        bias=f"{_GM}, one per sensor triad",
        options=FILTER_OPTIONS,
    ),
    Format(
        "gz-sim",
        "gz-sim SDF <imu> <noise> (GM bias)",
        "sim:gz_sim_sdf",
        None,
        ".sdf",
        "WN+GM",
        "per-sample",
        bias=f"{_GM} per axis",
        options=FILTER_OPTIONS,
    ),
    Format(
        "kf-gins",
        "KF-GINS imunoise (GM bias)",
        "ins:kfgins_yaml",
        None,
        ".yaml",
        "WN+GM",
        "density",
        bias=f"{_GM}, one T_c for the whole file",
        options=(*FILTER_OPTIONS, "scale_factor_std_ppm"),
        noise="ins:kfgins_noise",
    ),
    Format(
        "ros-imu",
        "sensor_msgs/Imu covariances",
        "ins:ros_imu_yaml",
        None,
        ".yaml",
        "WN",
        "per-sample",
        partial=True,
        options=FILTER_OPTIONS,
    ),
    Format(
        "vins",
        "VINS-Mono/Fusion acc_n/gyr_n/acc_w/gyr_w",
        "vio:vins_yaml",
        None,
        ".yaml",
        "WN+RW",
        "per-sample",
        bias=_RW,
        options=FILTER_OPTIONS,
    ),
):
    register(_fmt)
