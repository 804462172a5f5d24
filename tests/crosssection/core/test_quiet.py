"""What HiGHS prints on its own stays out of a command's output (crosssection.core.quiet)."""
from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

REPO = Path(__file__).resolve().parents[3]


def _stdout_of(code: str) -> str:
    run = subprocess.run([sys.executable, "-c", textwrap.dedent(code)], cwd=REPO,
                         capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    return run.stdout


def test_printf_inside_is_discarded_and_stdout_restored_after():
    out = _stdout_of("""
        import ctypes
        from crosssection.core.quiet import c_stdout_silenced
        libc = ctypes.CDLL(None)
        print("before", flush=True)
        libc.printf(b"C before\\n")
        with c_stdout_silenced():
            libc.printf(b"from C\\n")
            print("from Python", flush=True)
            with c_stdout_silenced():
                libc.printf(b"nested\\n")
            libc.printf(b"still silenced\\n")
        libc.printf(b"C after\\n")
        libc.fflush(None)
        print("after")
    """)
    assert out.splitlines() == ["before", "C before", "C after", "after"]


def test_a_generated_scene_prints_nothing():
    # this scene's layer counts make scipy's HiGHS repair integer solutions, which it
    # announces with printf 26 times whatever its display option says
    out = _stdout_of("""
        import numpy as np
        from crosssection.core.calibration import Calibration
        from crosssection.truth.network import make_scene
        n = np.arange(1, 41.0)
        make_scene(seed=100, n_stacks=120, max_layers=12, noise_sigma=6.0, blur_px=0.43,
                   jpeg_quality=75, specks=0, smears=2, pinholes=9,
                   calibration=Calibration(tuple(n), tuple(0.1 * n)))
    """)
    assert out == ""
