"""Reading map files within limits: grey images and .npy arrays, every failure a MapError naming
the file and the reason (so the CLI prints one line and exits 2).
"""

from __future__ import annotations

import math
import re
import threading
from contextlib import contextmanager
from pathlib import Path
from typing import cast

import cv2
import numpy as np


class MapError(Exception):
    """A map that cannot be used; the message names the file and the reason."""

    def __init__(self, path: str | Path, reason: str):
        self.path = str(path)
        self.reason = reason
        super().__init__(f"{self.path}: {reason}")


MAX_IMAGE_PIXELS = 1 << 26  # 64 Mpixel: beyond this an image is refused, not decoded


MAX_GRID_CELLS = 1 << 26  # the same bound for .npy grids


def _peek_image_size(data: np.ndarray) -> tuple[int, int] | None:
    """(width, height) from a PNG or PNM header, read before decoding; None if not recognised.

    Lets a tiny file that declares an enormous image be rejected before OpenCV allocates it.
    """
    head = data[:1024].tobytes()
    if head.startswith(b"\x89PNG\r\n\x1a\n") and len(head) >= 24 and head[12:16] == b"IHDR":
        return int.from_bytes(head[16:20], "big"), int.from_bytes(head[20:24], "big")
    if len(head) >= 2 and head[:1] == b"P" and head[1:2] in b"123456":
        tokens: list[int] = []
        position = 2
        while len(tokens) < 2 and position < len(head):
            char = head[position : position + 1]
            if char == b"#":
                newline = head.find(b"\n", position)
                if newline < 0:
                    return None
                position = newline + 1
            elif char.isspace():
                position += 1
            elif char.isdigit():
                match = re.match(rb"\d+", head[position:])
                assert match is not None
                tokens.append(int(match.group()))
                position += match.end()
            else:
                return None
        if len(tokens) == 2:
            return tokens[0], tokens[1]
    return None


def is_file_named(path: Path) -> bool:
    """Path.is_file that says False (not raises) for a name the OS rejects (too long, NUL byte)."""
    try:
        return path.is_file()
    except (OSError, ValueError):
        return False


_OPENCV_QUIET_LOCK = threading.Lock()
_opencv_quiet_depth = 0
_opencv_saved_level: int | None = None


@contextmanager
def _opencv_quiet():
    """Silence OpenCV's own logging (its `[ WARN:0@...]` lines on a corrupt image) for the block.

    Counted, so overlapping blocks in several threads restore the level saved by the first.
    """
    global _opencv_quiet_depth, _opencv_saved_level
    logging = getattr(getattr(cv2, "utils", None), "logging", None)
    if logging is None:  # an OpenCV build without the logging bindings
        yield
        return
    with _OPENCV_QUIET_LOCK:
        if _opencv_quiet_depth == 0:
            _opencv_saved_level = logging.getLogLevel()
            logging.setLogLevel(logging.LOG_LEVEL_SILENT)
        _opencv_quiet_depth += 1
    try:
        yield
    finally:
        with _OPENCV_QUIET_LOCK:
            _opencv_quiet_depth -= 1
            if _opencv_quiet_depth == 0 and _opencv_saved_level is not None:
                logging.setLogLevel(_opencv_saved_level)
                _opencv_saved_level = None


def read_gray_image(path: Path) -> np.ndarray:
    """An image file as a 2-D uint8 array (colour converted to gray, 16-bit reduced to 8)."""
    if not is_file_named(path):
        raise MapError(path, "file not found")
    try:
        data = np.fromfile(str(path), dtype=np.uint8)
    except OSError as error:
        raise MapError(path, f"cannot read the file ({error.strerror or type(error).__name__})") from None
    if data.size == 0:
        raise MapError(path, "not a readable image (the file is empty)")
    declared = _peek_image_size(data)
    if declared is not None and declared[0] * declared[1] > MAX_IMAGE_PIXELS:
        raise MapError(
            path, f"image of {declared[0]}x{declared[1]} pixels exceeds the limit of {MAX_IMAGE_PIXELS} pixels"
        )
    try:
        with _opencv_quiet():
            image: np.ndarray | None = cv2.imdecode(data, cv2.IMREAD_UNCHANGED)
    except cv2.error as error:
        raise MapError(path, f"not a readable image (OpenCV: {_first_line(error)})") from None
    if image is None or image.size == 0:
        raise MapError(path, "not a readable image")
    if image.ndim == 2 or image.shape[2] == 1:
        image = image.reshape(image.shape[0], image.shape[1])
    elif image.shape[2] == 2:  # gray + alpha
        image = np.ascontiguousarray(image[:, :, 0])
    if image.dtype not in (np.uint8, np.uint16):
        raise MapError(path, f"unsupported pixel type {image.dtype} (expected 8- or 16-bit)")
    if image.ndim == 3:
        if image.shape[2] == 3:
            image = cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
        elif image.shape[2] == 4:
            image = cv2.cvtColor(image, cv2.COLOR_BGRA2GRAY)
        else:
            raise MapError(path, f"unsupported image with {image.shape[2]} channels")
    if image.dtype == np.uint16:
        # 16-bit images: keep the top byte so thresholds stay in 0..255.
        image = (cast(np.ndarray, image) >> 8).astype(np.uint8)
    if image.size > MAX_IMAGE_PIXELS:
        raise MapError(
            path, f"image of {image.shape[1]}x{image.shape[0]} pixels exceeds the limit of {MAX_IMAGE_PIXELS} pixels"
        )
    return image


def _first_line(error: BaseException) -> str:
    """The gist of an exception's message, short enough for a one-line error."""
    lines = [line.strip() for line in str(error).strip().splitlines() if line.strip()]
    text = lines[-1] if lines else type(error).__name__
    return text if len(text) <= 160 else text[:157] + "..."


def read_npy_array(path: Path) -> np.ndarray:
    """A 2-D boolean/integer array from a .npy file, checking its header before loading it."""
    if not is_file_named(path):
        raise MapError(path, "file not found")
    try:
        with open(path, "rb") as stream:
            try:
                version = np.lib.format.read_magic(stream)
                if version == (1, 0):
                    shape, _, dtype = np.lib.format.read_array_header_1_0(stream)
                elif version == (2, 0):
                    shape, _, dtype = np.lib.format.read_array_header_2_0(stream)
                else:
                    raise MapError(
                        path, f"not a readable .npy array (unsupported format version {version[0]}.{version[1]})"
                    )
            except MapError:
                raise
            except Exception as error:  # numpy raises ValueError and friends for a bad header
                raise MapError(path, f"not a readable .npy array ({_first_line(error)})") from None
            data_offset = stream.tell()
        file_size = path.stat().st_size
    except OSError as error:
        raise MapError(path, f"cannot read the file ({error.strerror or type(error).__name__})") from None
    if dtype.hasobject or dtype.kind not in "biu" or dtype.fields is not None or dtype.subdtype is not None:
        raise MapError(path, f"grid must be boolean or integer (1 = free), got dtype {dtype}")
    if len(shape) != 2:
        raise MapError(path, f"grid must be 2-D, got {len(shape)}-D array of shape {shape}")
    if any(size < 0 for size in shape):
        raise MapError(path, f"not a readable .npy array (negative shape {shape} in its header)")
    cells = math.prod(shape)
    if cells > MAX_GRID_CELLS:
        raise MapError(path, f"grid of shape {shape} exceeds the limit of {MAX_GRID_CELLS} cells")
    if file_size - data_offset < cells * dtype.itemsize:
        raise MapError(
            path,
            f"truncated .npy file: shape {shape} of {dtype} needs {cells * dtype.itemsize} bytes of data, "
            f"found {file_size - data_offset}",
        )
    try:
        array = np.load(str(path), allow_pickle=False)
    except Exception as error:  # numpy raises several types for corrupt files
        raise MapError(path, f"not a readable .npy array ({_first_line(error)})") from None
    if not isinstance(array, np.ndarray) or array.shape != tuple(shape) or array.dtype != dtype:
        raise MapError(path, "not a readable .npy array (contents disagree with its header)")
    return array
