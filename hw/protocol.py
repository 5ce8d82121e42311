"""The tactile sensor's serial frame protocol: encoding and incremental parsing.

Binary frames are little-endian:

======  ================  ==============================================
offset  size              field
======  ================  ==============================================
0       2                 sync bytes 0xAA 0x55
2       1                 version, 1
3       1                 rows
4       1                 cols
5       1                 reserved, 0
6       4                 sequence number, uint32
10      4                 device time in microseconds, uint32
14      2 x rows x cols   taxel values, uint16, row-major
end     2                 CRC-16/CCITT-FALSE over bytes 2 .. end-1
======  ================  ==============================================

The text variant sends one frame per line: ``seq,t_us,v0,v1,...\\n``.  It has
no checksum, so a flipped digit cannot be detected; only malformed lines are
rejected.  Prefer the binary protocol on noisy links.
"""

from __future__ import annotations

import binascii
import math
import struct
from dataclasses import dataclass

import numpy as np

from meshsal.util.registry import Registry

__all__ = [
    "SYNC",
    "VERSION",
    "HEADER_SIZE",
    "FRAME_PROTOCOLS",
    "Frame",
    "crc16_ccitt_false",
    "frame_size",
    "encode_frame",
    "encode_text_frame",
    "encode",
    "FrameParser",
]

SYNC = b"\xaa\x55"
VERSION = 1
HEADER_SIZE = 14
_HEADER = struct.Struct("<2sBBBBII")
_MAX_COUNTER = 2**32


@dataclass(frozen=True, eq=False)
class Frame:
    """One sensor frame.

    Attributes
    ----------
    seq : int
        Sequence number (uint32, wraps).
    t_us : int
        Device time in microseconds (uint32, wraps).
    values : (rows, cols) uint16
        Raw taxel readings, row-major.
    """

    seq: int
    t_us: int
    values: np.ndarray

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.values.shape)


def crc16_ccitt_false(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE: poly 0x1021, init 0xFFFF, no reflection, no final xor.

    ``binascii.crc_hqx`` is exactly this polynomial without reflection, so it
    runs in C; ``crc`` continues a running checksum.

    Examples
    --------
    >>> hex(crc16_ccitt_false(b"123456789"))
    '0x29b1'
    """
    return binascii.crc_hqx(data, crc)


def frame_size(rows: int, cols: int) -> int:
    """Bytes in one binary frame of a ``rows`` x ``cols`` sensor."""
    return HEADER_SIZE + 2 * rows * cols + 2


def _check_frame_fields(seq, t_us, values) -> np.ndarray:
    values = np.asarray(values)
    if values.ndim != 2 or not (1 <= values.shape[0] <= 255 and 1 <= values.shape[1] <= 255):
        raise ValueError(f"frame values must be a (rows, cols) array with 1..255 rows and cols, got {values.shape}")
    if values.size and (values.min() < 0 or values.max() > 0xFFFF):
        raise ValueError("frame values must lie in 0..65535 (uint16)")
    for name, v in (("seq", seq), ("t_us", t_us)):
        if not 0 <= int(v) < _MAX_COUNTER:
            raise ValueError(f"frame {name} must lie in 0..2**32-1, got {v}")
    return values.astype("<u2")


def encode_frame(seq: int, t_us: int, values) -> bytes:
    """Encode one binary frame.

    Parameters
    ----------
    seq, t_us : int
        Sequence number and device time, each in 0..2**32-1.
    values : (rows, cols) array of ints in 0..65535

    Examples
    --------
    >>> data = encode_frame(7, 1000, np.zeros((2, 3), np.uint16))
    >>> len(data), data[:2]
    (28, b'\\xaaU')
    >>> FrameParser().feed(data)[0].seq
    7
    """
    v = _check_frame_fields(seq, t_us, values)
    rows, cols = v.shape
    body = _HEADER.pack(SYNC, VERSION, rows, cols, 0, int(seq), int(t_us)) + v.tobytes()
    return body + struct.pack("<H", crc16_ccitt_false(body[2:]))


def encode_text_frame(seq: int, t_us: int, values) -> bytes:
    """Encode one text frame: ``seq,t_us,v0,...,v(rows*cols-1)\\n`` (ASCII).

    Examples
    --------
    >>> encode_text_frame(3, 40, [[1, 2], [3, 4]])
    b'3,40,1,2,3,4\\n'
    """
    v = _check_frame_fields(seq, t_us, values)
    return (",".join(map(str, [int(seq), int(t_us), *v.ravel().tolist()])) + "\n").encode("ascii")


#: The frame protocols, each with its encoder ``(seq, t_us, values) -> bytes``.
FRAME_PROTOCOLS = Registry(
    "frame protocol",
    [
        ("binary", encode_frame, "CRC-checked binary frames"),
        ("text", encode_text_frame, "one line of comma-separated numbers per frame, no checksum"),
    ],
)


def encode(seq: int, t_us: int, values, protocol: str = "binary") -> bytes:
    """Encode one frame in ``protocol`` (one of :data:`FRAME_PROTOCOLS`)."""
    return FRAME_PROTOCOLS.get(protocol)(seq, t_us, values)


def _plausible(version: int, rows: int, cols: int, reserved: int) -> bool:
    return version == VERSION and reserved == 0 and rows > 0 and cols > 0


class FrameParser:
    """Incremental parser: feed it bytes as they arrive, get back whole frames.

    It resynchronizes after garbage, rejects corrupt frames and never raises
    on any byte input.  A binary header is taken seriously only when its
    version is 1, its reserved byte 0 and its rows and cols at least 1 (and
    equal to ``rows``/``cols`` when given), so that a stray sync pattern
    rarely makes it wait for a large fake frame; when one does, its CRC fails
    and the bytes after the stray sync are scanned again, so no valid frame
    is lost.

    Parameters
    ----------
    rows, cols : int, optional
        The expected sensor size.  Binary headers of another size are skipped
        (counted in ``size_errors``).  In text mode they fix the number of
        values per line; without them a line of n values is read as a square
        sqrt(n) x sqrt(n) array, and other counts are rejected.
    protocol : {"binary", "text"}

    Attributes
    ----------
    frames : int
        Frames accepted.
    crc_errors : int
        Binary candidates whose CRC failed.
    bad_lines : int
        Text lines that did not parse (text mode).
    size_errors : int
        Frames or headers whose size differs from ``rows`` x ``cols``.
    gaps : int
        Sequence numbers missing between accepted frames (dropped or
        corrupt frames).
    bytes_skipped : int
        Bytes discarded because they belonged to no accepted frame.

    Examples
    --------
    >>> good = encode_frame(1, 0, np.ones((2, 2), np.uint16))
    >>> later = encode_frame(3, 0, np.ones((2, 2), np.uint16))
    >>> p = FrameParser()
    >>> [f.seq for f in p.feed(b"junk" + good + later[:5])] + [f.seq for f in p.feed(later[5:])]
    [1, 3]
    >>> p.gaps, p.bytes_skipped
    (1, 4)
    """

    def __init__(self, rows: int | None = None, cols: int | None = None, protocol: str = "binary"):
        FRAME_PROTOCOLS.get(protocol)  # ValueError naming the protocols
        if (rows is None) != (cols is None):
            raise ValueError("give both rows and cols, or neither")
        if rows is not None and not (1 <= rows <= 255 and 1 <= cols <= 255):
            raise ValueError(f"rows and cols must lie in 1..255, got {rows} x {cols}")
        self.rows = rows
        self.cols = cols
        self.protocol = protocol
        self.frames = 0
        self.crc_errors = 0
        self.bad_lines = 0
        self.size_errors = 0
        self.gaps = 0
        self.bytes_skipped = 0
        self._buf = bytearray()
        self._last_seq: int | None = None
        if protocol == "text":
            n = 255 * 255 if rows is None else rows * cols
            # seq and t_us (10 digits each), n values of up to 5 digits, commas, CR.
            self._max_line = 24 + 6 * n + 2

    @property
    def rejected(self) -> int:
        """Frames rejected for any reason (CRC, malformed line, size)."""
        return self.crc_errors + self.bad_lines + self.size_errors

    def feed(self, data) -> list[Frame]:
        """Add received bytes; return the frames completed by them, in order."""
        self._buf += bytes(data)
        frames = self._parse_binary() if self.protocol == "binary" else self._parse_text()
        for frame in frames:
            self._count_gap(frame.seq)
        self.frames += len(frames)
        return frames

    def _count_gap(self, seq: int) -> None:
        if self._last_seq is not None:
            step = (seq - self._last_seq) % _MAX_COUNTER
            # A step backwards (device restart) or a duplicate is no loss.
            if 1 < step < _MAX_COUNTER // 2:
                self.gaps += step - 1
        self._last_seq = seq

    def _skip(self, n: int) -> None:
        del self._buf[:n]
        self.bytes_skipped += n

    def _frame_size_at(self, pos: int) -> int | None:
        """Size of the frame whose header starts at ``pos``: 0 if the header is
        not plausible, None if it is not complete yet."""
        buf = self._buf
        if len(buf) - pos < HEADER_SIZE:
            return None
        _, version, rows, cols, reserved, _, _ = _HEADER.unpack_from(buf, pos)
        if not _plausible(version, rows, cols, reserved):
            return 0
        if self.rows is not None and (rows, cols) != (self.rows, self.cols):
            return 0
        return frame_size(rows, cols)

    def _crc_ok(self, pos: int, size: int) -> bool:
        (crc,) = struct.unpack_from("<H", self._buf, pos + size - 2)
        return crc16_ccitt_false(bytes(self._buf[pos + 2 : pos + size - 2])) == crc

    def _later_valid_frame(self) -> int:
        """Position of a complete, CRC-valid frame after position 0, or -1."""
        buf = self._buf
        pos = 1
        while (pos := buf.find(SYNC, pos)) >= 0:
            size = self._frame_size_at(pos)
            if size and pos + size <= len(buf) and self._crc_ok(pos, size):
                return pos
            pos += 1
        return -1

    def _parse_binary(self) -> list[Frame]:
        out = []
        buf = self._buf
        while True:
            start = buf.find(SYNC)
            if start < 0:
                # Keep a trailing first sync byte: its partner may come next.
                self._skip(len(buf) - 1 if buf.endswith(SYNC[:1]) else len(buf))
                return out
            if start:
                self._skip(start)
            size = self._frame_size_at(0)
            if size == 0:
                if self.rows is not None and _plausible(*_HEADER.unpack_from(buf)[1:5]):
                    self.size_errors += 1
                self._skip(1)
                continue
            if size is None or len(buf) < size:
                # A valid frame further on means this header was a stray sync
                # (a real frame cannot hold a whole valid frame in its
                # payload but by a 2**-48 chance), so stop waiting for it.
                later = self._later_valid_frame() if size is not None else -1
                if later < 0:
                    return out
                self._skip(later)
                continue
            if not self._crc_ok(0, size):
                self.crc_errors += 1
                self._skip(1)
                continue
            _, _, rows, cols, _, seq, t_us = _HEADER.unpack_from(buf)
            values = np.frombuffer(bytes(buf[HEADER_SIZE : size - 2]), dtype="<u2").reshape(rows, cols)
            out.append(Frame(seq, t_us, values.astype(np.uint16)))
            del buf[:size]

    def _parse_text(self) -> list[Frame]:
        out = []
        buf = self._buf
        while True:
            end = buf.find(b"\n")
            if end < 0:
                if len(buf) > self._max_line:
                    self.bad_lines += 1
                    self._skip(len(buf))
                return out
            line = bytes(buf[:end])
            del buf[: end + 1]
            frame = self._parse_line(line)
            if frame is None:
                self.bytes_skipped += end + 1
            else:
                out.append(frame)

    def _parse_line(self, line: bytes) -> Frame | None:
        line = line.rstrip(b"\r")
        if not line:
            return None
        parts = line.split(b",")
        # Plain digits only: int() would also take signs, spaces and underscores.
        if len(parts) < 3 or not all(p.isdigit() and len(p) <= 10 for p in parts):
            self.bad_lines += 1
            return None
        fields = [int(p) for p in parts]
        seq, t_us, values = fields[0], fields[1], fields[2:]
        if seq >= _MAX_COUNTER or t_us >= _MAX_COUNTER or max(values) > 0xFFFF:
            self.bad_lines += 1
            return None
        if self.rows is not None:
            shape = (self.rows, self.cols)
            if len(values) != self.rows * self.cols:
                self.size_errors += 1
                return None
        else:
            side = math.isqrt(len(values))
            if side * side != len(values) or side > 255:
                self.size_errors += 1
                return None
            shape = (side, side)
        return Frame(seq, t_us, np.array(values, dtype=np.uint16).reshape(shape))
