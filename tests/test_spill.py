"""Instance places waiting on disk for their jobs: the same samples back, the same results, nothing left behind."""

import os

import numpy as np
import pytest
import quick
import shapes
from quick import QUICK

from classify.experiment import place as place_mod
from classify.experiment.spill import StoredPlaceSample, stored
from classify.policies import PackedPlaceSample, Places, PlaceSample
from classify.runtime.cluster import FilePool, Inline, open_executor, shares_disk
from meshsal.util.npzfile import NpzError


def _sample(rng, codebook=True):
    P = 5
    places = Places(
        rng.integers(0, 100, P),
        rng.normal(size=(P, 3)),
        rng.normal(size=(P, 3)),
        rng.normal(size=(P, 4)),
        rng.random(P) < 0.6,
    )
    readings = (rng.integers(0, 256, (1, P, 16, 16)) / 255).astype(np.float32)
    book = rng.normal(size=(P, 3, 42)).astype(np.float32) if codebook else None
    return PlaceSample(places, readings, book)


def _same(a, b):
    for name in ("vertex_ids", "positions", "normals", "features", "touchable"):
        x, y = getattr(a.places, name), getattr(b.places, name)
        assert x.dtype == y.dtype and np.array_equal(x, y), name
    assert np.array_equal(a.imprints, b.imprints) and a.imprints.dtype == b.imprints.dtype
    assert (a.codebook is None) == (b.codebook is None)
    if a.codebook is not None:
        assert np.array_equal(a.codebook, b.codebook) and a.codebook.dtype == b.codebook.dtype


@pytest.mark.parametrize("packed", [True, False])
def test_a_stored_sample_reads_back_bit_for_bit_packed_as_it_was_written(tmp_path, packed):
    rng = np.random.default_rng(3)
    sample = _sample(rng)
    if packed:
        sample = sample.packed()
        assert isinstance(sample, PackedPlaceSample)
    else:
        sample = PlaceSample(sample.places, sample.imprints + 1e-3, sample.codebook)  # off the ADC's grid
    s = stored(sample, tmp_path)
    assert isinstance(s.in_memory(), type(sample))
    _same(s.in_memory(), sample)
    _same(s.unpacked(), sample.unpacked())
    assert np.array_equal(s.landmarks, sample.landmarks)
    assert s.without_codebook().codebook is None and sample.without_codebook().codebook is None
    assert s.to_arrays().keys() == sample.to_arrays().keys()
    plain = stored(_sample(rng, codebook=False), tmp_path)
    assert plain.codebook is None and plain.in_memory().codebook is None


def test_a_damaged_stored_sample_stops_with_its_file_named(tmp_path):
    s = stored(_sample(np.random.default_rng(0)).packed(), tmp_path)
    with open(s.path, "r+b") as f:
        f.truncate(100)
    with pytest.raises(NpzError, match=s.path.rsplit("/", 1)[-1]):
        s.in_memory()


def _objects():
    return [shapes.box(half=40.0, n=20).replace(name="box"), shapes.sphere(radius=50.0, n=24).replace(name="ball")]


#: The place-aware jobs' places, as :func:`_spy` saw them (a module's function: a file pool pickles its tasks).
SEEN = []
_PLACE_JOB = place_mod.place_job


def _spy(job):
    SEEN.append(list(job.training.values()) + list(job.tests))
    return _PLACE_JOB(job)


def test_places_wait_on_disk_for_their_jobs_give_the_results_of_places_in_memory_and_go_with_their_run(
    tmp_path, monkeypatch
):
    config = QUICK.replace(
        methods=("uniform",),
        protocols=("instance",),
        classifiers=("knn", "place"),
        policies=("info_gain",),
        replicates=2,
    )
    seen = SEEN
    seen.clear()
    monkeypatch.setattr(place_mod, "place_job", _spy)
    # Local processes, as the command line's default pool hands them tasks (here run in this process, so that
    # the spy sees the jobs): the places wait on disk.
    (tmp_path / "tasks").mkdir()
    pool = FilePool(Inline(), tmp_path / "tasks")
    quick.run(_objects(), config, out_dir=tmp_path / "disk", executor=pool, replicates_at_once=1)
    on_disk = [s for job in seen for s in job]
    assert len(seen) == 2 and all(isinstance(s, StoredPlaceSample) for s in on_disk)
    assert len({s.path for s in on_disk}) == len(on_disk) == 2 * 2 * 3  # replicates x objects x instances
    folders = {s.path.rsplit("/", 2)[0] for s in on_disk}
    assert len(folders) == 1 and not any(os.path.exists(f) for f in folders)

    # An executor whose workers may run elsewhere (a Dask cluster's): in memory.
    class Elsewhere:
        map = Inline.map

    seen.clear()
    quick.run(_objects(), config, out_dir=tmp_path / "memory", executor=Elsewhere(), replicates_at_once=1)
    assert all(isinstance(s, PackedPlaceSample) for job in seen for s in job)
    # A LocalCluster's worker reads the places this process's run writes, as a local process does.
    monkeypatch.undo()  # the spy is this process's
    with open_executor(workers=1) as executor:
        assert shares_disk(executor)
        quick.run(_objects(), config, out_dir=tmp_path / "cluster", executor=executor, replicates_at_once=1)
    for name in ("results.csv", "stopping.csv"):
        disk = (tmp_path / "disk" / name).read_bytes()
        assert disk == (tmp_path / "memory" / name).read_bytes() == (tmp_path / "cluster" / name).read_bytes(), name
