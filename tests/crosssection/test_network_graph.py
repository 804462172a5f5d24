"""The folded network as a graph (``crosssection.tables.network_graph``)."""
from __future__ import annotations

import warnings

import pandas as pd
import pytest

import crosssection
from crosssection.tables import network_graph
from crosssection.truth.network import make_scene


def test_the_network_of_an_analysis_holds_its_tables(tmp_path):
    sc = make_scene(seed=3, n_stacks=40, max_layers=4)
    p = sc.params
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = crosssection.analyze(sc.rgb, px_per_mm=p["px_per_mm"], thickness_mm=0.1,
                                   calibration=sc.calibration)
    g = res.network()
    assert g.number_of_edges() == res.summary["n_stacks"]
    assert sum(d["n_br"] for *_, d in g.edges(data=True)) == res.summary["n_branches"]
    assert sum(d["energy"] for *_, d in g.edges(data=True)) == pytest.approx(
        res.summary["total_energy"])
    for row in res.junctions.itertuples():
        assert g.degree(row.junction_id) == row.n_stacks
        assert g.nodes[row.junction_id]["x_px"] == row.x_px
    # the same graph from the tables written to disk
    res.write(tmp_path, figure=False)
    read = {k: pd.read_csv(tmp_path / f"{k}.csv") for k in ("junctions", "stacks", "branches")}
    g2 = network_graph(read["junctions"], read["stacks"], read["branches"])
    assert sorted(g2.edges(keys=True)) == sorted(g.edges(keys=True))


def test_free_ends_and_loops_get_their_own_nodes():
    junctions = pd.DataFrame({"junction_id": [0, 1], "x_px": [0.0, 10.0], "y_px": [0.0, 0.0],
                              "n_stacks": [3, 3]})
    stacks = pd.DataFrame({
        "stack_id": [0, 1, 2, 3, 4], "junction_a": [0, 0, 0, 1, -1],
        "junction_b": [1, 1, -1, 1, -1], "n_br": [1, 2, 1, 1, 1],
        "kind": ["junction", "junction", "free_end", "junction", "loop"]})
    branches = pd.DataFrame({"stack_id": [0, 1, 1, 2, 3, 4],
                             "energy": [1.0, 2.0, 2.0, 3.0, 4.0, 5.0]})
    g = network_graph(junctions, stacks, branches)
    assert g.number_of_edges() == 5
    assert g.number_of_edges(0, 1) == 2              # two stacks between the same junctions
    assert g.nodes["end2b"]["kind"] == "free_end" and g.has_edge(0, "end2b", key=2)
    assert g.has_edge(1, 1, key=3)                   # a stack closing on its junction
    assert g.nodes["loop4"]["kind"] == "loop" and g.has_edge("loop4", "loop4", key=4)
    assert g.edges[0, 1, 1]["energy"] == 4.0
    assert "energy" not in network_graph(junctions, stacks).edges[0, 1, 0]


def _tables():
    junctions = pd.DataFrame({"junction_id": [0, 1], "x_px": [0.0, 10.0]})
    stacks = pd.DataFrame({"stack_id": [0, 1], "junction_a": [0, 0], "junction_b": [1, -1],
                           "n_br": [1, 2], "kind": ["junction", "free_end"]})
    branches = pd.DataFrame({"stack_id": [0, 1, 1], "energy": [1.0, 2.0, 2.0]})
    return junctions, stacks, branches


@pytest.mark.parametrize("table, column, value, words", [
    ("stacks", "junction_a", None, ["stacks table", "lacks the column 'junction_a'"]),
    ("junctions", "junction_id", None, ["junctions table", "lacks the column 'junction_id'"]),
    ("stacks", "junction_a", [float("nan"), 0.0], ["stacks table", "'junction_a', row 1",
                                                   "not a whole number"]),
    ("stacks", "junction_b", [1.0, 0.5], ["stacks table", "'junction_b', row 2"]),
    ("stacks", "stack_id", [3, 3], ["stacks table", "'stack_id', row 2", "3 is given twice"]),
    ("junctions", "junction_id", [1, 1], ["junctions table", "'junction_id', row 2"]),
    ("stacks", "junction_a", [0, 999], ["stacks table", "'junction_a', row 2",
                                        "junction 999 is not in the junctions table"]),
    ("branches", "stack_id", [0, 1, 7], ["branches table", "'stack_id', row 3",
                                         "stack 7 is not in the stacks table"]),
    ("branches", "energy", None, ["branches table", "lacks the column 'energy'"]),
])
def test_tables_read_back_with_defects_are_named(table, column, value, words):
    from crosssection.core.errors import ParameterError

    tables = dict(zip(("junctions", "stacks", "branches"), _tables()))
    if value is None:
        tables[table] = tables[table].drop(columns=[column])
    else:
        tables[table][column] = value
    with pytest.raises(ParameterError) as err:
        network_graph(tables["junctions"], tables["stacks"], tables["branches"])
    msg = err.value.one_line()
    assert all(w in msg for w in words), msg
    # the same tables without the defect make a graph
    assert network_graph(*_tables()).number_of_edges() == 2
