"""``gmwm fit`` with several channels (MGMWM) or several recordings (replicate fit).

The command-line side of :mod:`engine.multivariate` and :mod:`engine.fit.replicates`: it
loads the inputs (with the command's shared loaders, :mod:`engine.cli.common`) and formats the
results; the numerics never import the command line.
"""

from __future__ import annotations

import argparse
from typing import Any

from .._jsonutil import json_ready
from ..fit import FitError
from ..fit.replicates import fit_replicates
from ..inference.temperature import TemperatureFit
from ..io import load_log
from ..multivariate import MultiModel, dependence_test, fit_mgmwm
from ..wv import wv_matrix
from .common import (
    bootstrap_kwargs,
    checked_log,
    cli_text,
    load_wv,
    log_kwargs,
    queue_warning,
    temperature_fit,
    warn_fs_unknown,
    without_compensation,
)
from .progress import Bar

__all__ = ["cli_fit"]


def cli_fit(args: argparse.Namespace) -> dict[str, Any] | str:
    """``gmwm fit`` for several channels (MGMWM) or several recordings (replicates).

    ``gmwm fit IN.h5 --model WN+RW --channels gyro_x,gyro_y,gyro_z [--shared RW]
    [--dependence-test]`` fits a multivariate model; ``gmwm fit IN1.h5 IN2.h5 ... --model M
    [--channel gyro_x]`` fits one model to every file. Errors are raised as FitError /
    ModelError / LoadError (the command prints them on one line, exit status 2).

    Parameters
    ----------
    args : argparse.Namespace
        The parsed ``gmwm fit`` options.

    Returns
    -------
    dict or str
        The JSON-ready object (``--json``) or the readable text.
    """

    files = [args.input] + list(getattr(args, "more_inputs", None) or [])
    channels = getattr(args, "channels", None)
    shared = getattr(args, "shared", None)
    if getattr(args, "ci", None):
        raise FitError("--ci intervals are available for single-channel fits only")
    if channels is None:
        if shared:
            raise FitError("--shared needs --channels (the channels that share the processes)")
        if getattr(args, "dependence_test", False):
            raise FitError("--dependence-test needs --channels and --shared")
        if args.weights == "efficient":
            raise FitError(
                "--weights efficient is not available for replicate fits; use ci or identity"
            )
        wvs, names, checks, temps = [], [], [], []
        with Bar("gmwm fit: files", "file", total=len(files)) as bar:  # on a terminal only
            for f in files:
                one = argparse.Namespace(**{**vars(args), "input": f, "warnings": []})
                # the log check (and --temperature) of each file, one stderr line each
                wv, name = load_wv(one, check=True, label=f"{f}: ")
                for w in one.warnings:  # e.g. this file's fs is unknown: printed with the result
                    queue_warning(args, w)
                wvs.append(wv)
                names.append(name)
                q, tf = getattr(one, "qualification", None), getattr(one, "temperature_fit", None)
                checks.append(q.to_dict() if q is not None else None)
                temps.append(tf.to_dict() if tf is not None else None)
                bar.step()
        res = fit_replicates(wvs, args.model, weights=args.weights)
        if args.json:
            d = res.to_dict()
            d["inputs"] = files
            d["channels"] = names
            d["qualification"] = checks  # per input, in order (None: not checked, --stream)
            d["temperature"] = temps
            return json_ready(d)
        head = "\n".join(f"{f} [{n}]" for f, n in zip(files, names, strict=True))
        return f"{head}\n{res.summary()}"
    if len(files) > 1:
        raise FitError(
            "--channels takes one INPUT (channels recorded together); several "
            "INPUT files are replicates of one channel (use --channel)"
        )
    if getattr(args, "robust", False):
        raise FitError("--robust is not available with --channels (the WCCV is classical)")
    if getattr(args, "stream", False):
        raise FitError("--stream is not available with --channels")
    names = [c.strip() for c in channels.split(",") if c.strip()]
    log = load_log(args.input, fs=args.fs, **log_kwargs(args))
    if log.is_summary:
        raise FitError(
            f"{args.input} is a WV summary file: --channels needs the raw channels "
            "(the WCCV is not stored)"
        )
    if log.fs_source == "default":
        warn_fs_unknown(args, str(args.input))
    unknown = [c for c in names if c not in log.channels]
    if unknown:
        raise FitError(
            f"{args.input}: unknown channel(s) {', '.join(unknown)}; the channels "
            f"are {', '.join(log.channels)}"
        )
    model = MultiModel(names, args.model, shared=shared or ())
    # the log check of `gmwm fit` (one stderr line; --drop-warmup), on the channels fitted
    log, q = checked_log(args, log, names)
    raw_log = log
    # --temperature as the single-channel fit: each channel's relation fitted, said in one
    # stderr line, and taken out when the fit says so (TemperatureFit.applied: always for a
    # channel named, with auto only when its test rejects); the WVs and WCCVs are then those
    # of the compensated signals
    fits: dict[str, TemperatureFit] = {}
    for c in names:
        tf = temperature_fit(args, log, c)
        if tf is not None:
            fits[c] = tf
            log = tf.compensated_log(log)
    wvm = wv_matrix(log, channels=names, levels=args.levels)
    mres = fit_mgmwm(wvm, model, weights=args.weights)
    test = None
    if getattr(args, "dependence_test", False):
        test = dependence_test(wvm, model, **bootstrap_kwargs(args))
    done = [c for c, tf in fits.items() if tf.applied]
    raw = None  # the raw signals' fit beside a compensated one, as the single-channel fit's
    if done:
        raw_wvm = wv_matrix(raw_log, channels=names, levels=args.levels)
        raw = fit_mgmwm(raw_wvm, model, weights=args.weights)
    if args.json:
        d = mres.to_dict()
        d["input"] = args.input
        d["qualification"] = q.to_dict()
        d["fit_raw"] = raw.to_dict() if raw is not None else None
        # per channel its temperature fit (None: no temperature channel beside it); None
        # when no channel has one
        d["temperature"] = {c: fits[c].to_dict() if c in fits else None for c in names}
        if not fits:
            d["temperature"] = None
        if test is not None:
            d["dependence_test"] = test.to_dict()
        return json_ready(d)
    text = f"{args.input} [{', '.join(names)}]\n{mres.summary()}"
    for tf in fits.values():
        text += f"\n\n  {cli_text(tf.line())}"
    if raw is not None:
        what = f"the temperature-compensated {', '.join(done)}"
        text += f"\n  {without_compensation(what, raw)}"
    if test is not None:
        text += f"\n\n  {test.summary()}"
    return text
