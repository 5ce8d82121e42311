"""hw.protocol: CRC, frame encoding, and the incremental parser (with fuzzing)."""

import struct

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from hw.protocol import (
    HEADER_SIZE,
    FrameParser,
    crc16_ccitt_false,
    encode,
    encode_frame,
    encode_text_frame,
    frame_size,
)


def test_crc_standard_check_value():
    assert crc16_ccitt_false(b"123456789") == 0x29B1
    assert crc16_ccitt_false(b"") == 0xFFFF
    # Running form: the CRC of a concatenation continues from the first part.
    assert crc16_ccitt_false(b"6789", crc16_ccitt_false(b"12345")) == 0x29B1


def test_binary_layout_matches_the_table():
    values = np.arange(6, dtype=np.uint16).reshape(2, 3) * 1000
    data = encode_frame(0x01020304, 0xA0B0C0D0, values)
    assert len(data) == frame_size(2, 3) == 14 + 12 + 2
    assert data[:6] == bytes([0xAA, 0x55, 1, 2, 3, 0])
    assert struct.unpack_from("<II", data, 6) == (0x01020304, 0xA0B0C0D0)
    assert struct.unpack_from("<6H", data, HEADER_SIZE) == tuple(range(0, 6000, 1000))
    assert struct.unpack_from("<H", data, len(data) - 2)[0] == crc16_ccitt_false(data[2:-2])


def test_round_trip_binary_and_text():
    rng = np.random.default_rng(0)
    values = rng.integers(0, 65536, size=(16, 16)).astype(np.uint16)
    for protocol, enc in (("binary", encode_frame), ("text", encode_text_frame)):
        data = enc(2**32 - 1, 123456, values)
        assert encode(2**32 - 1, 123456, values, protocol) == data
        (frame,) = FrameParser(protocol=protocol).feed(data)
        assert frame.seq == 2**32 - 1 and frame.t_us == 123456
        assert frame.values.dtype == np.uint16 and np.array_equal(frame.values, values)


def test_an_unknown_protocol_is_refused_naming_the_protocols():
    with pytest.raises(ValueError, match="unknown frame protocol 'csv'; choose from binary, text"):
        encode(0, 0, np.zeros((2, 2)), "csv")
    with pytest.raises(ValueError, match="unknown frame protocol 'csv'; choose from binary, text"):
        FrameParser(protocol="csv")


def test_encode_rejects_bad_values():
    with pytest.raises(ValueError, match="uint16"):
        encode_frame(0, 0, np.full((2, 2), 70000))
    with pytest.raises(ValueError, match="rows"):
        encode_frame(0, 0, np.zeros(4))
    with pytest.raises(ValueError, match="seq"):
        encode_frame(2**32, 0, np.zeros((2, 2)))


def test_corrupt_frame_rejected_and_gap_counted():
    frames = [encode_frame(i, 10 * i, np.full((4, 4), i, np.uint16)) for i in range(5)]
    bad = bytearray(frames[2])
    bad[HEADER_SIZE + 3] ^= 0x10
    parser = FrameParser()
    got = parser.feed(b"".join([frames[0], frames[1], bytes(bad), frames[3], frames[4]]))
    assert [f.seq for f in got] == [0, 1, 3, 4]
    assert parser.crc_errors == 1 and parser.gaps == 1
    assert parser.bytes_skipped == len(bad)


def test_every_single_bit_flip_is_caught():
    values = np.random.default_rng(1).integers(0, 4096, size=(3, 3)).astype(np.uint16)
    good = encode_frame(5, 6, values)
    for bit in range(8 * len(good)):
        bad = bytearray(good)
        bad[bit // 8] ^= 1 << (bit % 8)
        assert FrameParser().feed(bytes(bad)) == [], bit


def test_expected_size_skips_other_headers():
    parser = FrameParser(rows=4, cols=4)
    got = parser.feed(encode_frame(0, 0, np.zeros((2, 2), np.uint16)) + encode_frame(1, 0, np.ones((4, 4))))
    assert [f.seq for f in got] == [1] and parser.size_errors == 1


def test_stray_header_claiming_a_huge_frame_does_not_hold_back_valid_frames():
    # A fake 255 x 255 header (130 kB) followed by a real frame: the real
    # frame comes out at once instead of after 130 kB more bytes.
    fake = bytes([0xAA, 0x55, 1, 255, 255, 0]) + bytes(8)
    real = encode_frame(9, 0, np.ones((16, 16), np.uint16))
    parser = FrameParser()
    assert [f.seq for f in parser.feed(fake + real)] == [9]


def test_sequence_wrap_is_not_a_gap_and_restart_is_not_counted():
    parser = FrameParser()
    v = np.zeros((1, 1), np.uint16)
    parser.feed(encode_frame(2**32 - 1, 0, v) + encode_frame(0, 0, v) + encode_frame(2, 0, v))
    assert parser.gaps == 1
    parser.feed(encode_frame(0, 0, v))  # device restarted
    assert parser.gaps == 1


def test_text_lines_malformed_rejected():
    parser = FrameParser(protocol="text")
    data = b"1,2,3,4,5,6\nx,1,2\n2,3,-1,2,3,4\n3,4,1,2,3\n4,5,70000,1,1,1\n5,6,7,8,9,10\r\n"
    got = parser.feed(data)
    assert [f.seq for f in got] == [1, 5]
    assert got[0].values.tolist() == [[3, 4], [5, 6]]
    assert parser.bad_lines == 3 and parser.size_errors == 1 and parser.gaps == 3


def _frames_strategy():
    return st.lists(
        st.tuples(
            st.integers(0, 2**32 - 1),
            st.integers(0, 2**32 - 1),
            st.integers(1, 4),
            st.integers(1, 4),
            st.integers(0, 2**16 - 1),
        ),
        min_size=1,
        max_size=6,
    )


@settings(max_examples=300, deadline=None)
@given(
    st.binary(max_size=2000),
    st.sampled_from(["binary", "text"]),
    st.sampled_from([None, (2, 3)]),
    st.lists(st.integers(1, 50), max_size=10),
)
def test_fuzz_arbitrary_bytes_never_raise(data, protocol, shape, cuts):
    rows, cols = shape if shape else (None, None)
    parser = FrameParser(rows, cols, protocol=protocol)
    pos = 0
    for n in cuts + [len(data)]:
        frames = parser.feed(data[pos : pos + n])
        pos += n
        for f in frames:
            assert f.values.dtype == np.uint16 and f.values.ndim == 2
    assert parser.bytes_skipped <= len(data)


@settings(max_examples=300, deadline=None)
@given(_frames_strategy(), st.lists(st.binary(max_size=40), min_size=7, max_size=7), st.data())
def test_fuzz_valid_frames_split_anywhere_with_garbage_between(specs, garbage, data):
    encoded, expected = [], []
    for seq, t_us, rows, cols, seed in specs:
        values = np.random.default_rng(seed).integers(0, 65536, size=(rows, cols)).astype(np.uint16)
        encoded.append(encode_frame(seq, t_us, values))
        expected.append((seq, t_us, values))
    stream = b"".join(g + f for g, f in zip(garbage, encoded)) + garbage[-1]
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=20)))
    parser = FrameParser()
    got = []
    for a, b in zip([0] + cuts, cuts + [len(stream)]):
        got += parser.feed(stream[a:b])
    assert len(got) == len(expected)
    for frame, (seq, t_us, values) in zip(got, expected):
        assert (frame.seq, frame.t_us) == (seq, t_us)
        assert np.array_equal(frame.values, values)


@settings(max_examples=200, deadline=None)
@given(
    _frames_strategy(),
    st.lists(
        st.binary(max_size=30).filter(lambda g: b"\n" not in g and g.strip(b"0123456789,\r")), min_size=7, max_size=7
    ),
    st.data(),
)
def test_fuzz_text_frames_split_anywhere_with_garbage_lines_between(specs, garbage, data):
    encoded, expected = [], []
    for seq, t_us, _, _, seed in specs:
        values = np.random.default_rng(seed).integers(0, 65536, size=(2, 2)).astype(np.uint16)
        encoded.append(encode_text_frame(seq, t_us, values))
        expected.append((seq, values))
    stream = b"".join(g + b"\n" + f for g, f in zip(garbage, encoded))
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=20)))
    parser = FrameParser(protocol="text")
    got = []
    for a, b in zip([0] + cuts, cuts + [len(stream)]):
        got += parser.feed(stream[a:b])
    assert [(f.seq, f.values.tolist()) for f in got] == [(s, v.tolist()) for s, v in expected]
