"""Shared material of the property-based fuzz suite: small scans, their encodings, and the
contract every entry point must keep.

The contract (what the fuzz tests check): an input either succeeds (exit 0, a result) or
fails with exactly one stderr line naming the file and the cause and exit status 2; never a
traceback, never exit 1, never a hang, and a corrupted file is never read as different valid
pixels where its format can tell (PNG's CRCs, zlib's Adler-32, truncation).

Images are 160 px so that each case takes milliseconds; hypothesis runs derandomized, so a
CI run is reproducible.
"""
from __future__ import annotations

import io
import signal
import types
from contextlib import contextmanager

import cv2
import numpy as np
import pytest
import tifffile
from hypothesis import HealthCheck, settings
from PIL import Image

from crosssection.testing import drawn_scan

# derandomize: the same cases on every run (CI reproducible); no deadline: a loaded machine
# must not fail a case for being slow (hangs are caught by ``time_limit``)
settings.register_profile(
    "fuzz", derandomize=True, deadline=None, database=None, print_blob=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow,
                           HealthCheck.data_too_large])

# analysis parameters under which the small scans analyse successfully (h = 2 px)
GOOD_ARGS = ["--px-per-mm", "20", "--thickness-mm", "0.1"]


def small_scan(seed: int, size: int = 160) -> np.ndarray:
    """A small RGB uint8 scan: a ring of blue ink and four chords across it."""
    return drawn_scan(seed, size, ring_frac=0.42, ring_px=4, chord_px=(3, 8))


def encode(rgb: np.ndarray, fmt: str) -> bytes:
    """``rgb`` (uint8) in one of the formats of :data:`FORMATS`."""
    if fmt == "png8":
        return cv2.imencode(".png", rgb[..., ::-1])[1].tobytes()
    if fmt == "png16":
        return cv2.imencode(".png", (rgb.astype(np.uint16) * 257)[..., ::-1])[1].tobytes()
    if fmt == "png_palette":
        buf = io.BytesIO()
        Image.fromarray(rgb).quantize(16).save(buf, "PNG")
        return buf.getvalue()
    if fmt == "png_rgba":
        buf = io.BytesIO()
        Image.fromarray(np.dstack([rgb, np.full(rgb.shape[:2], 255, np.uint8)])).save(buf, "PNG")
        return buf.getvalue()
    if fmt in ("tiff_raw", "tiff_zlib", "tiff16", "tiff_float"):
        arr = {"tiff16": rgb.astype(np.uint16) * 257,
               "tiff_float": rgb.astype(np.float32) / 255}.get(fmt, rgb)
        buf = io.BytesIO()
        tifffile.imwrite(buf, arr, photometric="rgb",
                         compression="zlib" if fmt == "tiff_zlib" else None)
        return buf.getvalue()
    if fmt == "jpeg":
        buf = io.BytesIO()
        Image.fromarray(rgb).save(buf, "JPEG", quality=92)
        return buf.getvalue()
    raise ValueError(fmt)


SUFFIX = {"png8": ".png", "png16": ".png", "png_palette": ".png", "png_rgba": ".png",
          "tiff_raw": ".tif", "tiff_zlib": ".tif", "tiff16": ".tif", "tiff_float": ".tif",
          "jpeg": ".jpg"}
FORMATS = tuple(SUFFIX)
# formats whose every byte of pixel data is covered by a check (PNG: CRC per chunk; zlib
# TIFF: the deflate stream's Adler-32): a changed pixel must not pass silently
CHECKED = ("png8", "png16", "png_palette", "png_rgba")


class _Corpus(dict):
    """The corpus; a short repr keeps hypothesis's failure reports readable."""

    def __repr__(self):
        return f"<corpus of {len(self)} encodings>"


class _Tools(types.SimpleNamespace):
    def __repr__(self):
        return "<fuzz tools>"


@pytest.fixture(scope="session")
def corpus(tmp_path_factory):
    """Intact encodings of two small scans: {(fmt, seed): (bytes, decoded reference)}."""
    from crosssection.stages.load import load_image

    out = _Corpus()
    folder = tmp_path_factory.mktemp("corpus")
    for seed in (1, 2):
        rgb = small_scan(seed)
        for fmt in FORMATS:
            data = encode(rgb, fmt)
            path = folder / f"ref{seed}_{fmt}{SUFFIX[fmt]}"
            path.write_bytes(data)
            out[fmt, seed] = (data, load_image(path))
    return out


class Hang(Exception):
    """A case ran past its time limit."""


@contextmanager
def time_limit(seconds: float):
    """Raise :class:`Hang` if the block runs longer than ``seconds`` (main thread only)."""
    def on_alarm(signum, frame):
        raise Hang(f"no answer within {seconds:g} s")

    old = signal.signal(signal.SIGALRM, on_alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


def check_one_line(status: int, err: str, name: str | None) -> None:
    """The failure contract: exit 2, exactly one ``error:`` line on stderr (besides
    ``warning:`` lines), naming ``name`` when given."""
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert "Traceback" not in err, err
    assert status == 2, f"exit {status}: {err}"
    errors = [ln for ln in lines if not ln.startswith("warning: ")]
    assert len(errors) == 1, err
    assert errors[0].startswith("error: ") and (name is None or name in errors[0]), err


@pytest.fixture(scope="session")
def fuzz_tools():
    """The helpers above, for test modules (imported by pytest under importlib mode)."""
    return _Tools(small_scan=small_scan, encode=encode, SUFFIX=SUFFIX,
                                 FORMATS=FORMATS, CHECKED=CHECKED, time_limit=time_limit,
                                 Hang=Hang, check_one_line=check_one_line, GOOD_ARGS=GOOD_ARGS)
