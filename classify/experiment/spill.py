"""Instance places kept on disk while a block's stages run: the run holds paths, each job reads what it uses.

With touch policies or the place-aware recognizer every instance has
places, and a training instance's have touch codebooks: about 150 kB an
instance, gigabytes at a thousand objects.  Held in memory, the main
process keeps all of them for the block, and each worker that fits a
replicate keeps a second copy of that replicate's.  With local worker
processes or a LocalCluster (``classify.runtime.cluster.shares_disk``)
each instance task writes its places to a folder of the block
(:func:`stored`) and hands back a :class:`StoredPlaceSample`, a path.  Jobs
carry the paths; fitting reads one instance's arrays at a time (the
samples' ``in_memory``), so neither the main process nor a worker holds a
replicate's places whole.  On a Dask cluster by address they stay in
memory: its workers may not share this machine's disk.
"""

from __future__ import annotations

import dataclasses
import os
import tempfile
from dataclasses import dataclass

import numpy as np

from classify.policies import PackedPlaceSample, Places, PlaceSample
from meshsal.util.npzfile import read_npz

__all__ = ["StoredPlaceSample", "stored"]


@dataclass(frozen=True)
class StoredPlaceSample:
    """A :class:`~classify.policies.PlaceSample` written by :func:`stored`, read on use.

    Every attribute of a place sample reads the file again: code that reads
    several takes :meth:`in_memory` once.

    Attributes
    ----------
    path : str, the ``.npz`` file
    with_codebook : bool, whether :meth:`in_memory` reads the codebook the file may hold
    """

    path: str
    with_codebook: bool = True

    def in_memory(self) -> PlaceSample | PackedPlaceSample:
        """The sample, read from the file (packed when it was written packed)."""
        a = read_npz(self.path, "stored instance places")
        places = Places.from_arrays(a)
        book = a.get("codebook") if self.with_codebook else None
        if "codes" in a:
            return PackedPlaceSample(places, a["codes"], book)
        return PlaceSample(places, a["imprints"], book)

    def without_codebook(self) -> StoredPlaceSample:
        """This sample, read without its codebook."""
        return dataclasses.replace(self, with_codebook=False)

    def unpacked(self) -> PlaceSample:
        return self.in_memory().unpacked()

    def to_arrays(self) -> dict:
        return self.in_memory().to_arrays()

    @property
    def places(self) -> Places:
        return self.in_memory().places

    @property
    def imprints(self) -> np.ndarray:
        return self.in_memory().imprints

    @property
    def codebook(self) -> np.ndarray | None:
        return self.in_memory().codebook

    @property
    def landmarks(self) -> np.ndarray:
        return self.in_memory().landmarks


def stored(sample: PlaceSample | PackedPlaceSample, folder) -> StoredPlaceSample:
    """Write ``sample`` (packed imprints stay packed) to a new file in ``folder``; its :class:`StoredPlaceSample`.

    Examples
    --------
    >>> import tempfile
    >>> from classify.policies import PlaceSample, Places
    >>> p = Places(np.arange(2), np.zeros((2, 3)), np.ones((2, 3)), np.zeros((2, 1)), np.ones(2, bool))
    >>> s = stored(PlaceSample(p, np.full((1, 2, 4, 4), 0.5, np.float32)), tempfile.mkdtemp())
    >>> s.imprints.shape, s.places.touchable.tolist()
    ((1, 2, 4, 4), [True, True])
    """
    arrays = sample.places.to_arrays()
    if isinstance(sample, PackedPlaceSample):
        arrays["codes"] = sample.codes
    else:
        arrays["imprints"] = sample.imprints
    if sample.codebook is not None:
        arrays["codebook"] = sample.codebook
    handle, path = tempfile.mkstemp(suffix=".npz", dir=folder)
    try:
        with os.fdopen(handle, "wb") as f:
            np.savez(f, **arrays)
    except BaseException:
        os.unlink(path)  # no half-written file left for a job to read
        raise
    return StoredPlaceSample(path)
