"""The validation atlas (``python -m simulate benchmark``): tables, charts, readings, CLI."""
import numpy as np
import pandas as pd
import pytest

from simulate import atlas
from simulate.cli import main

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def report(tmp_path_factory):
    """The smallest atlas (every sweep, both generators), run inline."""
    out = tmp_path_factory.mktemp("atlas")
    res = atlas.run_atlas(out, atlas.AtlasConfig.tiny(), seed=3, workers=1)
    return out, res


def test_every_sweep_has_a_sane_table(report):
    out, res = report
    assert set(res["tables"]) == set(atlas.SWEEPS)
    for name, info in atlas.SWEEPS.items():
        df = pd.read_csv(out / f"{name}.csv")
        assert len(df), name
        swept = [c for c in (info.x, info.y) if c]
        need = swept + ["generator", "seed", "analyze_s", "rod_length_rel_error", "junction_f1",
                        "n_br_exact_length_fraction", "n_br_mean_abs_error",
                        "n_voids_rel_error", "total_energy_rel_error", "error"]
        assert not [c for c in need if c not in df.columns], name
        assert list(df.columns[:len(swept)]) == swept, name
        stages = [c for c in df.columns if c.startswith("t_") and c.endswith("_s")]
        assert {"t_threshold_s", "t_skeleton_s", "t_curvature_s"} <= set(stages), name
        ok = df[df["error"].isna()]
        assert len(ok), name
        for c in ("rod_length_rel_error", "junction_f1", "n_br_exact_length_fraction",
                  "total_energy_rel_error", "analyze_s"):
            assert np.isfinite(ok[c]).all(), (name, c)
        assert df["junction_f1"].between(0, 1).all(), name
        assert df["n_br_exact_length_fraction"].between(0, 1).all(), name
        assert (df["analyze_s"] > 0).all() and (df[stages] >= 0).all().all(), name
        # the per-stage times are parts of the analysis' wall time
        assert (df[stages].sum(axis=1) <= df["analyze_s"] * 1.05 + 1e-3).all(), name
    assert set(pd.read_csv(out / "failures.csv").columns) >= {"sweep", "error"}


def test_sweeps_hold_what_they_sweep(report):
    _, res = report
    t, cfg = res["tables"], atlas.AtlasConfig.tiny()
    assert sorted(t["resolution"]["h_px"].unique()) == sorted(cfg.resolution_h)
    assert set(t["resolution"]["generator"]) == {"network", "render"}
    assert sorted(t["noise"]["noise_sigma"].unique()) == sorted(cfg.noise)
    assert np.allclose(t["resolution"]["px_per_mm"] * atlas.THICKNESS_MM,
                       t["resolution"]["h_px"])
    v = t["variants"]
    assert atlas.DEFAULT.name in set(v["variant"])
    assert set(v["variant"]) == set(cfg.variant_names)
    # every variant ran on the same scans
    assert v.groupby("variant")["seed"].apply(frozenset).nunique() == 1
    m = t["map_h_layers"]
    assert len(m.groupby(["h_px", "mean_layers"])) == len(cfg.map_h) * len(cfg.map_layers)
    e = t["epsilon"]
    assert sorted(e["epsilon"].unique()) == sorted(cfg.epsilon)
    assert set(e["generator"]) == {"compact"}
    assert (e["n_segments"] == cfg.epsilon_segments).all()
    assert (e["truth_n_stacks"] > 0).all() and (e["h_px"] == 5.0).all()
    # the compaction's final hold is recorded with every compacted scene
    assert (e["hold_force"] > 0).all()


def test_epsilon_sweep_plan():
    cfg = atlas.AtlasConfig.full()
    rods, tasks = atlas.plan(cfg, 1, ["epsilon"])
    assert rods == []  # nothing to quench: the rods are compacted in the tasks
    assert len(tasks) == len(cfg.epsilon) * cfg.epsilon_configs
    bases = [b for b, _ in tasks]
    assert {b.generator for b in bases} == {"compact"}
    for b, treats in tasks:
        o = dict(b.options)
        assert o["n_segments"] == cfg.epsilon_segments
        assert dict(b.labels)["epsilon"] == o["epsilon"]
        assert [t.sweep for t in treats] == ["epsilon"]
    # the same initial shapes at every epsilon
    seeds = {e: sorted(b.seed for b in bases if dict(b.options)["epsilon"] == e)
             for e in cfg.epsilon}
    assert len({tuple(v) for v in seeds.values()}) == 1
    assert len(seeds[cfg.epsilon[0]]) == len(set(seeds[cfg.epsilon[0]])) == cfg.epsilon_configs
    # compactions are the longest tasks: they start first
    others = atlas.plan(cfg, 1, [s for s in atlas.SWEEPS if s != "epsilon"])[1]
    assert min(b.cost() for b in bases) > max(b.cost() for b, _ in others)


def test_compaction_grows_the_stacks():
    """A tiny rod compacted further: thicker stacks in its scan's truth, and the rows carry
    epsilon and the rod's segments."""
    rows = {}
    for eps in (3.0, 8.0):
        lab = (("epsilon", eps),)
        base = atlas.Base("epsilon", "compact", 11, 5.0, (("epsilon", eps), ("n_segments", 300)),
                          labels=lab)
        (row,) = atlas.run_base(base, [atlas.Treatment("epsilon", lab)])
        assert row["error"] == "" and row["epsilon"] == eps and row["n_segments"] == 300
        rows[eps] = row
    assert rows[8.0]["truth_mean_n_br"] > rows[3.0]["truth_mean_n_br"]
    assert rows[8.0]["truth_max_n_br"] > rows[3.0]["truth_max_n_br"]


def test_failed_compaction_is_a_generation_failure(monkeypatch):
    from crosssection.core.errors import AnalysisError

    def fail(params, rng):
        raise AnalysisError("the wall stopped at R = 0.1 before 0.05")

    monkeypatch.setattr("simulate.compact.compact_rod", fail)
    lab = (("epsilon", 19.0),)
    base = atlas.Base("epsilon", "compact", 1, 5.0, (("epsilon", 19.0), ("n_segments", 2000)),
                      labels=lab)
    rows = atlas.run_base(base, [atlas.Treatment("epsilon", lab)])
    assert len(rows) == 1 and rows[0]["stage"] == "generate"
    assert "wall stopped" in rows[0]["error"] and rows[0]["epsilon"] == 19.0
    tables, failures = atlas._tables(rows, ["epsilon"])
    assert "epsilon" not in tables  # left out of the table, listed as a failure
    assert failures[["sweep", "generator"]].values.tolist() == [["epsilon", "compact"]]


def test_charts_and_index(report):
    out, res = report
    names = list(atlas.SWEEPS) + ["stage_times"]
    assert set(res["charts"]) == set(names)
    index = (out / "index.md").read_text()
    for name in names:
        png = out / f"{name}.png"
        data = png.read_bytes()
        assert data[:8] == PNG_MAGIC and len(data) > 20_000, name
        assert f"]({name}.png)" in index
        assert res["readings"][name].strip(), name
    assert "python -m simulate benchmark" in index
    assert res["readings"]["epsilon"].startswith("compacted simulator rods:")


def test_index_names_the_package_and_library_versions(report):
    """The quenched rods and the scores' last bits follow the code that computed them."""
    from crosssection._version import __version__
    from crosssection.core.provenance import library_versions

    out, _ = report
    index = (out / "index.md").read_text()
    assert f"Versions: foldstat {__version__}; " in index
    for name in ("numpy", "scipy", "numba", "llvmlite", "opencv", "scikit-image"):
        version = library_versions((name,))[name]
        assert f"{name} {version or 'not installed'}" in index, name


def test_failed_analysis_is_scored_as_empty():
    base = atlas.Base("variants", "network", 5, 3.0, (("max_layers", 3), ("n_stacks", 15)))
    broken = atlas.Variant("nothing passes", (("threshold_method", "fixed"),
                                              ("blue_min", 255.0), ("rg_max", 0.0)))
    rows = atlas.run_base(base, [atlas.Treatment("variants", variant=broken),
                                 atlas.Treatment("variants")])
    bad, good = rows
    assert "empty mask" in bad["error"]
    assert bad["junction_f1"] == 0 and bad["n_br_exact_length_fraction"] == 0
    assert bad["rod_length_rel_error"] == -1
    assert good["error"] == "" and good["junction_f1"] > 0.5


def test_readings_come_from_the_numbers():
    rows = []
    for h, nbr in [(2.0, 0.5), (2.5, 0.7), (3.0, 0.9), (5.0, 1.0)]:
        for seed in (1, 2):
            rows.append(dict(generator="network", seed=seed, h_px=h, analyze_s=0.1 * h,
                             n_br_exact_length_fraction=nbr, junction_f1=0.95,
                             rod_length_rel_error=0.0, n_voids_rel_error=0.0,
                             total_energy_rel_error=0.3 if h == 5.0 else 0.1,
                             n_br_mean_abs_error=0.0))
    text = atlas.reading("resolution", pd.DataFrame(rows))
    assert "exact n_br < 0.8 at h <= 2.5 px" in text
    assert "junction F1 holds everywhere" in text
    assert "|energy error| > 20 % at h = 5 px only" in text


def test_pareto_front_and_failure_boundary():
    # time, accuracy: (1, 0.5) beaten by nobody, (2, 0.4) beaten by it, (3, 0.9) best
    assert atlas.pareto_front([2, 1, 3], [0.4, 0.5, 0.9]).tolist() == [1, 2]
    assert atlas.pareto_front([2, 1, 3], [4.0, 5.0, 1.0], maximize=False).tolist() == [1, 0, 2]
    fail = np.array([[True, False], [False, False]])
    assert sorted(atlas._cell_edges(fail)) == [((-0.5, 0.5), (0.5, 0.5)),
                                               ((0.5, 0.5), (-0.5, 0.5))]


def test_seeds_fix_the_scenes():
    cfg = atlas.AtlasConfig.quick()
    a, b, c = (atlas.plan(cfg, s)[1] for s in (1, 1, 2))
    assert [x[0] for x in a] == [x[0] for x in b]
    assert [x[0].seed for x in a] != [x[0].seed for x in c]


def test_rods_are_recorded_and_reused(report, tmp_path, monkeypatch):
    """A report keeps the quenched rods it rendered; ``rods=`` renders them again instead of
    quenching (the quench is chaotic across library builds), the render rows unchanged."""
    out, res = report
    with np.load(out / "rods.npz") as f:
        keys = list(f.files)
        assert keys and all(k.startswith("rod_") for k in keys)
        assert all(f[k].ndim == 2 and f[k].shape[1] == 2 for k in keys)

    def no_quench(*args, **kwargs):
        raise AssertionError("the rod was quenched again")

    monkeypatch.setattr(atlas, "quench_rod", no_quench)
    again = atlas.run_atlas(tmp_path / "again", atlas.AtlasConfig.tiny(), seed=3, workers=1,
                            sweeps=("resolution",), rods=out / "rods.npz")
    cols = ["h_px", "seed", "truth_n_stacks", "n_br_exact_length_fraction", "junction_f1",
            "rod_length_rel_error"]
    first = res["tables"]["resolution"]
    first = first[first["generator"] == "render"][cols].reset_index(drop=True)
    second = again["tables"]["resolution"]
    second = second[second["generator"] == "render"][cols].reset_index(drop=True)
    assert len(first) and first.equals(second)


def test_rods_of_another_seed_are_refused(report, tmp_path):
    out, _ = report
    with pytest.raises(atlas.ParameterError, match="no rod"):
        atlas.run_atlas(tmp_path / "r", atlas.AtlasConfig.tiny(), seed=4, workers=1,
                        sweeps=("resolution",), rods=out / "rods.npz")
    with pytest.raises(atlas.ParameterError, match="not found"):
        atlas.run_atlas(tmp_path / "r", atlas.AtlasConfig.tiny(), seed=3, workers=1,
                        sweeps=("resolution",), rods=tmp_path / "missing.npz")


def test_a_rods_file_of_another_format_is_named_so(tmp_path, capsys):
    """numpy takes a file of no known format for a pickle: the cause is the format, never
    advice to load it unsafely."""
    bad = tmp_path / "rods.npz"
    bad.write_text("junk\n")
    assert main(["benchmark", "--out", str(tmp_path / "r"), "--quick", "--sweeps",
                 "resolution", "--rods", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err == f"error: {bad}: unreadable rods file (not a NumPy .npz archive)\n"


@pytest.mark.parametrize("args, message", [
    (["--workers", "0"], "--workers"),
    (["--seed", "-1"], "--seed"),
    (["--sweeps", "nonsense"], "unknown sweep"),
])
def test_bad_options_one_line_exit_2(tmp_path, capsys, args, message):
    assert main(["benchmark", "--out", str(tmp_path / "r"), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and message in err[0]
    assert not (tmp_path / "r").exists()


def test_unparsable_option_one_line_exit_2(tmp_path, capsys):
    with pytest.raises(SystemExit) as exc:
        main(["benchmark", "--out", str(tmp_path / "r"), "--workers", "two"])
    assert exc.value.code == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "invalid int" in err[0]


def test_report_folder_is_a_file(tmp_path, capsys):
    f = tmp_path / "report"
    f.write_text("x")
    assert main(["benchmark", "--out", str(f), "--quick"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "file" in err[0]


def test_a_folder_of_the_users_files_is_refused_as_the_report(tmp_path):
    """A run replaces the report's files: a folder holding the user's own index.md (or any
    file) and no atlas report is refused before anything runs; an earlier report's is not."""
    own = tmp_path / "notes"
    own.mkdir()
    (own / "index.md").write_text("my notes\n")
    with pytest.raises(atlas.ParameterError, match="holds index.md, and no atlas report"):
        atlas.run_atlas(own, atlas.AtlasConfig.tiny(), seed=3, workers=1, sweeps=["noise"])
    assert (own / "index.md").read_text() == "my notes\n"
    report = tmp_path / "report"
    report.mkdir()
    (report / "index.md").write_text(atlas.ATLAS_TITLE + "\n\nan earlier run\n")
    atlas._check_report_folder(report)  # an earlier report: no error
