"""What one page of the app costs the server, part by part (a script; pytest does not collect it).

    python tests/benchmarks/bench_page.py [--repeat 5]

In this process, no server: the page of a session (``gmwm_app.app.create_app``, data not
loaded) built into a fresh Bokeh document as the server builds it (the document's model graph
frozen during the build), in three steps timed in CPU time (``time.process_time``): the Panel
objects (``create_app``), the Bokeh document (Panel's ``server_doc``: every Bokeh model, the
template's roots) and its JSON (``Document.to_json``, what the browser pulls). Then the Bokeh
models by type, and each part of the sidebar and of the Fit tab built alone into a document
of its own (its CPU time and its models).

Same-run references: one Panel Markdown pane and one Panel button with their Bokeh models,
one bare Bokeh ``Div``, one empty Bokeh ``figure``; the page is given in those units too, so
that the figures compare across loads of this shared machine.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from collections import Counter
from pathlib import Path
from typing import Any

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO))


def _cpu(f: Any) -> tuple[float, Any]:
    t = time.process_time()
    out = f()
    return time.process_time() - t, out


def _unit(f: Any, n: int = 30) -> float:
    f()
    t = time.process_time()
    for _ in range(n):
        f()
    return (time.process_time() - t) / n


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=5, help="pages built (after one warm-up)")
    args = ap.parse_args(argv)

    import panel as pn
    from bokeh.document import Document
    from bokeh.models import Div
    from bokeh.plotting import figure
    from panel.io.state import set_curdoc

    from gmwm_app.app import create_app

    def build() -> tuple[float, float, float, Any, Any]:
        doc = Document()
        with set_curdoc(doc), doc.models.freeze():
            t_obj, page = _cpu(lambda: create_app(load=False))
            t_doc, _ = _cpu(lambda: page.server_doc(doc))
        t_json, _ = _cpu(lambda: doc.to_json())
        return t_obj, t_doc, t_json, doc, page

    d = Document()
    ref = {
        "Panel Markdown pane + its models": _unit(lambda: pn.pane.Markdown("x").get_root(d)),
        "Panel Button + its models": _unit(lambda: pn.widgets.Button(label="x").get_root(d)),
        "bare Bokeh Div": _unit(lambda: Div(text="x")),
        "empty Bokeh figure": _unit(lambda: figure(), 10),
    }
    build()  # warm-up: imports, templates
    runs = [build() for _ in range(args.repeat)]
    obj = statistics.median(r[0] for r in runs)
    doc_s = statistics.median(r[1] for r in runs)
    js = statistics.median(r[2] for r in runs)
    total = obj + doc_s + js
    _, _, _, doc, page = runs[-1]
    models = list(doc.models)
    load = os.getloadavg()
    print(
        f"bench_page: {os.cpu_count()} cores, load average {load[0]:.1f}; median of "
        f"{args.repeat} pages (CPU time)"
    )
    div = ref["bare Bokeh Div"]
    print(
        f"page: {total:.3f} s = Panel objects {obj:.3f} s + Bokeh document {doc_s:.3f} s + "
        f"JSON {js:.3f} s; {len(models)} Bokeh models; {total / div:.0f} bare Divs"
    )
    for name, t in ref.items():
        print(f"  reference: {name}: {t * 1e3:.1f} ms ({t / div:.1f} bare Divs)")
    print(
        "Bokeh models by type: "
        + ", ".join(
            f"{k} {v}" for k, v in Counter(type(m).__name__ for m in models).most_common(25)
        )
    )

    app = page.gmwm_app
    rows = []
    for where, parts in (("sidebar", page.sidebar[0].objects), ("Fit tab", app.tabs[0].objects)):
        for o in parts:
            dd = Document()
            with set_curdoc(dd):
                t, root = _cpu(lambda o=o, dd=dd: o.get_root(dd))
            label = str(getattr(o, "object", "") or getattr(o, "label", "") or "")[:40]
            rows.append((t, len(root.references()), where, type(o).__name__, label))
    rows.sort(key=lambda r: -r[0])
    print(f"parts built alone (sum {sum(r[0] for r in rows):.3f} s):")
    for t, n, where, kind, label in rows:
        print(f"  {t * 1e3:6.1f} ms {n:4d} models  {where:8s} {kind} {label!r}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
