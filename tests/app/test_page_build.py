"""The work of one page open, counted (not timed: these hold on a busy machine).

A class opening the app at once builds one page per person (``tests/benchmarks/bench_load.py``
measures it); these tests keep the per-page work from growing back silently:

* a page's document is built with one walk of its model graph (Bokeh's ``recompute``; it was
  8-10 before the build was frozen), and only the process's first document is validated;
* the initial document has at most :data:`MAX_PAGE_MODELS` Bokeh models, the hidden tabs'
  views are not built until shown, the pool of component curves grows when a model needs it;
* the demo log is read once per process and its WV computed once; the sessions share the log
  (read-only arrays) and have their own WV caches and fits.
"""

from __future__ import annotations

import os
import shutil
import threading
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from bokeh.document import Document
from bokeh.document.models import DocumentModelManager

import engine as eg
from gmwm_app import _panel_compat as compat
from gmwm_app import data, server
from gmwm_app.app import live_apps
from gmwm_app.model_panel import N_POOL
from gmwm_app.state import AppState
from gmwm_app.wv_figures import N_COMPONENTS, N_INITIAL_COMPONENTS

#: Bokeh models of a page's initial document: 342 measured (Panel 1.9.4, Bokeh 3.9.2, the
#: Fit tab and the sidebar; the other tabs are placeholders until shown). It was 434 before
#: the Fit tab's glyphs lost their unused selected/muted copies and the component pool
#: started at 6 renderers instead of 12.
MAX_PAGE_MODELS = 360


@pytest.fixture
def counted(monkeypatch: pytest.MonkeyPatch) -> dict[str, list[int]]:
    """Count Bokeh's walks of a document's model graph and its validations."""
    calls: dict[str, list[int]] = {"recompute": [], "validate": []}
    recompute, validate = DocumentModelManager.recompute, Document.validate

    def counting_recompute(self: Any) -> None:
        calls["recompute"].append(1)
        recompute(self)

    def counting_validate(self: Any) -> None:
        calls["validate"].append(1)
        validate(self)

    monkeypatch.setattr(DocumentModelManager, "recompute", counting_recompute)
    monkeypatch.setattr(Document, "validate", counting_validate)
    monkeypatch.setattr(server, "_VALIDATED", threading.Event())  # as in a new process
    return calls


def _build_page() -> tuple[Document, Any]:
    doc = Document()
    factory = server.create_app_factory()
    server.build_document(partial(compat.eval_panel, factory, "GMWM"), doc)
    return doc, live_apps()[-1]


def test_page_built_with_one_walk_and_bounded(app_demo: Path, counted: dict) -> None:
    sizes = []
    for _ in range(2):
        counted["recompute"].clear()
        doc, app = _build_page()
        assert len(counted["recompute"]) == 1, counted["recompute"]  # one walk per page
        assert app.state.wv is not None and app.state.error == ""  # the page is complete
        assert app.lazy_views == {}  # hidden tabs: placeholders only
        sizes.append(len(list(doc.models)))
        assert doc.validate is server._no_validation  # not again on the loop
    assert len(counted["validate"]) == 1  # the first page of the process only
    assert sizes[0] == sizes[1] <= MAX_PAGE_MODELS, sizes
    # a hidden tab is built when shown, and adds its models then
    app.open_view("Slope method")
    assert set(app.lazy_views) == {"Slope method"}
    assert len(list(doc.models)) > sizes[1]


def test_process_rows_grow_past_the_initial_pool(app_demo: Path, counted: dict) -> None:
    # the sidebar's process rows start at N_POOL (built with every page) and grow when a
    # model has more processes: each process gets its row, label and remove button
    _, app = _build_page()
    panel = app.model_panel
    spec = "4*GM+WN+QN+RW+DR"  # 8 processes
    assert len(eg.parse_model(spec).processes) > N_POOL
    panel.spec_input.value_input = spec
    panel.spec_input.param.trigger("enter_pressed")
    assert app.state.error == "" and len(app.state.model.processes) == 8
    rows = [r for r in panel.process_list.objects[1:] if r.visible]
    assert len(rows) == 8
    labels = [r.objects[0].object for r in rows]
    assert sum("GM" in x for x in labels) == 4 and all(x for x in labels)
    rows[-1].objects[1].clicks += 1  # the grown row's remove button works
    assert len(app.state.model.processes) == 7


def test_page_build_failure_leaves_an_empty_document(counted: dict) -> None:
    doc = Document()

    def broken(d: Document) -> None:
        from bokeh.models import Div

        d.add_root(Div(text="half a page"))
        raise ValueError("the factory failed")

    with pytest.raises(ValueError, match="the factory failed"):
        server.build_document(broken, doc)
    assert doc.roots == []  # built again on the loop
    with pytest.raises(RuntimeError, match="empty document"):
        server.build_document(lambda d: None, Document())


def test_demo_read_once_and_shared(app_demo: Path, tmp_path: Path, monkeypatch) -> None:
    a, b = AppState(), AppState()
    pa = a.prepare_query({}, "demo", "")
    pb = b.prepare_query({}, "demo", "")
    la, lb = pa.loaded, pb.loaded
    assert la.log is lb.log  # one read per process
    assert (la.computations, lb.computations) == (1, 0)  # one WV per process
    assert la.wv_cache is not lb.wv_cache  # each session adds to its own cache
    key = next(iter(la.wv_cache))
    assert la.wv_cache[key] is lb.wv_cache[key]
    x = next(iter(la.log.channels.values()))
    with pytest.raises(ValueError, match="read-only"):
        x[0] = 1.0  # no session can change another's data
    assert a.from_query({}, prepared=pa) and b.from_query({}, prepared=pb)
    assert a.set_model("WN+RW") and b.set_model("GM+WN")  # independent sessions
    assert a.model.spec() == "WN+RW" and b.model.spec() == "GM+WN"
    # the shared WV is the one a fresh read computes
    fresh = AppState()
    data.clear_shared()
    assert fresh.load_demo() and fresh.wv_computations == 1
    np.testing.assert_array_equal(fresh.wv.variance, a.wv.variance)
    assert fresh.set_model("WN+RW")
    assert dict(fresh.result.params) == pytest.approx(dict(a.result.params), rel=1e-12)

    # a changed demo file is read again
    copy = tmp_path / "demo.h5"
    shutil.copy(app_demo, copy)
    monkeypatch.setenv("GMWM_APP_DEMO", str(copy))
    first = AppState().prepare_query({}, "demo", "").loaded
    assert AppState().prepare_query({}, "demo", "").loaded.log is first.log
    st = copy.stat()
    os.utime(copy, ns=(st.st_atime_ns, st.st_mtime_ns + 10**9))
    again = AppState().prepare_query({}, "demo", "").loaded
    assert again.log is not first.log and again.computations == 1


def test_component_pool_grows_on_demand(app: Any) -> None:
    v = app.views
    assert len(v.comps) == N_INITIAL_COMPONENTS < N_COMPONENTS  # built with the page
    spec = "4*GM+WN+RW+QN+DR"  # 8 processes, more than the initial pool
    assert app.state.set_model(spec), app.state.error
    labels = list(app.state.model.labels)
    assert len(labels) == 8 and len(v.comps) == 8
    assert [r.visible for r in v.comp_renderers] == [True] * 8
    assert [src.data["label"][0] for src in v.comps] == labels  # each its own curve
    assert all(len(src.data["wv"]) == len(v.total.data["wv"]) > 0 for src in v.comps)
    assert [src.name for src in v.comps] == [f"component_{i}" for i in range(8)]
    assert v.figure.renderers[-1] is v.total_renderer  # the total stays on top
    assert set(v.comp_renderers) <= set(v.figure.renderers)
    assert v.legend.items[-8:] == v.comp_items and all(it.visible for it in v.comp_items)
    assert set(v.comp_renderers) <= set(v.model_hover.renderers)
    # a smaller model hides the extra curves (the pool does not shrink)
    assert app.state.set_model("WN+RW")
    assert [r.visible for r in v.comp_renderers] == [True, True] + [False] * 6
    # never more than N_COMPONENTS renderers (the first ones drawn), as before
    v._grow_components(N_COMPONENTS + 5)
    assert len(v.comps) == len(v.comp_renderers) == len(v.comp_items) == N_COMPONENTS


def test_document_serialized_ahead_for_the_first_pull(app_demo: Path) -> None:
    from bokeh.models import Div

    ids = []
    for change in (False, True):
        doc, _app = _build_page()
        server.serialize_ahead(doc)
        before = dict(server.PULLS)
        if change:  # a change after the build: the pull must see it
            doc.add_root(Div(text="added after the build", name="gmwm-late-root"))
        first = doc.to_json()
        roots = [r["id"] for r in first.content["roots"]]
        assert roots == [r.id for r in doc.roots]
        assert ("gmwm-late-root" in str(first.content)) is change
        kind = "fresh" if change else "ahead"
        assert server.PULLS[kind] == before[kind] + 1
        assert doc.to_json() is not first  # later calls are Bokeh's own
        assert "to_json" not in vars(doc) and not doc.callbacks._change_callbacks
        ids.append(roots)
    assert len(ids[1]) == len(ids[0]) + 1


def test_a_callback_of_one_session_changes_no_other_page(app_demo: Path) -> None:
    import panel as pn

    docs = [_build_page()[0] for _ in range(2)]
    events: list[Any] = []
    for d in docs:
        d.on_change(lambda event: events.append(event))
    # what Panel does around every callback of any session (pn.state.busy is per process)
    pn.state._add_busy_event("gmwm-test")
    assert pn.state.busy
    pn.state._remove_busy_event("gmwm-test")
    assert not pn.state.busy
    assert events == []  # no page shows the process's busy state (was 2 changes per page)


def test_a_pages_first_data_wake_each_part_once(app_demo: Path) -> None:
    """The data and the model a URL names reach the page in one dispatch: each watcher of
    the state (a part of the page) runs once, with the final values. It ran twice (the data
    without the model, then the model), so the first draw of a page made twice the Panel
    updates on the server loop. The state is the one of the two steps done one by one."""
    q = {"source": "demo", "channel": "gyro_y", "model": "WN+RW"}
    s = AppState()
    prepared = s.prepare_query(q, "demo", "")
    calls: list[list[str]] = []
    names = ["wv", "channel", "filename", "model", "result", "loads"]
    s.param.watch(lambda *events: calls.append(sorted(e.name for e in events)), names)
    assert s.from_query(q, prepared=prepared), s.error
    assert calls == [sorted(names)]
    steps = AppState()
    assert steps.load_demo() and steps.select_channel("gyro_y") and steps.set_model("WN+RW")
    assert (s.channel, s.model.spec(), s.error) == ("gyro_y", "WN+RW", "")
    assert dict(s.result.params) == pytest.approx(dict(steps.result.params), rel=1e-12)
    # a model the data cannot take: the data are shown, the message says why, in one dispatch
    calls.clear()
    bad, bq = AppState(), {**q, "model": "WN+WN"}
    bad.param.watch(lambda *events: calls.append(sorted(e.name for e in events)), names)
    assert not bad.from_query(bq, prepared=bad.prepare_query(bq, "demo", ""))
    assert len(calls) == 1 and bad.channel == "gyro_y" and "2 WN terms" in bad.error
