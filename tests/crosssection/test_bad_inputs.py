"""Bad inputs to ``python -m crosssection analyze``: non-zero exit, one stderr line naming the
file and the cause, no traceback."""
from __future__ import annotations

import subprocess
import sys

import cv2
import numpy as np
import pytest
from PIL import Image

from crosssection.cli import main


def _good_rgb(seed, size=120):
    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), 245, np.uint8)
    mask = np.zeros((size, size), np.uint8)
    for _ in range(3):
        p0, p1 = rng.integers(10, size - 10, (2, 2))
        cv2.line(mask, tuple(map(int, p0)), tuple(map(int, p1)), 1, 6)
    img[mask > 0] = (40, 70, 190)
    return img


def _make(kind, folder, seed):
    p = folder / f"bad_{kind}.png"
    img = _good_rgb(seed)
    if kind == "truncated":
        Image.fromarray(img).save(p)
        data = p.read_bytes()
        p.write_bytes(data[: len(data) * 2 // 3])
    elif kind == "text":
        p.write_text("hello, I am not a PNG\n" * 20)
    elif kind == "empty_file":
        p.write_bytes(b"")
    elif kind == "grayscale":
        Image.fromarray(img[..., 1]).save(p)
    elif kind == "all_white":
        Image.fromarray(np.full((100, 100, 3), 255, np.uint8)).save(p)
    elif kind == "all_blue":
        Image.fromarray(np.tile(np.array([40, 70, 190], np.uint8), (100, 100, 1))).save(p)
    elif kind == "tiny":
        Image.fromarray(img[:12, :12]).save(p)
    elif kind == "missing":
        pass
    elif kind == "directory":
        p.mkdir()
    return p


KINDS = ["truncated", "text", "empty_file", "grayscale", "all_white", "all_blue", "tiny",
         "missing", "directory"]


@pytest.mark.parametrize("kind", KINDS)
def test_bad_input_in_process(kind, tmp_path, capsys):
    p = _make(kind, tmp_path, seed=KINDS.index(kind))
    status = main(["analyze", str(p), "--px-per-mm", "50", "--thickness-mm", "0.1",
                   "--no-figure", "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert status != 0
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1, err
    assert p.name in lines[0]
    assert "Traceback" not in err
    assert not (tmp_path / "out" / "summary.json").exists()


@pytest.mark.parametrize("kind", ["truncated", "all_white"])
def test_bad_input_subprocess(kind, tmp_path):
    p = _make(kind, tmp_path, seed=7)
    run = subprocess.run([sys.executable, "-m", "crosssection", "analyze", str(p),
                          "--px-per-mm", "50", "--thickness-mm", "0.1", "--out",
                          str(tmp_path / "out")], capture_output=True, text=True, timeout=300)
    assert run.returncode != 0
    assert "Traceback" not in run.stderr
    lines = [line for line in run.stderr.splitlines() if line.strip()]
    assert len(lines) == 1 and p.name in lines[0]


@pytest.mark.parametrize("args", [["--px-per-mm", "-50"], ["--thickness-mm", "0"],
                                  ["--s-min-mm2", "1e9"], ["--hole-radius-mm", "-2"]])
def test_absurd_parameters_exit_nonzero(args, tmp_path, capsys):
    p = tmp_path / "ok.png"
    Image.fromarray(_good_rgb(3)).save(p)
    status = main(["analyze", str(p), *args, "--no-figure", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status != 0
    assert len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_bad_calibration_names_the_file(tmp_path, capsys):
    p = tmp_path / "ok.png"
    Image.fromarray(_good_rgb(5)).save(p)
    cal = tmp_path / "cal.csv"
    cal.write_text("layers,w\n1,0.1\n")
    status = main(["analyze", str(p), "--calibration", str(cal), "--no-figure",
                   "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status != 0 and "cal.csv" in err and len(err.strip().splitlines()) == 1


def test_good_input_exits_zero(tmp_path, capsys):
    p = tmp_path / "ok.png"
    Image.fromarray(_good_rgb(11, size=200)).save(p)
    status = main(["analyze", str(p), "--no-figure", "--out", str(tmp_path / "o")])
    assert status == 0, capsys.readouterr().err
    assert (tmp_path / "o" / "summary.json").exists()


def test_truncated_16bit_png_one_line_no_libpng_noise(tmp_path, capfd):
    img = (_good_rgb(13).astype(np.uint16) * 257)
    p = tmp_path / "trunc16.png"
    cv2.imwrite(str(p), img[..., ::-1])
    data = p.read_bytes()
    p.write_bytes(data[: len(data) // 2])
    status = main(["analyze", str(p), "--no-figure", "--out", str(tmp_path / "o")])
    err = capfd.readouterr().err  # file-descriptor level: catches C libraries' messages too
    assert status != 0
    lines = [line for line in err.splitlines() if line.strip()]
    assert len(lines) == 1 and "trunc16.png" in lines[0], err


@pytest.mark.parametrize("out", ["a_file", "a_file/sub"])
def test_an_output_folder_blocked_by_a_file_is_one_line(out, tmp_path, capsys):
    p = tmp_path / "scan.png"
    Image.fromarray(_good_rgb(0)).save(p)
    (tmp_path / "a_file").write_text("not a folder")
    status = main(["analyze", str(p), "--no-figure", "--out", str(tmp_path / out)])
    err = capsys.readouterr().err.strip().splitlines()
    assert status == 2
    assert len(err) == 1 and err[0].startswith(f"error: {tmp_path / out}: ")
    assert "a file is in the way of a folder" in err[0]


@pytest.mark.parametrize("dpi, named", [(254, True), (1270, False)])
def test_a_size_refused_at_the_default_scale_names_the_file_resolution(dpi, named, tmp_path,
                                                                       capsys):
    """A small scan at 10 px/mm with its true hole given in mm: at the default 50 px/mm the
    hole is more than twice the scan. The error names the resolution the file records
    when the scale used is not it."""
    p = tmp_path / "small.png"
    Image.fromarray(_good_rgb(3, size=150)).save(p, dpi=(dpi, dpi))
    status = main(["analyze", str(p), "--hole-radius-mm", "6.4", "--hole-center-px", "75",
                   "75", "--no-figure", "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err
    assert status == 2 and len(err.strip().splitlines()) == 1
    assert "more than twice the scan" in err
    assert ("the file records 254 dpi = 10.00 px/mm" in err) is named


def test_a_blank_first_page_names_the_other_pages(tmp_path, capsys):
    import tifffile

    scan = _good_rgb(1)
    path = tmp_path / "two.tif"
    tifffile.imwrite(path, np.stack([np.full_like(scan, 245), scan]), photometric="rgb")
    assert main(["analyze", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(path) in err[0]
    assert "the file holds 2 images and only the first is read" in err[0]


def test_an_all_ink_image_is_told_as_such(tmp_path, capsys):
    path = tmp_path / "ink.png"
    Image.fromarray(np.full((200, 200, 3), (36, 66, 181), np.uint8)).save(path)
    assert main(["analyze", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "100 % of the image is ink-coloured" in err[0]


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="named pipes are POSIX")
@pytest.mark.parametrize("which", ["scan", "calibration"])
def test_a_named_pipe_is_refused_not_read(which, tmp_path, capsys):
    """Reading a pipe blocks until something writes to it: the command hung."""
    import os

    scan = tmp_path / "scan.png"
    Image.fromarray(_good_rgb(3)).save(scan)
    pipe = tmp_path / {"scan": "pipe.png", "calibration": "pipe.csv"}[which]
    os.mkfifo(pipe)
    args = ["analyze", str(pipe if which == "scan" else scan), "--out", str(tmp_path / "out"),
            "--px-per-mm", "50"]
    args += ["--calibration", str(pipe)] if which == "calibration" else []
    assert main(args) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and str(pipe) in err[0]
    assert "is a named pipe, not a file" in err[0]


@pytest.mark.skipif(not hasattr(__import__("os"), "mkfifo"), reason="named pipes are POSIX")
def test_a_named_pipe_beside_another_scans_output_is_refused_unread(tmp_path, capsys):
    """Checking whether the scan is the one of the step images in --out hashed the pipe."""
    import os

    scan = tmp_path / "scan.png"
    Image.fromarray(_good_rgb(3)).save(scan)
    out = tmp_path / "out"
    assert main(["steps", str(scan), "--out", str(out), "--px-per-mm", "50"]) == 0
    os.mkfifo(tmp_path / "pipe.png")
    capsys.readouterr()
    assert main(["analyze", str(tmp_path / "pipe.png"), "--out", str(out),
                 "--px-per-mm", "50"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "is a named pipe, not a file" in err[0]


def test_a_calibration_of_megabytes_is_another_file(tmp_path, capsys):
    scan = tmp_path / "scan.png"
    Image.fromarray(_good_rgb(3)).save(scan)
    cal = tmp_path / "cal.csv"
    cal.write_text("n_layers,width_mm\n" + "1,0.1\n" * 300_000)
    assert main(["analyze", str(scan), "--out", str(tmp_path / "out"), "--px-per-mm", "50",
                 "--calibration", str(cal)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"error: {cal}: ") and "bytes" in err[0]


def test_blue_min_with_otsu_is_refused_not_ignored(tmp_path, capsys):
    """Otsu chooses the blue cut itself: a --blue-min given with it was recorded in
    summary.json as used and changed nothing."""
    from crosssection.core.errors import ParameterError
    from crosssection.params import AnalysisParams

    scan = tmp_path / "scan.png"
    Image.fromarray(_good_rgb(3)).save(scan)
    assert main(["analyze", str(scan), "--out", str(tmp_path / "out"), "--px-per-mm", "50",
                 "--threshold-method", "otsu", "--blue-min", "250"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "blue_min = 250 is not used by the otsu threshold" in err[0]
    with pytest.raises(ParameterError, match="not used by the otsu"):
        AnalysisParams(px_per_mm=50, thickness_mm=0.1, threshold_method="otsu", blue_min=90)
    AnalysisParams(px_per_mm=50, thickness_mm=0.1, threshold_method="otsu", rg_max=120)


def test_a_width_law_with_a_calibration_is_refused_not_ignored(tmp_path, capsys):
    """The law stands in for a calibration: asked for beside one it changed nothing."""
    from crosssection.params import AnalysisParams

    scan, cal = tmp_path / "scan.png", tmp_path / "cal.csv"
    Image.fromarray(_good_rgb(3)).save(scan)
    cal.write_text("n_layers,width_mm\n1,0.1\n2,0.2\n")
    assert main(["analyze", str(scan), "--out", str(tmp_path / "out"), "--px-per-mm", "50",
                 "--calibration", str(cal), "--width-law", "linear"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["error: --width-law: linear is not used with --calibration (the calibration "
                   "gives the widths of n layers): leave one of them out"]
    assert not (tmp_path / "out").exists()
    # in Python (and a set's calibration under a batch's --width-law) the calibration wins
    AnalysisParams(px_per_mm=50, calibration=str(cal), width_law="linear")


@pytest.mark.parametrize("method, options, named", [
    ("otsu", ["--rg-max", "10"], "(rg_max = 10)"),
    ("fixed", ["--blue-min", "255"], "(blue_min = 255, rg_max = 130)")])
def test_bounds_that_exclude_every_pixel_are_named(tmp_path, capsys, method, options, named):
    scan = tmp_path / "scan.png"
    Image.fromarray(_good_rgb(3)).save(scan)
    assert main(["analyze", str(scan), "--out", str(tmp_path / "out"), "--px-per-mm", "50",
                 "--threshold-method", method, *options]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "empty mask" in err[0] and named in err[0]


def test_a_file_name_with_a_line_break_stays_on_one_error_line(tmp_path, capsys):
    # warnings joined such a name's lines; errors printed it over two
    p = tmp_path / "bad\nname.png"
    p.write_text("not a PNG")
    assert main(["analyze", str(p), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and "bad name.png" in err
