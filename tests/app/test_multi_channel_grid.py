"""The Multi-channel tab's grid of small figures builds the component curves it draws.

A k-channel grid has k(k+1)/2 cells; each cell held 8 component renderers (a line, its data
source and their Bokeh companions) from the start, so a 6-channel grid's first opening built
2,676 Bokeh models, most never drawn. A cell now starts with the curves GM+WN+RW draws (3 on
the diagonal, 1 off it) and grows when a fit draws more, up to 8, the model's total staying on
top of the components.
"""

from __future__ import annotations

import numpy as np

from gmwm_app.multi_figures import N_CELL_COMPONENTS, N_CELL_INITIAL, GridFigure


def _curves(n: int) -> list:
    tau = np.geomspace(0.01, 100.0, 9)
    return [(f"P{i}", f"P{i}", False, {"tau_s": tau, "wv": tau ** -(i + 1.0)}) for i in range(n)]


def _data(n: int) -> dict:
    tau = np.geomspace(0.01, 100.0, 9)
    nan = np.full(tau.size, np.nan)
    emp = {k: tau.copy() for k in ("tau_s", "value", "ci_low", "ci_high", "y", "y_low", "y_high")}
    emp["level"] = np.arange(1, tau.size + 1)
    emp["fill"] = ["#000"] * tau.size
    emp["sign"] = ["+"] * tau.size
    return {
        "emp": emp,
        "total": {"tau_s": tau, "value": tau, "pos": tau, "neg": nan},
        "components": _curves(n),
    }


def test_grid_starts_with_the_curves_a_first_fit_draws() -> None:
    g = GridFigure(6)
    assert len(g.cells) == 21
    for (p, q), cell in g.cells.items():
        assert len(cell.comp_renderers) == len(cell.comps) == N_CELL_INITIAL[p == q]
        assert not any(r.visible for r in cell.comp_renderers)
    assert N_CELL_INITIAL == {True: 3, False: 1}
    # 21 cells x (8 - 3 or 1) fewer lines, data sources and their companions than before
    assert len(g.layout.references()) < 1600  # 2,676 with 8 curves per cell


def test_a_cell_grows_to_the_fit_and_keeps_the_total_on_top() -> None:
    g = GridFigure(2)
    cell = g.cells[(1, 0)]  # off the diagonal: one curve to start with
    fig = cell.figure
    cell.update(_data(5), "t", "y")
    assert len(cell.comp_renderers) == 5 and [r.visible for r in cell.comp_renderers] == [True] * 5
    assert all(r in fig.renderers for r in cell.comp_renderers)
    assert fig.renderers[-len(cell.total_renderers) :] == cell.total_renderers  # on top
    for src, (_k, _lab, _neg, d) in zip(cell.comps, _curves(5), strict=True):
        np.testing.assert_array_equal(src.data["wv"], d["wv"])
    cell.update(_data(2), "t", "y")  # fewer: the others hidden and emptied, none removed
    assert [r.visible for r in cell.comp_renderers] == [True, True, False, False, False]
    assert all(len(s.data["tau_s"]) == 0 for s in cell.comps[2:])
    cell.update(_data(12), "t", "y")  # at most N_CELL_COMPONENTS
    assert len(cell.comp_renderers) == N_CELL_COMPONENTS == 8
    assert all(r.visible for r in cell.comp_renderers)
    assert fig.renderers[-len(cell.total_renderers) :] == cell.total_renderers
    cell.update(None, "", "")
    assert not any(r.visible for r in cell.comp_renderers)
