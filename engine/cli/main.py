"""The ``gmwm`` command: wavelet variance, GMWM fit and simulation from the shell.

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

Without ``--json`` a readable table with units is printed; with ``--json`` exactly one JSON
object. Bad input exits with status 2 and a one-line message on stderr, never a traceback.
Warnings (queued by the subcommands, or issued by the engine as Python warnings) are printed
after the result as ``gmwm COMMAND: warning: ...``, one line each. An option name has one
meaning in every subcommand (tests/cli/test_cli_options.py holds the table); old spellings
(``--alpha``, ``--level``, ``--out``, ``--select``, ``gmwm virtual --scale``) still work and
print a deprecation warning naming the new option.
"""

from __future__ import annotations

import argparse
import dataclasses
import importlib
import json
import math
import os
import sys
import warnings
from collections.abc import Sequence
from typing import Any, NoReturn

from .._jsonutil import json_ready
from .._limits import check_sample_count
from ..errors import GmwmError
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
    queue_warning,
    sample_count,
    terminal_text,
)

__all__ = ["main", "build_parser"]

# Subcommands that live in their own module engine/cli/<name>.py, each with
# ``add_parser(subparsers)`` and ``run(args) -> dict | str``.
_MODULE_COMMANDS = ("export", "check", "virtual", "batch", "report", "segments", "plan")


class _Parser(argparse.ArgumentParser):
    def error(self, message: str) -> NoReturn:  # one line, exit 2 (argparse's own convention)
        raise CliError(f"{self.prog}: {message}")


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(prog="gmwm", description="GMWM stochastic calibration of inertial sensors.")
    sub = p.add_subparsers(dest="command", required=True, parser_class=_Parser)

    def data_args(sp: argparse.ArgumentParser) -> None:
        sp.add_argument(
            "input",
            help="log file: CSV/TSV/text, NPY/NPZ, HDF5, ROS bag, PX4 .ulg, ArduPilot .bin "
            "or a WV summary HDF5",
        )
        sp.add_argument("--channel", help="channel name or index (default: the first)")
        add_wv_options(sp, robust=True)
        sp.add_argument("--json", action="store_true", help="print one JSON object")
        add_log_options(sp)  # --segment --scale --units --topic --stream

    wv = sub.add_parser("wv", help="empirical Haar wavelet variance with intervals")
    data_args(wv)
    add_confidence_option(wv, "the WV intervals", "--alpha")

    fit = sub.add_parser("fit", help="fit a latent model by GMWM")
    data_args(fit)
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

    sel = sub.add_parser("select", help="rank candidate models by WVIC")
    data_args(sel)
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

    sim = sub.add_parser("simulate", help="simulate a model with given values")
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
    st = sub.add_parser(
        "study",
        help="Monte Carlo studies: slope = AVSM vs ARMAV vs GMWM (the GMWM paper, Fig. 1-2)",
    )
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
    for name in _MODULE_COMMANDS:  # each in its own module: add_parser(sub) and run(args)
        importlib.import_module(f".{name}", __package__).add_parser(sub)
    return p


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
        text += (
            f"\n\n  {tf.line()}\n  the fit above is of the compensated signal; without "
            f"compensation: {raw.model.spec(values=True)}"
        )
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


def _one_line(e: BaseException | Warning | str) -> str:
    """An engine error or warning as one line, in the command's words (:func:`cli_text`)."""
    return cli_text(" ".join(str(e).split()))


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


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``gmwm`` console script; returns the exit status."""
    from .._blas import set_blas_threads

    if argv is None:  # the command itself (not a call from Python): see engine._blas
        set_blas_threads(1)
    try:
        args = build_parser().parse_args(argv)
        args.argv = list(sys.argv[1:] if argv is None else argv)  # as given (gmwm report)
        handler = {
            "wv": _cmd_wv,
            "fit": _cmd_fit,
            "simulate": _cmd_simulate,
            "select": _cmd_select,
            "study": _cmd_study,
        }.get(args.command)
        if handler is None:  # a subcommand in its own module (_MODULE_COMMANDS)
            handler = importlib.import_module(f".{args.command}", __package__).run
        with warnings.catch_warnings(record=True) as caught:  # the engine's, e.g. PX4 range
            out = handler(args)
        for w in caught:
            queue_warning(args, _one_line(w.message))
    except GmwmError as e:  # every engine error (engine.errors): one line, exit status 2
        print(terminal_text(f"gmwm: error: {_one_line(e)}"), file=sys.stderr)
        return 2
    except (ValueError, OSError, TypeError) as e:  # data-dependent errors from numpy/h5py
        print(terminal_text(f"gmwm: error: {_one_line(e)}"), file=sys.stderr)
        return 2
    except KeyboardInterrupt:  # pragma: no cover
        print("gmwm: interrupted", file=sys.stderr)
        return 130
    for warning in getattr(args, "warnings", ()):  # e.g. fs unknown, deprecated option
        print(terminal_text(f"gmwm {args.command}: warning: {warning}"), file=sys.stderr)
    text = json.dumps(out, allow_nan=False) if isinstance(out, dict) else out
    try:
        print(terminal_text(text))
        sys.stdout.flush()  # here, not at exit, so that a closed pipe is caught
    except BrokenPipeError:  # `gmwm wv ... | head -3`: the reader left; no traceback
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())  # the exit-time flush writes nowhere
        return 141  # 128 + SIGPIPE, what a shell tool killed by the closed pipe reports
    return 0
