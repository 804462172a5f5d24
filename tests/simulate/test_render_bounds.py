"""``render`` refuses what no scan can be, before drawing anything: a blur wider than a scan
has, a rod with coinciding consecutive nodes or coordinates far beyond the rod length, a scale
whose scene overflows, an output folder inside the simulation it reads (simulate.render)."""
import shutil

import numpy as np
import pytest

from crosssection.core.errors import ParameterError
from simulate import render
from simulate.cli import main
from simulate.render import (MAX_BLUR_PX, MAX_NOISE_SIGMA, MAX_ROD_COORD, MAX_SCENE_PX,
                             render_configuration)

pytestmark = [pytest.mark.filterwarnings("ignore::simulate.render.TruthWarning"),
              pytest.mark.filterwarnings("ignore::simulate.render.ScanRangeWarning")]

FAST = ["--px-per-mm", "25", "--clean", "--limit", "1"]


@pytest.fixture(scope="module")
def sim(tmp_path_factory):
    """A quench ensemble of one short rod."""
    out = tmp_path_factory.mktemp("quench") / "sim"
    assert main(["quench", "--n-configs", "1", "--segments", "60", "--seed", "1",
                 "--runs", "2", "--nematic-runs", "0", "--maxiter", "5", "--no-progress",
                 "--out", str(out)]) == 0
    return out


@pytest.fixture
def not_drawn(monkeypatch):
    """Fail on the first drawing step: a refusal comes before any memory is spent."""
    def drawn(*args, **kwargs):
        raise AssertionError("drawn")

    for f in ("_hooked_lines", "_stack_lines", "_draw_bands", "_draw_passes"):
        monkeypatch.setattr(render, f, drawn)


def _error(capsys, *argv) -> str:
    """The one ``error:`` line of ``render *argv``, which exits 2."""
    capsys.readouterr()
    assert main(["render", *map(str, argv)]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), lines
    assert "Traceback" not in lines[0] and "unexpected" not in lines[0]
    return lines[0]


def _with_rods(sim, folder, change):
    """A copy of ``sim`` whose rods are ``change(rod)``."""
    shutil.copytree(sim, folder)
    with np.load(sim / "rods.npz") as rods:
        np.savez(folder / "rods.npz", **{k: change(rods[k]) for k in rods.files})
    return folder


@pytest.mark.parametrize("blur", ["1e30", "1e4", str(MAX_BLUR_PX * 1.01)])
def test_a_blur_wider_than_a_scan_is_refused(sim, tmp_path, capsys, not_drawn, blur):
    line = _error(capsys, sim, "--out", tmp_path / "s", "--blur", blur, *FAST)
    assert line.startswith(f"error: --blur: must be at most {MAX_BLUR_PX:g} px")
    assert not (tmp_path / "s").exists()
    with pytest.raises(ParameterError, match="blur_px must be at most"):
        render_configuration(np.load(sim / "rods.npz")["config_00000"], blur_px=float(blur))


@pytest.mark.parametrize("noise", ["1e9", "256"])
def test_noise_beyond_the_inks_contrast_is_refused(sim, tmp_path, capsys, not_drawn, noise):
    """1e9 grey levels of noise was drawn with a warning only."""
    line = _error(capsys, sim, "--out", tmp_path / "s", "--noise", noise, *FAST)
    assert line.startswith(f"error: --noise: must be at most {MAX_NOISE_SIGMA:g} grey levels")
    assert not (tmp_path / "s").exists()


def test_a_rod_too_short_to_draw_is_refused(sim, tmp_path, capsys, not_drawn):
    """A 10-um rod of 0.1-mm sheets was drawn as one blot with warnings only."""
    line = _error(capsys, sim, "--out", tmp_path / "s", "--rod-length-mm", "0.01", *FAST)
    assert line.startswith("error: --rod-length-mm: 0.01 mm draws the whole rod within ")
    assert "less than two of its widest bands" in line and "give at least " in line
    assert not (tmp_path / "s").exists()
    least = float(line.rsplit("give at least ", 1)[1].split()[0])
    xy = np.load(sim / "rods.npz")["config_00000"]
    with pytest.raises(ParameterError, match="less than two of its widest bands"):
        render_configuration(xy, rod_length_mm=0.99 * least, px_per_mm=25.0, clean=True)


def test_a_blur_at_the_bound_is_drawn(sim, tmp_path, capsys):
    capsys.readouterr()
    assert main(["render", str(sim), "--out", str(tmp_path / "s"), "--blur",
                 str(MAX_BLUR_PX), *FAST]) == 0


def test_repeated_nodes_are_refused_naming_the_file_and_configuration(sim, tmp_path, capsys):
    """Each node twice: the same drawing, but zero-length segments whose bends have no
    length, and a truth energy a thousand times the rod's."""
    dup = _with_rods(sim, tmp_path / "dup", lambda xy: np.repeat(xy, 2, axis=0))
    line = _error(capsys, dup, "--out", tmp_path / "s", *FAST)
    assert line.startswith(f"error: {dup / 'rods.npz'}: array 'config_00000' has ")
    assert "zero length" in line
    assert not (tmp_path / "s").exists()
    xy = np.load(sim / "rods.npz")["config_00000"]
    with pytest.raises(ParameterError, match="zero length"):
        render_configuration(np.insert(xy, 5, xy[5], axis=0))


@pytest.mark.filterwarnings("ignore:overflow encountered:RuntimeWarning")
@pytest.mark.parametrize("factor", [1e200, 2 * MAX_ROD_COORD])
def test_coordinates_far_beyond_the_rod_length_are_refused(sim, tmp_path, capsys, factor):
    far = _with_rods(sim, tmp_path / "far", lambda xy: (xy - xy.mean(0)) * factor
                     + factor * MAX_ROD_COORD / 100)
    line = _error(capsys, far, "--out", tmp_path / "s", *FAST)
    assert line.startswith(f"error: {far / 'rods.npz'}: array 'config_00000' has a coordinate")
    assert f"beyond {MAX_ROD_COORD:g}" in line
    with pytest.raises(ParameterError, match="beyond"):
        render_configuration(np.load(far / "rods.npz")["config_00000"])


@pytest.mark.parametrize("flags", [["--px-per-mm", "1e30"], ["--thickness-mm", "1e30"],
                                   ["--hole", "1e30"], ["--rod-length-mm", "1e30"],
                                   ["--px-per-mm", "1e200", "--rod-length-mm", "1e200"]])
def test_an_overflowing_scene_size_is_told_as_it_is(sim, tmp_path, capsys, not_drawn, flags):
    line = _error(capsys, sim, "--out", tmp_path / "s", "--limit", "1", *flags)
    assert line.startswith("error: --px-per-mm: the scene would be ")
    w, h = (float(v) for v in line.split("would be ")[1].split(" px")[0].split(" x "))
    assert w > 0 and h > 0 and w * h > MAX_SCENE_PX


def test_an_out_inside_the_simulation_folder_is_refused(sim, tmp_path, capsys):
    sim = shutil.copytree(sim, tmp_path / "sim")
    before = sorted(p.name for p in sim.iterdir())
    for out in (sim / "scenes", sim / "a" / "b"):
        line = _error(capsys, sim, "--out", out, *FAST)
        assert line.startswith("error: --out: ") and "inside the simulation folder" in line
        assert "outside" in line
    assert sorted(p.name for p in sim.iterdir()) == before
    # the simulation stays a quench output that a later quench extends
    assert main(["quench", "--n-configs", "2", "--segments", "60", "--seed", "1",
                 "--runs", "2", "--nematic-runs", "0", "--maxiter", "5", "--no-progress",
                 "--out", str(sim)]) == 0


@pytest.mark.parametrize("value,extra,word", [("1", (), "applies only to --draw 'passes'"),
                                              ("1e9", ("--draw", "passes"), "[0, 50]"),
                                              ("nan", ("--draw", "passes"), "[0, 50]"),
                                              ("-1", ("--draw", "passes"), "[0, 50]")])
def test_pass_smooth_is_refused_out_of_range_or_without_passes(sim, tmp_path, capsys,
                                                               not_drawn, value, extra, word):
    line = _error(capsys, sim, "--out", tmp_path / "s", "--pass-smooth", value, *extra, *FAST)
    assert line.startswith("error: --pass-smooth: ") and word in line
    assert not (tmp_path / "s").exists()


def test_pass_smooth_reaches_the_drawing_and_its_record(sim, tmp_path):
    import json

    out = tmp_path / "s"
    assert main(["render", str(sim), "--out", str(out), "--draw", "passes",
                 "--pass-smooth", "1", *FAST]) == 0
    assert json.loads((out / "render.json").read_text())["params"]["pass_smooth"] == 1.0


def test_an_unfinished_ensemble_is_rendered_with_a_warning(sim, tmp_path, capsys):
    """A quench stopped before the end (params.json asking for more configurations than
    rods.npz holds) was rendered, and fitted by stats, without a word."""
    import json

    from crosssection.cli import main as foldstat

    short = tmp_path / "short"
    shutil.copytree(sim, short)
    params = json.loads((short / "params.json").read_text())
    params["n_configs"] = 5
    (short / "params.json").write_text(json.dumps(params))
    capsys.readouterr()
    assert main(["render", str(short), "--out", str(tmp_path / "s"), *FAST]) == 0
    err = capsys.readouterr().err
    assert f"warning: {short}: rods.npz holds 1 of the 5 configurations" in err
    foldstat(["stats", str(short), "--out", str(tmp_path / "r"), "--n-boot", "0", "--no-gof",
              "--no-figures"])
    assert "configs.csv: 1 of the 5 configurations params.json asks for" in \
        capsys.readouterr().err


def test_a_second_render_into_the_same_folder_is_refused(sim, tmp_path, capsys):
    """Two renders with other options started together each took the folder for theirs
    (render.json of one, the scenes of the other): the second is refused in one line."""
    from crosssection.core.fileio import exclusive_lock

    out = tmp_path / "s"
    with exclusive_lock(tmp_path / ".s.render.lock", where=out, busy="held"):
        line = _error(capsys, sim, "--out", out, *FAST)
    assert "another render is writing into it" in line and not out.exists()
    assert main(["render", str(sim), "--out", str(out), *FAST]) == 0
    assert not (tmp_path / ".s.render.lock").exists()


def test_a_damaged_scene_is_rendered_again_on_resume(sim, tmp_path):
    """A scene whose image was cut short or whose truth table was removed was trusted by a
    resumed render (validate then failed it): it is rendered again, identically."""
    out = tmp_path / "s"
    assert main(["render", str(sim), "--out", str(out), *FAST]) == 0
    scene = out / "config_00000"
    image = (scene / "image.png").read_bytes()
    (scene / "image.png").write_bytes(image[:1000])
    assert main(["render", str(sim), "--out", str(out), *FAST]) == 0
    assert (scene / "image.png").read_bytes() == image
    (scene / "truth" / "stacks.csv").unlink()
    assert main(["render", str(sim), "--out", str(out), *FAST]) == 0
    assert (scene / "truth" / "stacks.csv").is_file()


def test_a_sheet_wider_than_opencv_draws_is_refused_before_drawing():
    # 700 mm sheets at 50 px/mm failed inside OpenCV's line drawing (widths above 32767 px)
    import numpy as np
    import pytest

    from crosssection.core.errors import ParameterError
    from simulate.render import render_configuration

    import warnings

    from simulate import shapes

    xy = shapes.resample(shapes.hairpin(0.001), 300)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the rod's length capped to keep the image small
        with pytest.raises(ParameterError, match="px thick"):
            render_configuration(xy, px_per_mm=50.0, thickness_mm=700.0, clean=True)


def test_a_rod_beyond_its_wall_is_refused():
    # the hole is the wall: a rod lying outside it is no configuration of that wall
    import warnings

    from simulate import shapes

    xy = shapes.resample(shapes.hairpin(0.001), 300)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        with pytest.raises(ParameterError, match="beyond the wall"):
            render_configuration(xy, wall_radius=1e-3, clean=True)
        reach = float(np.max(np.hypot(*xy.T)))
        sc = render_configuration(xy, wall_radius=1.01 * reach, clean=True)
    assert sc.rgb.ndim == 3
