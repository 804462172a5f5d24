"""The whole pipeline on generated scans with exact truth.

Targets per scene: rod length within 3 %, junction F1 >= 0.95 (matched within 3 h), exact n_br
on >= 90 % of the stack length, void count within 5 %. Scenes vary in density (20-150 stacks
here; up to 300 in ``benchmarks/accuracy_sweep.py``), layers (1-12), noise, blur, JPEG, smears,
specks and pinholes. The truth comes from ``crosssection.truth.network`` (independent of the
pipeline) and is compared by ``crosssection.truth.scoring``.
"""
import pytest

from crosssection.truth.scoring import analyze_scene_folder, score
from crosssection.truth.network import make_scene
from crosssection.truth.scene import write_scene

pytest.importorskip("crosssection.pipeline")

#: (id, seed, generator options) - a few quick scenes of 600-1100 px
SCENES = [
    ("sparse-thick-clean", 101, dict(n_stacks=25, max_layers=12, mean_layers=5.0)),
    ("medium-noise-blur", 102, dict(n_stacks=60, max_layers=6, mean_layers=3.0, noise_sigma=8.0,
                                    blur_px=1.0, smears=4)),
    ("dense-thin-jpeg", 103, dict(n_stacks=130, max_layers=3, jpeg_quality=75, specks=20,
                                  pinholes=10)),
    ("mixed-jpeg-noise", 104, dict(n_stacks=45, max_layers=8, mean_layers=3.5, noise_sigma=5.0,
                                   jpeg_quality=85, pinholes=15, smears=3)),
]


@pytest.fixture(scope="module", params=SCENES, ids=[s[0] for s in SCENES])
def scored(request, tmp_path_factory):
    name, seed, opts = request.param
    scene = make_scene(seed=seed, **opts)
    folder = write_scene(scene, tmp_path_factory.mktemp(name))
    _, pair = analyze_scene_folder(folder)
    s = score(pair, (scene.summary, scene.tables))
    brief = {k: round(v, 4) if isinstance(v, float) else v for k, v in s.items()}
    return name, s, brief


def test_rod_length_within_3_percent(scored):
    name, s, brief = scored
    assert abs(s["rod_length_rel_error"]) <= 0.03, f"{name}: {brief}"


def test_junction_f1(scored):
    name, s, brief = scored
    assert s["junction_f1"] >= 0.95, f"{name}: {brief}"


def test_exact_n_br_on_90_percent_of_length(scored):
    name, s, brief = scored
    assert s["n_br_exact_length_fraction"] >= 0.90, f"{name}: {brief}"


def test_void_count_within_5_percent(scored):
    name, s, brief = scored
    assert abs(s["n_voids_rel_error"]) <= 0.05, f"{name}: {brief}"

