"""The page's "Download report": the calibration report of the session's fit (no widgets).

:func:`session_report` hands the session's loaded log and its fit to the engine
(:func:`engine.reporting.gather_report` with ``fits=``: the fit is reported as it is, nothing is
refitted; :func:`engine.reporting.render_html` draws the page); :func:`report_file` is the
download button's callback: the page as a file, or, when it cannot be made (no log, no fit, an
engine error), the reason as the page's error message (and a short HTML file saying it); any
other failure is a bug, which Panel hands to the app's error boundary (:mod:`gmwm_app.boundary`).
"""

from __future__ import annotations

import html
import io
from dataclasses import replace
from pathlib import Path

from engine.reporting import gather_report, render_html
from gmwm_app.data import message_of, temperature_fit_of
from gmwm_app.state import AppState

__all__ = ["session_report", "report_filename", "report_file"]


def session_report(state: AppState) -> str:
    """The calibration report (one self-contained HTML page) of the session's fitted channel.

    Raises
    ------
    ValueError
        No log loaded, or no fit (an empty model) to report.
    """
    lg, res = state.log, state.result
    if lg is None:
        raise ValueError("load a log first: the report is of the session's log and fit")
    if res is None or not state.channel:
        raise ValueError("fit a model first (add a process): the report shows the session's fit")
    # unless the compensation is off, the temperature fit in force: the report says whether
    # the fit is of the compensated signal
    off = state.compensate == "off"
    tf = None if off else temperature_fit_of(lg, state.channel, state.compensate)
    rep = gather_report(
        lg,
        fits={state.channel: res},
        temperatures={state.channel: replace(tf, fit=res)} if tf is not None else None,
        command_line=f"gmwm-app: {state.filename or 'log'}, channel {state.channel}, "
        f"model {res.model.spec()}, {res.weights} weights",
    )
    return render_html(rep, title=f"Calibration report: {state.filename} ({state.channel})")


def report_filename(state: AppState) -> str:
    """``gmwm_report_<file>_<channel>.html``."""
    stem = Path(state.filename or "data").stem
    return f"gmwm_report_{stem}_{state.channel or 'none'}.html"


def report_file(state: AppState) -> io.StringIO:
    """The download's content: :func:`session_report`, or the reason it cannot be made, shown
    as the page's error (:meth:`AppState.report_error`) and written in the file."""
    try:
        page = session_report(state)
    except ValueError as e:  # no log or no fit, or an engine error (GmwmError): say why
        msg = f"Download report: {message_of(e)}"
        state.report_error(msg)
        page = (
            "<!DOCTYPE html><html lang='en'><meta charset='utf-8'><title>No report</title>"
            f"<p>{html.escape(msg)}</p></html>"
        )
    return io.StringIO(page)
