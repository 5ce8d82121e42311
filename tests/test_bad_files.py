"""Damaged and hostile files: every reader refuses them by name within its caps, and the CLI says so.

The files are built here: zip members with hand-made ``.npy`` headers, deflate
streams with flipped bytes, zip directories that lie about sizes, JSON nested
100,000 deep, a 5000-digit integer.
"""

import json
import re
import tracemalloc
import zipfile

import numpy as np
import pytest
import shapes

import tactile
from meshsal.util.jsonfile import parse_json, read_json
from meshsal.util.npzfile import NpzError, read_npz


def npy_header(shape, descr="<f8", fortran=False) -> bytes:
    """A version 1.0 ``.npy`` header, as numpy writes it."""
    text = repr({"descr": descr, "fortran_order": fortran, "shape": tuple(shape)})
    text += " " * (63 - (len(text) + 10) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + len(text).to_bytes(2, "little") + text.encode("latin1")


def write_zip(path, members: dict, compression=zipfile.ZIP_DEFLATED):
    with zipfile.ZipFile(path, "w", compression) as archive:
        for name, data in members.items():
            archive.writestr(name, data)
    return path


def declare_size(path, size: int):
    """Make a one-member zip's directory and local header claim ``size`` inflated bytes."""
    data = bytearray(path.read_bytes())
    local, central = data.index(b"PK\x03\x04"), data.index(b"PK\x01\x02")
    data[local + 22 : local + 26] = size.to_bytes(4, "little")
    data[central + 24 : central + 28] = size.to_bytes(4, "little")
    path.write_bytes(bytes(data))


def flip(path, start: int, stop: int):
    data = bytearray(path.read_bytes())
    for i in range(start, stop):
        data[i] ^= 0xA5
    path.write_bytes(bytes(data))


def peak_bytes(function, *args, **kwargs):
    """Peak of traced allocations (numpy's included) while ``function`` runs, and its exception."""
    tracemalloc.start()
    try:
        function(*args, **kwargs)
    except Exception as exc:  # noqa: BLE001 - returned to the test
        error = exc
    else:
        error = None
    finally:
        peak = tracemalloc.get_traced_memory()[1]
        tracemalloc.stop()
    return peak, error


# ---------------------------------------------------------------- read_npz: what numpy wrote reads back


def test_read_npz_gives_what_np_load_gives(tmp_path):
    arrays = {
        "c": np.arange(24.0).reshape(2, 3, 4),
        "f": np.asfortranarray(np.arange(6).reshape(2, 3)),
        "meta": np.array(json.dumps({"format": "x"})),
        "empty": np.zeros((0, 16, 16), np.float32),
        "rec": np.ones(3, dtype=[("a", "<f4"), ("b", ">i2")]),
        "flag": np.array(True),
    }
    for save in (np.savez, np.savez_compressed):
        path = tmp_path / f"{save.__name__}.npz"
        save(path, **arrays)
        back = read_npz(path, "test archive")
        with np.load(path) as reference:
            assert list(back) == reference.files
            for name in reference.files:
                assert back[name].dtype == reference[name].dtype and back[name].shape == reference[name].shape
                np.testing.assert_array_equal(back[name], reference[name])
                assert back[name].flags.writeable


# ---------------------------------------------------------------- read_npz: caps before allocating or inflating


def test_a_header_declaring_a_huge_array_is_refused_without_allocating_it(tmp_path):
    path = write_zip(tmp_path / "huge.npz", {"x.npy": npy_header((10**12,))})
    peak, error = peak_bytes(read_npz, path, "cache entry")
    assert isinstance(error, NpzError) and error.path == path
    assert re.search(
        r"huge.npz: cache entry too large: 'x' is \(1000000000000,\) float64 = 7.3 TiB, more than "
        r"the cap of 256.0 MiB per array",
        str(error),
    ), error
    assert peak < 1 << 20


def test_arrays_are_capped_one_by_one_and_together(tmp_path):
    path = tmp_path / "two.npz"
    np.savez(path, a=np.zeros(1000), b=np.zeros(1000))  # 8000 bytes each
    assert len(read_npz(path, "x", max_bytes=16000, max_array_bytes=8000)) == 2
    with pytest.raises(NpzError, match="'a' is .* more than the cap of 7.8 KiB per array"):
        read_npz(path, "x", max_array_bytes=7999)
    with pytest.raises(NpzError, match="more than the cap of 15.6 KiB"):
        read_npz(path, "x", max_bytes=15999)


def test_a_zip_bomb_is_stopped_by_the_declared_size_before_inflating(tmp_path):
    path = write_zip(tmp_path / "bomb.npz", {"x.npy": npy_header((2_500_000,)) + bytes(20_000_000)})
    assert path.stat().st_size < 25_000  # 20 MB of zeros in 20 kB
    assert read_npz(path, "x")["x"].shape == (2_500_000,)  # under the default caps: fine
    peak, error = peak_bytes(read_npz, path, "imprint set", max_bytes=1 << 20)
    assert isinstance(error, NpzError) and "members declare 19.1 MiB inflated, more than the cap" in str(error)
    assert peak < 1 << 20


def test_a_bomb_whose_zip_sizes_lie_is_never_inflated_past_its_header(tmp_path):
    # The header says 10 float64, the zip says 208 bytes, the stream inflates to 20 MB.
    path = write_zip(tmp_path / "liar.npz", {"x.npy": npy_header((10,)) + bytes(20_000_000)})
    declare_size(path, 128 + 80)
    peak, error = peak_bytes(read_npz, path, "imprint set")
    assert isinstance(error, NpzError) and str(error).startswith(f"{path}: damaged"), error
    assert peak < 1 << 20
    # The header says 10 float64, the zip admits the truth: the extra bytes are refused, not skipped.
    path = write_zip(tmp_path / "long.npz", {"x.npy": npy_header((10,)) + bytes(20_000_000)})
    peak, error = peak_bytes(read_npz, path, "imprint set")
    assert isinstance(error, NpzError) and "'x' holds more bytes than its shape (10,) float64" in str(error)
    assert peak < 1 << 20


def test_python_objects_are_never_unpickled(tmp_path):
    marker = tmp_path / "unpickled"

    class Trap:
        def __reduce__(self):
            return (open, (str(marker), "w"))

    import pickle

    path = write_zip(tmp_path / "objects.npz", {"x.npy": npy_header((1,), "|O") + pickle.dumps([Trap()])})
    with pytest.raises(NpzError, match=r"objects.npz: not a batch entry: 'x' holds Python objects \(dtype object\)"):
        read_npz(path, "batch entry")
    assert not marker.exists()


# ---------------------------------------------------------------- read_npz: every damage is one error naming the file


def small_archive(path, save=np.savez_compressed):
    save(path, x=np.random.default_rng(0).random(20), meta=np.array('{"format": "t"}'))
    return path


@pytest.mark.parametrize("save", [np.savez, np.savez_compressed])
def test_every_truncation_is_an_npz_error_naming_the_file(tmp_path, save):
    whole = small_archive(tmp_path / "whole.npz", save).read_bytes()
    path = tmp_path / "cut.npz"
    for n in range(len(whole)):
        path.write_bytes(whole[:n])
        with pytest.raises(NpzError, match=rf"^{re.escape(str(path))}: (damaged|not a)") as caught:
            read_npz(path, "test archive")
        assert caught.value.path == path


@pytest.mark.parametrize("save", [np.savez, np.savez_compressed])
def test_every_flipped_byte_is_an_npz_error_or_harmless(tmp_path, save):
    whole = small_archive(tmp_path / "whole.npz", save).read_bytes()
    x = np.random.default_rng(0).random(20)
    path = tmp_path / "flipped.npz"
    harmless = []
    for i in range(len(whole)):
        data = bytearray(whole)
        data[i] ^= 0x5A
        path.write_bytes(bytes(data))
        try:
            back = read_npz(path, "test archive")
        except NpzError as error:
            assert str(error).startswith(f"{path}: ")
        else:  # a timestamp, an attribute, an unchecked field: same arrays
            harmless.append(i)
            np.testing.assert_array_equal(back["x"], x)
    assert len(harmless) < len(whole) // 3
    if save is np.savez:  # stored, not deflated: every flip of the array's bytes is caught
        start = whole.index(x.tobytes())
        assert not [i for i in harmless if start <= i < start + x.nbytes]


def test_a_corrupted_deflate_stream_names_the_file(tmp_path):
    path = write_zip(tmp_path / "deflate.npz", {"x.npy": npy_header((4000,)) + np.arange(4000.0).tobytes()})
    flip(path, 400, 440)
    with pytest.raises(NpzError, match=r"deflate.npz: damaged or truncated imprint set \((zlib.error|Bad CRC)"):
        read_npz(path, "imprint set")


def test_foreign_files_are_refused_by_name(tmp_path):
    (tmp_path / "text.npz").write_text("hello")
    np.save(tmp_path / "bare.npy", np.zeros(3))
    write_zip(tmp_path / "docs.npz", {"readme.txt": b"hi"})
    (tmp_path / "folder.npz").mkdir()
    cases = {
        "text.npz": "not an imprint set: not an .npz (zip) archive",
        "bare.npy": "not an imprint set: a bare .npy array, not an .npz archive",
        "docs.npz": "not an imprint set: member 'readme.txt' is not a NumPy array (.npy)",
        "folder.npz": "not an imprint set: a directory",
    }
    for name, problem in cases.items():
        with pytest.raises(NpzError) as caught:
            read_npz(tmp_path / name, "imprint set")
        assert str(caught.value) == f"{tmp_path / name}: {problem}"
    with pytest.raises(FileNotFoundError, match="missing.npz: imprint set not found"):
        read_npz(tmp_path / "missing.npz", "imprint set")


# ---------------------------------------------------------------- JSON: size, nesting, long integers


def test_json_nested_100000_deep_is_refused_before_parsing(tmp_path):
    path = tmp_path / "deep.json"
    path.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(
        ValueError,
        match=r"deep.json: not a valid points file: arrays and objects nested more "
        r"than 100 deep",
    ):
        read_json(path, "points file")
    path.write_text('{"a": ' * 100_000 + "1" + "}" * 100_000)
    with pytest.raises(ValueError, match="deep.json: .* nested more than 100 deep"):
        read_json(path, "points file")


def test_the_nesting_cap_is_exact_and_ignores_brackets_in_strings(tmp_path):
    path = tmp_path / "d.json"
    path.write_text("[" * 100 + "]" * 100)
    assert read_json(path, "x") is not None
    path.write_text("[" * 101 + "]" * 101)
    with pytest.raises(ValueError, match="nested more than 100 deep"):
        read_json(path, "x")
    tricky = {"a": ["[[[[", '\\"{{{{', "\\", '"]]]]'], "b": "[" * 500, "é": "{" * 500}
    text = json.dumps(tricky, ensure_ascii=False)
    assert parse_json(text, "t.json", "x", max_depth=2) == tricky
    with pytest.raises(ValueError, match="t.json: not a valid x: arrays and objects nested more than 1 deep"):
        parse_json(text, "t.json", "x", max_depth=1)


def test_a_5000_digit_integer_names_the_file(tmp_path):
    path = tmp_path / "long.json"
    path.write_text('{"points": [{"id": ' + "7" * 5000 + "}]}")
    with pytest.raises(ValueError, match=r"long.json: not a valid points file: an integer of more than \d+ digits"):
        read_json(path, "points file")


def test_json_larger_than_the_cap_is_refused_before_it_is_read(tmp_path):
    path = tmp_path / "big.json"
    path.write_text(json.dumps(list(range(30))))
    size = path.stat().st_size
    assert read_json(path, "x", max_bytes=size) == list(range(30))
    with pytest.raises(ValueError, match=rf"big.json: not a valid x: larger than the cap of {size - 1} bytes"):
        read_json(path, "x", max_bytes=size - 1)


def test_a_file_without_a_size_is_read_no_further_than_the_cap():
    with pytest.raises(ValueError, match="^/dev/zero: not a valid x: larger than the cap of 1000 bytes$"):
        read_json("/dev/zero", "x", max_bytes=1000)  # stat says 0 bytes; it never ends


# ---------------------------------------------------------------- every reader, and the command line

DEEP = "[" * 100_000 + "]" * 100_000
LONG_INTEGER = '{"format": "x", "n": ' + "9" * 5000 + "}"


def _cli(argv, capsys):
    from classify.cli import main

    status = main(argv)
    return status, capsys.readouterr().err


@pytest.mark.parametrize(
    "content,problem",
    [(DEEP, "arrays and objects nested more than 100 deep"), (LONG_INTEGER, "an integer of more than")],
)
def test_imprints_refuses_a_hostile_points_file_by_name(tmp_path, capsys, content, problem):
    shapes.write_obj(tmp_path / "ball.obj", shapes.sphere(radius=1.0, n=4))
    points = tmp_path / "points.json"
    points.write_text(content)
    out = tmp_path / "set.npz"
    status, err = _cli(["imprints", str(tmp_path / "ball.obj"), "--points", str(points), "--out", str(out)], capsys)
    assert status == 1
    assert f"visuotactile imprints: error: {points}: not a valid points file: {problem}" in err
    assert not out.exists()


@pytest.mark.parametrize(
    "content,problem",
    [(DEEP, "arrays and objects nested more than 100 deep"), (LONG_INTEGER, "an integer of more than")],
)
def test_points_refuses_a_hostile_touch_model_by_name(tmp_path, capsys, content, problem):
    model = tmp_path / "model.json"
    model.write_text(content)
    status, err = _cli(
        ["points", "cup", "--method", "learned", "--model", str(model), "--quiet", "--out", str(tmp_path / "o")], capsys
    )
    assert status == 1
    assert f"visuotactile points: error: {model}: not a valid touch model file: {problem}" in err
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "error,message",
    [
        (MemoryError(), "out of memory (MemoryError)"),
        (
            RecursionError("maximum recursion depth exceeded"),
            "recursion too deep (RecursionError: maximum recursion depth exceeded)",
        ),
    ],
)
def test_the_command_line_turns_recursion_and_memory_errors_into_a_message(
    tmp_path, capsys, monkeypatch, error, message
):
    def fail(path):
        raise error

    monkeypatch.setattr(tactile.ImprintSet, "load", fail)
    status, err = _cli(["experiment", "--real", str(tmp_path / "x.npz"), "--out", str(tmp_path / "o")], capsys)
    assert (status, err) == (1, f"visuotactile experiment: error: {message}\n")


def imprint_set(path):
    rng = np.random.default_rng(0)
    tactile.ImprintSet(
        imprints=rng.random((6, 16, 16)),
        labels=[0, 0, 0, 1, 1, 1],
        object_names=("a", "b"),
        point_ids=[0, 1, 2, 0, 1, 2],
        positions=np.zeros((6, 3)),
        normals=[[0, 0, 1.0]] * 6,
        sensor=tactile.Sensor(),
    ).save(path)
    return path


def _truncate(path):
    path.write_bytes(path.read_bytes()[:-200])


def _deflate(path):
    size = path.stat().st_size
    flip(path, size // 3, size // 3 + 16)


def _huge(path):
    write_zip(
        path,
        {
            "meta.npy": npy_header((), "<U20") + "x".encode("utf-32-le") * 20,
            "imprints.npy": npy_header((10**9, 16, 16), "<f4"),
        },
    )


def _deep_meta(path):
    np.savez(path, meta=np.array(DEEP))


DAMAGE = {
    "truncated": (_truncate, "damaged or truncated imprint set"),
    "corrupt deflate": (_deflate, "damaged or truncated imprint set"),
    "huge header": (_huge, "imprint set too large: 'imprints' is (1000000000, 16, 16) float32 = 953.7 GiB"),
    "deep meta": (_deep_meta, "not a valid imprint set: arrays and objects nested more than 100 deep"),
}


@pytest.mark.parametrize("damage", DAMAGE, ids=list(DAMAGE))
def test_experiment_real_refuses_a_damaged_imprint_set_by_name(tmp_path, capsys, damage):
    spoil, problem = DAMAGE[damage]
    path = imprint_set(tmp_path / "real.npz")
    spoil(path)
    status, err = _cli(["experiment", "--real", str(path), "--out", str(tmp_path / "out"), "--quiet"], capsys)
    assert status == 1
    assert f"visuotactile experiment: error: {path}: {problem}" in err, err


@pytest.mark.parametrize("damage", DAMAGE, ids=list(DAMAGE))
def test_load_store_refuses_a_damaged_entry_by_name(tmp_path, damage):
    from classify import batch

    spoil, problem = DAMAGE[damage]
    store = tmp_path / "store"
    (store / "meshes").mkdir(parents=True)
    (store / "store.json").write_text(json.dumps({"format": batch.FORMAT, "version": batch.VERSION}))
    entry = imprint_set(store / "meshes" / "ball.npz")
    spoil(entry)
    with pytest.raises(ValueError) as caught:
        batch.load_store(store)
    assert str(caught.value).startswith(f"{entry}: ")
    assert problem.replace("imprint set", "batch entry") in str(caught.value)


def test_load_store_refuses_an_entry_of_another_kind_or_missing_fields(tmp_path):
    from classify import batch

    store = tmp_path / "store"
    (store / "meshes").mkdir(parents=True)
    (store / "store.json").write_text("{}")
    entry = imprint_set(store / "meshes" / "ball.npz")
    with pytest.raises(ValueError, match=rf"{re.escape(str(entry))}: not a version 1 batch entry"):
        batch.load_store(store)
    np.savez(entry, meta=np.array(json.dumps({"format": batch.ENTRY_FORMAT, "version": batch.VERSION})))
    with pytest.raises(ValueError, match=rf"{re.escape(str(entry))}: damaged batch entry \(KeyError: 'source'\)"):
        batch.load_store(store)
