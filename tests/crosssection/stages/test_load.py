"""Stage 1, decoding: exotic TIFFs, decompression bombs at every depth, crafted PNGs, and no
library message on stderr (checked at the file-descriptor level)."""
from __future__ import annotations

import io
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
    tifffile.imwrite(p, (img / 255.0).astype(dtype), photometric="rgb")
    out = load_image(p)
    assert capfd.readouterr().err == ""
    assert out.dtype == np.uint16
    tol = 40 if dtype == np.float16 else 1  # float16 keeps 11 significant bits
    np.testing.assert_allclose(out.astype(float), img * 257.0, atol=tol)


def test_float_tiff_outside_unit_range_names_the_cause(tmp_path, capfd):
    p = tmp_path / "f255.tif"
    tifffile.imwrite(p, _scan(2).astype(np.float32), photometric="rgb")
    err = _error(p, capfd)
    # a file's fix is a file to save, not numpy code
    assert "must lie in [0, 1]" in err and "save it as 8-bit integers" in err
    assert "numpy" not in err


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


def test_a_scanners_thumbnail_page_is_not_another_scan(tmp_path, capfd):
    from crosssection.stages.load import recorded_header

    p = tmp_path / "thumb.tif"
    with tifffile.TiffWriter(p) as w:
        w.write(_scan(5), photometric="rgb")
        w.write(_scan(6)[:20, :20], photometric="rgb", subfiletype=1)  # reduced image
    np.testing.assert_array_equal(load_image(p), _scan(5))
    assert capfd.readouterr().err == ""
    assert recorded_header(p).pages == 1


def test_a_32_bit_bmp_whose_fourth_byte_is_all_0_reads_opaque(tmp_path):
    # BITMAPV5HEADER with an alpha mask, alpha left 0 by the writer: "unused", not transparent
    img = _scan(7)
    h, w = img.shape[:2]
    bgra = np.dstack([img[..., ::-1], np.zeros((h, w), np.uint8)])[::-1].tobytes()
    hdr = struct.pack("<IiiHHIIiiII", 124, w, h, 1, 32, 3, len(bgra), 2835, 2835, 0, 0)
    hdr += struct.pack("<IIII", 0x00FF0000, 0x0000FF00, 0x000000FF, 0xFF000000)
    hdr += b"sRGB" + b"\0" * 64
    off = 14 + len(hdr)
    p = tmp_path / "scan.bmp"
    p.write_bytes(b"BM" + struct.pack("<IHHI", off + len(bgra), 0, 0, off) + hdr + bgra)
    assert Image.open(p).mode == "RGBA"
    np.testing.assert_array_equal(load_image(p), img)


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
    cause = _error(p, capfd)
    assert "image too large" in cause and "crop the scan" in cause


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


# ----------------------------------------------------------------------------- 8-bit RGB PNG
def _texture(h, w, seed):
    """Noise, smooth ramps and flat runs: every Paeth branch and every filter gets used."""
    rng = np.random.default_rng(seed)
    y, x = np.mgrid[0:h, 0:w]
    img = np.dstack([(x * 7 + y * 3) % 256, (x * y) % 251, (255 - y * 5) % 256]).astype(np.uint8)
    img[h // 3:h // 2] = rng.integers(0, 256, (h // 2 - h // 3, w, 3), dtype=np.uint8)
    img[h // 2:h // 2 + 4, : w // 2] = (40, 70, 190)
    return img


def _filtered_rows(img, kinds):
    """The PNG byte stream (filter type byte + filtered row) of an 8-bit RGB image, row r
    filtered with ``kinds[r]`` (0 None, 1 Sub, 2 Up, 3 Average, 4 Paeth; PNG specification)."""
    h, w, _ = img.shape
    x = img.reshape(h, 3 * w).astype(np.int32)
    out = []
    for r, kind in enumerate(kinds):
        cur = x[r]
        up = x[r - 1] if r else np.zeros_like(cur)
        left = np.concatenate([np.zeros(3, np.int32), cur[:-3]])
        upleft = np.concatenate([np.zeros(3, np.int32), up[:-3]])
        if kind == 4:
            p = left + up - upleft
            pa, pb, pc = np.abs(p - left), np.abs(p - up), np.abs(p - upleft)
            pred = np.where((pa <= pb) & (pa <= pc), left, np.where(pb <= pc, up, upleft))
        else:
            pred = [np.zeros_like(cur), left, up, (left + up) // 2][kind]
        out.append(bytes([kind]) + ((cur - pred) % 256).astype(np.uint8).tobytes())
    return b"".join(out)


def _rgb8_png(img, stream, n_idat=1, ihdr=None):
    """An 8-bit RGB PNG of ``img``'s size holding the zlib ``stream`` in ``n_idat`` chunks."""
    h, w, _ = img.shape
    ihdr = ihdr or struct.pack(">IIBBBBB", w, h, 8, 2, 0, 0, 0)
    cuts = np.linspace(0, len(stream), n_idat + 1).astype(int)
    idat = [(b"IDAT", stream[a:b]) for a, b in zip(cuts[:-1], cuts[1:])]
    return _assemble([(b"IHDR", ihdr), *idat, (b"IEND", b"")])


def _fast_path_only(monkeypatch):
    """Make OpenCV's decoder fail, so that a result comes from the 8-bit RGB fast path."""
    def no_opencv(*args, **kwargs):
        raise AssertionError("decoded by OpenCV, not by the 8-bit RGB path")
    monkeypatch.setattr(cv2, "imdecode", no_opencv)


def _opencv(data):
    return cv2.cvtColor(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED),
                        cv2.COLOR_BGR2RGB)


def _encodings(img):
    """8-bit RGB PNGs of ``img`` from Pillow, OpenCV and a hand-made filter per row."""
    out = {}
    for level in range(10):
        buf = io.BytesIO()
        Image.fromarray(img).save(buf, "PNG", compress_level=level)
        out[f"pillow{level}"] = buf.getvalue()
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, "PNG", optimize=True)
    out["pillow_optimize"] = buf.getvalue()
    bgr = np.ascontiguousarray(img[..., ::-1])
    for name in ("DEFAULT", "FILTERED", "HUFFMAN_ONLY", "RLE", "FIXED"):
        flag = getattr(cv2, f"IMWRITE_PNG_STRATEGY_{name}")
        out[f"opencv_{name}"] = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_STRATEGY, flag])[1]
    for name in ("NONE", "SUB", "UP", "AVG", "PAETH", "ALL"):
        name = "ALL_FILTERS" if name == "ALL" else f"FILTER_{name}"
        flag = getattr(cv2, f"IMWRITE_PNG_{name}")
        out[f"opencv_{name}"] = cv2.imencode(".png", bgr, [cv2.IMWRITE_PNG_FILTER, flag])[1]
    kinds = np.arange(img.shape[0]) % 5
    for level in (0, 9):
        stream = zlib.compress(_filtered_rows(img, kinds), level)
        out[f"row_filters_z{level}"] = _rgb8_png(img, stream)
        out[f"row_filters_z{level}_7idat"] = _rgb8_png(img, stream, n_idat=7)
    return {k: bytes(v) for k, v in out.items()}


@pytest.mark.parametrize("h, w", [(16, 17), (37, 1001), (120, 64)])
def test_rgb8_png_fast_path_reads_opencvs_pixels(tmp_path, monkeypatch, h, w):
    img = _texture(h, w, seed=h)
    cases = _encodings(img)
    refs = {name: _opencv(data) for name, data in cases.items()}
    _fast_path_only(monkeypatch)
    for name, data in cases.items():
        p = tmp_path / f"{name}.png"
        p.write_bytes(data)
        out = load_image(p)
        assert out.dtype == np.uint8 and out.flags.c_contiguous, name
        np.testing.assert_array_equal(out, refs[name], err_msg=name)
        np.testing.assert_array_equal(out, img, err_msg=name)


def test_rgb8_row_filters_each_used(tmp_path, monkeypatch):
    """Rows of one filter type each, on random pixels: a wrong predictor changes pixels."""
    img = np.random.default_rng(21).integers(0, 256, (40, 33, 3), dtype=np.uint8)
    _fast_path_only(monkeypatch)
    for kind in range(5):
        p = tmp_path / f"filter{kind}.png"
        p.write_bytes(_rgb8_png(img, zlib.compress(_filtered_rows(img, [kind] * 40))))
        np.testing.assert_array_equal(load_image(p), img, err_msg=f"filter {kind}")


def _corrupt_rgb8(kind):
    img = _texture(24, 19, seed=3)
    rows = _filtered_rows(img, np.arange(24) % 5)
    stream = zlib.compress(rows)
    if kind == "deflate":
        stream = stream[:2] + b"\xff" * 8 + stream[10:]  # block type 3: reserved
    elif kind == "truncated":
        stream = stream[:-9]
    elif kind == "adler":
        stream = stream[:-4] + bytes([stream[-4] ^ 1]) + stream[-3:]
    elif kind == "short":
        stream = zlib.compress(rows[:-1])
    elif kind == "long":
        stream = zlib.compress(rows + rows[:58])  # one more row
    elif kind == "filter":
        row = 5 * (1 + 3 * 19)
        stream = zlib.compress(rows[:row] + b"\x05" + rows[row + 1:])
    elif kind == "filter_first_row":
        stream = zlib.compress(b"\xff" + rows[1:])
    elif kind == "dictionary":
        stream = b"\x78\xbb" + stream[2:]
    return _rgb8_png(img, stream, n_idat=2)


@pytest.mark.parametrize("kind, cause", [
    ("deflate", "invalid deflate stream"),
    ("truncated", "truncated deflate stream"),
    ("adler", "Adler-32 checksum does not match"),
    ("short", "Not enough image data"),
    ("long", "Too much image data"),
    ("filter", "invalid filter type 5 of row 5"),
    ("filter_first_row", "invalid filter type 255 of row 0"),
    ("dictionary", "preset dictionary"),
])
def test_corrupt_rgb8_png_names_the_cause(tmp_path, capfd, monkeypatch, kind, cause):
    p = tmp_path / f"{kind}.png"
    p.write_bytes(_corrupt_rgb8(kind))
    _fast_path_only(monkeypatch)
    assert cause in _error(p, capfd)


def _small_window(stream):
    """The zlib stream with a 256-byte window declared (header check bits recomputed)."""
    cmf = 0x08
    return bytes([cmf, 0xC0 | (31 - ((cmf << 8) | 0xC0) % 31) % 31]) + stream[2:]


@pytest.mark.parametrize("kind, cause", [("extra", "Extra compressed data"),
                                         ("window", "invalid distance too far back")])
def test_streams_libdeflate_would_accept_are_judged_by_libpng(tmp_path, capfd, kind, cause):
    """Bytes after the end of the stream, or back-references beyond the declared window:
    libdeflate reads both, libpng rejects them."""
    img = np.repeat(_texture(1, 200, seed=4), 30, axis=0)
    stream = zlib.compress(_filtered_rows(img, [0] * 30), 9)
    stream = stream + b"garbage" if kind == "extra" else _small_window(stream)
    p = tmp_path / f"{kind}.png"
    p.write_bytes(_rgb8_png(img, stream))
    assert cause in _error(p, capfd)


def _adam7(img):
    """The filter-0 byte stream of an interlaced (Adam7) 8-bit RGB image."""
    passes = [(0, 0, 8, 8), (4, 0, 8, 8), (0, 4, 4, 8), (2, 0, 4, 4), (0, 2, 2, 4), (1, 0, 2, 2),
              (0, 1, 1, 2)]
    out = []
    for x0, y0, dx, dy in passes:
        sub = img[y0::dy, x0::dx]
        if sub.size:
            out += [b"\x00" + row.tobytes() for row in sub]
    return b"".join(out)


def test_interlaced_rgb8_png_is_read_by_libpng(tmp_path, monkeypatch):
    img = _texture(21, 19, seed=5)
    ihdr = struct.pack(">IIBBBBB", 19, 21, 8, 2, 0, 0, 1)
    p = tmp_path / "adam7.png"
    p.write_bytes(_rgb8_png(img, zlib.compress(_adam7(img)), ihdr=ihdr))
    np.testing.assert_array_equal(load_image(p), img)


def test_rgb8_png_without_libdeflate_is_read_by_libpng(tmp_path, monkeypatch):
    """A build of imagecodecs without libdeflate: the 8-bit RGB PNG goes to libpng."""
    import types

    import imagecodecs

    img = _texture(23, 31, seed=6)
    p = tmp_path / "scan.png"
    Image.fromarray(img).save(p)
    monkeypatch.setattr(imagecodecs, "DEFLATE", types.SimpleNamespace(available=False))
    calls = []
    imdecode = cv2.imdecode
    monkeypatch.setattr(cv2, "imdecode", lambda *a, **k: calls.append(1) or imdecode(*a, **k))
    np.testing.assert_array_equal(load_image(p), img)
    assert calls == [1]


_TO_STORED = {2: "FLIP_LEFT_RIGHT", 3: "ROTATE_180", 4: "FLIP_TOP_BOTTOM", 5: "TRANSPOSE",
              6: "ROTATE_90", 7: "TRANSVERSE", 8: "ROTATE_270"}


def _saved_oriented(rgb, orientation, path, **kw):
    """``rgb`` (the displayed frame) stored turned, with the EXIF orientation that turns it
    back."""
    from PIL import Image

    im = Image.fromarray(rgb)
    if orientation != 1:
        im = im.transpose(getattr(Image.Transpose, _TO_STORED[orientation]))
    exif = Image.Exif()
    exif[274] = orientation
    im.save(path, exif=exif.tobytes(), **kw)
    return path


@pytest.mark.parametrize("orientation", range(1, 9))
def test_exif_orientation_is_applied_on_every_path(tmp_path, orientation):
    """PNG (eXIf chunk, 8-bit fast path and libpng), TIFF and JPEG: the pixels come back in the
    displayed frame, as Pillow's exif_transpose gives them, and the value is reported."""
    from PIL import Image, ImageOps

    from crosssection.stages.load import exif_orientation, load_image

    rng = np.random.default_rng(orientation)
    shown = rng.integers(0, 256, (40, 64, 3), dtype=np.uint8)
    for name, kw, exact in (("a.png", {}, True), ("a.tif", {}, True),
                            ("a.jpg", {"quality": 95}, False)):
        path = _saved_oriented(shown, orientation, tmp_path / name, **kw)
        got = load_image(path)
        with Image.open(path) as im:
            want = np.asarray(ImageOps.exif_transpose(im).convert("RGB"))
        assert exif_orientation(path) == orientation
        assert got.shape == shown.shape and np.array_equal(got, want)
        if exact:
            assert np.array_equal(got, shown)
    # a palette PNG goes through libpng
    path = tmp_path / "p.png"
    with Image.open(_saved_oriented(shown, orientation, tmp_path / "q.png")) as im:
        im.convert("P").save(path, exif=im.getexif().tobytes())
    with Image.open(path) as im:
        want = np.asarray(ImageOps.exif_transpose(im).convert("RGB"))
    assert np.array_equal(load_image(path), want) and want.shape == shown.shape


@pytest.mark.parametrize("orientation", [1, 3, 6, 7])
def test_a_scan_stored_turned_gives_the_same_analysis(tmp_path, orientation):
    """The same scan saved with an EXIF orientation: the same junctions, at the same
    coordinates of the displayed frame."""
    import crosssection
    from crosssection.truth.network import make_scene

    sc = make_scene(seed=21, n_stacks=25, max_layers=5)
    path = _saved_oriented(sc.rgb, orientation, tmp_path / "scan.png")
    res = crosssection.analyze(str(path), px_per_mm=sc.params["px_per_mm"], warn=False)
    ref = crosssection.analyze(sc.rgb, px_per_mm=sc.params["px_per_mm"], warn=False)
    assert res.summary["n_junctions"] == ref.summary["n_junctions"] > 0
    a = res.junctions[["x_px", "y_px"]].sort_values(["x_px", "y_px"]).to_numpy()
    b = ref.junctions[["x_px", "y_px"]].sort_values(["x_px", "y_px"]).to_numpy()
    assert np.allclose(a, b, atol=0.5)
    # the summary says which frame the coordinates are in
    assert res.summary["exif_orientation"] == orientation
    assert ref.summary["exif_orientation"] == 1


def test_a_float_image_a_rounding_beyond_its_range_reads_as_its_end():
    # float arithmetic leaves 1 + 1e-7 (float32's step) after a colour conversion: it is the
    # pixel 1 means, not an image in another range; beyond half a 16-bit level it is refused,
    # its value printed whole (with :g, 1.00001 read "1" in a message saying [0, 1])
    from crosssection.stages.load import as_rgb

    img = np.full((16, 16, 3), 0.5, np.float32)
    img[0, 0, 2] = np.nextafter(np.float32(1), np.float32(2))
    img[0, 1, 0] = -1e-7
    rgb = as_rgb(img)
    assert rgb.dtype == np.uint16 and rgb[0, 0, 2] == 65535 and rgb[0, 1, 0] == 0
    img = img.astype(np.float64)
    img[0, 0, 2] = 1.0 + 1e-5
    with pytest.raises(ImageError, match=r"\.\.1\.00001: they must lie in \[0, 1\]"):
        as_rgb(img)


def test_two_channels_and_full_transparency_are_named_as_such():
    from crosssection.stages.load import as_rgb

    with pytest.raises(ImageError, match="2-channel image"):
        as_rgb(np.zeros((64, 64, 2), np.uint8))
    with pytest.raises(ImageError, match="fully transparent"):
        as_rgb(np.zeros((64, 64, 4), np.uint8))


def test_a_masked_array_is_refused_unless_nothing_is_masked():
    """numpy drops a masked array's mask unseen: the pixels under it would be analysed as
    they are, so the caller is asked what they are."""
    from crosssection.stages.load import rgb_and_opacity

    rgb = np.full((40, 50, 3), 255, np.uint8)
    rgb[10:30, 20:24] = (30, 40, 160)
    mask = np.zeros(rgb.shape, bool)
    mask[:, :25] = True
    with pytest.raises(ImageError, match="masked array: the mask is not used"):
        rgb_and_opacity(np.ma.masked_array(rgb, mask=mask), path="scan")
    # nothing masked: the data, as given
    got, see_through = rgb_and_opacity(np.ma.masked_array(rgb))
    assert np.array_equal(got, rgb) and see_through is None
    got, _ = rgb_and_opacity(np.ma.masked_array(rgb, mask=np.zeros(rgb.shape, bool)))
    assert np.array_equal(got, rgb)
