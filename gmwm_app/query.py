"""The URL round trip of a session: its shareable settings as query parameters and back.

:class:`QueryMixin` holds these methods of :class:`gmwm_app.state.AppState` (it has the
state's parameters, ``read``, ``precompute``, ``install``, ``set_model`` and ``_publish``).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any, ClassVar

from param.parameterized import batch_call_watchers

from gmwm_app.data import (
    COMPENSATION,
    PreparedQuery,
    channel_names,
    check_fs,
    compensation_mode,
    message_of,
)

__all__ = ["QueryMixin"]

if TYPE_CHECKING:  # the state's names this mixin uses (AppState defines them)
    from gmwm_app.state_fields import StateFields
else:
    StateFields = object


class QueryMixin(StateFields):
    """URL query methods of :class:`gmwm_app.state.AppState`."""

    param: Any

    #: The state's plain parameters in a served page's URL: query key by parameter. Their
    #: query value is the parameter's own, they are always in the URL, and the state reacts to
    #: a change of them by itself (the weights refit), so Panel keeps them in step both ways
    #: (``pn.state.location.sync``, :meth:`gmwm_app.app.GMWMApp.link_url`). The data and the
    #: model are not plain: a change reads a file or computes a WV first, and their keys come
    #: and go (``path``, ``temperature``, ``model``), which a synced key cannot; they are
    #: :meth:`to_query`'s and :meth:`from_query`'s. :meth:`to_query` lists every key (a
    #: session file keeps the whole link).
    URL_SYNCED: ClassVar[dict[str, str]] = {"weights": "weights"}

    def to_query(self) -> dict[str, str]:
        """The shareable state as URL query parameters (all strings).

        E.g. ``{"source": "demo", "channel": "gyro_x", "fs": "100", "robust": "0",
        "model": "2*GM+WN+RW"}``; ``path`` is added for a server file, ``temperature=0`` when
        the temperature compensation is off (as links made before the choice had it) and
        ``temperature=always`` when it is forced (``auto``, the default: no parameter).
        """
        q = {"source": self.source}
        if self.source == "path" and self.path:
            q["path"] = self.path
        if self.source == "scenario" and self.path:
            q["scenario"] = self.path
        if self.channel:
            q["channel"] = self.channel
        if self.fs:
            q["fs"] = f"{self.fs:.12g}"
        q["robust"] = "1" if self.robust else "0"
        if self.compensate != "auto":
            q["temperature"] = "0" if self.compensate == "off" else str(self.compensate)
        if self.weights != "ci":
            q["weights"] = self.weights
        if len(self.model):
            q["model"] = self.model.spec()
        return q

    def parse_query(self, query: Mapping[str, Any]) -> dict[str, Any]:
        """Read URL query parameters (strings or lists of strings) into settings.

        Returns ``{"source", "path", "channel", "fs", "robust", "compensate", "weights",
        "model", "problems"}``;
        unreadable values are left out and described in ``problems``.
        """
        q = {k: (v[-1] if isinstance(v, (list, tuple)) and v else v) for k, v in query.items()}
        q = {k: (v.decode() if isinstance(v, bytes) else str(v)) for k, v in q.items()}
        out: dict[str, Any] = {"problems": []}
        src = q.get("source", "").strip().lower()
        if src == "path" or (not src and q.get("path")):
            out["source"], out["path"] = "path", q.get("path", "")
        elif src == "scenario":
            out["source"], out["path"] = "scenario", q.get("scenario", "")
        elif src == "upload":
            out["source"] = None  # an upload cannot be replayed from a link
            out["problems"].append(
                "the link refers to an uploaded file, which is not part of "
                "the link: upload it again"
            )
        elif src in ("", "demo"):
            out["source"] = "demo" if src == "demo" else None
        else:
            out["source"] = None
            out["problems"].append(f"unknown source {src!r} in the link (use demo or path)")
        if q.get("channel"):
            out["channel"] = q["channel"].strip()
        if q.get("fs"):
            try:
                out["fs"] = check_fs(float(q["fs"]))
            except ValueError:
                out["problems"].append(f"fs={q['fs']!r} in the link is not a positive number of Hz")
        if "robust" in q:
            r = q["robust"].strip().lower()
            if r in ("1", "true", "yes", "on"):
                out["robust"] = True
            elif r in ("0", "false", "no", "off", ""):
                out["robust"] = False
            else:
                out["problems"].append(f"robust={q['robust']!r} in the link is not 0 or 1")
        if "temperature" in q:
            try:  # the choice, or the switch of older links (1: on, that is auto; 0: off)
                out["compensate"] = compensation_mode(q["temperature"])
            except ValueError:
                out["problems"].append(
                    f"temperature={q['temperature']!r} in the link is not one of "
                    f"{', '.join(COMPENSATION)} (or 0 for off)"
                )
        if "weights" in q:
            w = q["weights"].strip().lower()
            allowed = list(self.param.weights.objects)
            if w in allowed:
                out["weights"] = w
            else:
                out["problems"].append(
                    f"weights={q['weights']!r} in the link is not one of {', '.join(allowed)}"
                )
        if "model" in q:
            out["model"] = q["model"].strip()
        return out

    def prepare_query(
        self, query: Mapping[str, Any], default_source: str = "demo", default_path: str = ""
    ) -> PreparedQuery:
        """Read the data a URL query asks for and precompute its WV (worker-thread safe).

        A server path that cannot be read falls back to the demo (with a message).
        """
        s = self.parse_query(query)
        problems = list(s["problems"])
        src = s.get("source") or default_source
        path = s.get("path") if s.get("source") in ("path", "scenario") else default_path
        loaded = None
        try:
            loaded = self.read(src, path=path)
        except ValueError as e:
            problems.append(message_of(e))
            if src != "demo":
                try:
                    loaded = self.read("demo")
                    problems.append("showing the demo instead")
                except ValueError as e2:
                    problems.append(message_of(e2))
        if loaded is not None:
            self.precompute(
                loaded,
                s.get("channel"),
                s.get("fs"),
                bool(s.get("robust", False)),
                s.get("compensate", "auto"),
            )
        return PreparedQuery(s, loaded, problems)

    def from_query(
        self,
        query: Mapping[str, Any],
        prepared: PreparedQuery | None = None,
        default_source: str = "demo",
        default_path: str = "",
    ) -> bool:
        """Restore a session from URL query parameters (see :meth:`to_query`).

        Parameters
        ----------
        query : mapping
            Query parameters, e.g. ``pn.state.location.query_params`` (values may be lists).
        prepared : PreparedQuery, optional
            The data already read by :meth:`prepare_query` (in a worker thread).
        default_source, default_path
            Data to load when the query names none (the demo, or the app's FILE argument).

        Returns
        -------
        bool
            True when everything in the query could be honoured; otherwise :attr:`error`
            lists what could not (the rest is applied).
        """
        if prepared is None:
            prepared = self.prepare_query(query, default_source, default_path)
        if prepared.loaded is not None:  # the new channels offered now, not in the batch
            self.offer_channels(channel_names(prepared.loaded.log))
        # the data, then the model: one call of each watcher, with the final values (a page's
        # first draw redraws each of its parts once, not once per step)
        with batch_call_watchers(self):
            return self._apply_query(prepared)

    def _apply_query(self, prepared: PreparedQuery) -> bool:
        """:meth:`from_query`'s steps (the data, the weights, the model) on prepared data."""
        s = prepared.settings
        problems = list(prepared.problems)
        if prepared.loaded is not None:
            self.install(
                prepared.loaded,
                channel=s.get("channel"),
                fs=s.get("fs"),
                robust=s.get("robust"),
                compensate=s.get("compensate", "auto"),
            )
            if self.error:
                problems.append(self.error)
        else:
            if s.get("robust") is not None:
                self._publish(robust=s["robust"])
            if s.get("compensate") is not None:
                self._publish(compensate=s["compensate"])
        if s.get("weights") is not None and s["weights"] != self.weights:
            self._publish(weights=s["weights"])  # before the model: one fit
            if s.get("model") is None and len(self.model) and not self.set_model(self.model):
                problems.append(self.error)
        if s.get("model") is not None and (s["model"] or len(self.model)):
            if not self.set_model(s["model"]):
                problems.append(self.error)
        if problems:
            self._publish(error="; ".join(dict.fromkeys(problems)))
            return False
        return True

    def data_info(self) -> dict[str, Any]:
        """Description of the data shown (for exports and the info panel): the channel, fs and
        robust choice of the WV shown (:attr:`shown`; a choice whose WV is still being
        computed is not yet the data's)."""
        shown = self.shown
        return {
            "source": self.source,
            "file": self.filename,
            "path": self.path,
            "channel": shown["channel"],
            "channels": list(self.channels),
            "fs_hz": shown["fs"],
            "fs_source": self.fs_source,
            "n_samples": self.n,
            "duration_s": self.duration_s,
            "unit": self.unit,
            "robust_wv": shown["robust"],
            "temperature_compensated": bool(self.wv_raw is not None),
            "temperature_compensation": self.compensate,
            "wv_summary_file": self.is_summary,
        }
