"""Read the project's NumPy archives (``.npz``) within memory caps, with errors that name the file.

``np.load`` trusts an archive: it allocates whatever shape a member's
``.npy`` header declares (10**12 float64 is a ``MemoryError``), inflates
without a bound, and lets ``zipfile``, ``zlib`` and ``EOFError`` escape on a
damaged file.  :func:`read_npz` checks every member's declared dtype and
shape before it allocates anything, refuses Python objects (pickles), caps
the bytes of each array and of the whole archive, reads each member no
further than its header says, and turns every failure into one
:class:`NpzError` that names the file and the problem.
"""

from __future__ import annotations

import math
import zipfile
import zlib
from pathlib import Path

import numpy as np
from numpy.lib import format as npy_format

__all__ = ["NpzError", "read_npz", "MAX_BYTES", "MAX_ARRAY_BYTES"]

#: Default cap on the bytes of all arrays of one archive together (inflated): 512 MiB.  The largest
#: archives the toolkit writes hold far less: 445 kB for the batch entry of a 50k-vertex mesh (its vertex
#: saliency, 8 bytes a vertex, is most of it), 82 kB for an experiment cache entry (six toys).
MAX_BYTES = 512 << 20
#: Default cap on the bytes of one array: 256 MiB (the vertex saliency of a 33M-vertex mesh).
MAX_ARRAY_BYTES = 256 << 20

# The .npy header of a member: magic (6), version (2), length (2 or 4), then at most numpy's own
# limit on the text (10,000 characters); anything longer is not an array numpy wrote.
_MAX_HEADER_BYTES = 10_000 + 12
_CHUNK = 1 << 20


class NpzError(ValueError):
    """A ``.npz`` file cannot be used; the message names the file and the problem.

    Attributes
    ----------
    path : pathlib.Path
    problem : str
        The message without the file name.
    """

    def __init__(self, path, problem: str):
        super().__init__(f"{path}: {problem}")
        self.path = Path(path)
        self.problem = problem


def read_npz(
    path, what: str = "NumPy archive", max_bytes: int = MAX_BYTES, max_array_bytes: int = MAX_ARRAY_BYTES
) -> dict[str, np.ndarray]:
    """Every array of the ``.npz`` archive ``path``, a ``what`` (e.g. ``"imprint set"``).

    Parameters
    ----------
    path : str or Path
        The ``.npz`` file.
    what : str
        What the file should be; it goes into every error message.
    max_bytes : int
        Cap on the arrays' bytes all together, as declared by the archive and
        as inflated (default :data:`MAX_BYTES`, 512 MiB).
    max_array_bytes : int
        Cap on one array's bytes (default :data:`MAX_ARRAY_BYTES`, 256 MiB).

    Returns
    -------
    dict of str to ndarray
        Keyed by member name without ``.npy``, in the archive's order;
        writable, as ``np.load`` gives them.

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist; the message names it.
    NpzError (a ValueError)
        The file is not a zip archive (or is a bare ``.npy``), is truncated,
        has a corrupt deflate stream or a bad CRC, holds a member that is not
        an ``.npy`` array, holds Python objects (never unpickled), or declares
        more bytes than the caps.  Nothing larger than the caps is allocated
        or inflated, whatever the archive's sizes claim.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "a.npz"
    >>> np.savez_compressed(path, x=np.arange(3), y=np.eye(2))
    >>> sorted(read_npz(path, "demo archive"))
    ['x', 'y']
    >>> read_npz(path, "demo archive", max_array_bytes=16)
    Traceback (most recent call last):
    ...
    meshsal.util.npzfile.NpzError: ...a.npz: demo archive too large: 'x' is (3,) int64 = 24 B, more than the cap of 16 B...
    """
    path = Path(path)
    try:
        fh = open(path, "rb")
    except FileNotFoundError:
        raise FileNotFoundError(f"{path}: {what} not found") from None
    except IsADirectoryError:
        raise NpzError(path, f"not {_a(what)}: a directory") from None
    with fh:
        try:
            if fh.read(6) == npy_format.MAGIC_PREFIX:
                raise NpzError(path, f"not {_a(what)}: a bare .npy array, not an .npz archive")
            fh.seek(0)
            with zipfile.ZipFile(fh) as archive:
                return _read_members(path, archive, what, max_bytes, max_array_bytes)
        except NpzError:
            raise
        except zipfile.BadZipFile as exc:
            fh.seek(0)
            if fh.read(4) not in (b"PK\x03\x04", b"PK\x05\x06"):
                raise NpzError(path, f"not {_a(what)}: not an .npz (zip) archive") from None
            raise NpzError(path, f"damaged or truncated {what} ({exc})") from None
        except (zlib.error, EOFError, ValueError, NotImplementedError, OverflowError, OSError) as exc:
            # zlib.error: a corrupt deflate stream; EOFError, ValueError: a member ends early; OSError: a
            # damaged offset (a seek before the start) or the disk; NotImplementedError: a compression
            # numpy never writes; OverflowError: absurd zip fields.
            kind = "zlib.error" if isinstance(exc, zlib.error) else type(exc).__name__
            raise NpzError(path, f"damaged or truncated {what} ({kind}: {exc})") from None
        except MemoryError:
            raise NpzError(path, f"{what} does not fit in this machine's memory") from None


def _read_members(
    path: Path, archive: zipfile.ZipFile, what: str, max_bytes: int, max_array_bytes: int
) -> dict[str, np.ndarray]:
    members = archive.infolist()
    for info in members:
        if not info.filename.endswith(".npy"):
            raise NpzError(path, f"not {_a(what)}: member {info.filename!r} is not a NumPy array (.npy)")
        if info.flag_bits & 0x1:
            raise NpzError(path, f"not {_a(what)}: member {info.filename!r} is encrypted")
    declared = sum(info.file_size for info in members)
    if declared > max_bytes + len(members) * _MAX_HEADER_BYTES:
        raise NpzError(
            path,
            f"{what} too large: its members declare {_size(declared)} inflated, more than the "
            f"cap of {_size(max_bytes)}",
        )
    arrays, total = {}, 0
    for info in members:
        name = info.filename[:-4]
        with archive.open(info) as member:
            shape, fortran, dtype = _header(path, member, name, what)
            nbytes = math.prod(shape) * dtype.itemsize
            if nbytes > max_array_bytes:
                raise NpzError(
                    path,
                    f"{what} too large: {name!r} is {shape} {dtype} = {_size(nbytes)}, more than "
                    f"the cap of {_size(max_array_bytes)} per array",
                )
            total += nbytes
            if total > max_bytes:
                raise NpzError(
                    path,
                    f"{what} too large: its arrays hold more than the cap of {_size(max_bytes)} in all (at {name!r})",
                )
            arrays[name] = _body(path, member, name, what, shape, fortran, dtype, nbytes)
    return arrays


def _header(path: Path, member, name: str, what: str):
    try:
        version = npy_format.read_magic(member)
        if version == (1, 0):
            shape, fortran, dtype = npy_format.read_array_header_1_0(member)
        elif version == (2, 0):
            shape, fortran, dtype = npy_format.read_array_header_2_0(member)
        else:
            raise NpzError(
                path,
                f"not {_a(what)}: {name!r} is a .npy of version {version[0]}.{version[1]}, which "
                f"this reader does not read",
            )
    except (NpzError, zipfile.BadZipFile, zlib.error, EOFError):
        raise
    except Exception as exc:
        # numpy parses the header text with ast and, for old files, tokenize: a damaged header can raise
        # whatever those raise (ValueError, tokenize.TokenError, RecursionError...).
        raise NpzError(
            path, f"damaged {what}: {name!r} has an unreadable .npy header ({type(exc).__name__}: {exc})"
        ) from None
    if dtype.hasobject:
        raise NpzError(
            path, f"not {_a(what)}: {name!r} holds Python objects (dtype {dtype}), which are never unpickled"
        )
    if any(n < 0 for n in shape):
        raise NpzError(path, f"damaged {what}: {name!r} declares the shape {shape}")
    return shape, fortran, dtype


def _body(path: Path, member, name: str, what: str, shape, fortran: bool, dtype, nbytes: int) -> np.ndarray:
    # Reads exactly the bytes the (already capped) header declares, so a member inflating to more
    # than its zip entry or its header says is never inflated past them.
    buffer = bytearray(nbytes)
    view, done = memoryview(buffer), 0
    while done < nbytes:
        got = member.readinto(view[done : done + _CHUNK])
        if not got:
            raise NpzError(path, f"damaged or truncated {what}: {name!r} ends after {done} of its {nbytes} bytes")
        done += got
    if member.read(1):
        raise NpzError(path, f"damaged {what}: {name!r} holds more bytes than its shape {shape} {dtype}")
    order = "F" if fortran else "C"
    if not nbytes:
        return np.empty(shape, dtype, order=order)
    return np.frombuffer(buffer, dtype=dtype).reshape(shape, order=order)


def _a(what: str) -> str:
    return f"an {what}" if what[:1].lower() in "aeiou" else f"a {what}"


def _size(n: int) -> str:
    for unit, scale in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if n >= scale:
            return f"{n / scale:.1f} {unit}"
    return f"{n} B"
