"""The result of the slope-method Monte Carlo study: per parameter and method the bias, SD
and RMSE in Table I's datasheet units, as a table, JSON and box plots."""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .._files import atomic_output, write_atomic
from .table1 import TABLE_I

__all__ = ["StudyResult"]


_SHORT = {"ARMAV-unweighted": "ARMAV-unw"}  # plot labels


# -------------------------------------------------------------------------------------------
# results
# -------------------------------------------------------------------------------------------
def _sci(n: float) -> str:
    """2500000 -> '2.5e6'."""
    e = int(math.floor(math.log10(n)))
    return f"{n / 10**e:g}e{e}"


def _json_num(v: Any) -> Any:
    """NaN/inf as None (JSON has no NaN)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _fmt(v: float, sig: int = 3) -> str:
    if v is None or not math.isfinite(v):
        return "n/a"
    return f"{v:.{sig}g}" if 1e-3 <= abs(v) < 1e4 or v == 0 else f"{v:.{sig - 1}e}"


@dataclass(frozen=True, eq=False)
class StudyResult:
    """Estimates of every replicate and their summary.

    Attributes
    ----------
    estimates : dict
        ``estimates[n][sensor][method][code]``: ndarray (reps,) of datasheet values (Table I
        units; NaN where the method failed or does not estimate the process).
    errors : list of dict
        ``{"n", "sensor", "rep", "method", "error"}`` for every failed estimate.
    settings : dict
        reps, seed, n_values, fs, methods, sensors, workers, regions (per n and sensor).
    wall_time_s : float
        Wall time of the run.
    """

    estimates: dict[int, dict[str, dict[str, dict[str, np.ndarray]]]]
    errors: list[dict[str, Any]]
    settings: dict[str, Any]
    wall_time_s: float
    rows: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.rows:
            object.__setattr__(self, "rows", self._summarise())

    def _summarise(self) -> list[dict[str, Any]]:
        rows = []
        for n, by_sensor in self.estimates.items():
            for sensor, by_method in by_sensor.items():
                for code, sym, truth, unit in TABLE_I[sensor]["params"]:
                    for meth, by_code in by_method.items():
                        v = np.asarray(by_code[code], float)
                        ok = v[np.isfinite(v)]
                        if ok.size == 0:
                            continue  # the method does not estimate this process
                        mean = float(np.mean(ok))
                        sd = float(np.std(ok, ddof=1)) if ok.size > 1 else math.nan
                        rmse = float(np.sqrt(np.mean((ok - truth) ** 2)))
                        rows.append(
                            {
                                "n": int(n),
                                "sensor": sensor,
                                "process": code,
                                "symbol": sym,
                                "unit": unit,
                                "truth": truth,
                                "method": meth,
                                "mean": mean,
                                "bias": mean - truth,
                                "rel_bias": (mean - truth) / truth,
                                "sd": sd,
                                "rmse": rmse,
                                "rel_rmse": rmse / truth,
                                "n_ok": int(ok.size),
                                "n_failed": int(v.size - ok.size),
                                "zero_frac": float(np.mean(ok == 0.0)),
                            }
                        )
        return rows

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> StudyResult:
        """Reload a saved study (``study.json`` with its raw estimates), e.g. to redraw it."""
        d = json.loads(Path(path).read_text())
        if "estimates" not in d:
            raise ValueError(f"{path} has no raw estimates (it is a summary)")
        est = {
            int(n): {
                s: {
                    m: {
                        c: np.array([math.nan if x is None else x for x in v], float)
                        for c, v in bm.items()
                    }
                    for m, bm in bs.items()
                }
                for s, bs in bn.items()
            }
            for n, bn in d["estimates"].items()
        }
        return cls(
            estimates=est,
            errors=d.get("errors", []),
            settings=d["settings"],
            wall_time_s=float(d["wall_time_s"]),
        )

    # ---- ranking -----------------------------------------------------------------------
    def _paired_z(self, n: int, sensor: str, code: str, method: str, gmwm: str = "GMWM") -> float:
        """z of the mean paired difference of squared errors, ``gmwm`` (a GMWM variant) minus
        ``method`` (positive: GMWM worse), over the replicates where both have an estimate."""
        truth = {c: v for c, _, v, _ in TABLE_I[sensor]["params"]}[code]
        g = np.asarray(self.estimates[n][sensor][gmwm][code], float)
        m = np.asarray(self.estimates[n][sensor][method][code], float)
        ok = np.isfinite(g) & np.isfinite(m)
        d = (g[ok] - truth) ** 2 - (m[ok] - truth) ** 2
        if d.size < 2:
            return math.nan
        se = float(np.std(d, ddof=1)) / math.sqrt(d.size)
        return float(np.mean(d)) / se if se > 0 else (0.0 if np.mean(d) == 0 else math.inf)

    def ranking(self) -> dict[str, Any]:
        """Lowest-RMSE method per (n, sensor, process) and whether GMWM wins everywhere.

        GMWM is its best variant there (``GMWM`` with ci weights or ``GMWM-efficient``);
        an exception (a method with a lower RMSE than GMWM) is a *tie* when the paired
        difference of squared errors is within 2 Monte Carlo standard errors (``z < 2``, the
        same replicates feed every method) or the RMSEs differ by less than 1 %.
        """
        best: dict[str, str] = {}
        losses = []
        groups: dict[tuple, list[dict[str, Any]]] = {}
        for r in self.rows:
            groups.setdefault((r["n"], r["sensor"], r["process"]), []).append(r)
        for (n, sensor, code), rs in groups.items():
            win = min(rs, key=lambda r: r["rmse"])
            best[f"{n}/{sensor}/{code}"] = win["method"]
            g = sorted((r for r in rs if r["method"].startswith("GMWM")), key=lambda r: r["rmse"])
            if g and not win["method"].startswith("GMWM"):
                z = self._paired_z(n, sensor, code, win["method"], g[0]["method"])
                tie = bool(not z >= 2.0 or g[0]["rmse"] <= 1.01 * win["rmse"])
                losses.append(
                    {
                        "n": n,
                        "sensor": sensor,
                        "process": code,
                        "best": win["method"],
                        "best_rmse": win["rmse"],
                        "best_zero_frac": win.get("zero_frac", 0.0),
                        "gmwm_method": g[0]["method"],
                        "gmwm_rmse": g[0]["rmse"],
                        "gmwm_zero_frac": g[0].get("zero_frac", 0.0),
                        "z": z,
                        "tie": tie,
                    }
                )
        return {
            "best": best,
            "gmwm_lowest_everywhere": not losses,
            "gmwm_lowest_or_tied_everywhere": all(e["tie"] for e in losses),
            "exceptions": losses,
        }

    def ranking_text(self) -> str:
        """A paragraph on the paper's ranking (GMWM lowest RMSE on every parameter)."""
        rk = self.ranking()
        if rk["gmwm_lowest_everywhere"]:
            return (
                "The paper's ranking holds: GMWM has the lowest RMSE on every parameter, "
                "for every sensor and log length."
            )

        def item(e: dict[str, Any]) -> str:
            t = (
                f"{e['sensor']} {e['process']} at T = {_sci(e['n'])} ({e['best']} "
                f"{_fmt(e['best_rmse'])} vs {e.get('gmwm_method', 'GMWM')} {_fmt(e['gmwm_rmse'])}, "
                f"z = {e['z']:.1f}"
            )
            if e.get("gmwm_zero_frac", 0.0) >= 0.05:
                t += f"; GMWM estimates 0 in {100 * e['gmwm_zero_frac']:.0f} % of the replicates"
            if e.get("best_zero_frac", 0.0) >= 0.05:
                t += f"; {e['best']} in {100 * e['best_zero_frac']:.0f} %"
            return t + ")"

        ties = [item(e) for e in rk["exceptions"] if e["tie"]]
        losses = [item(e) for e in rk["exceptions"] if not e["tie"]]
        out = []
        if losses:
            out.append(
                "The paper's ranking does not hold everywhere: another method has a "
                "clearly lower RMSE than GMWM for " + "; ".join(losses) + "."
            )
        else:
            out.append(
                "The paper's ranking holds within Monte Carlo error: GMWM has the "
                "lowest RMSE or is tied with the best on every parameter."
            )
        if ties:
            out.append(
                "Ties (within 2 Monte Carlo standard errors of the paired difference, or "
                "within 1 %): " + "; ".join(ties) + "."
            )
        return " ".join(out)

    # ---- tables ------------------------------------------------------------------------
    def table(self) -> str:
        """Plain-text table of bias, SD and RMSE per parameter and method."""
        s = self.settings
        lines = [
            f"Slope-method study: {s['reps']} replicates, seed {s['seed']}, fs = "
            f"{s['fs']:g} Hz, wall time {self.wall_time_s:.0f} s"
        ]
        head = (
            f"{'T':>9} {'sensor':<6} {'param':<22} {'truth':>10} {'method':<16} "
            f"{'mean':>10} {'bias':>10} {'bias %':>8} {'SD':>10} {'RMSE':>10} "
            f"{'RMSE/truth':>10}"
        )
        lines += [head, "-" * len(head)]
        for r in self.rows:
            p = f"{r['process']} {r['symbol']} [{r['unit']}]"
            lines.append(
                f"{r['n']:>9.3g} {r['sensor']:<6} {p:<22} {_fmt(r['truth']):>10} "
                f"{r['method']:<16} {_fmt(r['mean']):>10} {_fmt(r['bias']):>10} "
                f"{100 * r['rel_bias']:>8.1f} {_fmt(r['sd']):>10} {_fmt(r['rmse']):>10} "
                f"{_fmt(r['rel_rmse']):>10}"
            )
        lines += ["", self.ranking_text()]
        if self.errors:
            lines.append(f"{len(self.errors)} estimate(s) failed (NaN), see the JSON")
        return "\n".join(lines)

    def markdown(self) -> str:
        """Markdown tables (one per log length), lowest RMSE per parameter in bold."""
        s = self.settings
        out = [
            f"Monte Carlo with Table I's true values: {s['reps']} replicates per log length, "
            f"seed {s['seed']}, fs = {s['fs']:g} Hz, methods {', '.join(s['methods'])}; "
            f"wall time {self.wall_time_s:.0f} s on {s['workers']} worker(s). Bias and RMSE "
            "in Table I's units (and relative to the truth)."
        ]
        for n in self.estimates:
            hours = n / s["fs"] / 3600.0
            out += [
                "",
                f"**T = {_sci(n)} samples ({hours:.1f} h at {s['fs']:g} Hz)**",
                "",
                "| Sensor | Parameter | Truth | Method | Bias (%) | SD | RMSE | RMSE / truth |",
                "|---|---|---|---|---|---|---|---|",
            ]
            rows = [r for r in self.rows if r["n"] == n]
            groups: dict[tuple, list[dict[str, Any]]] = {}
            for r in rows:
                groups.setdefault((r["sensor"], r["process"]), []).append(r)
            for (sensor, _), rs in groups.items():
                win = min(r["rmse"] for r in rs)
                for r in rs:
                    b = "**" if r["rmse"] == win else ""
                    out.append(
                        f"| {TABLE_I[sensor]['label']} | {r['process']} {r['symbol']} "
                        f"[{r['unit']}] | {_fmt(r['truth'])} | {r['method']} | "
                        f"{_fmt(r['bias'])} ({100 * r['rel_bias']:+.1f} %) | {_fmt(r['sd'])} | "
                        f"{b}{_fmt(r['rmse'])}{b} | {b}{_fmt(r['rel_rmse'])}{b} |"
                    )
        regs = self.settings.get("regions") or {}
        if regs and "AVSM" in self.settings["methods"]:
            out += ["", "AVSM regions (averaging time, s), as a typical user picks them:"]
            for n, by_s in regs.items():
                parts = [
                    f"{TABLE_I[s]['label'].lower()} "
                    + ", ".join(f"{c} {_fmt(lo)}-{_fmt(hi)}" for c, (lo, hi) in r.items())
                    for s, r in by_s.items()
                ]
                out.append(f"- T = {_sci(float(n))}: " + "; ".join(parts))
        out += ["", self.ranking_text()]
        return "\n".join(out)

    def to_dict(self, raw: bool = True) -> dict[str, Any]:
        """JSON-ready dictionary: settings, summary rows, ranking, and the raw estimates."""
        d: dict[str, Any] = {
            "study": "slope",
            "settings": self.settings,
            "truth": {
                sensor: {
                    c: {"symbol": sym, "value": v, "unit": u}
                    for c, sym, v, u in TABLE_I[sensor]["params"]
                }
                for sensor in self.settings["sensors"]
            },
            "summary": [{k: _json_num(v) for k, v in r.items()} for r in self.rows],
            "ranking": {
                k: (
                    [{kk: _json_num(vv) for kk, vv in e.items()} for e in v]
                    if k == "exceptions"
                    else v
                )
                for k, v in self.ranking().items()
            },
            "wall_time_s": float(self.wall_time_s),
            "errors": self.errors,
        }
        if raw:
            d["estimates"] = {
                str(n): {
                    sensor: {
                        m: {
                            c: [None if not math.isfinite(x) else float(x) for x in v]
                            for c, v in bm.items()
                        }
                        for m, bm in bs.items()
                    }
                    for sensor, bs in bn.items()
                }
                for n, bn in self.estimates.items()
            }
        return d

    # ---- figures -----------------------------------------------------------------------
    def _panels(self) -> list[tuple[str, str, str, float, str]]:
        return [
            (sensor, c, sym, v, u)
            for sensor in self.settings["sensors"]
            for c, sym, v, u in TABLE_I[sensor]["params"]
        ]

    def boxplot(self, path: str | os.PathLike) -> Path:
        """Box plots of estimate / truth per parameter and method (Fig. 1 of the paper)."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        panels = self._panels()
        ns = list(self.estimates)
        fig, axes = plt.subplots(
            len(ns), len(panels), figsize=(3.0 * len(panels), 3.2 * len(ns)), squeeze=False
        )
        for i, n in enumerate(ns):
            for j, (sensor, code, sym, truth, _unit) in enumerate(panels):
                ax = axes[i][j]
                by_m = self.estimates[n][sensor]
                meths = [m for m in by_m if np.any(np.isfinite(by_m[m][code]))]
                data = [
                    np.asarray(by_m[m][code])[np.isfinite(by_m[m][code])] / truth for m in meths
                ]
                ax.boxplot(data, showfliers=True, flierprops={"markersize": 2})
                ax.set_xticks(
                    range(1, len(meths) + 1),
                    [_SHORT.get(m, m) for m in meths],
                    rotation=30,
                    fontsize=8,
                )
                ax.axhline(1.0, color="k", ls="--", lw=0.8)
                allv = np.concatenate(data) if data else np.ones(1)
                if allv.size and (allv.min() < 0.5 or allv.max() > 2.0):
                    # wide spread: log scale, linear near 0 so that estimates at 0 show
                    ax.set_yscale("symlog", linthresh=0.1)
                    ax.set_ylim(bottom=0.0)
                ax.set_title(
                    f"{TABLE_I[sensor]['label']} {code} ({sym})\nT = {_sci(n)}", fontsize=9
                )
                if j == 0:
                    ax.set_ylabel("estimate / truth")
        fig.suptitle(f"Estimates over {self.settings['reps']} replicates (truth = 1)")
        fig.tight_layout()
        p = Path(path)
        with atomic_output(p) as tmp:  # a full disk never leaves half a picture
            fig.savefig(tmp, dpi=110)  # (the same suffix: the same format)
        plt.close(fig)
        return p

    def rmse_plot(self, path: str | os.PathLike) -> Path:
        """RMSE / truth per parameter and method (Fig. 2 of the paper)."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        panels = self._panels()
        ns = list(self.estimates)
        meths = list(self.settings["methods"])
        fig, axes = plt.subplots(1, len(ns), figsize=(6.0 * len(ns), 4.0), squeeze=False)
        width = 0.8 / len(meths)
        for i, n in enumerate(ns):
            ax = axes[0][i]
            for k, m in enumerate(meths):
                vals = []
                for sensor, code, *_ in panels:
                    r = [
                        r
                        for r in self.rows
                        if r["n"] == n
                        and r["sensor"] == sensor
                        and r["process"] == code
                        and r["method"] == m
                    ]
                    vals.append(r[0]["rel_rmse"] if r else np.nan)
                ax.bar(
                    np.arange(len(panels)) + (k - (len(meths) - 1) / 2) * width,
                    vals,
                    width,
                    label=_SHORT.get(m, m),
                )
            ax.set_xticks(
                range(len(panels)),
                [f"{TABLE_I[s]['label']} {c}" for s, c, *_ in panels],
                fontsize=8,
            )
            ax.set_yscale("log")
            ax.set_ylabel("RMSE / truth")
            ax.set_title(f"T = {_sci(n)} samples")
            ax.legend(fontsize=8)
        fig.tight_layout()
        p = Path(path)
        with atomic_output(p) as tmp:  # a full disk never leaves half a picture
            fig.savefig(tmp, dpi=110)  # (the same suffix: the same format)
        plt.close(fig)
        return p

    def save(self, out_dir: str | os.PathLike) -> dict[str, str]:
        """Write ``study.json``, ``study.md``, ``study.txt`` and, with matplotlib,
        ``boxplot.png`` and ``rmse.png`` to ``out_dir``; return the paths by kind."""
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        paths = {"json": d / "study.json", "markdown": d / "study.md", "text": d / "study.txt"}
        write_atomic(paths["json"], json.dumps(self.to_dict(), allow_nan=False, indent=1))
        write_atomic(paths["markdown"], self.markdown() + "\n")
        write_atomic(paths["text"], self.table() + "\n")
        try:
            import matplotlib  # noqa: F401
        except ImportError:  # pragma: no cover - matplotlib is optional
            pass
        else:
            paths["boxplot"] = self.boxplot(d / "boxplot.png")
            paths["rmse"] = self.rmse_plot(d / "rmse.png")
        return {k: str(v) for k, v in paths.items()}
