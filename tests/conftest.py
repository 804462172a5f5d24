"""Fixtures shared across the test tree (it mirrors the packages: tests/crosssection/...,
tests/simulate/...).

Scenes are generated, never read from fixtures on disk, so every test states the conditions it
runs under; session-scoped fixtures are generated once per worker.
"""
from __future__ import annotations

from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    """The bundled sample scans (``sample_images/``, with ``set.toml`` and truth scenes)."""
    return REPO / "sample_images"


@pytest.fixture(scope="session")
def scene_folder(tmp_path_factory):
    """A generated scene written in the scene-folder layout: ``(folder, scene)``.

    30 stacks of 1-4 layers, clean (seed 31).
    """
    from crosssection.truth.network import make_scene
    from crosssection.truth.scene import write_scene

    scene = make_scene(seed=31, n_stacks=30, max_layers=4)
    folder = tmp_path_factory.mktemp("scene")
    write_scene(scene, folder)
    return folder, scene
