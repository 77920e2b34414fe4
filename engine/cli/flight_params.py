"""``gmwm check LOG --params FILE|log``: a flight's EKF noise parameters against its own still
segments (:func:`engine.formats.flight_check.check_flight_params`).

The log is loaded with ``--segments`` (default ``auto``: its still segments); its first IMU's
gyroscope and accelerometer channels (``gyro_*``/``accel_*``, or ``imu0_*``) are fitted with
``--model`` (default ``WN+RW``); the parameters come from the file (QGroundControl
``.params``, Mission Planner ``.param``) or, with ``--params log``, from the log itself.
"""

from __future__ import annotations

import argparse
from typing import Any

from ..fit import fit_gmwm
from ..formats.flight_check import check_flight_params, read_params_file
from ..io import load_log
from ..units import ExportError
from .common import log_kwargs

__all__ = ["run"]


def run(args: argparse.Namespace) -> dict[str, Any] | str:
    """The comparison as a table or a JSON-ready dict."""
    kw = log_kwargs(args)
    kw.setdefault("segments", "auto")
    log = load_log(args.input, fs=args.fs, **kw)
    names = [
        k
        for k in log.names
        if ("gyr" in k.lower() or "acc" in k.lower())
        and (not k.startswith("imu") or k.startswith("imu0_"))
    ]
    if not names:
        raise ExportError(
            f"'{args.input}' has no gyroscope or accelerometer channel (gyro_*/accel_*): "
            f"channels are {', '.join(log.names)}"
        )
    if args.params == "log":
        params = dict(log.meta.get("params") or {})
        if not params:
            raise ExportError(
                f"'{args.input}' holds no parameters: give the vehicle's file, --params FILE"
            )
    else:
        params = read_params_file(args.params)
    model = args.model or "WN+RW"
    wvs = {k: log.wavelet_variance(k, levels=args.levels) for k in names}
    fits = {k: fit_gmwm(wv, model) for k, wv in wvs.items()}
    res = check_flight_params(fits, params)
    segs = log.meta.get("segments", [])
    seconds = sum(b - a for a, b in segs) / log.fs if segs else log.duration_s
    head = (
        f"{args.input}: {len(segs) or 1} still segment(s), {seconds:.1f} s; channels "
        f"{', '.join(names)}; model {model}"
    )
    if args.json:
        d = res.to_dict()
        d.update(input=str(args.input), channels=names, model=model, still_s=seconds)
        return d
    return f"{head}\n{res.table()}"
