"""The options of an export (:class:`ExportOptions`): one typed, immutable object, built and
checked once by :func:`engine.formats.export` and read by every writer.

Each format declares which options it uses (:attr:`engine.formats.Format.options`); an option
that a format does not use and that was given a value other than its default is named in one
warning (:meth:`ExportOptions.ignored_by`). Like the format records, this module imports no
writer (docs/fit-to-filter.md, "Export options").
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

from ..errors import ExportError

if TYPE_CHECKING:  # pragma: no cover
    from ..fit import GMWMResult
    from ..inference import ParamInterval
    from ..io import ImuLog
    from .tails import TailFactors

__all__ = ["ExportOptions", "FleetUnit", "PROJECTIONS", "DATA_BOUNDS", "CONTEXT", "check_inflate"]

#: The values of :attr:`ExportOptions.projection`.
PROJECTIONS = ("bound", "plain", "fit")

#: The values of :attr:`ExportOptions.data`: what of the empirical WV the bound covers at its
#: dyadic scales in the band, as the WV's attribute (``""``: nothing): its interval's lower
#: limit (the default: the data give no evidence that the sensor is quieter than the file
#: there), its estimate, its upper limit, or nothing (the fitted model alone).
DATA_BOUNDS: dict[str, str] = {
    "low": "ci_low",
    "estimate": "variance",
    "high": "ci_high",
    "none": "",
}

#: What the fits are (not how to write them): every format accepts these, and using none of
#: them is never warned about.
CONTEXT = ("intervals", "log", "units", "source")

#: Options whose value a format refuses outright when it does not use them (an error, not the
#: warning of :meth:`ExportOptions.ignored_by`): a report's inflate factor, a report's fleet.
REFUSED = ("inflate", "fleet")


def check_inflate(inflate: float) -> float:
    """The ``inflate`` factor as a float; refuses a non-finite or non-positive one."""
    try:
        f = float(inflate)
    except (TypeError, ValueError):
        f = math.nan
    if isinstance(inflate, bool) or not (math.isfinite(f) and f > 0):
        raise ExportError(f"inflate must be a positive number, got {inflate!r}")
    return f


@dataclass(frozen=True, eq=False)
class FleetUnit:
    """One more unit of a fleet file (``engine.export(..., fleet=)``): its fits, with the
    same channels as the first unit's, and their tail factors.

    Attributes
    ----------
    source : str
        The unit's log (for the file's header and messages).
    fits : mapping of str to GMWMResult
        Channel to fit.
    tails : mapping of str to TailFactors, optional
        Per channel (:func:`~engine.formats.tails.log_tail_factors` of the unit's log); None:
        no tail factors.
    """

    source: str
    fits: Mapping[str, GMWMResult]
    tails: Mapping[str, TailFactors] | None = None


@dataclass(frozen=True)
class ExportOptions:
    """How to write an export; every field has a default (the file of the fit alone).

    Built and checked once by :func:`engine.formats.export` from its keywords; a bad value is
    one :class:`~engine.errors.ExportError` that names the option, the value and what it
    must be. The formats' writers take ``(fits, options)`` and read the fields.

    Attributes
    ----------
    intervals : mapping of channel to sequence of ParamInterval, optional
        Parameter intervals per channel (the JSON report, the datasheets).
    log : ImuLog, optional
        The log of the fits: the JSON report's log section, the tail factors of the data bound
        (:attr:`tails`) and the default :attr:`rostopic` (a bag's IMU topic).
    units : mapping of channel to unit, optional
        Signal unit per channel (default each WV's unit).
    source : str
        The source name written in the file (a path given as a path is its string).
    rostopic : str, optional
        Kalibr/OpenVINS ``rostopic`` (default: the bag's IMU topic, else ``/imu0``).
    allow_partial : bool
        Kalibr: a file with only gyroscope or only accelerometer keys.
    inflate : float
        Filter formats: every noise value times this factor (variances times its square),
        written in the header; must be finite and > 0 (the reports refuse any but 1).
    filter_rate : float [Hz], optional
        The rate the consumer's filter predicts at (required by the formats whose records say
        ``needs_filter_rate``); the other filter formats: the filter's step of the projection
        and the rate of their per-sample values (default the log's rate).
    projection : {"bound", "plain", "fit"}
        Filter formats and the JSON report: projected onto the consumer's noise model and
        over-bounded (default), the projection rule alone, or the fit's own terms one by one.
    horizon_s : float [s], optional
        The longest time the filter runs unaided: the longest WV scale the bound covers
        (default the log length); given, the tail factors apply at the scales from
        ``horizon_s / TAIL_SPAN`` to it only (:func:`~engine.formats.tails.tail_band`).
    band : (float, float) [s], optional
        The WV scales ``(low, high)`` the bound covers, ``0 < low <= high`` (default two
        filter steps to the horizon).
    confidence : float, optional
        Bound the upper limit of the fitted WV's interval at this level in (0, 1) instead of
        the WV itself.
    ci : {"asymptotic", None}
        The intervals of the exported values (None: none, faster).
    vehicle_id : int
        PX4: the MAVLink system id of the ``.params`` lines, 1..255.
    scale_factor_std_ppm : float [ppm], optional
        KF-GINS: ``gsstd``/``asstd`` (not identified by GMWM; default 1000 ppm).
    consumers : tuple of str, optional
        JSON report: the consumer models or filter formats each fit is projected onto
        (default ``("WN+RW",)``).
    data : {"low", "estimate", "high", "none"}
        What of the empirical WV the bound covers too (:data:`DATA_BOUNDS`).
    tails : bool
        The data bound's variance times the log's tail factors (default True; needs
        :attr:`log`).
    fleet : tuple of FleetUnit
        More units of the same sensor model: the fleet file (WN+RW and white-noise formats).
    tail_factors : mapping of channel to TailFactors, optional
        Not an option: the tail factors :func:`~engine.formats.export` computed from
        :attr:`log` for this format (None: none apply).
    """

    intervals: Mapping[str, Sequence[ParamInterval]] | None = None
    log: ImuLog | None = None
    units: Mapping[str, str] | None = None
    source: str = ""
    rostopic: str | None = None
    allow_partial: bool = False
    inflate: float = 1.0
    filter_rate: float | None = field(default=None, metadata={"unit": "Hz", "positive": True})
    projection: str = "bound"
    horizon_s: float | None = field(default=None, metadata={"unit": "s", "positive": True})
    band: tuple[float, float] | None = field(default=None, metadata={"unit": "s"})
    confidence: float | None = None
    ci: str | None = "asymptotic"
    vehicle_id: int = 1
    scale_factor_std_ppm: float | None = field(
        default=None, metadata={"unit": "ppm", "positive": True}
    )
    consumers: tuple[str, ...] | None = None
    data: str = "low"
    tails: bool = True
    fleet: tuple[FleetUnit, ...] = ()
    tail_factors: Mapping[str, TailFactors] | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "inflate", check_inflate(self.inflate))
        for name, must in (
            ("band", "two WV scales (low, high) in s with 0 < low <= high, or None"),
            ("consumers", "names of consumer models or filter formats"),
            ("fleet", "a sequence of FleetUnit"),
        ):
            v: Any = getattr(self, name)
            if v is None:
                continue
            if isinstance(v, str) and name == "consumers":  # one name, not its letters
                v = (v,)
            try:
                object.__setattr__(self, name, tuple(v))
            except TypeError:
                raise ExportError(f"{name} must be {must}, got {v!r}") from None
        self._check()

    def _check(self) -> None:
        """One :class:`ExportError` for the first bad value: which option, what it must be."""

        def bad(name: str, must: str) -> ExportError:
            return ExportError(f"{name} must be {must}, got {getattr(self, name)!r}")

        def number(v: Any) -> bool:
            return isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)

        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            if f.metadata.get("positive") and v is not None and not (number(v) and v > 0):
                raise bad(f.name, f"a positive number ({f.metadata['unit']}) or None")
        if self.projection not in PROJECTIONS:
            raise bad("projection", f"one of {', '.join(PROJECTIONS)}")
        if self.data not in DATA_BOUNDS:
            raise bad("data", f"one of {', '.join(DATA_BOUNDS)}")
        if self.band is not None and not (
            len(self.band) == 2
            and all(number(v) for v in self.band)
            and 0 < self.band[0]
            and self.band[0] <= self.band[1]
        ):
            raise bad("band", "two WV scales (low, high) in s with 0 < low <= high, or None")
        c = self.confidence
        if c is not None and not (number(c) and 0 < c < 1):
            raise bad("confidence", "a level in (0, 1) or None")
        if self.ci not in ("asymptotic", None):
            raise bad("ci", "'asymptotic' or None")
        v = self.vehicle_id
        if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= 255:
            raise bad("vehicle_id", "a MAVLink system id 1..255")
        for name in ("allow_partial", "tails"):
            if not isinstance(getattr(self, name), bool):
                raise bad(name, "True or False")
        if self.rostopic is not None and not isinstance(self.rostopic, str):
            raise bad("rostopic", "a topic name (str) or None")
        if self.consumers is not None and not all(isinstance(x, str) for x in self.consumers):
            raise bad("consumers", "names of consumer models or filter formats")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The options a user gives (every field but :attr:`tail_factors`)."""
        return tuple(f.name for f in dataclasses.fields(cls) if f.name != "tail_factors")

    def given(self) -> dict[str, Any]:
        """The options whose value is not the default (in field order)."""
        out: dict[str, Any] = {}
        for f in dataclasses.fields(self):
            if f.name == "tail_factors":
                continue
            v = getattr(self, f.name)
            if not (v is f.default or (not isinstance(v, Mapping) and v == f.default)):
                out[f.name] = v
        return out

    def ignored_by(self, name: str, uses: Sequence[str]) -> str:
        """One line naming the options given that the format ``name`` does not use (``uses``,
        its :attr:`~engine.formats.Format.options`), or ``""``. The :data:`CONTEXT` (what the
        fits are) is never named, nor the options a format refuses (:data:`REFUSED`)."""
        skip = {*uses, *CONTEXT, *REFUSED}
        extra = {k: v for k, v in self.given().items() if k not in skip}
        if not extra:
            return ""
        said = ", ".join(f"{k}={v!r}" for k, v in extra.items())
        return f"the {name} export does not use {said}: ignored"
