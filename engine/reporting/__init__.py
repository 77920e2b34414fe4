"""Calibration reports: one self-contained HTML file per IMU log.

* :mod:`.data`: :func:`gather_report` computes what the report shows (pure numerics, every
  number from the engine's own operations) into a :class:`CalibrationReport`;
* :mod:`.figures`: the figures as data (curves, bands, points);
* :mod:`.render`: :func:`render_html` draws them, Bokeh with inline resources (interactive)
  or matplotlib PNGs (``static=True``), in a Jinja2 page;
* :func:`report`: both steps, and the file;
* :mod:`.fleet`: :func:`gather_fleet` fits a fleet of logs (a batch) into a
  :class:`FleetReport` (noise terms per unit, verdicts against limits or a datasheet, robust
  outliers), :func:`render_fleet_html` draws it with every unit's own section, and
  :func:`fleet_report` does both and writes the file.

``engine.report`` and ``engine.fleet_report`` are the functions of this package that users call.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path
from typing import Any

from .._files import write_atomic
from .data import DEFAULT_SELECT, CalibrationReport, ChannelReport, gather_report
from .fleet import FleetReport, gather_fleet
from .render import ReportError, render_fleet_html, render_html

__all__ = [
    "report",
    "gather_report",
    "render_html",
    "CalibrationReport",
    "ChannelReport",
    "ReportError",
    "DEFAULT_SELECT",
    "fleet_report",
    "gather_fleet",
    "render_fleet_html",
    "FleetReport",
]


def _check_html_output(output: str | os.PathLike[str]) -> None:
    """A report's output path: an ``.html``/``.htm`` file in a folder that exists."""
    out = Path(output)
    if out.suffix.lower() not in (".html", ".htm"):
        raise ReportError(f"output {str(output)!r}: a report is an HTML file; end it in .html")
    if not out.parent.is_dir():
        raise ReportError(
            f"output {str(output)!r}: folder '{out.parent}' does not exist; create it first"
        )


def report(
    source: Any,
    output: str | os.PathLike[str] | None = None,
    *,
    static: bool = False,
    title: str | None = None,
    **options: Any,
) -> str:
    """A calibration report of one IMU log as one self-contained HTML page.

    Parameters
    ----------
    source : path or ImuLog
        The log, or a log already loaded.
    output : path, optional
        Where to write the page (``.html``/``.htm``); the page is returned either way.
    static : bool
        PNG figures (matplotlib) instead of interactive Bokeh plots, for archiving.
    title : str, optional
        Page title.
    **options
        The keywords of :func:`gather_report`: ``model`` or ``select``, ``channels``, ``fs``,
        ``levels``, ``weights``, ``level``, ``datasheet``, ``export_format``,
        ``load_options``, ``command_line``, and ``progress`` (``progress(stage, done,
        total)``, called through every stage: fits, intervals, figures, writing).

    Returns
    -------
    str
        The HTML page.

    Examples
    --------
    The report of a simulated gyroscope log (``eg.report(eg.demo_path(), "demo.html",
    model="GM+WN+RW")`` writes the bundled demo's):

    >>> import re
    >>> import numpy as np
    >>> import engine as eg
    >>> x = eg.parse_model("WN(1e-6) + RW(1e-12)").simulate(2**14, rng=np.random.default_rng(1))
    >>> log = eg.ImuLog({"gyro_x": x}, fs=100.0, units={"gyro_x": "rad/s"}, source="sim.h5")
    >>> page = eg.report(log, model="WN+RW")
    >>> re.search("<title>(.*)</title>", page).group(1), page.count('id="fig-')
    ('Calibration report: sim.h5', 4)
    """
    if output is not None:  # before the fits: a bad path fails at once
        _check_html_output(output)
    rep = gather_report(source, **options)
    page = render_html(rep, static=static, title=title, progress=options.get("progress"))
    if output is not None:
        write_atomic(output, page)
    return page


def fleet_report(
    paths: Iterable[str | os.PathLike[str]],
    output: str | os.PathLike[str] | None = None,
    *,
    static: bool = False,
    title: str | None = None,
    **options: Any,
) -> str:
    """A fleet acceptance report of many logs (one unit each) as one self-contained HTML page.

    Parameters
    ----------
    paths : iterable of path or glob pattern
        The units' logs; a log that cannot be read or fitted is listed with its reason.
    output : path, optional
        Where to write the page (``.html``/``.htm``); the page is returned either way.
    static : bool
        PNG figures (matplotlib) instead of interactive Bokeh plots.
    title : str, optional
        Page title.
    **options
        The keywords of :func:`gather_fleet`: ``model`` or ``select``, ``datasheet``,
        ``spec`` (limits ``"arw<=0.3 deg/sqrt(h)"``), ``level``, ``channels``, ``fs``,
        ``levels``, ``weights``, ``load_options``, ``workers``, ``executor`` (e.g. a Dask
        ``Client.get_executor()``), ``progress``, ``export_format``, ``command_line``.

    Returns
    -------
    str
        The HTML page.

    Examples
    --------
    >>> import engine as eg
    >>> html = eg.fleet_report(["lab/unit_*.h5"], "fleet.html", model="GM+WN+RW",
    ...                        spec=["arw<=0.3 deg/sqrt(h)"])  # doctest: +SKIP
    """
    if output is not None:
        _check_html_output(output)
    page = render_fleet_html(gather_fleet(paths, **options), static=static, title=title)
    if output is not None:
        write_atomic(output, page)
    return page
