"""Stage 1: read a scan as an RGB array at its native bit depth.

Accepted: PNG (8- or 16-bit per channel), TIFF (8- or 16-bit, read with tifffile), JPEG, and
any other format Pillow reads. Conversions, documented choices:

- RGB: kept as is, dtype uint8 or uint16 (16-bit PNG/TIFF are not reduced to 8 bits; the
  threshold scales its defaults by 257).
- RGBA (or palette with transparency): a fully opaque alpha is dropped; a partly transparent
  image is composited over white, i.e. transparent pixels are read as paper (a scan has no
  transparency; white is the neutral background that the threshold rejects).
- Palette (indexed) images: expanded to RGB.
- Grayscale (L, I;16, 1-bit, two-channel gray+alpha): rejected with ``ImageError``: the
  threshold separates blue ink from grey-blue receding surfaces by colour, which a grey image
  cannot do.
- float arrays (TIFF or ``ndarray`` input to ``analyze``) with values in [0, 1]: scaled to
  uint16.
- Corrupt, truncated or non-image files, images smaller than 16 px on a side, more than one
  page/frame of different sizes: ``ImageError`` naming the file.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

from crosssection.core.errors import ImageError

MIN_SIDE_PX = 16
_TIFF_SUFFIXES = {".tif", ".tiff"}


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
    """Validate and convert an array to (H, W, 3) uint8/uint16 RGB (see module docstring).

    Parameters
    ----------
    arr : array_like
        (H, W, 3) or (H, W, 4) array; uint8, uint16, or float in [0, 1]; other integer
        types with values within 0..65535 are accepted as uint16 when needed.
    path : str, optional
        File the array came from, for error messages.

    Returns
    -------
    (H, W, 3) uint8 or uint16 array

    Raises
    ------
    ImageError
        Grayscale, wrong shape, bad dtype or values, too small.
    """
    a = np.asarray(arr)
    if a.ndim == 2 or (a.ndim == 3 and a.shape[2] in (1, 2)):
        raise ImageError("grayscale image: an RGB scan of blue ink is needed to threshold "
                         "on colour", path)
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        raise ImageError(f"not an RGB image (array shape {a.shape})", path)
    if a.dtype == np.bool_:
        raise ImageError("binary image: an RGB scan is needed", path)
    if a.dtype.kind == "f":
        if not np.all(np.isfinite(a)) or a.min() < 0 or a.max() > 1:
            raise ImageError("float image values must lie in [0, 1]", path)
        a = np.round(a * 65535.0).astype(np.uint16)
    elif a.dtype not in (np.uint8, np.uint16):
        if a.dtype.kind not in "ui":
            raise ImageError(f"unsupported pixel type {a.dtype}", path)
        lo, hi = (int(a.min()), int(a.max())) if a.size else (0, 0)
        if lo < 0 or hi > 65535:
            raise ImageError(f"pixel values {lo}..{hi} out of the 16-bit range", path)
        a = a.astype(np.uint8 if hi <= 255 and a.dtype.itemsize == 1 else np.uint16)
    if a.shape[2] == 4:
        a = _composite_alpha(a)
    h, w = a.shape[:2]
    if min(h, w) < MIN_SIDE_PX:
        raise ImageError(f"image too small ({w}x{h} px; at least {MIN_SIDE_PX} px a side)",
                         path)
    return np.ascontiguousarray(a)


def _png_bit_depth(head: bytes):
    if head[:8] == b"\x89PNG\r\n\x1a\n" and len(head) >= 26 and head[12:16] == b"IHDR":
        return head[24], head[25]  # bit depth, colour type
    return None


def _read_tiff(path: Path) -> np.ndarray:
    import tifffile

    try:
        with tifffile.TiffFile(path) as tif:
            page = tif.pages[0]
            arr = page.asarray()
            photometric = getattr(page, "photometric", None)
    except Exception as exc:  # tifffile raises several types for bad files
        raise ImageError(f"cannot read TIFF ({type(exc).__name__}: "
                         f"{' '.join(str(exc).split())[:120]})", path) from None
    if arr.ndim == 3 and arr.shape[0] in (3, 4) and arr.shape[2] not in (3, 4):
        arr = np.moveaxis(arr, 0, -1)  # planar configuration
    if photometric is not None and int(photometric) == 3 and arr.ndim == 2:  # palette
        cmap = tif_cmap(path)
        if cmap is not None:
            arr = cmap[arr]
    return arr


def tif_cmap(path):
    """The colour map of a palette TIFF as (N, 3) uint16, or None."""
    import tifffile

    with tifffile.TiffFile(path) as tif:
        cm = tif.pages[0].colormap
    return None if cm is None else np.ascontiguousarray(np.asarray(cm).T)


def _read_pillow(path: Path, head: bytes) -> np.ndarray:
    from PIL import Image, UnidentifiedImageError

    depth = _png_bit_depth(head)
    if depth is not None and depth[0] == 16 and depth[1] in (2, 6):
        # 16-bit RGB(A) PNG: Pillow reduces it to 8 bits, OpenCV keeps it. Pillow checks
        # the file first: libpng, under OpenCV, would print its own errors on stderr
        import cv2

        try:
            with Image.open(path) as im:
                im.load()
        except (OSError, SyntaxError, ValueError) as exc:
            msg = " ".join(str(exc).split())[:120]
            raise ImageError(f"cannot read image (corrupt or truncated file: {msg})",
                             path) from None
        data = np.frombuffer(path.read_bytes(), np.uint8)
        arr = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
        if arr is None or arr.ndim != 3:
            raise ImageError("cannot decode 16-bit PNG (corrupt or truncated file)", path)
        return arr[..., [2, 1, 0, 3][:arr.shape[2]]]
    try:
        with Image.open(path) as im:
            im.load()
            mode = im.mode
            if mode == "P":
                im = im.convert("RGBA" if "transparency" in im.info else "RGB")
            elif mode in ("LA", "La", "PA"):
                im = im.convert("LA")
            elif mode in ("CMYK", "YCbCr", "LAB", "HSV", "RGBX", "RGBa"):
                im = im.convert("RGB")
            arr = np.asarray(im)
    except UnidentifiedImageError:
        raise ImageError("not an image file (unknown or corrupt format)", path) from None
    except Image.DecompressionBombError as exc:
        raise ImageError(f"image too large ({' '.join(str(exc).split())[:100]})",
                         path) from None
    except (OSError, SyntaxError, ValueError) as exc:
        msg = " ".join(str(exc).split())[:120]
        raise ImageError(f"cannot read image (corrupt or truncated file: {msg})", path) from None
    if mode in ("I;16", "I;16B", "I;16L", "I", "F", "L", "1", "LA"):
        raise ImageError(f"grayscale image (mode {mode}): an RGB scan of blue ink is needed "
                         "to threshold on colour", path)
    return arr


def load_image(path) -> np.ndarray:
    """Read a scan as an RGB array at native dtype.

    Parameters
    ----------
    path : str or Path
        PNG, TIFF, JPEG (or any format Pillow reads).

    Returns
    -------
    (H, W, 3) uint8 or uint16 array
        See the module docstring for the conversions (alpha, palette, float).

    Raises
    ------
    ImageError
        Missing, unreadable, corrupt, truncated, grayscale or too small file; one line
        naming the file.
    """
    path = Path(path)
    if not path.exists():
        raise ImageError("file not found", path)
    if path.is_dir():
        raise ImageError("is a directory, not an image file", path)
    try:
        with open(path, "rb") as fh:
            head = fh.read(64)
    except OSError as exc:
        raise ImageError(f"cannot open ({exc.strerror or type(exc).__name__})", path) from None
    if not head:
        raise ImageError("empty file", path)
    is_tiff = head[:4] in (b"II*\x00", b"MM\x00*", b"II+\x00", b"MM\x00+")
    if is_tiff or (path.suffix.lower() in _TIFF_SUFFIXES and not _png_bit_depth(head)):
        arr = _read_tiff(path)
    else:
        arr = _read_pillow(path, head)
    return as_rgb(arr, path=path)
