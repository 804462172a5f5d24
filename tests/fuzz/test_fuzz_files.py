"""Corrupted image files (cut points, bit flips, header edits) through ``load_image`` and the
``analyze`` command.

Property: the file is rejected with one ``ImageError`` line naming it, or it is read; and
where the format can tell (every PNG byte is under a CRC, a cut loses data), a file that is
read decodes to exactly the pixels of the intact file. Nothing reaches stderr (checked at the
file-descriptor level, which catches C libraries' messages).
"""
from __future__ import annotations

import itertools
import struct
import zlib

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from crosssection.cli import main
from crosssection.core.errors import ImageError
from crosssection.stages.load import load_image

FUZZ = settings.get_profile("fuzz")
FORMATS = ("png8", "png16", "png_palette", "png_rgba", "tiff_raw", "tiff_zlib", "tiff16",
           "tiff_float", "jpeg")
CHECKED = ("png8", "png16", "png_palette", "png_rgba")
# hypothesis reuses one tmp_path for all the examples of a test: each case gets its own names
_CASE = itertools.count()


def _load(path, tools, capfd):
    """``load_image(path)`` under the contract: the array, or None after one-line error."""
    capfd.readouterr()
    try:
        with tools.time_limit(10):
            arr = load_image(path)
    except ImageError as exc:
        line = exc.one_line()
        assert "\n" not in line and path.name in line, line
        arr = None
    out = capfd.readouterr()
    assert out.err == "" and out.out == "", out
    if arr is not None:
        assert arr.ndim == 3 and arr.shape[2] == 3 and arr.dtype in (np.uint8, np.uint16)
    return arr


def _write(tmp_path, tools, fmt, data, tag):
    path = tmp_path / f"case{next(_CASE)}_{tag}{tools.SUFFIX[fmt]}"
    path.write_bytes(bytes(data))
    return path


@settings(FUZZ, max_examples=260)
@given(fmt=st.sampled_from(FORMATS), seed=st.sampled_from((1, 2)),
       frac=st.floats(0.0, 1.0, exclude_max=True))
def test_cut_file_is_rejected_or_reads_the_same(fmt, seed, frac, corpus, fuzz_tools,
                                                tmp_path, capfd):
    """A file cut short loses data: rejected, or (a cut in a trailing part that holds no
    pixel, e.g. a JPEG's end marker) the same pixels as the intact file."""
    data, ref = corpus[fmt, seed]
    cut = int(frac * len(data))
    arr = _load(_write(tmp_path, fuzz_tools, fmt, data[:cut], "cut"), fuzz_tools, capfd)
    assert arr is None or np.array_equal(arr, ref), f"{fmt} cut at {cut}/{len(data)}"


@settings(FUZZ, max_examples=260)
@given(fmt=st.sampled_from(CHECKED), seed=st.sampled_from((1, 2)),
       pos=st.floats(0.0, 1.0, exclude_max=True), bit=st.integers(0, 7))
def test_bit_flip_in_png_is_caught(fmt, seed, pos, bit, corpus, fuzz_tools, tmp_path, capfd):
    """Every PNG byte after the signature lies under a chunk CRC: one flipped bit must be
    rejected (a flip in the signature makes it a non-image)."""
    data, ref = corpus[fmt, seed]
    b = bytearray(data)
    i = int(pos * len(b))
    b[i] ^= 1 << bit
    arr = _load(_write(tmp_path, fuzz_tools, fmt, b, "flip"), fuzz_tools, capfd)
    assert arr is None, f"{fmt}: bit {bit} of byte {i}/{len(b)} flipped, read as valid"


@settings(FUZZ, max_examples=200)
@given(fmt=st.sampled_from(("tiff_raw", "tiff_zlib", "tiff16", "tiff_float", "jpeg")),
       seed=st.sampled_from((1, 2)), pos=st.floats(0.0, 1.0, exclude_max=True),
       bit=st.integers(0, 7))
def test_bit_flip_in_tiff_or_jpeg_never_crashes(fmt, seed, pos, bit, corpus, fuzz_tools,
                                                tmp_path, capfd):
    """TIFF and JPEG carry no checksum over their structure and raw TIFF strips or JPEG
    entropy data none over their pixels: a flipped bit there is undetectable by any decoder
    and may give other pixels. Only the contract is asserted: no crash, no stderr noise, one
    clean line when rejected."""
    data, _ = corpus[fmt, seed]
    b = bytearray(data)
    b[int(pos * len(b))] ^= 1 << bit
    _load(_write(tmp_path, fuzz_tools, fmt, b, "flip"), fuzz_tools, capfd)


@settings(FUZZ, max_examples=150)
@given(fmt=st.sampled_from(FORMATS), seed=st.sampled_from((1, 2)),
       offset=st.integers(0, 63), value=st.integers(0, 255))
def test_header_byte_edit_never_crashes(fmt, seed, offset, value, corpus, fuzz_tools,
                                        tmp_path, capfd):
    """One of the first 64 bytes (signature, IHDR, TIFF header and first IFD, JPEG markers)
    set to any value: no crash; a PNG must not read as other pixels (CRC)."""
    data, ref = corpus[fmt, seed]
    b = bytearray(data)
    b[offset] = value
    arr = _load(_write(tmp_path, fuzz_tools, fmt, b, "head"), fuzz_tools, capfd)
    if fmt in CHECKED and arr is not None:
        assert np.array_equal(arr, ref), f"{fmt}: byte {offset} = {value} read differently"


_IHDR_FIELDS = {"width": (16, ">I"), "height": (20, ">I"), "depth": (24, ">B"),
                "colour": (25, ">B"), "interlace": (28, ">B")}


@settings(FUZZ, max_examples=80)
@given(fmt=st.sampled_from(("png8", "png16")), field=st.sampled_from(sorted(_IHDR_FIELDS)),
       value=st.integers(0, 400))
def test_png_header_edited_with_valid_crc(fmt, field, value, corpus, fuzz_tools, tmp_path,
                                          capfd):
    """A crafted IHDR (a field changed and its CRC recomputed, e.g. a height halved so that
    the pixel data end cleanly half way): the pixel data no longer match the header, which
    libpng reports; the file must be rejected unless the edit changed nothing."""
    data, ref = corpus[fmt, 1]
    b = bytearray(data)
    off, code = _IHDR_FIELDS[field]
    if code == ">B":
        value %= 256
    b[off:off + struct.calcsize(code)] = struct.pack(code, value)
    b[29:33] = struct.pack(">I", zlib.crc32(bytes(b[12:29])))
    arr = _load(_write(tmp_path, fuzz_tools, fmt, b, "ihdr"), fuzz_tools, capfd)
    if arr is not None:
        assert bytes(b) == data or np.array_equal(arr, ref), f"{field} = {value} accepted"


def _truncated_stream_png(data: bytes) -> bytes:
    """The PNG with its pixel data re-compressed after half the rows: every CRC valid, the
    deflate stream complete, only the rows missing."""
    pos, chunks = 8, []
    while pos < len(data):
        (n,), kind = struct.unpack(">I", data[pos:pos + 4]), data[pos + 4:pos + 8]
        chunks.append((kind, data[pos + 8:pos + 8 + n]))
        pos += 12 + n
    raw = zlib.decompress(b"".join(d for k, d in chunks if k == b"IDAT"))
    short = zlib.compress(raw[:len(raw) // 2])
    out = data[:8]
    for kind, body in [chunks[0], (b"IDAT", short), (b"IEND", b"")]:
        out += struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body))
    return out


@pytest.mark.parametrize("fmt", CHECKED)
def test_png_whose_data_end_cleanly_half_way_is_rejected(fmt, corpus, fuzz_tools, tmp_path,
                                                         capfd):
    data, _ = corpus[fmt, 1]
    path = _write(tmp_path, fuzz_tools, fmt, _truncated_stream_png(data), "half")
    assert _load(path, fuzz_tools, capfd) is None


@settings(FUZZ, max_examples=45)
@given(fmt=st.sampled_from(FORMATS), kind=st.sampled_from(("cut", "flip", "head")),
       pos=st.floats(0.0, 1.0, exclude_max=True), bit=st.integers(0, 7))
def test_corrupt_file_through_analyze_command(fmt, kind, pos, bit, corpus, fuzz_tools,
                                              tmp_path, capfd):
    """The ``analyze`` command on a corrupted file: exit 0, or exit 2 with one line naming
    the file; a checked format that analyses decodes to the intact pixels."""
    data, ref = corpus[fmt, 2]
    b = bytearray(data)
    i = int(pos * len(b))
    if kind == "cut":
        b = b[:i]
    elif kind == "flip":
        b[i] ^= 1 << bit
    else:
        b[i % 64] ^= 0xFF
    path = _write(tmp_path, fuzz_tools, fmt, b, kind)
    out = tmp_path / f"out{next(_CASE)}"
    capfd.readouterr()
    with fuzz_tools.time_limit(60):
        status = main(["analyze", str(path), *fuzz_tools.GOOD_ARGS, "--no-figure",
                       "--out", str(out)])
    err = capfd.readouterr().err
    if status == 0:
        assert (out / "summary.json").exists()
        if fmt in CHECKED:
            assert np.array_equal(load_image(path), ref)
    else:
        fuzz_tools.check_one_line(status, err, path.name)
        assert not (out / "summary.json").exists()
