"""``benchmarks/`` is a folder of scripts, not a package: its tests load a script from its file."""
from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"


@pytest.fixture(scope="session")
def load_script():
    """A function loading ``benchmarks/<name>.py`` as the module ``<name>``."""
    def load(name: str):
        path = BENCHMARKS / f"{name}.py"
        spec = importlib.util.spec_from_file_location(path.stem, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[path.stem] = module  # dataclasses look their module up while being built
        spec.loader.exec_module(module)
        return module

    return load
