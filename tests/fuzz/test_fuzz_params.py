"""Random parameters (finite, huge, tiny, negative, NaN, inf, wrong types, strings) through
``AnalysisParams``, ``analyze`` and the ``crosssection`` and ``simulate`` command lines.

Property: accepted (a result, exit 0) or rejected with one line (a ``FoldstatError``; exit 2
and one stderr line naming the file); never another exception, exit 1, a traceback or a hang.
A value that is accepted is a finite number where a number is expected.
"""
from __future__ import annotations

import itertools
import math
import warnings

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import crosssection
from crosssection.cli import main as cs_main
from crosssection.core.errors import FoldstatError
from crosssection.params import PARAM_NAMES, AnalysisParams

FUZZ = settings.get_profile("fuzz")
_CASE = itertools.count()

SPECIAL = [0.0, -0.0, 1e-300, 5e-324, 1e-6, 1e300, 1.7976931348623157e308, -1.0, -1e300,
           math.nan, math.inf, -math.inf, 0.5, 1.0, 2.0, 50.0, 1e9]
numbers = st.one_of(st.sampled_from(SPECIAL), st.floats(allow_nan=True, allow_infinity=True),
                    st.floats(-1e3, 1e3), st.integers(-10**20, 10**20))
wrong_types = st.one_of(st.text(max_size=8), st.booleans(), st.lists(numbers, max_size=3),
                        st.just(None), st.just({"a": 1}), st.just(b"12"),
                        st.sampled_from(["nan", "inf", "-1", "1e300", "", "auto", "paper"]))
values = st.one_of(numbers, numbers, wrong_types)
# optional fields only: leaving px_per_mm and thickness_mm sane keeps h small enough that a
# valid case runs in milliseconds on the small scan
SCALAR_FIELDS = [n for n in PARAM_NAMES if n not in ("calibration",)]


@settings(FUZZ, max_examples=400)
@given(kw=st.dictionaries(st.sampled_from(SCALAR_FIELDS), values, max_size=4))
def test_analysis_params_validate_once(kw):
    """Construction either validates every value or raises ParameterError naming one."""
    try:
        p = AnalysisParams.from_mapping(kw, path="scan.png")
    except FoldstatError as exc:
        line = exc.one_line()
        assert "\n" not in line and line.startswith("scan.png: "), line
        return
    for name in PARAM_NAMES:
        v = getattr(p, name)
        if isinstance(v, float):
            assert math.isfinite(v), (name, v)
    assert p.thickness_px >= 1.0


def _analyze_kw(data):
    kw = data.draw(st.dictionaries(
        st.sampled_from(["s_min_mm2", "l_min_mm", "blue_min", "rg_max", "merge_px",
                         "tangent_mm", "kappa_c_per_mm", "smooth_px", "hole_radius_mm",
                         "rod_length_mm", "bending_rigidity_J", "threshold_method",
                         "curvature_method", "px_per_mm", "thickness_mm"]),
        values, max_size=3))
    kw.setdefault("px_per_mm", 20.0)
    kw.setdefault("thickness_mm", 0.1)
    return kw


@settings(FUZZ, max_examples=70)
@given(data=st.data())
def test_analyze_api_succeeds_or_raises_one_line(data, fuzz_tools, capfd):
    """``analyze`` on a small scan with random parameters: a result or a FoldstatError."""
    kw = _analyze_kw(data)
    rgb = fuzz_tools.small_scan(3)
    capfd.readouterr()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # quality warnings are part of a valid result
        try:
            with fuzz_tools.time_limit(20):
                res = crosssection.analyze(rgb, **kw)
        except FoldstatError as exc:
            assert "\n" not in exc.one_line()
            res = None
    if res is not None:
        s = res.summary if hasattr(res, "summary") else {}
        for key in ("n_junctions", "n_stacks", "n_branches"):
            if key in s:
                assert 0 <= s[key] < rgb.shape[0] * rgb.shape[1], (key, s[key])
    assert capfd.readouterr().err == ""


def _as_arg(v) -> str:
    return repr(v) if isinstance(v, float) else str(v)


@settings(FUZZ, max_examples=70)
@given(data=st.data())
def test_analyze_command_exit_0_or_one_line(data, fuzz_tools, tmp_path, capsys):
    """``crosssection analyze`` with random numeric option values (as the shell passes them:
    text that ``float`` parses, including nan, inf and 1e300)."""
    opts = data.draw(st.dictionaries(
        st.sampled_from(["--px-per-mm", "--thickness-mm", "--s-min-mm2", "--l-min-mm",
                         "--blue-min", "--rg-max", "--merge-px", "--tangent-mm",
                         "--kappa-c-per-mm", "--hole-radius-mm", "--rod-length-mm"]),
        st.one_of(st.sampled_from(SPECIAL), st.floats(-1e3, 1e3)), max_size=3))
    img = tmp_path / f"scan{next(_CASE)}.png"
    from PIL import Image

    Image.fromarray(fuzz_tools.small_scan(4)).save(img)
    argv = ["analyze", str(img), *fuzz_tools.GOOD_ARGS]
    for k, v in opts.items():
        argv.append(f"{k}={_as_arg(v)}")  # "-1e300" alone would read as an option to argparse
    out = tmp_path / f"out{next(_CASE)}"
    with fuzz_tools.time_limit(30):
        status = cs_main(argv + ["--no-figure", "--out", str(out)])
    err = capsys.readouterr().err
    if status == 0:
        assert (out / "summary.json").exists()
    else:
        fuzz_tools.check_one_line(status, err, img.name)
        assert not (out / "summary.json").exists()


QUENCH_OPTS = {"--lambda": numbers, "--noise": numbers, "--u": numbers, "--ftol": numbers,
               "--xtol": numbers, "--wall-radius": numbers, "--contact-distance": numbers,
               "--seed": st.integers(-5, 2**40), "--workers": st.integers(-2, 1),
               "--runs": st.integers(-1, 2), "--maxiter": st.integers(-1, 2),
               "--segments": st.integers(-1, 12), "--n-configs": st.integers(-1, 1)}


@pytest.mark.slow
@settings(FUZZ, max_examples=8)
@given(data=st.data())
def test_quench_command_exit_0_or_one_line(data, fuzz_tools, tmp_path, capsys):
    """``simulate quench`` on a tiny ensemble (1 configuration, <= 12 segments, one short
    Powell run) with random option values; NaN and inf must be refused, not simulated."""
    from simulate.cli import main as sim_main

    keys = data.draw(st.sets(st.sampled_from(sorted(QUENCH_OPTS)), max_size=2))
    opts = {"--n-configs": 1, "--segments": 12, "--runs": 1, "--maxiter": 2,
            "--nematic-runs": "", "--seed": 1}
    for k in sorted(keys):
        opts[k] = data.draw(QUENCH_OPTS[k], label=k)
    out = tmp_path / f"sim{next(_CASE)}"
    argv = ["quench", "--no-progress", "--out", str(out)]
    for k, v in opts.items():
        argv += [f"{k}={_as_arg(v)}"]
    # the first example compiles the Powell kernels on an empty numba cache (about a minute
    # of CPU on a loaded machine): the limit catches hangs, not slow compiles
    with fuzz_tools.time_limit(300):
        status = sim_main(argv)
    captured = capsys.readouterr()
    if status == 0:
        for k in ("--lambda", "--noise", "--u", "--ftol", "--xtol", "--wall-radius",
                  "--contact-distance"):
            v = opts.get(k)
            assert v is None or math.isfinite(float(v)), f"{k}={v} accepted"
        assert "nan" not in captured.out.lower(), captured.out
    else:
        # a quench reads no input file: its one line names the parameter instead
        fuzz_tools.check_one_line(status, captured.err, None)
