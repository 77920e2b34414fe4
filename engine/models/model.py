"""Latent processes and their sums: the :class:`Process` base class, :class:`Model`, parsing.

:class:`Process` is the interface of one latent process (values, bounds, the unconstrained
space, the fitting basis, WV, simulation) and its algebra: ``WN() + RW() + 2 * GM()`` builds a
:class:`Model`. The concrete processes (:mod:`engine.models.processes`) register themselves
in :data:`PROCESS_TYPES`, which :func:`parse_model` reads for ``"2*GM+WN+RW"``.

A :class:`Model` is an immutable, flat tuple of processes kept in a canonical order
(GM, AR1, QN, WN, RW, DR), so that ``"WN+RW+2*GM"`` and ``"2*GM+RW+WN"`` are the same model.
Parameter names are unique: ``WN.sigma2``, ``GM_1.beta``, ``GM_2.beta`` (the index counts the
processes of one kind, from 1, and appears only when there are several).
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass, field, fields
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, ClassVar, Literal

import numpy as np

from .._limits import check_sample_count
from .._quantity import Quantity, squared
from ..errors import ModelError
from .spectrum import FilterTerms, PsdTerms, Spectral

__all__ = [
    "Param",
    "param",
    "Process",
    "PsdTerms",
    "FilterTerms",
    "Model",
    "parse_model",
    "ModelError",
    "PROCESS_TYPES",
    "TO_UNCONSTRAINED",
    "FROM_UNCONSTRAINED",
]

# code -> process class, in the canonical order (GM, AR1, QN, WN, RW, DR); every concrete
# process registers itself here when its class is created (engine.models.processes)
PROCESS_TYPES: dict[str, type[Process]] = {}

#: Behaviour every concrete process must implement (checked when its class is created).
BEHAVIOUR = ("basis", "simulate", "psd_terms", "filter_terms")
#: ... and, for a process with a non-linear parameter (AR1, GM), these too: the map between
#: its parameter and the fitter's value, and its search coordinate in its own terms.
NONLINEAR_BEHAVIOUR = (
    "phi_from_nl",
    "nl_from_phi",
    "search_range",
    "search_axis",
    "search_nl",
    "search_of_nl",
)
#: ... and, for a process that channels may share (multivariate models), this one.
SHARED_BEHAVIOUR = ("simulate_shared",)
#: Class attributes every concrete process must give (non-empty).
DESCRIPTIVE = ("description", "display_name", "help", "quantities")


_MAX_REPEAT = 20  # more AR1/GM terms than this cannot be identified from any real log


def _tanh_open(u: float) -> float:
    """``tanh(u)`` kept strictly inside (-1, 1) (a coefficient's open range)."""
    return min(max(math.tanh(u), -1 + 2**-52), 1 - 2**-52)


# the transforms to the unconstrained space and back, by name
_TRANSFORMS: dict[str, tuple[Callable[[float], float], Callable[[float], float]]] = {
    "log": (math.log, math.exp),  # a variance or a rate, > 0
    "atanh": (math.atanh, _tanh_open),  # a coefficient in (-1, 1)
    "identity": (float, float),  # either sign (a drift's slope)
}


def variance_unit(unit: str) -> str:
    """The unit of a variance-like parameter for a signal in ``unit`` (``(deg/s)^2``)."""
    return squared(unit)


def per_sample_unit(unit: str) -> str:
    """The unit of a slope per sample for a signal in ``unit`` (``deg/s per sample``)."""
    return f"{unit} per sample"


def rate_unit(unit: str) -> str:
    """The unit of a rate in 1/s, whatever the signal's unit."""
    return "1/s"


def coefficient_unit(unit: str) -> str:
    """The unit of a per-sample coefficient (an AR or MA coefficient): none."""
    return "1 (per sample)"


@dataclass(frozen=True)
class Param:
    """What a process declares about one of its parameters, as the field's metadata.

    Declared with :func:`param` on the process's dataclass field; :meth:`Process.params`
    reads them. The fit's unconstrained space, the units (:func:`engine.units.param_unit`),
    the app's what-if sliders and the parameter bounds all read this record, so a
    parameter's facts are written once, beside the parameter.

    Attributes
    ----------
    transform : {"log", "atanh", "identity"}
        The map to the unconstrained space: ``log`` for a variance or a rate (> 0),
        ``atanh`` for a coefficient in (-1, 1), ``identity`` for a value of either sign.
    unit : callable
        ``unit(u)``: the parameter's unit for a signal in ``u`` (``(deg/s)^2``, ``1/s`` ...).
    bounds : (float, float)
        Admissible range (open where the transform is).
    slider : {"log10", "log10(1-x)", "linear"}
        How the app's what-if slider moves the value: by decades of the value (variances,
        rates), by decades of ``1 - x`` (a coefficient near 1: an AR1's phi), or linearly
        over the bounds (a coefficient of either sign).
    magnitude : bool
        The WV depends on the value's magnitude only (a drift's slope ``omega``: its sign is
        not identified), so an interval is one of ``|value|``: it stops at 0.
    """

    transform: Literal["log", "atanh", "identity"] = "log"
    unit: Callable[[str], str] = variance_unit
    bounds: tuple[float, float] = (0.0, math.inf)
    slider: Literal["log10", "log10(1-x)", "linear"] = "log10"
    magnitude: bool = False

    def to_unconstrained(self, v: float) -> float:
        """The value mapped to R (the transform)."""
        return _TRANSFORMS[self.transform][0](v)

    def from_unconstrained(self, u: float) -> float:
        """The value of an unconstrained ``u`` (inverse of :meth:`to_unconstrained`)."""
        return _TRANSFORMS[self.transform][1](u)


def param(
    transform: Literal["log", "atanh", "identity"] = "log",
    unit: Callable[[str], str] = variance_unit,
    bounds: tuple[float, float] = (0.0, math.inf),
    slider: Literal["log10", "log10(1-x)", "linear"] = "log10",
    *,
    magnitude: bool = False,
) -> Any:
    """A process's parameter field (unknown by default) with its :class:`Param` record.

    Examples
    --------
    An AR1 declares its coefficient as
    ``phi: float | None = param("atanh", coefficient_unit, (-1.0, 1.0), "log10(1-x)")``.
    """
    spec = Param(transform, unit, bounds, slider, magnitude)
    return field(default=None, metadata={"param": spec})


#: Each process class's :class:`Param` records, by parameter name (:meth:`Process.params`).
_PARAMS: dict[type, Mapping[str, Param]] = {}


@dataclass(frozen=True)
class Process(Spectral):
    """Base class of a latent process.

    A concrete process is a frozen dataclass whose fields are its parameters, declared with
    its rank and description as class arguments::

        @dataclass(frozen=True, repr=False)
        class WN(Process, order=3, description="white noise"):
            sigma2: float | None = None

    Its ``code`` is the class name and ``param_names`` its fields, in order; it registers
    itself in :data:`PROCESS_TYPES`, which is how :func:`parse_model` finds it.

    Each field is declared with :func:`param`, whose :class:`Param` record gives the
    parameter's transform to the unconstrained space, unit, bounds and slider scale; a process
    with a non-linear parameter also states its search coordinate (:meth:`search_range`,
    :meth:`search_axis`, :meth:`search_nl`, :meth:`search_of_nl`), which the fit reads.

    A process owns its behaviour, so that adding a process means adding one class: its WV
    (:meth:`basis`), simulator, spectral density (:meth:`psd_terms`, :meth:`psd`), the rule
    that projects it onto a filter's model (:meth:`filter_terms`), its datasheet quantities
    (:attr:`quantities`, :meth:`datasheet_params`, :meth:`from_datasheet`), its names
    (:attr:`display_name`, :attr:`help`) and, when it has them, its Allan-variance slope
    (:attr:`allan_slope`, :attr:`read_tau`). Creating a class without one of them raises
    ``TypeError`` (:data:`BEHAVIOUR`, :data:`DESCRIPTIVE`).
    """

    code: ClassVar[str] = ""
    param_names: ClassVar[tuple[str, ...]] = ()
    # the non-linear parameter's name (AR1/GM), else None
    nonlinear: ClassVar[str | None] = None
    description: ClassVar[str] = ""
    # rank in the canonical order of a model's processes (GM, AR1, QN, WN, RW, DR)
    order: ClassVar[int] = 0
    #: Short name shown next to a label (``"white noise"``, ``"AR(1)"``).
    display_name: ClassVar[str] = ""
    #: One line on what the process does to the WV (the app's tooltips).
    help: ClassVar[str] = ""
    #: Fixed colour of its curves, or ``""`` for a kind that repeats (AR1, GM: a palette).
    color: ClassVar[str] = ""
    #: Datasheet quantities in print order (AR1 is reported as the GM it samples).
    quantities: ClassVar[tuple[Quantity, ...]] = ()
    #: Log-log slope of its Allan deviation (IEEE Std 952), None when it has no single slope.
    allan_slope: ClassVar[float | None] = None
    #: Averaging time T [s] at which the slope line reads the coefficient (``N`` at T = 1 s).
    read_tau: ClassVar[float | None] = None
    #: May several channels share it (one covariance matrix of its linear coefficient)?
    shareable: ClassVar[bool] = False
    #: Deterministic (a drift): no first-order contribution to the WV's covariance.
    deterministic: ClassVar[bool] = False
    #: May the fitter set phi to 0 (an AR1 then is white); a GM's phi = exp(-beta/fs) may not.
    phi_can_vanish: ClassVar[bool] = False
    #: At most one per model: two have the same WV shape, only their sum is identifiable.
    unique: ClassVar[bool] = False
    #: Processes a model may not hold beside this one, each with the reason (identifiability).
    excludes: ClassVar[dict[str, str]] = {}

    if TYPE_CHECKING:
        # the constructor of a concrete process: the dataclass generates it from the fields,
        # which are its parameters (positional in ``param_names`` order, or named)
        def __init__(self, *values: float | None, **named: float | None) -> None: ...

    def __init_subclass__(
        cls,
        *,
        order: int,
        description: str,
        nonlinear: str | None = None,
        **kwargs: Any,
    ) -> None:
        """Set a process's ``code``, ``param_names``, ``order``, ``description`` and
        ``nonlinear``, check that it implements every behaviour (:data:`BEHAVIOUR`,
        :data:`DESCRIPTIVE`), and register it in :data:`PROCESS_TYPES` (in ``order``)."""
        super().__init_subclass__(**kwargs)
        cls.code = cls.__name__
        # the fields (parameters): the class's own annotations other than ClassVar
        annotations = cls.__dict__.get("__annotations__", {})
        cls.param_names = tuple(n for n, a in annotations.items() if "ClassVar" not in str(a))
        cls.order, cls.description, cls.nonlinear = order, description, nonlinear
        missing = cls.missing_behaviour()
        if missing:
            raise TypeError(
                f"process {cls.code} does not implement {', '.join(missing)}: a process owns "
                "its behaviour (see engine.models.Process)"
            )
        PROCESS_TYPES[cls.code] = cls
        ranked = sorted(PROCESS_TYPES.values(), key=lambda c: c.order)
        PROCESS_TYPES.clear()
        PROCESS_TYPES.update((c.code, c) for c in ranked)

    @classmethod
    def missing_behaviour(cls) -> list[str]:
        """Names of the behaviour methods and class attributes a process class lacks."""
        need = list(BEHAVIOUR)
        if cls.nonlinear is not None:
            need += NONLINEAR_BEHAVIOUR
        if cls.shareable:
            need += SHARED_BEHAVIOUR
        out = [n for n in need if getattr(cls, n) is getattr(Process, n)]
        return out + [n for n in DESCRIPTIVE if not getattr(cls, n)]

    # ---- values -------------------------------------------------------------------------
    @property
    def values(self) -> tuple[float | None, ...]:
        """Parameter values in ``param_names`` order (None where unknown)."""
        return tuple(getattr(self, name) for name in self.param_names)

    @property
    def is_set(self) -> bool:
        """True when every parameter has a value."""
        return all(v is not None for v in self.values)

    def with_values(self, *args: float | None, **kwargs: float | None) -> Process:
        """A copy with new parameter values (positional in ``param_names`` order, or named)."""
        vals = dict(zip(self.param_names, self.values, strict=True))
        if len(args) > len(self.param_names):
            raise ValueError(
                f"{self.code} takes {len(self.param_names)} parameters: "
                f"{', '.join(self.param_names)}"
            )
        for name, v in zip(self.param_names, args, strict=False):
            vals[name] = v
        for name, v in kwargs.items():
            if name not in vals:
                raise ValueError(
                    f"{self.code} has no parameter {_shown(name)}; "
                    f"its parameters are {', '.join(self.param_names)}"
                )
            vals[name] = v
        return type(self)(**vals)

    def cleared(self) -> Process:
        """The same process with every value unknown."""
        return type(self)()

    def _require(self) -> tuple[float, ...]:
        vals = self.values
        missing = [n for n, v in zip(self.param_names, vals, strict=True) if v is None]
        if missing:
            raise ValueError(
                f"{self.code} has no value for {', '.join(missing)}; "
                f"give it, e.g. {self.code}({missing[0]}=...)"
            )
        return tuple(float(v) for v in vals if v is not None)

    def __post_init__(self) -> None:
        for name, v in zip(self.param_names, self.values, strict=True):
            if v is None:
                continue
            if not isinstance(v, (int, float, np.floating, np.integer)) or not math.isfinite(v):
                raise ValueError(f"{self.code}.{name} must be a finite number, got {v!r}")
            self._check_value(name, float(v))

    def _check_value(self, name: str, v: float) -> None:
        if v < 0:
            raise ValueError(f"{self.code}.{name} must be >= 0, got {v}")

    # ---- the parameters' declarations, bounds and the unconstrained space -------------------
    @classmethod
    def params(cls) -> Mapping[str, Param]:
        """The :class:`Param` record of each parameter, by name (its field's metadata).

        Read off the class's fields once (the fit's and the plan's every step asks for them:
        a fifth of a plan's CPU when read each time) and shared, so read-only."""
        known = _PARAMS.get(cls)
        if known is not None:
            return known
        out = {}
        for f in fields(cls):
            spec = f.metadata.get("param")
            if not isinstance(spec, Param):
                raise TypeError(
                    f"{cls.code}.{f.name} has no Param record: declare it with "
                    "engine.models.model.param(...)"
                )
            out[f.name] = spec
        _PARAMS[cls] = known = MappingProxyType(out)
        return known

    def bounds(self, fs: float = 1.0) -> dict[str, tuple[float, float]]:
        """Admissible range of each parameter (open where the transform is)."""
        return {n: spec.bounds for n, spec in self.params().items()}

    def to_unconstrained(self, fs: float = 1.0) -> np.ndarray:
        """Values mapped to R^k by each parameter's transform (:attr:`Param.transform`)."""
        vals = self._require()
        specs = self.params()
        return np.array(
            [specs[n].to_unconstrained(v) for n, v in zip(self.param_names, vals, strict=True)]
        )

    def from_unconstrained(self, u: np.ndarray, fs: float = 1.0) -> Process:
        """Inverse of :meth:`to_unconstrained`: a process with the mapped-back values."""
        u = np.asarray(u, dtype=float)
        if u.shape != (len(self.param_names),):
            raise ValueError(
                f"{self.code} takes {len(self.param_names)} unconstrained values, "
                f"got shape {u.shape}"
            )
        specs = self.params()
        return type(self)(
            *(
                specs[n].from_unconstrained(float(x))
                for n, x in zip(self.param_names, u, strict=True)
            )
        )

    # ---- fitting interface ----------------------------------------------------------------
    def basis(self, tau: np.ndarray, fs: float, nl: float | None = None) -> np.ndarray:
        """WV per unit of the linear coefficient, at scales ``tau`` (samples)."""
        raise NotImplementedError

    def linear_coef(self) -> float:
        """The linear coefficient ``h`` of the current values (``basis * h`` is the WV): by
        default the last parameter (the variance-like one)."""
        return self._require()[-1]

    def from_fit(self, h: float, nl: float | None, fs: float) -> Process:
        """Process with values from a linear coefficient and a non-linear value: by default
        (a one-parameter process) the parameter is ``h``."""
        return type(self)(float(h))

    def nl_value(self, fs: float) -> float | None:
        """The non-linear value in the fitter's space: the AR1 coefficient ``phi`` of the
        process sampled at ``fs`` (AR1: ``phi``; GM: ``exp(-beta / fs)``); None for a process
        without a non-linear parameter or when the value is unknown."""
        if self.nonlinear is None:
            return None
        v = getattr(self, self.nonlinear)
        return None if v is None else self.phi_from_nl(float(v), fs)

    def phi_from_nl(self, nl: float, fs: float) -> float:
        """The fitter's ``phi`` of a value of the non-linear parameter (AR1, GM only)."""
        raise NotImplementedError

    def nl_from_phi(self, phi: float, fs: float) -> float:
        """The non-linear parameter's value of a fitter's ``phi`` (inverse of
        :meth:`phi_from_nl`; AR1, GM only)."""
        raise NotImplementedError

    # ---- the non-linear search coordinate (engine.fit._varpro asks the process) -------------
    def search_range(self, n_max: int) -> tuple[float, float]:
        """The interval ``[lo, hi]`` of the search coordinate ``u`` the fit explores, for a
        series of ``n_max`` samples (AR1, GM: log correlation times from :data:`TC_MIN` to
        ``TC_MAX_FACTOR n_max`` samples)."""
        raise NotImplementedError

    def search_axis(self, tau_max: float, k: int) -> np.ndarray:
        """The grid of ``u`` the search starts from, for ``k`` interchangeable terms of this
        kind and a largest scale ``tau_max`` (samples)."""
        raise NotImplementedError

    def search_nl(self, u: Any, lo: float, hi: float) -> Any:
        """The fitter's non-linear value (:meth:`nl_value`'s space) at search coordinate
        ``u``, clipped into ``[lo, hi]``: a float for a float, an array for an array."""
        raise NotImplementedError

    def search_of_nl(self, nl: float) -> float | None:
        """The search coordinate of a fitter's non-linear value (inverse of
        :meth:`search_nl`), or None when the search cannot reach it."""
        raise NotImplementedError

    def basis_many(self, tau: np.ndarray, fs: float, nls: np.ndarray) -> np.ndarray:
        """:meth:`basis` at each non-linear value of ``nls`` (n,): an (n, J) array (the
        search's batched path; one :meth:`basis` per value by default)."""
        return np.array([self.basis(tau, fs, float(v)) for v in nls]).reshape(len(nls), -1)

    def search_kernel(
        self, tau: np.ndarray, fs: float, lo: float, hi: float
    ) -> Callable[[list[float]], np.ndarray]:
        """The search's hot path: a function of a list of ``n`` search coordinates that
        returns :meth:`basis_many` at their :meth:`search_nl` values (clipped into
        ``[lo, hi]``), an (n, J) array, the same numbers. Built once per fit problem, so a
        process may prepare what depends on the scales only (by default nothing)."""

        def columns(us: list[float]) -> np.ndarray:
            nls = np.array([self.search_nl(v, lo, hi) for v in us])
            return self.basis_many(tau, fs, nls)

        return columns

    def start_nl(self, tau: np.ndarray, nu: np.ndarray, fs: float) -> float | None:
        """A rough value of the non-linear parameter read off an empirical WV ``nu`` at scales
        ``tau`` (samples), for :func:`engine.fit.starting_values`; None (AR1, GM) when the
        start spreads correlation times over the scales with the model's other such terms."""
        return None

    def correlation_time(self, fs: float) -> float | None:
        """Correlation time in samples of the fitted process (AR1, GM: ``-1 / ln phi``; 0
        for ``phi <= 0``), None for a process without one."""
        return None

    def basis_scale(self, phi: float) -> float:
        """``basis(tau, fs, phi) / ar1_wv(tau, phi, 1)`` for a process with a non-linear
        parameter: 1 when the linear coefficient is the innovation variance (AR1),
        ``1 - phi^2`` when it is the stationary variance (GM). The fit's hot path uses it."""
        raise NotImplementedError

    # ---- datasheet ---------------------------------------------------------------------------
    def datasheet_params(self, fs: float) -> dict[str, float] | None:
        """Parameters in the parametrisation of :attr:`quantities` (an AR1 as the GM it
        samples), or None when the process has no datasheet form (an AR1 with phi outside
        (0, 1)). Every value must be set."""
        return dict(zip(self.param_names, self._require(), strict=True))

    def datasheet_intervals(
        self, intervals: dict[str, tuple[float, float]], fs: float
    ) -> dict[str, tuple[float, float]]:
        """Intervals of the process's parameters (by name) mapped to the parameters of
        :meth:`datasheet_params`; the same by default."""
        return dict(intervals)

    @classmethod
    def from_datasheet(cls, values: dict[str, float], fs: float) -> Process:
        """The per-sample process of datasheet values ``{symbol: value}``; by default (one
        parameter) from its first quantity (N, Q, K, R)."""
        q = cls.quantities[0]
        if q.inverse is None:  # pragma: no cover - every one-parameter quantity inverts
            raise ValueError(f"{q.symbol} of {cls.code} is not invertible alone")
        return cls(q.inverse(values[q.symbol], fs))

    # ---- multivariate ------------------------------------------------------------------------
    def simulate_shared(
        self, z: np.ndarray, root: np.ndarray, phi: float | None, rng: np.random.Generator
    ) -> np.ndarray:
        """Simulate the process shared by ``k`` channels from correlated normals.

        Parameters
        ----------
        z : ndarray, shape (n, k)
            Rows drawn from ``N(0, C)``, ``C`` the term's coefficient matrix (the linear
            coefficient of every channel and their covariances).
        root : ndarray, shape (k, k)
            ``root @ root.T = C`` (to draw a stationary start).
        phi : float or None
            The fitter's ``phi`` (AR1, GM), else None.
        rng : numpy.random.Generator
            For the stationary start of an AR1/GM.
        """
        raise NotImplementedError

    # ---- model-implied WV and simulation ------------------------------------------------------
    def wv(self, tau: np.ndarray, fs: float = 1.0) -> np.ndarray:
        """Implied Haar WV at scales ``tau`` (samples)."""
        self._require()
        return self.linear_coef() * self.basis(np.asarray(tau, float), fs, self.nl_value(fs))

    def simulate(
        self, n: int, rng: np.random.Generator | int | None = None, fs: float = 1.0
    ) -> np.ndarray:
        """Simulate ``n`` samples (AR1/GM start from the stationary distribution)."""
        raise NotImplementedError

    def autocovariance(self, lags: np.ndarray, fs: float = 1.0) -> np.ndarray:
        """Autocovariance at integer lags (stationary processes only)."""
        raise TypeError(f"{self.code} is not stationary: it has no autocovariance function")

    # ---- algebra --------------------------------------------------------------------------
    def __add__(self, other: Any) -> Model:
        return Model((self,)) + other

    def __radd__(self, other: Any) -> Model:
        if other == 0:
            return Model((self,))
        return Model.coerce(other) + Model((self,))

    def __mul__(self, k: int) -> Model:
        return Model((self,)) * k

    __rmul__ = __mul__

    def spec(self) -> str:
        """``CODE`` or ``CODE(name=value, ...)``."""
        if all(v is None for v in self.values):
            return self.code
        parts = [
            f"{n}={v!r}"
            for n, v in zip(self.param_names, self.values, strict=True)
            if v is not None
        ]
        return f"{self.code}({', '.join(parts)})"

    def __repr__(self) -> str:
        if all(v is None for v in self.values):
            return f"{self.code}()"
        return self.spec()


class _ByName(Mapping[str, Callable[[float], float]]):
    """A parameter's transform (or its inverse) by parameter name, read from the classes'
    :class:`Param` records (a name means the same parameter kind in every process)."""

    def __init__(self, inverse: bool) -> None:
        self._inverse = inverse

    def __getitem__(self, name: str) -> Callable[[float], float]:
        for cls in PROCESS_TYPES.values():
            spec = cls.params().get(name)
            if spec is not None:
                return spec.from_unconstrained if self._inverse else spec.to_unconstrained
        raise KeyError(name)

    def __iter__(self) -> Iterator[str]:
        return iter(dict.fromkeys(n for cls in PROCESS_TYPES.values() for n in cls.params()))

    def __len__(self) -> int:
        return sum(1 for _ in self)


#: Transforms to the unconstrained space by parameter name (the :class:`Param` records).
TO_UNCONSTRAINED: Mapping[str, Callable[[float], float]] = _ByName(inverse=False)
#: Their inverses.
FROM_UNCONSTRAINED: Mapping[str, Callable[[float], float]] = _ByName(inverse=True)


_ECHO = 60  # characters of a user's model text quoted in a message


def _shown(text: str) -> str:
    """A piece of a model specification as messages quote it: whole when short, else its first
    :data:`_ECHO` characters and its length (a pasted 20 KB string is not echoed back)."""
    t = text.strip()
    if len(t) <= _ECHO:
        return repr(t)
    return f"{t[:_ECHO]!r}... ({len(t)} characters)"


@dataclass(frozen=True)
class Model:
    """An immutable sum of independent latent processes.

    Build with ``WN() + RW() + 2 * GM()`` or :func:`parse_model`. ``repr`` evaluates back to
    the same model (with ``from engine import *``).
    """

    processes: tuple[Process, ...] = ()

    def __post_init__(self) -> None:
        procs = tuple(sorted(self.processes, key=lambda p: p.order))
        object.__setattr__(self, "processes", procs)

    # ---- algebra ----------------------------------------------------------------------
    @staticmethod
    def coerce(other: Any) -> Model:
        if isinstance(other, Model):
            return other
        if isinstance(other, Process):
            return Model((other,))
        if isinstance(other, str):
            return parse_model(other)
        raise TypeError(f"cannot add a {type(other).__name__} to a model")

    def __add__(self, other: Any) -> Model:
        return Model(self.processes + Model.coerce(other).processes)

    def __radd__(self, other: Any) -> Model:
        if other == 0:
            return self
        return Model.coerce(other) + self

    def __mul__(self, k: int) -> Model:
        if not isinstance(k, (int, np.integer)) or isinstance(k, bool) or k < 1:
            raise TypeError(f"a model can only be multiplied by a positive integer, got {k!r}")
        return Model(self.processes * int(k))

    __rmul__ = __mul__

    def __len__(self) -> int:
        return len(self.processes)

    def __iter__(self):
        return iter(self.processes)

    def __getitem__(self, i: int) -> Process:
        return self.processes[i]

    # ---- names ------------------------------------------------------------------------
    @property
    def labels(self) -> list[str]:
        """One label per process: ``WN``, or ``GM_1``, ``GM_2`` when a kind repeats."""
        counts = Counter(p.code for p in self.processes)
        seen: Counter[str] = Counter()
        out = []
        for p in self.processes:
            seen[p.code] += 1
            out.append(p.code if counts[p.code] == 1 else f"{p.code}_{seen[p.code]}")
        return out

    @property
    def indices(self) -> list[int]:
        """Index of each process among the processes of its kind, from 1."""
        seen: Counter[str] = Counter()
        out = []
        for p in self.processes:
            seen[p.code] += 1
            out.append(seen[p.code])
        return out

    @property
    def param_names(self) -> list[str]:
        """Unique parameter names, ``label.name``."""
        return [
            f"{lab}.{n}"
            for lab, p in zip(self.labels, self.processes, strict=True)
            for n in p.param_names
        ]

    @property
    def n_params(self) -> int:
        return sum(len(p.param_names) for p in self.processes)

    @property
    def is_set(self) -> bool:
        """True when every parameter has a value."""
        return all(p.is_set for p in self.processes)

    @property
    def is_linear(self) -> bool:
        """True for a model made only of QN, WN, RW and DR (closed-form GMWM)."""
        return all(p.nonlinear is None for p in self.processes)

    def values(self) -> dict[str, float | None]:
        """Parameter values by unique name."""
        return dict(
            zip(self.param_names, [v for p in self.processes for v in p.values], strict=True)
        )

    def cleared(self) -> Model:
        """The same structure with every value unknown."""
        return Model(tuple(p.cleared() for p in self.processes))

    def spec(self, values: bool = False) -> str:
        """Canonical specification string, e.g. ``2*GM+WN+RW``.

        With ``values=True`` every process is written with its values
        (``GM(beta=0.1, sigma2_gm=1e-4)+...``), one term per process.
        """
        if values:
            return "+".join(p.spec() for p in self.processes)
        counts = Counter(p.code for p in self.processes)
        parts = []
        for code in PROCESS_TYPES:
            k = counts.get(code, 0)
            if k:
                parts.append(code if k == 1 else f"{k}*{code}")
        return "+".join(parts)

    def __str__(self) -> str:
        return self.spec()

    def __repr__(self) -> str:
        return " + ".join(repr(p) for p in self.processes) if self.processes else "Model(())"

    # ---- validation ---------------------------------------------------------------------
    def validate(self, n_levels: int | None = None) -> Model:
        """Check identifiability; return self or raise :class:`ModelError` saying why.

        Rules: at least one process; at most one of each process declared
        :attr:`Process.unique` (WN, QN, RW, DR: two of a kind have the same WV shape, only
        their sum is identifiable); no two processes one of which :attr:`Process.excludes`
        the other (AR1 and GM: the same WV family in two parametrisations); no more
        parameters than WV levels.
        """
        if not self.processes:
            raise ModelError(
                f"the model is empty: add at least one process ({', '.join(PROCESS_TYPES)})"
            )
        counts = Counter(p.code for p in self.processes)
        for code, cls in PROCESS_TYPES.items():
            if cls.unique and counts.get(code, 0) > 1:
                raise ModelError(
                    f"the model has {counts[code]} {code} terms; only their sum is identifiable "
                    f"(they have the same WV shape): keep one {code}"
                )
        for code, cls in PROCESS_TYPES.items():
            for other, reason in cls.excludes.items():
                if counts.get(code) and counts.get(other):
                    raise ModelError(f"the model mixes {code} and {other}: {reason}")
        if n_levels is not None and self.n_params > n_levels:
            raise ModelError(
                f"the model has {self.n_params} parameters but the WV has only {n_levels} levels: "
                "use a longer series or a smaller model"
            )
        return self

    # ---- implied WV and simulation ---------------------------------------------------------
    def components(self, tau: np.ndarray, fs: float = 1.0) -> dict[str, np.ndarray]:
        """Implied WV of each process, by label (the decomposition)."""
        tau = np.asarray(tau, float)
        return {lab: p.wv(tau, fs) for lab, p in zip(self.labels, self.processes, strict=True)}

    def wv(self, tau: np.ndarray, fs: float = 1.0) -> np.ndarray:
        """Implied Haar WV at scales ``tau`` (samples): the sum of the components."""
        tau = np.asarray(tau, float)
        total = np.zeros_like(tau)
        for p in self.processes:
            total = total + p.wv(tau, fs)
        return total

    def simulate(
        self, n: int, *, fs: float = 1.0, rng: np.random.Generator | int | None = None
    ) -> np.ndarray:
        """Simulate ``n`` samples of the sum of the processes (independent draws each).

        ``n`` must be an integer from 1 to the memory-aware limit of
        :func:`engine._limits.check_sample_count` (a ValueError names the argument ``n``).

        Examples
        --------
        >>> import numpy as np
        >>> import engine as eg
        >>> m = eg.parse_model("WN(1e-2) + RW(1e-6)")
        >>> x = m.simulate(2**12, rng=np.random.default_rng(1))
        >>> x.shape, round(float(np.var(np.diff(x))), 3)  # 2 sigma2 + gamma2
        ((4096,), 0.02)
        """
        n = check_sample_count(n)
        missing = [name for name, v in self.values().items() if v is None]
        if missing:
            raise ModelError(
                f"cannot simulate: no value for {', '.join(missing)}; "
                "write e.g. WN(sigma2=1e-4)+RW(gamma2=1e-8)"
            )
        g = rng if isinstance(rng, np.random.Generator) else np.random.default_rng(rng)
        x = np.zeros(n)
        for p in self.processes:
            x += p.simulate(n, g, fs)
        return x

    def autocovariance(self, lags: np.ndarray, fs: float = 1.0) -> np.ndarray:
        """Autocovariance of a stationary model at integer lags."""
        return sum((p.autocovariance(lags, fs) for p in self.processes), np.zeros(np.shape(lags)))


_TERM = re.compile(
    r"^\s*(?:(?P<k>\d+)\s*\*\s*)?(?P<code>[A-Za-z][A-Za-z0-9]*)\s*(?:\((?P<args>[^()]*)\))?"
    r"\s*(?:\*\s*(?P<k2>\d+))?\s*$"
)
_ALIASES = {
    "AR": "AR1",
    "GAUSSMARKOV": "GM",
    "WHITE": "WN",
    "RANDOMWALK": "RW",
    "DRIFT": "DR",
    "QUANTIZATION": "QN",
}


def _split_top(spec: str) -> list[str]:
    parts: list[str] = []
    cur: list[str] = []
    depth = 0
    for ch in spec:
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
            if depth < 0:
                raise ModelError(f"unbalanced ')' in model {_shown(spec)}")
        if ch == "+" and depth == 0:
            parts.append("".join(cur))
            cur = []
        else:
            cur.append(ch)
    if depth != 0:
        raise ModelError(f"unbalanced '(' in model {_shown(spec)}")
    parts.append("".join(cur))
    return parts


def _parse_number(text: str, where: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise ModelError(f"{where}: {_shown(text)} is not a number") from None


def parse_model(spec: str | Model | Process) -> Model:
    """Parse a model specification.

    Terms joined by ``+`` in any order, each ``CODE``, ``k*CODE`` or ``CODE*k``, optionally with
    values: ``"WN(sigma2=1)+RW(gamma2=1e-4)"``, ``"GM(0.1, 1e-4)"`` (positional in the
    process's parameter order). Codes: those of :data:`PROCESS_TYPES` (case-insensitive).

    Raises
    ------
    ModelError
        With the offending term and what is accepted.

    Examples
    --------
    >>> import engine as eg
    >>> m = eg.parse_model("WN + RW + 2*GM")
    >>> m.labels
    ['GM_1', 'GM_2', 'WN', 'RW']
    >>> eg.parse_model("WN(1e-2) + RW(1e-6)").values()
    {'WN.sigma2': 0.01, 'RW.gamma2': 1e-06}
    """
    if isinstance(spec, Model):
        return spec
    if isinstance(spec, Process):
        return Model((spec,))
    if not isinstance(spec, str) or not spec.strip():
        raise ModelError("the model specification is empty: write e.g. WN+RW+2*GM")
    procs: list[Process] = []
    for term in _split_top(spec):
        if not term.strip():
            raise ModelError(f"empty term in model {_shown(spec)} (a '+' too many?)")
        m = _TERM.match(term)
        if not m:
            raise ModelError(
                f"cannot read the term {_shown(term)} in model {_shown(spec)}; "
                "write terms like WN, 2*GM or GM(beta=0.1, sigma2_gm=1e-4)"
            )
        code = m.group("code").upper()
        code = _ALIASES.get(code, code)
        if code not in PROCESS_TYPES:
            raise ModelError(
                f"unknown process {_shown(m.group('code'))} in model {_shown(spec)}; "
                f"known processes: {', '.join(PROCESS_TYPES)}"
            )
        cls = PROCESS_TYPES[code]
        digits = (m.group("k") or "1", m.group("k2") or "1")
        k = 0 if max(map(len, digits)) > 6 else int(digits[0]) * int(digits[1])
        if not 1 <= k <= _MAX_REPEAT:  # (a 5000-digit multiplier is not converted to int)
            raise ModelError(
                f"the multiplier in {_shown(term)} must be between 1 and {_MAX_REPEAT}"
            )
        p = cls()
        args = m.group("args")
        if args is not None and args.strip():
            pos: list[float] = []
            named: dict[str, float] = {}
            for a in args.split(","):
                a = a.strip()
                if not a:
                    continue
                if "=" in a:
                    name, val = (s.strip() for s in a.split("=", 1))
                    short = len(name) <= _ECHO
                    where = f"{code}.{name}" if short else f"{code} parameter {_shown(name)}"
                    named[name] = _parse_number(val, where)
                else:
                    if named:
                        raise ModelError(
                            f"in {_shown(term)} a positional value follows a named one"
                        )
                    pos.append(_parse_number(a, code))
            try:
                p = p.with_values(*pos, **named)
            except ValueError as e:
                raise ModelError(str(e)) from None
        procs.extend([p] * k)
    return Model(tuple(procs))
