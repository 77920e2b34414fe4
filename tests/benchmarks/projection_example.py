"""The worked example of docs/fit-to-filter.md: the ADIS16405 log projected and bounded.

    python tests/benchmarks/projection_example.py [--log PATH]

Fits ``2*GM+WN+RW`` (and ``WN+RW`` for reference) to ``gyro_x`` and ``accel_x`` of the real
``adis16405_imu1.h5`` (100 Hz, 10^6 samples) and projects the full fit onto the WN + RW of
Kalibr/OpenVINS (``engine.formats.projection.project``, the filter formats' default: the rule,
the bound from two filter steps to the log length, 95 % asymptotic intervals) and onto the
WN + GM of KF-GINS/Gazebo. Prints the fitted model, where each term went, and each exported
value with its interval, factor over the plain conversion and binding scale, in SI, as the page
shows them; ``tests/project/test_readme_numbers.py`` recomputes them (:func:`example`) and compares.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))

from conftest import real_data_dir  # noqa: E402

import engine as eg  # noqa: E402
from engine.formats import project  # noqa: E402

CHANNELS = ("gyro_x", "accel_x")


def example(log_path: Path) -> dict[str, dict[str, Any]]:
    """Per channel: the fits (``full``, ``wnrw``), the projections of ``full`` (``WN+RW``,
    ``WN+GM``) and the plain conversion of the WN+RW fit (``plain_wnrw``)."""
    log = eg.load_log(log_path)
    out: dict[str, dict[str, Any]] = {}
    for ch in CHANNELS:
        wv = eg.wavelet_variance(log[ch], fs=log.fs, unit=log.units[ch])
        full = eg.fit_gmwm(wv, "2*GM+WN+RW")
        out[ch] = {
            "unit": log.units[ch],
            "full": full,
            "wnrw": (wnrw := eg.fit_gmwm(wv, "WN+RW")),
            "plain_wnrw": project(wnrw, "WN+RW", bound=False, channel=ch, ci=None),
            "WN+RW": project(full, "WN+RW", channel=ch),
            "WN+GM": project(full, "WN+GM", channel=ch, ci=None),
        }
    return out


def model_line(fit: Any) -> str:
    """A fitted model's parameters, 4 significant digits (per sample, the log's unit)."""
    return ", ".join(f"{k} {v:.4g}" for k, v in fit.model.values().items())


def param_line(p: Any) -> str:
    """One exported value as docs/fit-to-filter.md writes it."""
    iv = f" [{p.low:.3g}, {p.high:.3g}]" if p.low == p.low else ""
    s = f"{p.name} = {p.value:.3g}{iv} {p.unit}, x{p.factor:.3g} over the plain {p.plain:.3g}"
    if p.binding_tau_s == p.binding_tau_s:
        s += f", binding at {p.binding_tau_s:.3g} s"
    return s


def report_lines(ex: dict[str, dict[str, Any]]) -> list[str]:
    """The lines the script prints (docs/fit-to-filter.md quotes them)."""
    out: list[str] = []
    for ch, d in ex.items():
        out += ["", f"{ch} [{d['unit']}], 2*GM+WN+RW: {model_line(d['full'])}"]
        a = d["plain_wnrw"]
        out.append(
            f"  WN+RW fit: {model_line(d['wnrw'])}: N = {a.value('N'):.3g}, "
            f"K = {a.value('K'):.3g}; the bounded WN+RW is N x"
            f"{d['WN+RW'].value('N') / a.value('N'):.3g}, K x"
            f"{d['WN+RW'].value('K') / a.value('K'):.3g} of these"
        )
        for cons in ("WN+RW", "WN+GM"):
            p = d[cons]
            g = p.inflation
            out.append(
                f"  {cons}: band {p.band[0]:.3g} .. {p.band[1]:.4g} s; WV / fitted WV: "
                f"geometric mean x{g['geometric_mean']:.3g}, largest x{g['max']:.3g} "
                f"at {g['max_tau_s']:.3g} s"
            )
            out += [f"    {lab} -> {where}" for lab, where in p.assignment.items()]
            out += [f"    {param_line(q)}" for q in p.params.values()]
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", type=Path, default=real_data_dir() / "adis16405_imu1.h5")
    args = ap.parse_args()
    if not args.log.is_file():
        sys.exit(f"projection_example: no log at {args.log}; give --log PATH (README, Data)")
    print("\n".join(report_lines(example(args.log))))


if __name__ == "__main__":
    main()
