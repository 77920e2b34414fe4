"""Report speed: CPU time of a calibration report and of a fleet report.

Run: ``nice -n 10 python tests/benchmarks/bench_report.py [--log PATH] [--fleet GLOB ...]
[--model GM+WN+RW] [--no-select] [--no-fleet] [--stages]``.

Prints, in CPU seconds (``time.process_time``, this process), with a ratio to a reference
measured in the same run (one Bokeh figure of a report's Allan deviation, 2 lines of 19 points,
serialised alone with ``bokeh.embed.components``: the unit of the report's own figure work),

* the single report of ``--log`` (default the real ADIS unit 1, six channels) with the fixed
  ``--model`` and, unless ``--no-select``, with the default model selection, as
  ``engine.report`` makes them (``gather_report`` then ``render_html``);
* with ``--stages``, the fixed-model report split into its stages (load and log check, fits,
  each channel's numbers, the export, figures as data, Bokeh models, their serialisation, the
  page);
* unless ``--no-fleet``, the fleet report of the six ADIS units with the fixed model, as
  ``gmwm batch ... --model M --report fleet.html`` makes it: the units' fits and numbers
  (``gather_fleet`` with one worker, in this process) and the page (``render_fleet_html``);
  with ``--before``, the fleet's figures serialised as before this change (each figure added
  to the document as its own root, the model graph recomputed after each), for the ratio.

The issue's targets: a report with model selection in at most 3 s of CPU, a fleet report in at
most 15 s. The reference makes the figures comparable between runs on a shared machine.
"""

from __future__ import annotations

import argparse
import glob
import os
import statistics
import time
from pathlib import Path

import numpy as np

import engine as eg

DATA = Path(__file__).resolve().parents[2].parent / "shared" / "data"


def reference() -> float:
    """CPU of one report-like Bokeh figure (2 lines, 19 points, log axes) serialised alone."""
    from bokeh.embed import components
    from bokeh.plotting import figure

    x = 2.0 ** np.arange(1, 20) / 100.0
    t = time.process_time()
    p = figure(x_axis_type="log", y_axis_type="log", sizing_mode="stretch_width", height=300)
    p.line(x, 1e-3 / np.sqrt(x), legend_label="a")
    p.line(x, 1e-4 * np.sqrt(x), legend_label="b")
    components(p)
    return time.process_time() - t


def _cpu_now() -> float:
    """CPU seconds of this process and of its finished children (a fleet's worker processes)."""
    t = os.times()
    return t.user + t.system + t.children_user + t.children_system


def cpu(fn):
    t = _cpu_now()
    out = fn()
    return _cpu_now() - t, out


def loose_components(specs) -> None:
    """The figures serialised as before (``bokeh.embed.components`` of figures without a
    document, which adds them one root at a time and recomputes the model graph after each):
    the "before" of the figures' cost, in the same run."""
    from bokeh.embed import components

    from engine.reporting import render as rr

    components(rr._bokeh_figures(specs, lambda: None))  # noqa: SLF001


def stages(path: str, model: str) -> list[tuple[str, float]]:
    """The fixed-model report of one log, stage by stage (CPU seconds)."""
    from engine.formats import export
    from engine.io import qualify_log
    from engine.reporting import render as rr
    from engine.reporting.data import _channel  # noqa: PLC2701 (a benchmark of its stages)

    rows = []
    dt, log = cpu(lambda: eg.load_log(path))
    rows.append(("load", dt))
    dt, _ = cpu(lambda: qualify_log(log, log.names))
    rows.append(("log check", dt))
    dt, fits = cpu(lambda: {ch: eg.fit_gmwm(log.wavelet_variance(ch), model) for ch in log.names})
    rows.append(("WVs and fits", dt))
    dt, _ = cpu(lambda: export(None, fits, "json", log=log))
    rows.append(("JSON export (fit_log's)", dt))
    dt, _ = cpu(
        lambda: {ch: _channel(log, ch, f, level=0.95, datasheet=None) for ch, f in fits.items()}
    )
    rows.append(("channels' numbers (intervals, J, PSD)", dt))
    dt, _ = cpu(lambda: export(None, fits, "kalibr", log=log, allow_partial=True))
    rows.append(("Kalibr export", dt))
    rep = eg.reporting.gather_report(log, fits=fits)
    dt, specs = cpu(lambda: rr.figure_specs(rep))
    rows.append(("figures as data", dt))
    dt, figs = cpu(lambda: rr._bokeh_figures(specs, lambda: None))  # noqa: SLF001
    rows.append((f"Bokeh models ({len(figs)} figures)", dt))
    dt, _ = cpu(lambda: rr.render_html(rep))
    rows.append(("render_html (figures in one document, page)", dt))
    dt, _ = cpu(lambda: loose_components(specs))
    rows.append(("before: the figures by components() of loose figures", dt))
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--log", default=str(DATA / "adis16405_imu1.h5"))
    ap.add_argument(
        "--fleet", nargs="*", default=sorted(glob.glob(str(DATA / "adis16405_imu*.h5")))
    )
    ap.add_argument("--model", default="GM+WN+RW")
    ap.add_argument("--no-select", action="store_true")
    ap.add_argument("--no-fleet", action="store_true")
    ap.add_argument("--stages", action="store_true")
    ap.add_argument(
        "--before", action="store_true", help="also the fleet's figures as before (minutes)"
    )
    args = ap.parse_args()
    import bokeh.embed  # noqa: F401 (imports outside the timings)

    import engine.reporting
    from engine.reporting import render as rr

    eg.report(eg.load_log(args.log), model=args.model, channels=["gyro_x"])  # warm imports
    refs = [reference() for _ in range(5)]
    rows: list[tuple[str, float]] = []

    def row(name: str, t: float) -> None:
        rows.append((name, t))
        print(f"  {name}: {t:.2f} s", flush=True)

    if args.stages:
        for n, t in stages(args.log, args.model):
            row(f"stage: {n}", t)
    dt, page = cpu(lambda: eg.report(args.log, model=args.model))
    row(f"report, {args.model} (no ranking), {len(page) / 1e6:.2f} MB", dt)
    if not args.no_select:
        dt, page = cpu(lambda: eg.report(args.log))
        row(f"report, model selection ({engine.reporting.DEFAULT_SELECT})", dt)
    if not args.no_fleet:
        refs += [reference() for _ in range(3)]
        n = len(args.fleet)
        dt, fleet = cpu(lambda: eg.reporting.gather_fleet(args.fleet, model=args.model, workers=1))
        row(f"fleet, {n} logs, {args.model}: fits and numbers (1 worker)", dt)
        dt, page = cpu(lambda: rr.render_fleet_html(fleet))
        nf = len(rr.fleet_figure_specs(fleet))
        row(f"fleet: page ({nf} figures, {len(page) / 1e6:.2f} MB)", dt)
        if args.before:
            dt, _ = cpu(lambda: loose_components(rr.fleet_figure_specs(fleet)))
            row("fleet, before: its figures by components() of loose figures", dt)
    refs += [reference() for _ in range(3)]
    r = statistics.median(refs)
    print(
        f"{Path(args.log).name}; reference (one Bokeh figure serialised) median "
        f"{r * 1e3:.1f} ms (range {min(refs) * 1e3:.1f}-{max(refs) * 1e3:.1f} ms)"
    )
    print("| what | CPU s | / reference |")
    print("|---|---|---|")
    for name, t in rows:
        print(f"| {name} | {t:.2f} | {t / r:.0f} |")


if __name__ == "__main__":
    main()
