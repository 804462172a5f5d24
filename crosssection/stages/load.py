"""Stage 1: read a scan as an RGB array at its native bit depth.

Accepted: PNG (1- to 16-bit), TIFF (8- to 64-bit, read with tifffile; its LZW, Deflate,
PackBits, JPEG and Zstandard compressions decoded by imagecodecs), JPEG, and any other format
Pillow reads. Conversions, documented choices:

- RGB: kept as is, dtype uint8 or uint16 (16-bit PNG/TIFF are not reduced to 8 bits; the
  threshold scales its defaults by 257).
- RGBA (or palette with transparency): a fully opaque alpha is dropped; a partly transparent
  image is composited over white, i.e. transparent pixels are read as paper (a scan has no
  transparency; white is the neutral background that the threshold rejects). The colour key
  of an RGB PNG (``tRNS``) is ignored: the pixels keep their colour.
- Palette (indexed) images: expanded to RGB.
- CMYK (a TIFF with ``photometric = separated`` and four inks, or a CMYK JPEG): converted
  to RGB with ``R = (1 - C)(1 - K)`` and likewise for G and B, at the native bit depth.
- Grayscale (L, I;16, 1-bit, two-channel gray+alpha): rejected with ``ImageError``: the
  threshold separates blue ink from grey-blue receding surfaces by colour, which a grey image
  cannot do. Lab, YCbCr, raw-sensor and other TIFF colour spaces are rejected likewise.
- float arrays (any float TIFF, or an ``ndarray`` given to ``analyze``) with values in
  [0, 1]: scaled to uint16; other float ranges are rejected. Other integer types with values
  within 0..65535 are read as uint16, and every integer image whose values all lie within
  0..255 as uint8 (an 8-bit image in a wider type; as 16 bits it would be black).

What is never read as valid data, each an ``ImageError`` naming the file and the cause:

- a truncated or corrupt PNG: every chunk's CRC is checked (a single flipped bit anywhere
  is caught), the file must end with ``IEND``, the deflate stream's Adler-32 must match, and
  the pixel data must fill exactly the rows the header announces, each with a valid filter
  type (libpng's checks, whose own messages are captured, not printed, or the same checks
  of the 8-bit RGB path below);
- a truncated TIFF or JPEG, or one the decoder reports as corrupt. Formats without a
  checksum over their pixels (raw TIFF strips, JPEG entropy data) cannot reveal a flipped
  bit inside the pixel data: such a file is read as the decoder sees it;
- an image of more than ``PIL.Image.MAX_IMAGE_PIXELS`` pixels (decompression bombs), at
  every bit depth, checked from the header before any pixel is decoded;
- a multi-page TIFF whose pages differ in size or pixel type (pages of one size: the first
  is read); images smaller than 16 px on a side; non-image files.

A non-interlaced 8-bit RGB PNG (the usual scan) is inflated by libdeflate and its row filters
undone by a compiled loop, the same pixels as libpng's: 39 ms against 73 ms for OpenCV's
decode of a 2000 x 2000 scan. Every other PNG is decoded by libpng (OpenCV).

EXIF orientation (tag 274 of a JPEG's or TIFF's header, or of a PNG's ``eXIf`` chunk) is
applied as every viewer applies it (Pillow's ``ImageOps.exif_transpose``, all 8 values): the
array, the coordinates and the overlays are in the frame the user sees.
:func:`exif_orientation` tells which value a file records (1: stored as displayed).

Library messages (tifffile's log, libpng's stderr, Pillow's and numpy's warnings) never reach
the user: they are captured while decoding, and what signals a corrupt file becomes the
cause of the ``ImageError``.
"""
from __future__ import annotations

import functools
import logging
import math
import os
import struct
import sys
import tempfile
import threading
import warnings
import zlib
from contextlib import contextmanager
from pathlib import Path
from typing import NamedTuple

import numpy as np
from numba import njit

from crosssection.core.errors import ImageError
from crosssection.params import _MAX_PX_PER_MM

MIN_SIDE_PX = 16
_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_TIFF_MAGIC = (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
# PNG colour type -> (name, allowed bit depths)
_PNG_COLOUR_TYPES = {0: ("grayscale", (1, 2, 4, 8, 16)), 2: ("RGB", (8, 16)),
                     3: ("palette", (1, 2, 4, 8)), 4: ("grayscale+alpha", (8, 16)),
                     6: ("RGBA", (8, 16))}
_PNG_CRITICAL = (b"IHDR", b"PLTE", b"IDAT", b"IEND")
# fd 2 is process-wide: one capture at a time
_FD2_LOCK = threading.Lock()


def max_pixels() -> int | None:
    """The pixel budget of one image: Pillow's ``Image.MAX_IMAGE_PIXELS`` (None: no limit).

    One knob for every format and depth, so a user who raises Pillow's limit raises ours.
    """
    from PIL import Image

    return Image.MAX_IMAGE_PIXELS


def _check_budget(width: int, height: int, path) -> None:
    limit = max_pixels()
    if limit is not None and int(width) * int(height) > limit:
        raise ImageError(_too_large(f"{width}x{height} = {int(width) * int(height)} px; "
                                    f"at most {limit} px"), path)


def _too_large(detail: str) -> str:
    return (f"image too large ({detail}, Pillow's Image.MAX_IMAGE_PIXELS): crop the scan to "
            "the cross-section, or raise that limit from Python")


def _short(exc: BaseException, n: int = 120) -> str:
    text = " ".join(str(exc).split()) or type(exc).__name__
    return text[:n]


def _composite_alpha(rgba: np.ndarray) -> np.ndarray:
    """Drop an opaque alpha channel, or composite over white (transparent = paper)."""
    rgb, alpha = rgba[..., :3], rgba[..., 3]
    vmax = np.iinfo(rgba.dtype).max if rgba.dtype.kind in "ui" else 1.0
    if np.all(alpha == vmax):
        return np.ascontiguousarray(rgb)
    a = alpha.astype(np.float64)[..., None] / vmax
    out = rgb.astype(np.float64) * a + vmax * (1.0 - a)
    return np.round(out).astype(rgba.dtype)


def as_rgb(arr, *, path=None) -> np.ndarray:
    """:func:`rgb_and_opacity` without the mask of the pixels it composited."""
    return rgb_and_opacity(arr, path=path)[0]


#: Values of a float image converted at a time (:func:`_float_to_uint16`).
_FLOAT_CHUNK = 1 << 22


def _float_to_uint16(a: np.ndarray, path=None) -> np.ndarray:
    """A float image with values in [0, 1] as 16-bit, converted a block of rows at a time:
    in one piece, the float64 copy and its temporaries took 1.1 GB for a 4000 x 4000 scan
    (peak 1.5-1.7 GB for the analysis, against 0.65-0.77 GB from 8- or 16-bit arrays).

    Raises
    ------
    ImageError
        NaN or infinite values, or values outside [0, 1].
    """
    out = np.empty(a.shape, np.uint16)
    rows = max(1, _FLOAT_CHUNK // max(int(np.prod(a.shape[1:])), 1))
    lo, hi = np.inf, -np.inf
    for r in range(0, a.shape[0], rows):
        # float64: float16 cannot hold 65535, and its product would overflow to inf
        c = a[r:r + rows].astype(np.float64)
        if not np.all(np.isfinite(c)):
            raise ImageError("float image with NaN or infinite values", path)
        lo, hi = min(lo, float(c.min())), max(hi, float(c.max()))
        np.multiply(c, 65535.0, out=c)
        np.round(c, out=c)
        np.clip(c, 0.0, 65535.0, out=c)  # out of range is refused below
        out[r:r + rows] = c
    # a value within half a 16-bit level of [0, 1] (a rounding of float arithmetic, 1 + 1e-7)
    # converts to the pixel 0 or 65535 it means
    tol = 0.5 / 65535.0
    if lo < -tol or hi > 1 + tol:
        # repr: a value a rounding above 1 prints as 1 with :g
        fix = ("save it as 8-bit integers, or as floats divided by 255" if path is not None
               else "divide by 255, or convert with astype(numpy.uint8)")
        hint = (f" (values up to 255 are an 8-bit image in floats: {fix})"
                if lo >= 0 and hi <= 255 else "")
        raise ImageError(f"float image values {lo!r}..{hi!r}: they must lie in [0, 1]{hint}",
                         path)
    return out


def rgb_and_opacity(arr, *, path=None) -> tuple[np.ndarray, np.ndarray | None]:
    """Validate and convert an array to (H, W, 3) uint8/uint16 RGB (see module docstring).

    Parameters
    ----------
    arr : array_like
        (H, W, 3) or (H, W, 4) array; uint8, uint16, or float in [0, 1]; other integer
        types with values within 0..65535 are accepted as uint16, and any integer image
        whose values all lie within 0..255 as uint8 (an 8-bit image held in a wider type).
    path : str, optional
        File the array came from, for error messages.

    Returns
    -------
    rgb : (H, W, 3) uint8 or uint16 array
    see_through : (H, W) bool array or None
        The pixels an alpha channel made transparent or partly (composited over white, the
        paper's colour); None when every pixel is opaque.

    Raises
    ------
    ImageError
        Grayscale, wrong shape, bad dtype or values, too small, or a masked array.
    """
    if np.ma.isMaskedArray(arr) and np.ma.getmask(arr) is not np.ma.nomask \
            and np.ma.getmask(arr).any():
        # its mask would be dropped unseen; what the masked pixels are (paper, or outside
        # the hole) is the caller's to say
        raise ImageError("masked array: the mask is not used; fill the masked pixels with "
                         "the paper's colour (numpy.ma.filled(a, 255) for 8-bit, 1.0 for "
                         "float) or give the hole", path)
    a = np.asarray(arr)
    if a.ndim == 2 or (a.ndim == 3 and a.shape[2] == 1):
        raise ImageError("grayscale image: an RGB scan of blue ink is needed to threshold "
                         "on colour", path)
    if a.ndim == 3 and a.shape[2] == 2:
        raise ImageError("2-channel image (grayscale with alpha, or two colour planes): an "
                         "RGB scan of blue ink is needed to threshold on colour", path)
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        hint = (": channels come last, (H, W, 3); move them with numpy.moveaxis(a, 0, -1)"
                if a.ndim == 3 and a.shape[0] in (3, 4) else "")
        raise ImageError(f"not an RGB image (array shape {a.shape}){hint}", path)
    if a.dtype == np.bool_:
        raise ImageError("binary image: an RGB scan is needed", path)
    if a.size == 0:
        raise ImageError(f"empty image (array shape {a.shape})", path)
    if a.dtype.kind == "f":
        a = _float_to_uint16(a, path)
    elif a.dtype != np.uint8:
        if a.dtype.kind not in "ui":
            raise ImageError(f"unsupported pixel type {a.dtype}", path)
        lo, hi = int(a.min()), int(a.max())
        if lo < 0:
            raise ImageError(f"negative pixel values ({lo}..{hi}): an image holds 0..255 "
                             "(8-bit) or 0..65535 (16-bit)", path)
        if hi > 65535:
            raise ImageError(f"pixel values {lo}..{hi} out of the 16-bit range", path)
        # values within 0..255 are an 8-bit image in a wider type (numpy arithmetic, or
        # astype(int)): read as 16-bit they would be a black scan. A real 16-bit scan whose
        # brightest pixel is 255 of 65535 holds no image either.
        if hi <= 255:
            a = a.astype(np.uint8)
        elif a.dtype != np.uint16:
            a = a.astype(np.uint16)
    see_through = None
    if a.shape[2] == 4:
        if not np.any(a[..., 3]):
            # composited over white it would read as a blank page, "no colour"
            raise ImageError("fully transparent image (alpha 0 everywhere): its colours "
                             "are not shown; save the scan without an alpha channel", path)
        see_through = a[..., 3] < np.iinfo(a.dtype).max
        see_through = see_through if see_through.any() else None
        a = _composite_alpha(a)
    h, w = a.shape[:2]
    if min(h, w) < MIN_SIDE_PX:
        raise ImageError(f"image too small ({w}x{h} px; at least {MIN_SIDE_PX} px a side)",
                         path)
    return np.ascontiguousarray(a), see_through


# ----------------------------------------------------------------------------- orientation
#: EXIF orientation (tag 274) -> the stored pixels turned into the displayed frame, as
#: Pillow's ``ImageOps.exif_transpose`` (2 and 4 mirror, 3 turns half a turn, 5 and 7
#: transpose about either diagonal, 6 and 8 turn a quarter clockwise and anticlockwise).
_ORIENT = {
    2: lambda a: a[:, ::-1],
    3: lambda a: a[::-1, ::-1],
    4: lambda a: a[::-1],
    5: lambda a: a.swapaxes(0, 1),
    6: lambda a: np.rot90(a, -1),
    7: lambda a: a[::-1, ::-1].swapaxes(0, 1),
    8: lambda a: np.rot90(a, 1),
}
_ORIENTATION_TAG = 274


def _oriented(arr: np.ndarray, orientation: int) -> np.ndarray:
    """``arr`` in the frame a viewer displays for an EXIF ``orientation`` (1 or an unknown
    value: as stored)."""
    turn = _ORIENT.get(int(orientation))
    return arr if turn is None else np.ascontiguousarray(turn(arr))


def _orientation_of_exif(raw: bytes) -> int:
    """The orientation value of raw EXIF data (a PNG ``eXIf`` chunk), 1 when absent or
    unreadable."""
    from PIL import Image

    try:
        exif = Image.Exif()
        exif.load(raw)
        value = int(exif.get(_ORIENTATION_TAG, 1))
    except Exception:  # noqa: BLE001 - metadata is advisory: any failure means none
        return 1
    return value if value in _ORIENT else 1


def _png_orientation(data: bytes, chunks) -> int:
    """The orientation of a PNG's ``eXIf`` chunk (1 without one): a look at the chunk list,
    no decoding."""
    for ctype, start, end in chunks:
        if ctype == b"eXIf":
            return _orientation_of_exif(bytes(data[start + 8:end - 4]))
    return 1


# ----------------------------------------------------------------------------- PNG
@functools.lru_cache(maxsize=None)
def _crc32():
    """``zlib.crc32``, or libdeflate's when imagecodecs has it: the same checksum, 0.14 ms
    against 1.8 ms for the 8 MB of chunks of a 2000x2000 scan."""
    try:
        import imagecodecs

        if imagecodecs.DEFLATE.available:
            return imagecodecs.deflate_crc32
    except (ImportError, AttributeError):
        pass
    return zlib.crc32


def _png_chunks(data: bytes, path):
    """Walk the chunks of a PNG, checking each CRC; return [(type, start, end)] up to IEND.

    ``start:end`` is the whole chunk (length, type, data and CRC). Raises ``ImageError`` on
    a CRC mismatch, a chunk running past the end of the file, or a missing ``IEND``.
    """
    view = memoryview(data)
    n = len(data)
    pos = len(_PNG_SIGNATURE)
    chunks = []
    crc32 = _crc32()
    while True:
        if pos + 12 > n:
            raise ImageError(f"truncated PNG: the file ends at byte {n} before the IEND chunk",
                             path)
        length, ctype = struct.unpack(">I4s", view[pos:pos + 8])
        if not ctype.isalpha() or not ctype.isascii():
            raise ImageError(f"corrupt PNG: invalid chunk type {ctype!r} at byte {pos}", path)
        end = pos + 12 + length
        if end > n:
            raise ImageError(f"truncated or corrupt PNG: the {ctype.decode()} chunk at byte "
                             f"{pos} runs past the end of the file ({n} bytes)", path)
        (crc,) = struct.unpack(">I", view[end - 4:end])
        if crc32(view[pos + 4:end - 4]) != crc:
            raise ImageError(f"corrupt PNG: CRC error in the {ctype.decode()} chunk at byte "
                             f"{pos}", path)
        chunks.append((ctype, pos, end))
        if ctype == b"IEND":
            return chunks
        pos = end


def _png_header(data: bytes, chunks, path):
    """Validate IHDR and the critical chunks; return (width, height, depth, colour type,
    interlace method)."""
    ctype, start, end = chunks[0]
    if ctype != b"IHDR" or end - start != 25:
        raise ImageError("corrupt PNG: the first chunk is not a valid IHDR", path)
    w, h, depth, colour, comp, filt, interlace = struct.unpack(">IIBBBBB",
                                                               data[start + 8:start + 21])
    name, depths = _PNG_COLOUR_TYPES.get(colour, (None, ()))
    if not (0 < w < 2**31 and 0 < h < 2**31) or depth not in depths or comp != 0 \
            or filt != 0 or interlace not in (0, 1):
        raise ImageError(f"corrupt PNG header ({w}x{h} px, bit depth {depth}, colour type "
                         f"{colour}, compression {comp}, filter {filt}, interlace "
                         f"{interlace})", path)
    kinds = [c[0] for c in chunks]
    unknown = [k for k in kinds if k[:1].isupper() and k not in _PNG_CRITICAL]
    if unknown:
        raise ImageError(f"corrupt PNG: unknown critical chunk {unknown[0].decode()}", path)
    idat = [i for i, k in enumerate(kinds) if k == b"IDAT"]
    if not idat:
        raise ImageError("corrupt PNG: no image data (IDAT chunk)", path)
    if idat != list(range(idat[0], idat[-1] + 1)):
        raise ImageError("corrupt PNG: the IDAT chunks are not consecutive", path)
    if colour == 3 and b"PLTE" not in kinds:
        raise ImageError("corrupt PNG: palette image without a PLTE chunk", path)
    _check_budget(w, h, path)
    if colour in (0, 4):
        raise ImageError(f"grayscale image ({depth}-bit {name} PNG): an RGB scan of blue ink "
                         "is needed to threshold on colour", path)
    return w, h, depth, colour, interlace


@njit(cache=True)
def _unfilter_rgb8(raw, out):  # pragma: no cover - numba
    """Undo the PNG row filters of 8-bit RGB rows, writing the pixels into ``out``.

    ``raw``: the inflated pixel data, ``h`` rows of a filter type byte and ``3 w`` bytes;
    ``out``: the (h, 3 w) uint8 image. Returns -1, or the first row whose filter type is not
    0..4 (the rows above it are written). The filters that predict from the pixel to the
    left (Sub, Average, Paeth) keep the left pixel's three bytes, and Paeth the upper left
    pixel's, in local variables, not read back from the row being written, and step through
    a row pixel by pixel (a range with a step of 3 compiles to a loop twice as slow): 5.6 ms
    against 7.7 ms for a 2000 x 2000 scan filtered Average on almost every row. With
    libdeflate's inflate (24 ms), which OpenCV cannot use, the decode takes about half of
    libpng's (73 ms; zlib's inflate alone: 57 ms).
    """
    h, n = out.shape
    stride = n + 1
    zero = np.zeros(n, np.uint8)
    for r in range(h):
        kind = raw[r * stride]
        src = raw[r * stride + 1:(r + 1) * stride]
        cur = out[r]
        prev = out[r - 1] if r > 0 else zero
        if kind == 0:
            for i in range(n):
                cur[i] = src[i]
        elif kind == 1:
            a0 = a1 = a2 = 0
            for j in range(n // 3):
                i = 3 * j
                a0 = (np.int64(src[i]) + a0) & 0xFF
                a1 = (np.int64(src[i + 1]) + a1) & 0xFF
                a2 = (np.int64(src[i + 2]) + a2) & 0xFF
                cur[i] = a0
                cur[i + 1] = a1
                cur[i + 2] = a2
        elif kind == 2:
            for i in range(n):
                cur[i] = (src[i] + prev[i]) & 0xFF
        elif kind == 3:
            # the first pixel has no left neighbour: a = 0
            a0 = a1 = a2 = 0
            for j in range(n // 3):
                i = 3 * j
                a0 = (np.int64(src[i]) + ((a0 + np.int64(prev[i])) >> 1)) & 0xFF
                a1 = (np.int64(src[i + 1]) + ((a1 + np.int64(prev[i + 1])) >> 1)) & 0xFF
                a2 = (np.int64(src[i + 2]) + ((a2 + np.int64(prev[i + 2])) >> 1)) & 0xFF
                cur[i] = a0
                cur[i + 1] = a1
                cur[i + 2] = a2
        elif kind == 4:
            # left (a), up (b) and upper left (c) bytes; the first pixel has no left
            # neighbour (a = c = 0), so Paeth predicts b
            a0 = a1 = a2 = 0
            c0 = c1 = c2 = 0
            for j in range(n // 3):
                i = 3 * j
                b0 = np.int64(prev[i])
                b1 = np.int64(prev[i + 1])
                b2 = np.int64(prev[i + 2])
                a0 = (np.int64(src[i]) + _paeth(a0, b0, c0)) & 0xFF
                a1 = (np.int64(src[i + 1]) + _paeth(a1, b1, c1)) & 0xFF
                a2 = (np.int64(src[i + 2]) + _paeth(a2, b2, c2)) & 0xFF
                cur[i] = a0
                cur[i + 1] = a1
                cur[i + 2] = a2
                c0 = b0
                c1 = b1
                c2 = b2
        else:
            return r
    return -1


@njit(cache=True)
def _paeth(a, b, c):  # pragma: no cover - numba
    # the PNG Paeth predictor of a byte from its left (a), upper (b) and upper left (c) ones
    pa = abs(b - c)
    pb = abs(a - c)
    pc = abs(a + b - 2 * c)
    if pa <= pb and pa <= pc:
        return a
    if pb <= pc:
        return b
    return c


def _read_png_rgb8(data: bytes, chunks, w: int, h: int, path) -> np.ndarray | None:
    """Decode a non-interlaced 8-bit RGB PNG: libdeflate inflates, :func:`_unfilter_rgb8`
    undoes the row filters; the same pixels as libpng's.

    libdeflate checks the stream and its Adler-32; the rows must fill exactly the ``h``
    rows of ``w`` pixels. Returns None, to leave the file to libpng, when bytes follow the
    end of the compressed stream (libpng rejects some, not others) or when the stream
    declares a window smaller than the image data.
    """
    import imagecodecs

    try:  # a build of imagecodecs without libdeflate leaves the file to libpng
        if not imagecodecs.DEFLATE.available:
            return None
    except AttributeError:
        return None
    view = memoryview(data)
    stream = b"".join(view[s + 8:e - 4] for k, s, e in chunks if k == b"IDAT")
    size = h * (1 + 3 * w)
    # libdeflate does not hold a stream to the window its header declares, libpng does: a
    # stream that could reach further back than its window is left to libpng
    if stream and stream[0] >> 4 < 7 and 256 << (stream[0] >> 4) < size:
        return None
    try:
        raw = np.empty(size, np.uint8)
        out = np.empty((h, w, 3), np.uint8)
    except MemoryError:
        raise ImageError("image too large to decode in memory", path) from None
    try:
        got = imagecodecs.deflate_decode(stream, out=raw)
    except imagecodecs.DeflateError as exc:
        if "INSUFFICIENT_SPACE" in str(exc):
            raise ImageError(f"corrupt PNG pixel data (Too much image data: more than the "
                             f"{size} bytes of {h} rows of {w} RGB pixels)", path) from None
        raise ImageError(f"corrupt PNG pixel data ({_inflate_error(stream)})", path) from None
    if len(got) != size:
        raise ImageError(f"corrupt or truncated PNG pixel data (Not enough image data: "
                         f"{len(got)} of the {size} bytes of {h} rows of {w} RGB pixels)",
                         path)
    if stream[-4:] != imagecodecs.deflate_adler32(raw).to_bytes(4, "big"):
        return None  # the Adler-32 (checked) is not the last bytes: something follows it
    bad = _unfilter_rgb8(raw, out.reshape(h, 3 * w))
    if bad >= 0:
        raise ImageError(f"corrupt PNG pixel data (invalid filter type "
                         f"{raw[bad * (1 + 3 * w)]} of row {bad}, at most 4)", path)
    return out


def _inflate_error(stream) -> str:
    """Why a zlib stream does not inflate, in zlib's words (libdeflate says only "bad data").

    Inflated a megabyte at a time and thrown away: a corrupt stream may announce any size.
    """
    inflater = zlib.decompressobj()
    rest = stream
    try:
        while True:
            piece = inflater.decompress(rest, 1 << 20)
            rest = inflater.unconsumed_tail
            if inflater.eof or not (rest or piece):
                break
    except zlib.error as exc:
        why = str(exc).split(": ", 1)[-1]
        if why == "incorrect data check":
            why = "its Adler-32 checksum does not match the inflated data"
        elif len(stream) > 1 and stream[1] & 0x20:
            why = "it asks for a preset dictionary, which PNG does not allow"
        return f"invalid deflate stream: {why}"
    if not inflater.eof:
        return "truncated deflate stream: it ends before its last block"
    return "invalid deflate stream"


@contextmanager
def _stderr_fd_captured():
    """Redirect file descriptor 2 while C code runs; yield a list that receives its text.

    libpng, under OpenCV, prints its errors and warnings straight to fd 2, out of reach of
    Python's ``sys.stderr``. Lines that are not libpng's (another thread writing meanwhile)
    are written back to fd 2 afterwards.
    """
    captured: list[str] = []
    with _FD2_LOCK, tempfile.TemporaryFile() as tmp:
        try:
            sys.stderr.flush()
            saved = os.dup(2)
        except (OSError, ValueError, AttributeError):  # no usable fd 2: nothing to capture
            yield captured
            return
        os.dup2(tmp.fileno(), 2)
        try:
            yield captured
        finally:
            os.dup2(saved, 2)
            os.close(saved)
            tmp.seek(0)
            text = tmp.read().decode("utf-8", "replace")
            ours = [ln for ln in text.splitlines() if "libpng" in ln or "png" in ln.lower()]
            other = [ln for ln in text.splitlines() if ln not in ours]
            captured.extend(ours)
            if other:
                os.write(2, ("\n".join(other) + "\n").encode())


def _read_png(path: Path, data: bytes) -> np.ndarray:
    """Check a PNG's structure and CRCs, then decode it at native depth: a non-interlaced
    8-bit RGB image with :func:`_read_png_rgb8`, any other with libpng (OpenCV).

    Pillow accepts a deflate stream that ends cleanly after a part of the rows (it fills the
    rest with black); libpng and the 8-bit RGB path reject it, so Pillow does not decode PNGs.
    libpng is given only the critical chunks (and a palette's transparency), which leaves it
    nothing benign to warn about: whatever it still says means the pixel data do not match
    the header. An ``eXIf`` chunk's orientation turns the decoded pixels (a look at the chunk
    list: a PNG without one costs nothing more).
    """
    return _read_png_oriented(path, data)[0]


def _read_png_oriented(path: Path, data: bytes) -> tuple[np.ndarray, int]:
    """:func:`_read_png` and the orientation of the ``eXIf`` chunk it applied (1: none)."""
    chunks = _png_chunks(data, path)
    w, h, depth, colour, interlace = _png_header(data, chunks, path)
    orientation = _png_orientation(data, chunks)
    return _oriented(_decode_png(data, chunks, w, h, depth, colour, interlace, path),
                     orientation), orientation


def _decode_png(data, chunks, w, h, depth, colour, interlace, path) -> np.ndarray:
    """The pixels of a checked PNG, as stored (see :func:`_read_png`)."""
    import cv2

    if colour == 2 and depth == 8 and interlace == 0:
        arr = _read_png_rgb8(data, chunks, w, h, path)
        if arr is not None:
            return arr
    keep = _PNG_CRITICAL + ((b"tRNS",) if colour == 3 else ())
    if all(k in keep for k, _, _ in chunks) and chunks[-1][2] == len(data):
        minimal = data  # the common case: nothing to drop, no copy
    else:
        minimal = _PNG_SIGNATURE + b"".join(data[s:e] for k, s, e in chunks if k in keep)
    # an 8-bit RGB image (the usual scan) is decoded straight into RGB order: the same
    # pixels without a channel swap over the whole image afterwards (5 % of the decoding);
    # every other kind keeps its depth and alpha, then is swapped
    rgb_flag = getattr(cv2, "IMREAD_COLOR_RGB", None)
    direct = rgb_flag is not None and colour == 2 and depth == 8
    flags = rgb_flag | cv2.IMREAD_IGNORE_ORIENTATION if direct else cv2.IMREAD_UNCHANGED
    with _stderr_fd_captured() as messages:
        arr = cv2.imdecode(np.frombuffer(minimal, np.uint8), flags)
    if arr is None or messages:
        why = "; ".join(m.strip() for m in messages)[:160] or "the decoder returned no image"
        raise ImageError(f"corrupt or truncated PNG pixel data ({why})", path)
    if arr.ndim != 3 or arr.shape[:2] != (h, w) or arr.shape[2] not in (3, 4):
        raise ImageError(f"corrupt PNG: decoded shape {arr.shape} does not match the header "
                         f"({w}x{h} px, colour type {colour})", path)
    if direct:
        return arr
    return cv2.cvtColor(arr, cv2.COLOR_BGR2RGB if arr.shape[2] == 3 else cv2.COLOR_BGRA2RGBA)


# ----------------------------------------------------------------------------- TIFF
class _LogCapture(logging.Handler):
    def __init__(self):
        super().__init__(logging.WARNING)
        self.messages: list[str] = []

    def emit(self, record):
        self.messages.append(" ".join(record.getMessage().split()))


@contextmanager
def _tifffile_log_captured():
    """Collect tifffile's log records instead of letting logging's last resort print them."""
    log = logging.getLogger("tifffile")
    handler = _LogCapture()
    old_propagate = log.propagate
    log.addHandler(handler)
    log.propagate = False
    try:
        yield handler.messages
    finally:
        log.removeHandler(handler)
        log.propagate = old_propagate


def _cmyk_to_rgb(cmyk: np.ndarray) -> np.ndarray:
    """Subtractive inks to RGB at the native depth: R = (1 - C)(1 - K), etc."""
    vmax = float(np.iinfo(cmyk.dtype).max) if cmyk.dtype.kind in "ui" else 1.0
    c = cmyk[..., :4].astype(np.float64) / vmax
    rgb = (1.0 - c[..., :3]) * (1.0 - c[..., 3:4])
    if cmyk.dtype.kind in "ui":
        return np.round(rgb * vmax).astype(cmyk.dtype)
    return rgb


def _tiff_page(tif, path):
    """The page to read: the first, after checking every page's size, type and budget."""
    pages = list(tif.pages)
    if not pages:
        raise ImageError("TIFF without any image page", path)
    # a scanner's thumbnail (NewSubfileType: reduced image) is not another scan
    pages = [p for p in pages if not getattr(p, "is_reduced", False)] or pages
    kinds = {(tuple(p.shape), str(p.dtype)) for p in pages}
    if len(kinds) > 1:
        shown = ", ".join(f"{'x'.join(map(str, s))} {d}" for s, d in sorted(kinds)[:4])
        raise ImageError(f"multi-page TIFF with pages of different sizes or types ({shown}): "
                         "save the scan alone", path)
    page = pages[0]
    _check_budget(page.imagewidth, page.imagelength * max(1, page.imagedepth), path)
    return page


def _tiff_colour(page, arr: np.ndarray, path) -> np.ndarray:
    """Interpret a decoded page by its photometric tag (planar, palette, CMYK, others)."""
    import tifffile

    ph = tifffile.PHOTOMETRIC
    photometric = int(page.photometric)
    if int(page.planarconfig) == 2 and arr.ndim == 3:
        arr = np.moveaxis(arr, 0, -1)  # separate planes -> (H, W, samples)
    if photometric == ph.PALETTE and arr.ndim == 2:
        cmap = page.colormap
        if cmap is None:
            raise ImageError("palette TIFF without a colour map", path)
        cmap = np.ascontiguousarray(np.asarray(cmap).T)
        if arr.size and int(arr.max()) >= len(cmap):
            raise ImageError(f"corrupt palette TIFF: index {int(arr.max())} beyond the "
                             f"{len(cmap)} colours of the map", path)
        return cmap[arr]
    if photometric == ph.SEPARATED:
        inkset = page.tags.valueof(332, 1)  # InkSet: 1 = CMYK
        if inkset != 1 or arr.ndim != 3 or arr.shape[2] < 4:
            raise ImageError("unsupported TIFF colour space: separated inks other than CMYK",
                             path)
        return _cmyk_to_rgb(arr)
    if photometric in (ph.RGB, ph.MINISBLACK, ph.MINISWHITE):
        return arr
    if photometric == ph.YCBCR and int(page.compression) in (6, 7):
        return arr  # JPEG-compressed: the decoder returns RGB
    name = getattr(page.photometric, "name", str(photometric))
    raise ImageError(f"unsupported TIFF colour space {name}: save the scan as RGB", path)


def _read_tiff(path: Path) -> np.ndarray:
    """Decode the first page of a TIFF with tifffile; corrupt structure is an error.

    tifffile logs what it skips over (a tag whose value lies past the end of the file, an
    invalid page offset) and goes on; a skipped BitsPerSample or strip offset would then
    decode other pixels, so any logged warning rejects the file.
    """
    import tifffile

    with _tifffile_log_captured() as logged:
        try:
            with tifffile.TiffFile(path) as tif:
                page = _tiff_page(tif, path)
                arr = page.asarray()
                arr = _tiff_colour(page, arr, path)
                orientation = page.tags.valueof(_ORIENTATION_TAG, 1)
        except ImageError as exc:
            if logged:  # tifffile's own words say why (e.g. an invalid offset)
                raise ImageError(f"{exc.cause} ({logged[0][:160]})", path) from None
            raise
        except MemoryError:
            raise ImageError("image too large to decode in memory", path) from None
        except Exception as exc:  # noqa: BLE001 - tifffile raises many types for bad files
            raise ImageError(f"cannot read TIFF, corrupt or truncated file "
                             f"({type(exc).__name__}: {_short(exc)})", path) from None
    if logged:
        raise ImageError(f"corrupt TIFF ({logged[0][:160]})", path)
    return _oriented(arr, orientation) if arr.ndim == 3 else arr


# ----------------------------------------------------------------------------- others
def _read_pillow(path: Path) -> np.ndarray:
    """JPEG and every other format Pillow reads (truncation is an error: Pillow's
    ``LOAD_TRUNCATED_IMAGES`` is left False)."""
    from PIL import Image, UnidentifiedImageError

    try:
        with Image.open(path) as im:
            _check_budget(im.size[0], im.size[1], path)
            im.load()
            orientation = im.getexif().get(_ORIENTATION_TAG, 1)
            mode = im.mode
            # a 32-bit BMP's fourth byte is often left 0 by its writer: unused, not transparent
            unused_alpha = im.format == "BMP" and mode == "RGBA"
            if mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif mode in ("LA", "La", "PA"):
                im = im.convert("LA")
            elif mode in ("CMYK", "YCbCr", "LAB", "HSV", "RGBX", "RGBa"):
                im = im.convert("RGB")
            arr = np.asarray(im)
            if unused_alpha and not arr[..., 3].any():
                arr = arr[..., :3]
    except UnidentifiedImageError:
        raise ImageError("not an image file (unknown or corrupt format)", path) from None
    except Image.DecompressionBombError as exc:
        raise ImageError(_too_large(_short(exc, 100)), path) from None
    except MemoryError:
        raise ImageError("image too large to decode in memory", path) from None
    except (OSError, SyntaxError, ValueError, EOFError, struct.error) as exc:
        raise ImageError(f"cannot read image (corrupt or truncated file: {_short(exc)})",
                         path) from None
    if mode in ("I;16", "I;16B", "I;16L", "I", "F", "L", "1", "LA"):
        raise ImageError(f"grayscale image (mode {mode}): an RGB scan of blue ink is needed "
                         "to threshold on colour", path)
    return _oriented(arr, orientation)


#: Recorded resolutions below this (dpi) are not a scanner's: 72 and 96 dpi are what image
#: software writes by default, whatever the scan.
MIN_SCANNER_DPI = 100.0
#: Recorded resolutions above this (dpi: the largest scale an analysis takes) are no scan's
#: either.
MAX_SCANNER_DPI = 25.4 * _MAX_PX_PER_MM


class Header(NamedTuple):
    """What a scan file's header records (:func:`recorded_header`)."""

    #: the resolution in px/mm, None when missing, not a scanner's, or not square
    px_per_mm: float | None
    #: how many images the file holds (TIFF pages, animation frames); 1 when unknown
    pages: int
    #: the recorded resolutions (dpi) along the rows and along the columns, when they differ
    #: by more than 1 % (pixels that are not square); None otherwise
    dpi_xy: tuple[float, float] | None = None


def recorded_header(path) -> Header:
    """What a scan file's header records: its resolution in px/mm (or None) and how many
    images it holds, from one read of the header (Pillow; the file is not checked here).

    The resolution: scanners write it into the file (PNG ``pHYs``, TIFF ``XResolution``, JPEG
    JFIF density; 1200 dpi = 47.24 px/mm); image software writes 72 or 96 dpi whatever the
    image, so a value below :data:`MIN_SCANNER_DPI` or above :data:`MAX_SCANNER_DPI`, a
    missing or unreadable one give None. A
    different resolution along the rows (x) and the columns (y) (more than 1 %) gives None
    and the two as ``dpi_xy``: such pixels are not square, and every length read from them
    is off along one axis. The images (TIFF pages, animation frames): the loader decodes the
    first; the others would be left out without a word (a scanner's batch saved as one
    multi-page TIFF holds several cuts); 1 when unknown.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    Header
    """
    from PIL import Image

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # e.g. Pillow's DecompressionBombWarning
            with Image.open(path) as im:
                dpi = im.info.get("dpi")
                pages = max(int(getattr(im, "n_frames", 1)), 1)
                if im.format == "TIFF" and pages > 1:
                    pages = max(_full_pages(im), 1)
    except Exception:  # noqa: BLE001 - metadata is advisory: any failure means no value
        return Header(None, 1)
    try:
        x, y = (float(v) for v in dpi)
    except (TypeError, ValueError):
        return Header(None, pages)
    if not (math.isfinite(x) and math.isfinite(y)) or min(x, y) < MIN_SCANNER_DPI \
            or max(x, y) > MAX_SCANNER_DPI:
        return Header(None, pages)
    if abs(x - y) > 0.01 * max(x, y):
        if exif_orientation(path) in (5, 6, 7, 8):
            x, y = y, x  # the pixels are shown turned a quarter: x as displayed
        return Header(None, pages, (x, y))
    return Header(0.5 * (x + y) / 25.4, pages)


def _full_pages(im) -> int:
    """The pages of an open Pillow TIFF that are not a reduced image (a thumbnail)."""
    n = 0
    for i in range(im.n_frames):
        im.seek(i)
        n += not int(im.tag_v2.get(254, 0)) & 1
    return n


def exif_orientation(path) -> int:
    """The EXIF orientation a scan file records (tag 274 of a JPEG's or TIFF's header, or of
    a PNG's ``eXIf`` chunk): 1 when the pixels are stored as displayed, when there is none or
    it cannot be read; 2-8 otherwise. :func:`load_image` returns the image turned into that
    frame.

    Parameters
    ----------
    path : str or Path

    Returns
    -------
    int
    """
    from PIL import Image

    try:
        # (a buffer of 1 MiB: the seeks over a PNG's chunks of 8 kB stay inside it, 0.5 ms
        # for a 2000x2000 scan against 1.9 ms with the default buffer's two system calls
        # per chunk)
        with open(path, "rb", buffering=1 << 20) as fh:
            if fh.read(8) == _PNG_SIGNATURE:
                # Pillow looks for a PNG's eXIf chunk by decoding the whole image (it may follow
                # the pixel data): walking the chunk lengths reads no pixel
                return _png_orientation_unchecked(fh)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # e.g. Pillow's DecompressionBombWarning
            with Image.open(path) as im:
                value = int(im.getexif().get(_ORIENTATION_TAG, 1))
    except Exception:  # noqa: BLE001 - metadata is advisory: any failure means none
        return 1
    return value if value in _ORIENT else 1


def _png_orientation_unchecked(fh) -> int:
    """The orientation of the ``eXIf`` chunk of the PNG ``fh`` (read past its signature),
    seeking over every other chunk; 1 without one. CRCs are not checked: :func:`load_image`
    checks them when it reads the pixels."""
    while True:
        head = fh.read(8)
        if len(head) < 8:
            return 1
        length, ctype = struct.unpack(">I4s", head)
        if ctype == b"eXIf":
            return _orientation_of_exif(fh.read(length))
        if ctype == b"IEND":
            return 1
        fh.seek(length + 4, 1)


def load_image(path) -> np.ndarray:
    """Read a scan as an RGB array at native dtype.

    Parameters
    ----------
    path : str or Path
        PNG, TIFF, JPEG (or any format Pillow reads); the format is told by the file's
        first bytes, not by its name.

    Returns
    -------
    (H, W, 3) uint8 or uint16 array
        See the module docstring for the conversions (alpha, palette, CMYK, float); turned
        by the file's EXIF orientation into the frame a viewer displays.

    Raises
    ------
    ImageError
        Missing, unreadable, corrupt, truncated, too large, grayscale or too small file; one
        line naming the file. Nothing is printed: library messages are captured.
    """
    return load_image_oriented(path)[0]


def load_image_oriented(path, *, opacity: bool = False) -> tuple:
    """:func:`load_image`, and for a PNG the orientation its ``eXIf`` chunk gave the pixels.

    The orientation is read with the pixels: :func:`exif_orientation` walks the chunks of the
    file again (1 ms for a 2000x2000 scan's 960).

    Parameters
    ----------
    path : str or Path
    opacity : bool
        Also return the mask of the pixels an alpha channel made see-through.

    Returns
    -------
    rgb : (H, W, 3) uint8 array
        As :func:`load_image` returns it (already turned by the orientation).
    orientation : int or None
        The EXIF orientation 1-8 of a PNG (1: none); None for another format, whose
        orientation :func:`exif_orientation` reads.
    see_through : (H, W) bool array or None
        With ``opacity`` only: as :func:`rgb_and_opacity` gives it.

    Raises
    ------
    ImageError
        As :func:`load_image`.
    """
    path = Path(path).expanduser()
    if not path.exists():
        from crosssection.core.fileio import missing_file_reason

        raise ImageError(missing_file_reason(path), path)
    if path.is_dir():
        raise ImageError("is a directory, not an image file", path)
    from crosssection.core.fileio import special_file_reason

    special = special_file_reason(path)
    if special:
        raise ImageError(special, path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(8)
            if head != _PNG_SIGNATURE:
                data = b""
            elif fh.seekable():
                # the whole file in one read: ``head + fh.read()`` makes a second copy, in
                # memory new to the process (12 ms for the 8 MB of a 2000x2000 scan, 6 ms
                # of an analysis; one read takes 0.4 ms)
                fh.seek(0)
                data = fh.read()
            else:
                data = head + fh.read()
    except OSError as exc:
        raise ImageError(f"cannot open ({exc.strerror or type(exc).__name__})", path) from None
    if not head:
        raise ImageError("empty file", path)
    with warnings.catch_warnings(record=True):
        # Pillow's DecompressionBombWarning and numpy's RuntimeWarnings: what matters of
        # them is checked here (pixel budget, value ranges) and raised as ImageError
        warnings.simplefilter("always")
        orientation = None
        if head == _PNG_SIGNATURE:
            arr, orientation = _read_png_oriented(path, data)
        elif head[:4] in _TIFF_MAGIC:
            arr = _read_tiff(path)
        else:
            arr = _read_pillow(path)
        rgb, see_through = rgb_and_opacity(arr, path=path)
        return (rgb, orientation, see_through) if opacity else (rgb, orientation)
