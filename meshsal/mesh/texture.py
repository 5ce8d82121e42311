"""Texture images of meshes, read with a cap on their size in pixels, and the material libraries that name them.

A texture is decoded whole into memory, three bytes a pixel, so a large or
hostile image (a few kilobytes of PNG can declare a gigapixel) could exhaust
it.  :func:`read_texture` reads the size from the header of PNG, JPEG and
BMP files first, without decoding, and refuses an image over the cap
before OpenCV allocates anything; other formats are decoded, then
measured (OpenCV itself refuses images over 2^30 pixels).  A refused or
unreadable texture is reported, never raised: the mesh loads without it.
"""

from __future__ import annotations

import re
import struct
from pathlib import Path

import numpy as np

__all__ = ["MAX_TEXTURE_PIXELS", "MAX_MATERIAL_BYTES", "image_size", "read_texture", "material_textures"]

#: Largest texture read, in pixels: an 8192 x 8192 image (192 MiB as RGB bytes).
MAX_TEXTURE_PIXELS = 8192 * 8192
#: A material library larger than this is not read (its textures are left out, with a note): MTL files
#: hold a few lines per material, so anything near this size is not one.
MAX_MATERIAL_BYTES = 16 * 2**20

# JPEG markers that start a frame (SOF0-15 but DHT, JPG and DAC) and hold the image size.
_JPEG_FRAMES = set(range(0xC0, 0xD0)) - {0xC4, 0xC8, 0xCC}


def image_size(path) -> tuple[int, int] | None:
    """(width, height) of a PNG, JPEG or BMP image from its header alone; None for other or damaged files.

    Examples
    --------
    >>> import tempfile, cv2
    >>> path = Path(tempfile.mkdtemp()) / "t.png"
    >>> _ = cv2.imwrite(str(path), np.zeros((3, 5, 3), np.uint8))
    >>> image_size(path)
    (5, 3)
    """
    try:
        with open(path, "rb") as f:
            head = f.read(32)
            if head.startswith(b"\x89PNG\r\n\x1a\n") and head[12:16] == b"IHDR":
                return struct.unpack(">II", head[16:24])
            if head.startswith(b"BM") and len(head) >= 26:
                width, height = struct.unpack("<ii", head[18:26])
                return abs(width), abs(height)
            if head.startswith(b"\xff\xd8"):
                return _jpeg_size(f)
    except (OSError, struct.error):
        return None
    return None


def _jpeg_size(f) -> tuple[int, int] | None:
    f.seek(2)
    while True:
        byte = f.read(1)
        while byte == b"\xff":
            byte = f.read(1)  # fill bytes before a marker
        if not byte:
            return None
        marker = byte[0]
        if marker in (0x01, 0xD8) or 0xD0 <= marker <= 0xD7:
            continue  # markers without a segment
        if marker == 0xD9:
            return None
        length = f.read(2)
        if len(length) < 2:
            return None
        size = struct.unpack(">H", length)[0]
        if marker in _JPEG_FRAMES:
            frame = f.read(5)
            if len(frame) < 5:
                return None
            height, width = struct.unpack(">HH", frame[1:5])
            return width, height
        f.seek(size - 2, 1)


def read_texture(path, max_pixels: int | None = MAX_TEXTURE_PIXELS) -> tuple[np.ndarray | None, str]:
    """An RGB texture image, or None and why.

    Parameters
    ----------
    path : str or os.PathLike
    max_pixels : int or None
        Images with more pixels are refused (None: no cap).

    Returns
    -------
    image : (H, W, 3) uint8, first row at the top, or None
    note : str
        Empty when the image was read; else what happened, naming the image
        (missing, unreadable, or its size and the cap).
    """
    import cv2

    path = Path(path)
    if not path.is_file():
        return None, f"texture image {path.name!r} is missing; loaded without texture"
    size = image_size(path)
    if max_pixels is not None and size is not None and size[0] * size[1] > max_pixels:
        return None, _too_large(path, *size, max_pixels)
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        return None, f"texture image {path.name!r} cannot be read; loaded without texture"
    if max_pixels is not None and image.shape[0] * image.shape[1] > max_pixels:
        return None, _too_large(path, image.shape[1], image.shape[0], max_pixels)
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB), ""


def _too_large(path: Path, width: int, height: int, max_pixels: int) -> str:
    return (
        f"texture image {path.name!r} has {width} x {height} = {width * height:,} pixels, over the cap of "
        f"{max_pixels:,}; loaded without texture"
    )


def _mtl_map_kd(rest: list) -> str:
    """The file name of a ``map_Kd`` statement, skipping its options (``-s 1 1 1``)."""
    i = 0
    while i < len(rest) - 1 and rest[i].startswith("-"):
        i += 1
        while i < len(rest) - 1 and (rest[i] in ("on", "off") or re.fullmatch(r"[-+.\deE]+", rest[i])):
            i += 1
    return " ".join(rest[i:])


def material_textures(obj_path, libraries, materials) -> tuple[list, list]:
    """The texture images (``map_Kd``) of an OBJ's ``materials``, from its material ``libraries``.

    Parameters
    ----------
    obj_path : pathlib.Path
        The OBJ file: library names are relative to its folder, image names to their library's.
    libraries : list of str
        The names of its ``mtllib`` statements.
    materials : list of str
        The materials its faces use (``usemtl``), in order.

    Returns
    -------
    images : list of pathlib.Path
        The distinct images those materials name, in order.
    notes : list of str
        Libraries missing, unreadable or over :data:`MAX_MATERIAL_BYTES`.
    """
    maps, notes = {}, []
    for name in libraries:
        lib = Path(obj_path).parent / name
        if not lib.is_file():
            notes.append(f"material library {name!r} not found")
            continue
        try:
            size = lib.stat().st_size
            text = lib.read_bytes().decode("utf-8", errors="replace") if size <= MAX_MATERIAL_BYTES else None
        except OSError as e:
            notes.append(f"material library {name!r} cannot be read ({e.strerror or e})")
            continue
        if text is None:
            notes.append(
                f"material library {name!r} has {size} bytes, over the cap of "
                f"{MAX_MATERIAL_BYTES}; loaded without its textures"
            )
            continue
        current = None
        for line in text.splitlines():
            parts = line.split()
            if len(parts) >= 2 and parts[0] == "newmtl":
                current = " ".join(parts[1:])
            elif len(parts) >= 2 and parts[0] == "map_Kd" and current is not None:
                maps[current] = (lib.parent / _mtl_map_kd(parts[1:])).resolve()
    images = []
    for material in materials:
        image = maps.get(material)
        if image is not None and image not in images:
            images.append(image)
    return images, notes
