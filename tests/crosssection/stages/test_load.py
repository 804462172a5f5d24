"""Stage 1, decoding: exotic TIFFs, decompression bombs at every depth, crafted PNGs, and no
library message on stderr (checked at the file-descriptor level)."""
from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest
import tifffile
from PIL import Image

from crosssection.core.errors import ImageError
from crosssection.stages.load import load_image


def _scan(seed=0, size=64):
    rng = np.random.default_rng(seed)
    img = np.full((size, size, 3), 245, np.uint8)
    img[10:30, 5:60] = (40, 70, 190)
    img[40:50] = rng.integers(0, 256, (10, size, 3), dtype=np.uint8)
    return img


def _error(path, capfd):
    capfd.readouterr()
    with pytest.raises(ImageError) as exc:
        load_image(path)
    assert capfd.readouterr().err == ""
    line = exc.value.one_line()
    assert line.startswith(f"{path}: ") and "\n" not in line
    return exc.value.cause


@pytest.mark.parametrize("dtype", [np.float16, np.float32, np.float64])
def test_float_tiff_in_unit_range_is_read_as_uint16(tmp_path, capfd, dtype):
    img = _scan(1)
    p = tmp_path / "f.tif"
    tifffile.imwrite(p, (img / 255.0).astype(dtype))
    out = load_image(p)
    assert capfd.readouterr().err == ""
    assert out.dtype == np.uint16
    tol = 40 if dtype == np.float16 else 1  # float16 keeps 11 significant bits
    np.testing.assert_allclose(out.astype(float), img * 257.0, atol=tol)


def test_float_tiff_outside_unit_range_names_the_cause(tmp_path, capfd):
    p = tmp_path / "f255.tif"
    tifffile.imwrite(p, _scan(2).astype(np.float32))
    assert "must lie in [0, 1]" in _error(p, capfd)


@pytest.mark.parametrize("dtype", [np.uint8, np.uint16])
def test_cmyk_tiff_is_converted_like_pillow(tmp_path, dtype):
    rng = np.random.default_rng(3)
    cmyk8 = rng.integers(0, 256, (32, 40, 4), dtype=np.uint8)
    p = tmp_path / "cmyk.tif"
    scale = 257 if dtype == np.uint16 else 1
    tifffile.imwrite(p, cmyk8.astype(dtype) * scale, photometric="separated")
    out = load_image(p)
    ref = np.asarray(Image.fromarray(cmyk8, "CMYK").convert("RGB")).astype(int) * scale
    assert out.dtype == dtype
    assert np.abs(out.astype(int) - ref).max() <= scale  # Pillow rounds in 8 bits


def test_multipage_tiff_of_different_sizes_is_rejected(tmp_path, capfd):
    p = tmp_path / "mp.tif"
    with tifffile.TiffWriter(p) as w:
        w.write(_scan(4))
        w.write(_scan(4)[:32])
    assert "pages of different sizes" in _error(p, capfd)


@pytest.mark.parametrize("compression, dtype", [
    (c, d) for c in ("lzw", "zlib", "packbits", "zstd") for d in (np.uint8, np.uint16)]
    + [("jpeg", np.uint8)])  # baseline JPEG has no 16-bit mode
def test_compressed_tiff_reads_as_the_uncompressed_one(tmp_path, capfd, compression, dtype):
    # scanners write LZW, Deflate or JPEG-compressed TIFFs: their codecs come with imagecodecs
    img = _scan(3).astype(dtype) * (257 if dtype == np.uint16 else 1)
    p = tmp_path / f"{compression}.tif"
    tifffile.imwrite(p, img, photometric="rgb", compression=compression)
    out = load_image(p)
    assert capfd.readouterr().err == ""
    assert out.dtype == dtype and out.shape == img.shape
    tol = 12 if compression == "jpeg" else 0
    assert np.abs(out.astype(int) - img.astype(int)).mean() <= tol


def test_pillow_lzw_tiff_reads_as_the_png(tmp_path):
    img = _scan(4)
    p = tmp_path / "scan.tif"
    Image.fromarray(img).save(p, compression="tiff_lzw")
    np.testing.assert_array_equal(load_image(p), img)


def test_multipage_tiff_of_one_size_reads_the_first_page(tmp_path):
    p = tmp_path / "mp.tif"
    with tifffile.TiffWriter(p) as w:
        w.write(_scan(5))
        w.write(_scan(6))
    np.testing.assert_array_equal(load_image(p), _scan(5))


def test_tiff_with_invalid_first_page_offset_one_line_no_log(tmp_path, capfd):
    p = tmp_path / "offset.tif"
    tifffile.imwrite(p, _scan(7))
    data = bytearray(p.read_bytes())
    data[4:8] = struct.pack("<I", 10**8)
    p.write_bytes(bytes(data))
    assert "invalid offset" in _error(p, capfd)


def _png(img):
    return cv2.imencode(".png", img[..., ::-1])[1].tobytes()


@pytest.mark.parametrize("fmt", ["png8", "png16", "tif8", "tif16", "jpg"])
def test_decompression_bomb_caught_at_every_depth(tmp_path, capfd, monkeypatch, fmt):
    monkeypatch.setattr(Image, "MAX_IMAGE_PIXELS", 1000)
    img = _scan(8)
    img16 = img.astype(np.uint16) * 257
    p = tmp_path / f"bomb.{fmt[:3]}"
    if fmt == "png8":
        p.write_bytes(_png(img))
    elif fmt == "png16":
        p.write_bytes(_png(img16))
    elif fmt.startswith("tif"):
        tifffile.imwrite(p, img if fmt == "tif8" else img16)
    else:
        Image.fromarray(img).save(p)
    assert "image too large" in _error(p, capfd)


def _chunks(data):
    pos, out = 8, []
    while pos < len(data):
        (n,) = struct.unpack(">I", data[pos:pos + 4])
        out.append((data[pos + 4:pos + 8], data[pos + 8:pos + 8 + n]))
        pos += 12 + n
    return out


def _assemble(chunks):
    return b"\x89PNG\r\n\x1a\n" + b"".join(
        struct.pack(">I", len(d)) + k + d + struct.pack(">I", zlib.crc32(k + d))
        for k, d in chunks)


@pytest.mark.parametrize("depth", [8, 16])
def test_png_whose_pixel_data_end_cleanly_half_way_is_rejected(tmp_path, capfd, depth):
    img = _scan(9) if depth == 8 else _scan(9).astype(np.uint16) * 257
    chunks = _chunks(_png(img))
    raw = zlib.decompress(b"".join(d for k, d in chunks if k == b"IDAT"))
    short = [chunks[0], (b"IDAT", zlib.compress(raw[:len(raw) // 2])), (b"IEND", b"")]
    p = tmp_path / "half.png"
    p.write_bytes(_assemble(short))
    assert "Not enough image data" in _error(p, capfd)


@pytest.mark.parametrize("depth", [8, 16])
def test_png_crc_error_in_pixel_data_is_named(tmp_path, capfd, depth):
    img = _scan(10) if depth == 8 else _scan(10).astype(np.uint16) * 257
    data = bytearray(_png(img))
    i = data.index(b"IDAT") + 20
    data[i] ^= 0x10
    p = tmp_path / "crc.png"
    p.write_bytes(bytes(data))
    assert "CRC error in the IDAT chunk" in _error(p, capfd)


def test_png_without_iend_is_truncated(tmp_path, capfd):
    p = tmp_path / "noend.png"
    p.write_bytes(_png(_scan(11))[:-12])
    assert "truncated" in _error(p, capfd)


def test_ancillary_chunks_are_kept_out_of_libpng(tmp_path, capfd):
    """A (valid-CRC) iCCP chunk that libpng would warn about does not reach stderr and the
    pixels are read."""
    img = _scan(12)
    chunks = _chunks(_png(img))
    bad_profile = (b"iCCP", b"bogus\x00\x00" + zlib.compress(b"not an ICC profile"))
    p = tmp_path / "iccp.png"
    p.write_bytes(_assemble([chunks[0], bad_profile, *chunks[1:]]))
    np.testing.assert_array_equal(load_image(p), img)
    assert capfd.readouterr().err == ""


def test_grayscale_png_rejected_from_the_header(tmp_path, capfd):
    p = tmp_path / "la.png"
    Image.fromarray(np.dstack([_scan(13)[..., 0], _scan(13)[..., 1]]), "LA").save(p)
    assert "grayscale" in _error(p, capfd)


def test_png_named_tif_is_read_by_its_content(tmp_path):
    p = tmp_path / "really_png.tif"
    p.write_bytes(_png(_scan(14)))
    np.testing.assert_array_equal(load_image(p), _scan(14))
