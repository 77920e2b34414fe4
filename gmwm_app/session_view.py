"""Sessions, exports and time gaps in the page: save/restore a session, Kalibr and datasheet.

Two layers, like the rest of the app:

* functions on an :class:`~gmwm_app.state.AppState` (no widgets, testable without a browser):
  :func:`session_json` writes the session (data reference, load options, channel, fs, robust
  WV, model, WV and fit) with :func:`engine.session.session_to_json`; :func:`prepare_restore`
  (worker-thread safe) reads a session file and its data again; :func:`apply_restore` puts it
  in the state; :func:`export_text` gives the Kalibr ``imu.yaml`` or the datasheet of the fit;
  :func:`export_fits` writes the fits of several channels in any registered format;
* :class:`SessionPanel`: the widgets of one page (downloads, restore input, the time-gap box
  with "Analyse the longest clean segment"), driven by a :class:`~gmwm_app.app.GMWMApp`.
"""

from __future__ import annotations

import io
import json
import warnings
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from functools import partial
from pathlib import Path
from typing import TYPE_CHECKING, Any

import panel as pn
import param

from engine.formats import FORMATS, Format, export, misfit
from engine.io import ImuLog
from engine.session import Session, session_from_json, session_to_json
from gmwm_app.data import LoadedData, compensation_mode, fitted_log
from gmwm_app.export_bound import BoundOptions
from gmwm_app.export_preview import ExportPreview
from gmwm_app.limits import check_path, check_upload_size, public_path
from gmwm_app.state import AppState, demo_path, state_param
from gmwm_app.views import redraws

if TYPE_CHECKING:
    from gmwm_app.jobs import Jobs

__all__ = [
    "download_button",
    "session_json",
    "session_filename",
    "prepare_restore",
    "apply_restore",
    "RestorePlan",
    "export_text",
    "export_fits",
    "fit_units",
    "is_gap_error",
    "fleet_note",
    "SessionPanel",
]

#: Text of the engine's time-gap error that says the longest clean segment can be analysed.
_GAP_MARK = "segment='longest'"


# ---------------------------------------------------------------------------------------------
# state layer
# ---------------------------------------------------------------------------------------------
def _data_path(state: AppState) -> str:
    if state.source == "path" and state.path:
        return str(check_path(state.path).resolve())
    if state.source == "demo":
        return str(demo_path().resolve())
    if state.source == "scenario":  # simulated again from its key and seed on restore
        return f"scenario:{state.path}"
    return state.filename or "upload"


def session_json(state: AppState, load: dict[str, Any] | None = None) -> str:
    """The session of ``state`` as JSON text (:func:`engine.session.session_to_json`).

    ``load``: the ``load_log`` options the data were read with (e.g. ``{"segment": "longest"}``).
    The app part holds the source, file name, channel, fs, robust flag, temperature
    compensation switch and model spec.
    """
    ch = state.channel
    models = {ch: state.model.spec()} if ch and len(state.model) else {}
    wvs = {ch: state.wv} if ch and state.wv is not None else {}
    fits = {ch: state.result} if ch and state.result is not None else {}
    app = {
        "source": state.source,
        "filename": state.filename,
        "channel": ch,
        "fs": state.fs,
        "fs_source": state.fs_source,
        "robust": bool(state.robust),
        "compensate": state.compensate,
        "model": state.model.spec(),
        "query": state.to_query(),
    }
    if state.source == "scenario":
        app["scenario"] = state.path
    data_path = _data_path(state)
    text = session_to_json(
        data_path=data_path,
        load=dict(load or {}),
        models=models,
        wvs=wvs,
        fits=fits,
        app=app,
        fingerprint=state.source in ("path", "demo"),
    )
    if state.source not in ("path", "demo"):
        return text
    # the file fingerprinted at its server path, named as the server's users know it
    # (relative to its data folder, gmwm_app.limits.public_path): a downloaded session never
    # carries the server's absolute path; restoring finds the file again from that name
    doc = json.loads(text)
    doc["data"]["path"] = public_path(data_path)
    if "path" in doc["app"].get("query", {}):
        doc["app"]["query"]["path"] = doc["data"]["path"]
    return json.dumps(doc, indent=1, allow_nan=False) + "\n"


def session_filename(state: AppState) -> str:
    """``gmwm_session_<file>_<channel>.json``."""
    stem = Path(state.filename or "data").stem
    return f"gmwm_session_{stem}_{state.channel or 'none'}.json"


@dataclass
class RestorePlan:
    """What :func:`prepare_restore` found: the session, its data (None if missing), notes."""

    session: Session
    loaded: LoadedData | None
    problems: list[str] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)


def prepare_restore(text: str | bytes, name: str = "<upload>") -> RestorePlan:
    """Read a session file and (when it is on the server) its data file; worker-thread safe.

    Raises
    ------
    ValueError
        The text is not a GMWM session file (``SessionError``), or is too large.
    """
    check_upload_size(len(text), name)
    sess = session_from_json(text, source=name)
    app = sess.app or {}
    source = str(app.get("source") or "path")
    channel = app.get("channel") or next(iter(sess.models), None)
    fs = app.get("fs")
    robust = bool(app.get("robust", False))
    # the choice (sessions saved with the switch of before: True is auto, False off; without
    # the key: auto, as then)
    try:
        compensate = compensation_mode(app.get("compensate", "auto"))
    except ValueError as e:  # a session file edited by hand: which file, what to do
        raise ValueError(f"{name}: {e}; edit 'compensate' in the file or remove it") from None
    segment = sess.load.get("segment")
    segment = segment if isinstance(segment, str) else None
    drop = sess.load.get("drop_warmup")  # samples dropped as a warm-up ("Drop the warm-up")
    drop = drop if isinstance(drop, int) and not isinstance(drop, bool) and drop > 0 else 0
    segs = sess.load.get("segments")  # a flight's still segments ("auto" or START:STOP,...)
    segs = segs if isinstance(segs, str) else None
    plan = RestorePlan(sess, None)
    fname = app.get("filename") or Path(sess.data_path).name
    if source == "upload":
        plan.problems.append(
            f"the session's data were the uploaded file {fname}, which the server does not "
            f"keep: upload {fname} again, then restore the session"
        )
        return plan
    if source == "scenario":  # a teaching scenario: deterministic, simulated again
        key = str(app.get("scenario") or sess.data_path.removeprefix("scenario:"))
        try:
            loaded = AppState.read("scenario", path=key, drop_warmup=drop)
        except ValueError as e:
            plan.problems.append(
                f"the session's teaching scenario {key!r} could not be simulated: {e}"
            )
            return plan
        AppState.precompute(loaded, channel, fs, robust, compensate)
        plan.loaded = loaded
        return plan
    given = sess.data_path
    try:  # the folders first: nothing is said of files outside them (not even existence)
        path = str(check_path(given)) if given else ""
    except ValueError as e:
        plan.problems.append(f"the session's data file could not be read: {e}")
        return plan
    if not path or not Path(path).is_file():
        plan.problems.append(
            f"the session's data file {given or fname} is not on this server: "
            "copy it back to that path (or upload it) and restore again"
        )
        return plan
    sess = replace(sess, data_path=path)
    plan.session = sess
    try:
        why = sess.data_changed()
        if why:
            plan.notes.append(
                f"{why} since the session was saved: the model was fitted again on the current data"
            )
        if source == "demo" and Path(path).resolve() == demo_path().resolve():
            loaded = AppState.read("demo", segment=segment, drop_warmup=drop, segments=segs)
        else:
            loaded = AppState.read(
                "path", path=path, segment=segment, drop_warmup=drop, segments=segs
            )
    except ValueError as e:
        plan.problems.append(f"the session's data file could not be read: {e}")
        return plan
    AppState.precompute(loaded, channel, fs, robust, compensate)
    plan.loaded = loaded
    return plan


def apply_restore(state: AppState, plan: RestorePlan) -> bool:
    """Put a prepared session in the state: data, channel, fs, robust WV, model (refitted).

    Returns True when everything was restored; otherwise :attr:`AppState.error` says what is
    missing (and the session is left as it was when the data are missing).
    """
    app = plan.session.app or {}
    problems = list(plan.problems)
    if (
        plan.loaded is None
        and app.get("source") == "upload"
        and state.source == "upload"
        and state.log is not None
        and state.filename == app.get("filename")
    ):
        # the uploaded file is loaded in this session again: restore the session on it
        plan = RestorePlan(
            plan.session,
            LoadedData(state.log, "upload", state.filename, "", wv_cache=state.cached_wvs()),
        )
        problems = []
    if plan.loaded is not None:
        fs = app.get("fs")
        user_fs = fs if app.get("fs_source") == "user" else None
        state.install(
            plan.loaded,
            channel=app.get("channel") or None,
            fs=user_fs,
            robust=bool(app.get("robust", False)),
            compensate=compensation_mode(app.get("compensate", "auto")),
        )
        if state.error:
            problems.append(state.error)
        model = app.get("model")
        if model is None:
            model = plan.session.models.get(state.channel, "")
        if (model or len(state.model)) and not state.set_model(model or ""):
            problems.append(state.error)
    if problems:
        state.report_error("Session not fully restored: " + "; ".join(dict.fromkeys(problems)))
        return False
    state.show_notice("; ".join(plan.notes), clear_error=True)
    return True


def export_text(
    state: AppState,
    fmt: str,
    *,
    projection: str = "bound",
    data: str = "low",
    horizon_s: float | None = None,
    tails: bool = True,
) -> str:
    """The Kalibr ``imu.yaml`` (``fmt="kalibr"``) or datasheet (``"datasheet"``) of the fit.

    One channel (the shown one); the Kalibr file is partial (that axis only). ``projection``:
    how a filter format maps the fit onto its noise model (``engine.export``: ``"bound"``, the
    default, ``"plain"`` or ``"fit"``, the fit's own terms); ``data``, ``horizon_s`` and
    ``tails``: what of the empirical WV the bound covers, up to which scale, and whether the
    loaded log's tail factors raise it (``engine.export``, as ``gmwm export`` does), read from
    the signal the fit was made on (:func:`gmwm_app.data.fitted_log`: temperature-compensated
    when the session compensates the channel).

    Raises
    ------
    ValueError
        No fit yet, or the fit cannot be exported (e.g. an unknown unit); the message says why.
    """
    if state.result is None:
        raise ValueError("no fit yet: add processes to the model first")
    fits = {state.channel: state.result}
    units = {state.channel: state.unit} if state.unit else None
    src = state.filename
    if fmt == "kalibr":
        return export(
            None,
            fits,
            "kalibr",
            units=units,
            source=src,
            allow_partial=True,
            projection=projection,
            data=data,
            horizon_s=horizon_s,
            log=None if state.log is None else fitted_log(state.log, fits, state.compensate),
            tails=tails,
        )
    return export(None, fits, fmt, units=units, source=src)


def fit_units(state: AppState, fits: Mapping[str, Any]) -> dict[str, str]:
    """The loaded log's unit of each fitted channel (channels without one are left out)."""
    log = state.log
    return {ch: u for ch in fits if (u := (log.units or {}).get(ch) if log else None)}


def export_fits(
    state: AppState,
    fits: Mapping[str, Any],
    fmt: str,
    *,
    inflate: float = 1.0,
    filter_rate: float | None = None,
    projection: str = "bound",
    data: str = "low",
    horizon_s: float | None = None,
    tails: bool = True,
) -> str:
    """The fits of several channels of the loaded log in any export format.

    Parameters
    ----------
    state : AppState
        The session (its units, file name and, for a ROS bag, its IMU topic).
    fits : mapping of channel to GMWMResult
        The fits to export (a filter format needs a gyroscope and an accelerometer unless
        it writes a partial file: ``Format.needs_both_sensors``).
    fmt : str
        A name of :data:`engine.formats.FORMATS`.
    inflate : float
        Filter formats: the noise values times this factor (written in the file).
    filter_rate : float, optional
        PX4/ArduPilot: the EKF prediction rate in Hz.
    projection : {"bound", "plain", "fit"}
        Filter formats: the fit projected onto the consumer's noise model and over-bounded
        (default), projected only, or the fit's own terms one by one (``engine.export``).
    data, horizon_s
        Filter formats: what of the empirical WV the bound covers (``"low"``, the default,
        ``"estimate"``, ``"high"``, ``"none"``) and the horizon in s (default the log length;
        ``engine.export``).
    tails : bool
        Filter formats: the data bound times the loaded log's tail factors (the default, as
        ``gmwm export``); False: ``--no-tails``.

    Raises
    ------
    ValueError
        No fit, or the format cannot be written from these fits; the message says why.
    """
    if not fits:
        raise ValueError("no fit yet: add processes to the model first")
    log = state.log
    units = fit_units(state, fits)
    return export(  # the rostopic: the bag's IMU topic when the log is a bag (engine.export)
        None,
        dict(fits),
        fmt,
        units=units or None,
        source=state.filename,
        allow_partial=FORMATS[fmt].takes("allow_partial"),  # Kalibr: the axes fitted
        inflate=inflate,
        filter_rate=filter_rate,
        projection=projection,
        data=data,
        horizon_s=horizon_s,
        log=None if log is None else fitted_log(log, fits, state.compensate),
        tails=tails,
    )


#: The app's choices of how a filter file maps the fit onto its consumer's model.
PROJECTIONS = {
    "Projected and bounded (default)": "bound",
    "Projected only": "plain",
    "The fit's own terms": "fit",
}


def sensors_note(f: Format) -> str:
    """What the export menu says of the sensors a format's file needs, from its record: a
    gyroscope and an accelerometer (:attr:`engine.formats.Format.needs_both_sensors`), or
    nothing for a format that writes a partial file (one sensor; the app asks Kalibr for the
    axes fitted) and for a report."""
    if not f.needs_both_sensors:
        return ""
    return (
        f" {f.name} needs a gyroscope and an accelerometer: show another channel and fit it "
        "to add it."
    )


def fleet_note(f: Format) -> str:
    """What the export menu says of one file for several units of a sensor model, from the
    format's record (:attr:`engine.formats.Format.fleet_file`); empty for a report."""
    if not f.is_filter:
        return ""
    if f.fleet_file:
        return (
            f" One {f.name} file for several units of this sensor: "
            f"`gmwm batch LOG1 LOG2 ... --export {f.name} -o DIR`."
        )
    return (
        f" No fleet file for {f.name}: its Gauss-Markov bias has a correlation time per unit; "
        "export each unit's own file."
    )


def is_gap_error(err: BaseException | str) -> bool:
    """True for the loader's "time gaps, choose a segment" error."""
    return _GAP_MARK in str(err)


# ---------------------------------------------------------------------------------------------
# widgets
# ---------------------------------------------------------------------------------------------
_SMALL = {"font-size": "12px", "color": "#555"}


def download_button(
    callback: Callable[[], Any], filename: str, label: str, color: str = "default"
) -> Any:
    """A full-width download button whose file ``callback`` makes on click.

    Parameters
    ----------
    callback
        Makes the file's content (a file-like object) when the button is clicked.
    filename
        The name the browser saves it under.
    label
        The button's text.
    color
        The button's colour (``"primary"`` or ``"default"``).

    Returns
    -------
    panel.widgets.FileDownload
        The button.
    """
    return pn.widgets.FileDownload(
        callback=callback,
        filename=filename,
        label=label,
        color=color,
        sizing_mode="stretch_width",
        embed=False,
    )


class SessionPanel(pn.viewable.Viewer):
    """The session, export and time-gap widgets of one page (see the module docstring).

    The file names, the fits kept for the exports and the time-gap box depend on the state
    parameters they show (``param.depends(..., watch=True)``).
    """

    state = state_param()

    def __init__(self, state: AppState, jobs: Jobs) -> None:
        super().__init__(state=state)
        self.jobs = jobs
        self._retry: tuple[str, dict[str, Any]] | None = None
        self._load: dict[str, Any] = {}  # load options of the data shown (for the session)
        self.session_download = download_button(
            self._session_file, "gmwm_session.json", "Download session", "primary"
        )
        self.restore_input = pn.widgets.FileInput(
            accept=".json", multiple=False, sizing_mode="stretch_width"
        )
        self.restore_input.param.watch(self._on_restore, "value")
        self.kalibr_download = download_button(
            partial(self._export, "kalibr"), "imu.yaml", "Kalibr imu.yaml", "default"
        )
        self.datasheet_download = download_button(
            partial(self._export, "datasheet"), "gmwm_datasheet.txt", "Datasheet (text)", "default"
        )
        self.export_note = pn.pane.Markdown("", margin=(0, 10), styles=_SMALL)
        # every format of the registry, from the fits of the channels fitted in this session
        self._fits: dict[str, Any] = {}  # channel -> its latest fit (this log, this fs)
        self._fits_log: ImuLog | None = None
        self._fits_of: tuple[Any, ...] = ()  # (load, fs, robust) of the kept fits
        self.format_select = pn.widgets.Select(
            label="Format",
            options={f"{f.description} ({k})": k for k, f in FORMATS.items()},
            value="openvins",
            sizing_mode="stretch_width",
        )
        self.inflate_input = pn.widgets.FloatInput(
            label="Inflate (x, filter formats)", value=1.0, start=1.0, step=0.5, width=140
        )
        self.rate_input = pn.widgets.FloatInput(
            label="Filter rate (Hz)", value=None, start=0.0, width=140, visible=False
        )
        self.projection_select = pn.widgets.Select(
            label="Filter numbers", options=PROJECTIONS, value="bound", sizing_mode="stretch_width"
        )
        self.format_download = download_button(
            self._export_format, "imu.yaml", "Download in this format", "default"
        )
        self.fits_note = pn.pane.Markdown("", margin=(0, 10), styles=_SMALL)
        self.preview = ExportPreview()  # the consumer's model before the download
        self.bound = BoundOptions(self._on_format)  # data bound and horizon, built when opened
        for w in (
            self.format_select,
            self.inflate_input,
            self.rate_input,
            self.projection_select,
            self.preview.toggle,
        ):
            w.param.watch(self._on_format, "value")
        self.gap_report = pn.pane.Markdown("", sizing_mode="stretch_width", margin=(0, 10))
        self.longest_button = pn.widgets.Button(
            label="Analyse the longest clean segment", color="warning", margin=(3, 10)
        )
        self.longest_button.on_click(self._on_longest)
        self.gap_box = pn.Column(
            pn.pane.Markdown("#### Time gaps in the log", margin=(0, 10)),
            self.gap_report,
            self.longest_button,
            visible=False,
            sizing_mode="stretch_width",
            styles={"border": "1px solid #e0a800", "border-radius": "4px"},
            margin=(5, 10),
        )
        self.refresh()

    # layout pieces ---------------------------------------------------------------------------
    def sidebar(self) -> list[Any]:
        """Export and session widgets for the sidebar."""
        h = pn.pane.Markdown
        return [
            pn.Column(  # one Bokeh root (each template root costs a document walk)
                pn.Row(self.kalibr_download, self.datasheet_download, margin=0),
                self.export_note,
                self.format_select,
                pn.Row(self.inflate_input, self.rate_input, margin=0),
                self.projection_select,
                self.bound.panel(),
                self.preview.panel(),
                self.format_download,
                self.fits_note,
                pn.layout.Divider(),
                h("### Session", margin=(0, 10)),
                self.session_download,
                h(
                    "Restore a session file (the data are read again from their server path):",
                    margin=(0, 10),
                    styles=_SMALL,
                ),
                self.restore_input,
                sizing_mode="stretch_width",
                margin=0,
            )
        ]

    def main(self) -> list[Any]:
        """The time-gap box for the main area."""
        return [self.gap_box]

    def __panel__(self) -> pn.Column:
        return pn.Column(*self.sidebar(), *self.main(), sizing_mode="stretch_width", margin=0)

    # state -> widgets ------------------------------------------------------------------------
    @param.depends(
        "state.filename",
        "state.channel",
        "state.result",
        "state.loads",
        "state.fs",
        "state.robust",
        watch=True,
    )
    @redraws("the export and session buttons")
    def refresh(self) -> None:
        """The download names, the fits kept for the exports and their preview, from the
        state."""
        s = self.state
        self.session_download.filename = session_filename(s)
        stem = Path(s.filename or "data").stem
        self.kalibr_download.filename = f"imu_{stem}_{s.channel or 'none'}.yaml"
        self.datasheet_download.filename = f"datasheet_{stem}_{s.channel or 'none'}.txt"
        fit = s.result is not None
        self.kalibr_download.disabled = self.datasheet_download.disabled = not fit
        self.export_note.object = (
            f"Exports of the fit of **{s.channel}** only (one axis; the Kalibr file is "
            "partial: fit and export the other axes with the `gmwm` CLI)."
            if fit
            else "Kalibr and datasheet exports need a fit: add processes to the model."
        )
        self._remember_fit()
        self._on_format()

    @param.depends("state.error", watch=True)
    def _hide_gap_box(self) -> None:
        """The time-gap box goes with its error (another message replaced it)."""
        if self.gap_box.visible and not is_gap_error(self.state.error):
            self.gap_box.visible = False

    def _remember_fit(self) -> None:
        """Keep the latest fit of each channel of the shown log (new data forget them)."""
        s = self.state
        # the fits of another load (even of the same, shared, demo log), rate or WV kind are
        # not kept
        of = (s.loads, s.fs, s.robust)
        if s.log is not self._fits_log or of != self._fits_of:
            self._fits, self._fits_log, self._fits_of = {}, s.log, of
        if s.result is not None and s.channel:
            self._fits[s.channel] = s.result
        elif s.channel:
            self._fits.pop(s.channel, None)

    def _on_format(self, _event: Any = None) -> None:
        key = self.format_select.value
        f = FORMATS[key]
        # only the options the format's record says its writer reads (Format.options)
        self.inflate_input.visible = f.takes("inflate")
        self.rate_input.visible = f.takes("filter_rate")
        self.projection_select.visible = f.takes("projection")
        self.rate_input.placeholder = "required" if f.needs_filter_rate else "the log's rate"
        stem = Path(self.state.filename or "data").stem
        self.format_download.filename = f"{key}_{stem}{f.suffix}"
        names = ", ".join(self._fits) or "none yet"
        disagree = [line for ch, r in self._fits.items() if (line := misfit(r, ch))]
        try:
            opts, bad = self.bound.options, ""
        except ValueError as e:
            opts, bad = {}, f"\n\n**Not exported:** {e}"
        self.format_download.disabled = not self._fits or bool(bad)
        self.fits_note.object = (
            f"Channels fitted in this session: **{names}**."
            + sensors_note(f)
            + fleet_note(f)
            + bad
            + "".join(f"\n\n**Warning:** {line}" for line in disagree)
        )
        self.preview.update(
            self._fits,
            key,
            channel=self.state.channel or "",
            units=fit_units(self.state, self._fits),
            filter_rate=self.rate_input.value if self.rate_input.visible else None,
            projection=self.projection_select.value,
            log=None
            if (lg := self.state.log) is None
            else fitted_log(lg, self._fits, self.state.compensate),
            **opts,
        )

    # callbacks -------------------------------------------------------------------------------
    def _session_file(self) -> io.StringIO:
        s = self.state
        try:
            return io.StringIO(session_json(s, self._load))
        except ValueError as e:  # eg.GmwmError (SessionError, LoadError ...) or numpy's
            s.report_error(f"Could not write the session: {e}")
            return io.StringIO(f"# could not write the session: {e}\n")

    def _export(self, fmt: str) -> io.StringIO:
        s = self.state
        try:
            opts = self.bound.options
            return io.StringIO(export_text(s, fmt, projection=self.projection_select.value, **opts))
        except ValueError as e:
            s.report_error(f"Could not export ({fmt}): {e}")
            return io.StringIO(f"# could not export: {e}\n")

    def _export_format(self) -> io.StringIO:
        s = self.state
        key = self.format_select.value
        rate = self.rate_input.value if self.rate_input.visible else None
        try:
            opts = self.bound.options
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always")
                text = export_fits(
                    s,
                    self._fits,
                    key,
                    inflate=float(self.inflate_input.value or 1.0)
                    if self.inflate_input.visible
                    else 1.0,
                    filter_rate=rate,
                    projection=self.projection_select.value,
                    **opts,
                )
        except ValueError as e:
            s.report_error(f"Could not export ({key}): {e}")
            return io.StringIO(f"# could not export: {e}\n")
        if caught:  # e.g. an autopilot value outside its documented range
            s.show_notice("Export warning: " + "; ".join(str(w.message) for w in caught))
        return io.StringIO(text)

    def _on_restore(self, event: Any) -> None:
        data = event.new
        if not data:
            return
        name = self.restore_input.filename or "session.json"

        def apply(plan: RestorePlan) -> None:
            if plan.loaded is not None:
                self._load = dict(plan.loaded.load)
            apply_restore(self.state, plan)
            self.restore_input.value = None  # the same file can be restored again

        self.jobs.load(f"Restoring the session {name}", partial(prepare_restore, data, name), apply)

    @property
    def load_options(self) -> dict[str, Any]:
        """The ``load_log`` options the data shown were read with (a copy)."""
        return dict(self._load)

    def loaded(self, loaded: LoadedData) -> None:
        """Remember the load options of newly installed data (for the session file)."""
        self._load = dict(loaded.load)
        self._retry = None

    def failed(self, err: BaseException) -> None:
        """A load failed: offer the longest clean segment when the log has time gaps."""
        read = getattr(err, "gmwm_read", None)
        if read is None or not is_gap_error(err):
            return
        self._retry = read
        text = str(err).split(". To go on,")[0]
        self.gap_report.object = (
            f"{text}.\n\nThe samples are not joined across the breaks. Analyse the longest "
            "clean segment, or fix the log and load it again."
        )
        self.gap_box.visible = True

    def _on_longest(self, _event: Any = None) -> None:
        if self._retry is None:
            return
        source, kw = self._retry
        self._retry = None
        self.gap_box.visible = False
        kw = {**kw, "segment": "longest"}
        what = kw.get("filename") or kw.get("path") or source
        self.jobs.load(
            f"Reading the longest clean segment of {what}",
            partial(self.state.read_and_warm, source, **kw),
        )
