"""Build hook: ship ``sample_images/`` inside the wheel as ``crosssection/_samples``.

Package data must live inside a package, while the demo reads ``sample_images/`` at the top
of the source tree; copying it at build time keeps one copy in the repository. Everything else
is declared in ``pyproject.toml``. An editable install reads ``sample_images/`` in place
(``crosssection.samples.samples_path``).
"""
import shutil
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

SAMPLES = Path(__file__).resolve().parent / "sample_images"


class BuildWithSamples(build_py):
    """``build_py`` that also copies the sample scans into the built package."""

    def run(self):
        super().run()
        if getattr(self, "editable_mode", False) or not SAMPLES.is_dir():
            return
        target = Path(self.build_lib) / "crosssection" / "_samples"
        shutil.rmtree(target, ignore_errors=True)
        shutil.copytree(SAMPLES, target)


setup(cmdclass={"build_py": BuildWithSamples})
