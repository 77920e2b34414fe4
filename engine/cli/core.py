"""The first sub-commands of ``gmwm``: wavelet variance, GMWM fit, model selection, simulation
and the slope-method study (the table of every sub-command and the dispatch:
:mod:`engine.cli.commands`).

::

    gmwm wv INPUT [--channel NAME] [--fs HZ] [--levels J] [--robust] [--eff E]
             [--confidence 0.95] [--json]
    gmwm fit INPUT --model SPEC [--channel NAME] [--fs HZ] [--levels J] [--robust] [--eff E]
             [--weights ci] [--ci asymptotic|bootstrap] [--confidence 0.95] [--json]
    gmwm simulate --model SPEC_WITH_VALUES -n N [--fs HZ] [--seed S] -o OUT(.h5|.npy|.csv)
    gmwm study slope --reps R --seed S [--n 2.5e6,6.3e6] [--workers 2] [--scheduler ADDRESS]
             [-o DIR] [--json]
    gmwm select INPUT --max-model SPEC | --models SPEC1,SPEC2 [--optimism asymptotic|bootstrap]
             [--weights ci|identity|efficient]

The output, the errors and the warnings are the dispatcher's (:mod:`engine.cli.commands`).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Callable
from typing import Any

from .._jsonutil import json_ready
from .._limits import check_sample_count
from ..fit import fit_gmwm
from ..models import parse_model
from .common import (
    CliError,
    add_bootstrap_options,
    add_check_options,
    add_confidence_option,
    add_deprecated_alias,
    add_log_options,
    add_weights_option,
    add_wv_options,
    alpha_of,
    bootstrap_kwargs,
    check_output,
    cli_text,
    load_wv,
    positive,
    sample_count,
    without_compensation,
)

__all__ = [
    "add_wv_parser",
    "add_fit_parser",
    "add_select_parser",
    "add_simulate_parser",
    "add_study_parser",
    "RUNNERS",
    "run",
]


def _data_args(sp: argparse.ArgumentParser) -> None:
    sp.add_argument(
        "input",
        help="log file: CSV/TSV/text, NPY/NPZ, HDF5, ROS bag, PX4 .ulg, ArduPilot .bin "
        "or a WV summary HDF5",
    )
    sp.add_argument("--channel", help="channel name or index (default: the first)")
    add_wv_options(sp, robust=True)
    sp.add_argument("--json", action="store_true", help="print one JSON object")
    add_log_options(sp)  # --segment --scale --units --topic --stream


def add_wv_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``wv`` sub-command to the ``gmwm`` sub-parsers."""
    wv: argparse.ArgumentParser = sub.add_parser("wv")
    _data_args(wv)
    add_confidence_option(wv, "the WV intervals", "--alpha")
    return wv


def add_fit_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``fit`` sub-command to the ``gmwm`` sub-parsers."""
    fit: argparse.ArgumentParser = sub.add_parser("fit")
    _data_args(fit)
    fit.add_argument("--model", required=True, help="model, e.g. '2*GM+WN+RW'")
    fit.add_argument(
        "more_inputs",
        nargs="*",
        metavar="INPUT",  # several channels/files
        help="more recordings of the same sensor: one model fitted to all",
    )
    fit.add_argument(
        "--channels",
        help="channels of INPUT fitted together by the "
        "multivariate GMWM, e.g. gyro_x,gyro_y,gyro_z",
    )
    fit.add_argument("--shared", help="processes shared by --channels, e.g. WN,RW")
    fit.add_argument(
        "--dependence-test",
        action="store_true",
        help="with --shared: parametric-bootstrap test of dependence (-B)",
    )
    add_weights_option(
        fit,
        "weighting matrix: ci (default, 1/(ci_high-ci_low)^2), identity, "
        "or efficient (two-step, V^-1 from the first fit)",
    )
    fit.add_argument(
        "--ci",
        choices=["asymptotic", "bootstrap"],
        help="parameter intervals: asymptotic sandwich or parametric bootstrap",
    )
    add_confidence_option(fit, "the --ci parameter intervals", "--level")
    add_bootstrap_options(fit, replicates="bootstrap replicates")
    add_check_options(fit)  # --drop-warmup --temperature
    return fit


def add_select_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``select`` sub-command to the ``gmwm`` sub-parsers."""
    sel: argparse.ArgumentParser = sub.add_parser("select")
    _data_args(sel)
    sel.add_argument(
        "--max-model", help="rank every sub-model of this model, e.g. '3*GM+WN+QN+RW+DR'"
    )
    sel.add_argument("--models", help="candidate models separated by commas")
    add_weights_option(
        sel,
        "weighting matrix, the same for every candidate: ci (default, "
        "1/(ci_high-ci_low)^2, the R package's), identity, or efficient (two-step: V from "
        "the largest candidate's ci fit, every candidate refitted with V^-1; the J-test's "
        "chi-square assumes efficient weights)",
    )
    sel.add_argument(
        "--optimism",
        choices=["asymptotic", "bootstrap"],
        default="asymptotic",
        help="optimism term of the WVIC: asymptotic formula (default) or parametric bootstrap",
    )
    add_bootstrap_options(
        sel,
        replicates="bootstrap replicates for --optimism bootstrap",
        workers="processes fitting the candidates",
    )
    sel.add_argument(
        "--top", type=positive(int, "--top"), help="show only the best N (all are ranked)"
    )
    add_check_options(sel)  # --drop-warmup --temperature
    return sel


def add_simulate_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``simulate`` sub-command to the ``gmwm`` sub-parsers."""
    sim: argparse.ArgumentParser = sub.add_parser("simulate")
    sim.add_argument(
        "--model", required=True, help="model with values, e.g. 'WN(sigma2=1e-4)+RW(gamma2=1e-9)'"
    )
    sim.add_argument(
        "-n",
        type=sample_count("-n"),
        required=True,
        help="number of samples (100000 or 1e5); at most what fits in half the available "
        "memory at 32 bytes per sample (engine._limits)",
    )
    sim.add_argument(
        "--fs", type=positive(float, "--fs"), default=1.0, help="sampling frequency in Hz (1)"
    )
    sim.add_argument("--seed", type=int, default=None, help="random seed")
    sim.add_argument("--channel", default="x", help="channel name in the output (default x)")
    sim.add_argument("--unit", default="", help="signal unit stored in the output")
    sim.add_argument(
        "-o",
        "--output",
        required=True,
        help="output file (.h5, .npy or .csv); fs, channel name and unit are kept: in the "
        "file (.h5, .csv) or in the sidecar OUT.npy.json (.npy)",
    )
    return sim


def add_study_parser(sub: Any) -> argparse.ArgumentParser:
    """Add the ``study`` sub-command to the ``gmwm`` sub-parsers."""
    st: argparse.ArgumentParser = sub.add_parser("study")
    st.add_argument("name", choices=["slope"], help="the study to run")
    st.add_argument(
        "--reps",
        type=positive(int, "--reps"),
        default=100,
        help="replicates per log length and sensor (100)",
    )
    st.add_argument("--seed", type=int, default=1, help="base seed (1)")
    st.add_argument(
        "--n",
        default="2.5e6,6.3e6",
        help="log lengths in samples, separated by commas (2.5e6,6.3e6)",
    )
    st.add_argument(
        "--workers", type=positive(int, "--workers"), default=2, help="worker processes (2)"
    )
    st.add_argument(
        "--methods",
        default="GMWM,GMWM-efficient,ARMAV,AVSM",
        help="comma-separated among GMWM (ci weights), GMWM-efficient (two-step "
        "Omega = V^-1, V from the first fit's model), ARMAV, ARMAV-unweighted, AVSM, "
        "AVSM-auto (default GMWM,GMWM-efficient,ARMAV,AVSM)",
    )
    from .batch import add_scheduler_option  # --scheduler local|ADDRESS (Dask)

    add_scheduler_option(st)
    out = st.add_argument(
        "-o",
        "--output",
        metavar="DIR",
        help="folder for study.json/.md/.txt, boxplot.png, rmse.png (created if missing)",
    )
    add_deprecated_alias(st, "--out", out)
    st.add_argument("--json", action="store_true", help="print one JSON object (the summary)")
    return st


def _cmd_wv(args: argparse.Namespace) -> dict[str, Any] | str:
    wv, name = load_wv(args, alpha_of(args.confidence))
    if args.json:
        d = wv.to_dict()
        d["channel"] = name
        return d
    return f"{args.input} [{name}]\n{wv.table()}"


def _cmd_fit(args: argparse.Namespace) -> dict[str, Any] | str:
    if args.channels or args.more_inputs or args.shared or args.dependence_test:
        from .multi import cli_fit  # multivariate GMWM (--channels) or replicates (files)

        return cli_fit(args)
    from ..units import datasheet_rows

    model = parse_model(args.model)
    wv, name = load_wv(args, check=True)  # the log check and --temperature first
    res = fit_gmwm(wv, model, weights=args.weights)
    tf = getattr(args, "temperature_fit", None)
    raw = None  # the raw signal's fit beside a compensated one (none when not compensated)
    if tf is not None and tf.wv_raw is not None:
        raw = fit_gmwm(tf.wv_raw, model, weights=args.weights)
    q = getattr(args, "qualification", None)
    intervals = None
    if args.ci:
        from ..inference import param_intervals

        intervals = param_intervals(
            res,
            method=args.ci,
            level=args.confidence,
            **bootstrap_kwargs(args),
        )
    if args.json:
        d = res.to_dict()
        d["channel"] = name
        d["qualification"] = q.to_dict() if q is not None else None
        if tf is not None:  # with the uncompensated fit beside a compensated one
            d["temperature"] = {**tf.to_dict(), "fit_raw": raw.to_dict() if raw else None}
        else:
            d["temperature"] = None
        if intervals is not None:
            d["intervals"] = [iv.to_dict() for iv in intervals]
        # the rows of `gmwm export --format datasheet` (one table: engine.units)
        d["datasheet"] = [
            r.to_dict()
            for r in datasheet_rows(
                res.model,
                res.fs,
                wv.unit,
                channel=name,
                intervals={iv.name: (iv.low, iv.high) for iv in intervals or ()},
                n_levels=wv.n_levels,
            )
        ]
        return json_ready(d)
    text = f"{args.input} [{name}]\n{res.summary()}"
    if tf is not None and raw is not None:
        text += f"\n\n  {tf.line()}\n  {without_compensation('the compensated signal', raw)}"
    elif tf is not None:
        text += f"\n\n  {cli_text(tf.line())}"
    if intervals is not None:
        text += f"\n\n  {100 * args.confidence:g}% intervals ({args.ci}):\n"
        text += "\n".join(
            f"  {iv.name:<16} {iv.value:>12.5e}  [{iv.low:.5e}, {iv.high:.5e}]  {iv.unit}"
            for iv in intervals
        )
    return text


def _cmd_select(args: argparse.Namespace) -> dict[str, Any] | str:
    from ..inference import rank_models
    from .progress import Bar

    if not args.max_model and not args.models:
        raise CliError("give --max-model SPEC or --models 'SPEC1,SPEC2,...'")
    wv, name = load_wv(args, check=True)  # the log check and --temperature first
    cands = [m for m in args.models.split(",") if m.strip()] if args.models else None

    with Bar("gmwm select: candidates", "fit") as bar:  # on a terminal only
        sel = rank_models(
            wv,
            cands,
            max_model=args.max_model,
            weights=args.weights,
            optimism=args.optimism,
            **bootstrap_kwargs(args),
            progress=bar,
        )
    n_ranked = len(sel.candidates)
    shown = sel.candidates[: args.top] if args.top else sel.candidates
    if args.json:
        d = sel.to_dict()
        d["candidates"] = d["candidates"][: len(shown)]
        d["n_ranked"], d["n_shown"] = n_ranked, len(shown)
        d["channel"] = name
        d["wv"] = wv.to_dict()
        best = sel.best.result
        # the IEEE quantities of the selected model (engine.fit.ieee), as gmwm fit --json
        d["ieee"] = best.ieee.to_dict() if best is not None else None
        d["ieee_model"] = sel.best.model
        q, tf = getattr(args, "qualification", None), getattr(args, "temperature_fit", None)
        d["qualification"] = q.to_dict() if q is not None else None
        d["temperature"] = tf.to_dict() if tf is not None else None
        return d
    table = dataclasses.replace(sel, candidates=shown).table()
    if len(shown) < n_ranked:  # say how many were ranked, not only how many are shown
        head, _, rest = table.partition("\n")
        head = head.replace(
            f"({len(shown)} candidates,",
            f"({n_ranked} candidates ranked, best {len(shown)} shown,",
            1,
        )
        table = f"{head}\n{rest}"
    return f"{args.input} [{name}]\n{table}"


def _cmd_simulate(args: argparse.Namespace) -> dict[str, Any] | str:
    from ..io import save_log

    out = args.output
    check_output(out, "-o", suffixes=(".h5", ".hdf5", ".npy", ".csv"))
    model = parse_model(args.model)
    model.validate()
    x = model.simulate(args.n, fs=args.fs, rng=args.seed)
    attrs = {"model": model.spec(values=True), "seed": "" if args.seed is None else str(args.seed)}
    save_log(out, {args.channel: x}, args.fs, units={args.channel: args.unit}, attrs=attrs)
    also = ""
    if out.lower().endswith(".npy"):  # the array holds samples only: fs, name, unit beside it
        from ..io import write_npy_sidecar

        side = write_npy_sidecar(out, args.fs, [args.channel], {args.channel: args.unit}, **attrs)
        also = f" (fs, channel and unit in {side})"
    return f"wrote {args.n} samples of {model.spec(values=True)} at {args.fs:g} Hz to {out}{also}"


def _cmd_study(args: argparse.Namespace) -> dict[str, Any] | str:
    check_output(args.output, "-o", kind="dir")  # before the (slow) imports and any work
    try:
        n_values = [float(v) for v in args.n.split(",") if v.strip()]
    except ValueError:
        raise CliError(f"--n takes sample counts separated by commas, got {args.n!r}") from None
    for v in n_values:  # each worker simulates one replicate at a time
        if not math.isfinite(v):
            raise CliError(f"--n takes sample counts, got {v}")
        check_sample_count(int(round(v)), name="--n", copies=args.workers)
    from ..teaching import run_slope_study
    from .progress import Bar

    methods = [m.strip() for m in args.methods.split(",") if m.strip()]
    from .batch import scheduler_executor

    with scheduler_executor(args) as ex, Bar("gmwm study slope", "replicate") as bar:
        res = run_slope_study(
            args.reps,
            seed=args.seed,
            n_values=n_values,
            methods=methods,
            workers=args.workers,
            progress=bar,  # a bar on a terminal only
            executor=ex,
        )
    paths = res.save(args.output) if args.output else {}
    if args.json:
        d = res.to_dict(raw=False)
        d["files"] = paths
        return d
    return res.table() + ("\n\nwrote " + ", ".join(paths.values()) if paths else "")


#: The sub-commands of this module and their bodies (:func:`run`).
RUNNERS: dict[str, Callable[[argparse.Namespace], dict[str, Any] | str]] = {
    "wv": _cmd_wv,
    "fit": _cmd_fit,
    "select": _cmd_select,
    "simulate": _cmd_simulate,
    "study": _cmd_study,
}


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """Run the sub-command ``args.command`` (one of :data:`RUNNERS`)."""
    return RUNNERS[args.command](args)
