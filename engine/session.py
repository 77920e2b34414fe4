"""Saving and restoring an analysis session: data reference, channels, models, WVs and fits.

The app (or a script) calls :func:`save_session` with what it holds and gets one JSON file;
:func:`load_session` gives it back as objects (:class:`~engine.wv.WaveletVariance`,
:class:`~engine.fit.GMWMResult`, :class:`~engine.inference.ParamInterval`) without
recomputing anything, plus a check that the data file has not changed since
(:func:`file_fingerprint`). Floats are written with ``repr`` (exact round trip); NaN is
written as ``null`` (strict JSON).

Layout (``schema = "gmwm-session/1"``)::

    {"schema", "engine_version", "created",
     "data": {"path", "load": {load_log keyword arguments}, "fingerprint": {...}},
     "channels": {name: {"model": spec, "wv": {...}, "fit": {...}, "intervals": [...]}},
     "app": {free-form state of the app: selected channel, view settings ...}}
"""

from __future__ import annotations

import datetime as _dt
import hashlib
import inspect
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ._files import open_regular, read_regular, write_atomic
from ._jsonutil import json_ready
from ._version import __version__
from .errors import SessionError
from .fit import FitError, GMWMResult, weight_matrix
from .inference import ParamInterval
from .io import load_log
from .models import parse_model
from .wv import WaveletVariance

__all__ = [
    "wv_to_dict",
    "wv_from_dict",
    "result_to_dict",
    "result_from_dict",
    "file_fingerprint",
    "Session",
    "save_session",
    "load_session",
    "session_to_json",
    "session_from_json",
    "SessionError",
]

SCHEMA = "gmwm-session/1"
#: The options a session can record: :func:`engine.io.load_log`'s keywords (the log is read
#: again with them), but the file's ``name`` in messages.
_LOAD_KEYS = tuple(k for k in inspect.signature(load_log).parameters if k not in ("path", "name"))


def _arr(v: Any, dtype: Any = float) -> np.ndarray:
    return np.array([math.nan if x is None else x for x in v], dtype=dtype)


def wv_to_dict(wv: WaveletVariance) -> dict[str, Any]:
    """:meth:`WaveletVariance.to_dict` plus the classical WV of a robust one."""
    d = wv.to_dict()
    if wv.classical is not None:
        d["classical"] = wv.classical.to_dict()
    return d


def wv_from_dict(d: Mapping[str, Any]) -> WaveletVariance:
    """Inverse of :func:`wv_to_dict` (and of ``WaveletVariance.to_dict``), exactly."""
    try:
        v = _arr(d["variance"])
        classical = wv_from_dict(d["classical"]) if d.get("classical") else None
        return WaveletVariance(
            levels=np.asarray(d.get("levels", np.arange(1, v.size + 1)), dtype=int),
            tau_samples=np.asarray(d.get("tau_samples", 2 ** np.arange(1, v.size + 1)), dtype=int),
            variance=v,
            ci_low=_arr(d["ci_low"]),
            ci_high=_arr(d["ci_high"]),
            n_coef=np.asarray(d["n_coef"], dtype=int),
            n=int(d["n"]),
            fs=float(d["fs"]),
            robust=bool(d.get("robust", False)),
            eff=float(d.get("eff", 0.6)),
            alpha=float(d.get("alpha", 0.05)),
            unit=str(d.get("unit", "")),
            classical=classical,
        )
    except (KeyError, TypeError, ValueError, AttributeError) as exc:
        raise SessionError(f"invalid wavelet variance in the session ({exc!r})") from exc


def result_to_dict(res: GMWMResult) -> dict[str, Any]:
    """:meth:`GMWMResult.to_dict` plus what an exact restore needs (Omega, message, time)."""
    d = res.to_dict()
    d["wv"] = wv_to_dict(res.wv)
    d["omega"] = res.omega.tolist()
    d["message"] = res.message
    d["elapsed_s"] = res.elapsed_s
    return d


def result_from_dict(d: Mapping[str, Any]) -> GMWMResult:
    """A :class:`GMWMResult` from :func:`result_to_dict` (or ``to_dict``) without refitting.

    The model comes from ``model_values`` (exact reprs), the implied WV and components are
    recomputed from it, Omega is read (or rebuilt from the ``weights`` name).
    """
    try:
        wv = wv_from_dict(d["wv"])
        model = parse_model(d["model_values"])
        if not model.is_set:
            raise SessionError(f"the fitted model {d['model_values']!r} has unset values")
        if d.get("omega") is not None:
            omega = np.array(d["omega"], dtype=float)
        else:
            omega = weight_matrix(wv, d.get("weights", "ci"))[0]
        comps = model.components(wv.tau_samples, wv.fs)
        implied = np.sum(np.array(list(comps.values())), axis=0)
        return GMWMResult(
            model=model,
            wv=wv,
            omega=omega,
            weights=str(d.get("weights", "ci")),
            objective=float(d["objective"]),
            implied=implied,
            components=comps,
            converged=bool(d.get("converged", True)),
            at_bound=list(d.get("at_bound", [])),
            n_evaluations=int(d.get("n_evaluations", 0)),
            method=str(d.get("method", "")),
            message=str(d.get("message", "")),
            elapsed_s=float(d.get("elapsed_s", 0.0)),
        )
    except SessionError:
        raise
    except (KeyError, TypeError, ValueError, AttributeError, FitError) as exc:
        raise SessionError(f"invalid fit in the session ({exc!r})") from exc


def file_fingerprint(path: str | os.PathLike[str], *, chunk: int = 1 << 20) -> dict[str, Any]:
    """Size, modification time and SHA-256 of the first and last MiB of a file (or of every
    file of a directory, e.g. a ROS 2 bag): cheap for multi-GB logs, and enough to notice
    that a file was replaced or re-recorded."""
    p = Path(path)
    files = sorted(q for q in p.rglob("*") if q.is_file()) if p.is_dir() else [p]
    h = hashlib.sha256()
    size = 0
    mtime = 0.0
    for q in files:
        st = q.stat()
        size += st.st_size
        mtime = max(mtime, st.st_mtime)
        with open_regular(q, error=SessionError) as fh:  # no FIFO or device: engine._files
            h.update(fh.read(chunk))
            if st.st_size > 2 * chunk:
                fh.seek(st.st_size - chunk)
            h.update(fh.read(chunk))
    return {"size": int(size), "mtime": float(mtime), "sha256_ends": h.hexdigest()}


@dataclass
class Session:
    """A restored session.

    Attributes
    ----------
    data_path : str
        The log file.
    load : dict
        Keyword arguments of :func:`engine.io.load_log` (channel, fs, segment, scale, units,
        topic).
    models : dict of str to str
        Model specification per channel.
    wvs, fits : dict
        WaveletVariance and GMWMResult per channel (those that were saved).
    intervals : dict of str to list of ParamInterval
        Parameter intervals per channel.
    app : dict
        The app's own state, as saved.
    fingerprint : dict or None
        The data file's fingerprint at save time.
    created : str
        ISO time of the save (UTC).
    """

    data_path: str
    load: dict[str, Any] = field(default_factory=dict)
    models: dict[str, str] = field(default_factory=dict)
    wvs: dict[str, WaveletVariance] = field(default_factory=dict)
    fits: dict[str, GMWMResult] = field(default_factory=dict)
    intervals: dict[str, list[Any]] = field(default_factory=dict)
    app: dict[str, Any] = field(default_factory=dict)
    fingerprint: dict[str, Any] | None = None
    created: str = ""

    def data_changed(self) -> str | None:
        """None when the data file matches its fingerprint, else what differs."""
        if self.fingerprint is None:
            return None
        p = Path(self.data_path)
        if not p.exists():
            return f"the data file '{self.data_path}' no longer exists"
        now = file_fingerprint(p)
        if now["size"] != self.fingerprint.get("size"):
            return (
                f"the data file '{self.data_path}' changed size "
                f"({self.fingerprint.get('size')} -> {now['size']} bytes)"
            )
        if now["sha256_ends"] != self.fingerprint.get("sha256_ends"):
            return f"the content of the data file '{self.data_path}' changed"
        return None

    def reload_log(self, *, check: bool = True) -> Any:
        """``load_log(data_path, **load)``; with ``check``, refuse a changed file."""
        if check and (why := self.data_changed()):
            raise SessionError(
                f"{why} since the session was saved: the saved fits may not "
                "describe it; reload without check=True to use it anyway"
            )
        return load_log(self.data_path, **self.load)


def session_to_json(
    *,
    data_path: str | os.PathLike[str],
    load: Mapping[str, Any] | None = None,
    models: Mapping[str, str] | None = None,
    wvs: Mapping[str, WaveletVariance] | None = None,
    fits: Mapping[str, GMWMResult] | None = None,
    intervals: Mapping[str, Sequence[Any]] | None = None,
    app: Mapping[str, Any] | None = None,
    fingerprint: bool = True,
) -> str:
    """The session document as JSON text (for a download; :func:`save_session` writes it).

    Parameters
    ----------
    data_path : str or path-like
        The log the session analyses (stored as given; an absolute path is safest).
    load : mapping, optional
        Keyword arguments used with :func:`engine.io.load_log` (``channel``, ``fs``,
        ``segment``, ``scale``, ``units``, ``topic``); other keys are refused.
    models : mapping of str to str or Model, optional
        Model specification per channel (``"2*GM+WN+RW"``).
    wvs, fits, intervals : mapping, optional
        Per-channel WaveletVariance, GMWMResult and ParamInterval lists.
    app : mapping, optional
        Free-form JSON-serialisable app state.
    fingerprint : bool
        Store :func:`file_fingerprint` of the data (if the file exists).

    Raises
    ------
    SessionError
        Unknown ``load`` keys, or ``app`` state that is not JSON-serialisable.
    """
    load = dict(load or {})
    bad = [k for k in load if k not in _LOAD_KEYS]
    if bad:
        raise SessionError(
            f"load options {bad} are not load_log arguments ({', '.join(_LOAD_KEYS)})"
        )
    if isinstance(load.get("segment"), tuple):
        load["segment"] = list(load["segment"])
    chans: dict[str, dict[str, Any]] = {}
    for name in dict.fromkeys([*(models or {}), *(wvs or {}), *(fits or {}), *(intervals or {})]):
        c: dict[str, Any] = {}
        if models and name in models:
            spec = models[name]
            c["model"] = spec if isinstance(spec, str) else spec.spec()
        if wvs and name in wvs:
            c["wv"] = wv_to_dict(wvs[name])
        if fits and name in fits:
            c["fit"] = result_to_dict(fits[name])
        if intervals and name in intervals:
            c["intervals"] = [iv.to_dict() for iv in intervals[name]]
        chans[str(name)] = c
    dp = Path(data_path)
    doc = {
        "schema": SCHEMA,
        "engine_version": __version__,
        "created": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "data": {
            "path": str(data_path),
            "load": load,
            "fingerprint": file_fingerprint(dp) if fingerprint and dp.exists() else None,
        },
        "channels": chans,
        "app": dict(app or {}),
    }
    try:
        return json.dumps(json_ready(doc), indent=1, allow_nan=False) + "\n"
    except (TypeError, ValueError) as exc:
        raise SessionError(
            f"the session cannot be written as JSON ({exc}): keep the app "
            "state to numbers, strings, lists and dicts"
        ) from exc


def save_session(path: str | os.PathLike[str], **kwargs: Any) -> Path:
    """Write a session file (JSON, atomically); returns the path.

    Keyword arguments are those of :func:`session_to_json` (``data_path``, ``load``,
    ``models``, ``wvs``, ``fits``, ``intervals``, ``app``, ``fingerprint``).
    """
    text = session_to_json(**kwargs)
    return write_atomic(path, text)  # a crash or a full disk never leaves half a session


def load_session(path: str | os.PathLike[str]) -> Session:
    """Read a session file written by :func:`save_session`.

    Raises
    ------
    SessionError
        Unreadable file, not JSON, another schema, or invalid content (the message says
        which channel and what).
    """
    text = read_regular(path, error=SessionError)  # no FIFO or device: engine._files
    return session_from_json(text, source=str(path))


def session_from_json(text: str | bytes, *, source: str = "<upload>") -> Session:
    """A :class:`Session` from JSON text (e.g. an uploaded file); see :func:`load_session`."""
    path = source
    try:
        doc = json.loads(text)
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SessionError(f"cannot read session file '{path}': {exc}") from exc
    if not isinstance(doc, dict) or doc.get("schema") != SCHEMA:
        raise SessionError(f"'{path}' is not a GMWM session file (schema {SCHEMA!r} expected)")

    def part(d: Any, key: str) -> dict[str, Any]:
        v = d.get(key) or {}
        if not isinstance(v, dict):
            raise SessionError(
                f"session '{path}': '{key}' must be an object, got {type(v).__name__}"
            )
        return v

    data = part(doc, "data")
    load = part(data, "load")
    bad = [k for k in load if k not in _LOAD_KEYS]
    if bad:
        raise SessionError(f"session '{path}': unknown load options {bad}")
    if isinstance(load.get("segment"), list):
        load["segment"] = tuple(load["segment"])
    fp = data.get("fingerprint")
    s = Session(
        data_path=str(data.get("path", "")),
        load=load,
        app=part(doc, "app"),
        fingerprint=fp if isinstance(fp, dict) else None,
        created=str(doc.get("created", "")),
    )
    for name, c in part(doc, "channels").items():
        if not isinstance(c, dict):
            raise SessionError(f"session '{path}', channel {name!r}: not an object")
        try:
            if "model" in c:
                s.models[name] = str(c["model"])
            if "wv" in c:
                s.wvs[name] = wv_from_dict(c["wv"])
            if "fit" in c:
                s.fits[name] = result_from_dict(c["fit"])
            if "intervals" in c:
                s.intervals[name] = [
                    ParamInterval(
                        name=iv["name"],
                        value=float(iv["value"]),
                        low=math.nan if iv["low"] is None else float(iv["low"]),
                        high=math.nan if iv["high"] is None else float(iv["high"]),
                        unit=iv.get("unit", ""),
                        method=iv.get("method", ""),
                        level=float(iv.get("level", 0.95)),
                    )
                    for iv in c["intervals"]
                ]
        except SessionError as exc:
            raise SessionError(f"session '{path}', channel {name!r}: {exc}") from exc
        except (KeyError, TypeError, ValueError, AttributeError) as exc:
            raise SessionError(
                f"session '{path}', channel {name!r}: invalid entry ({exc!r})"
            ) from exc
    return s
