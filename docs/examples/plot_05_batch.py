"""
A batch of meshes
=================

:func:`classify.run_batch` computes, for every mesh file under a folder, its interest points by
each method and their simulated imprints, one task per mesh, into a store that a rerun extends
(``visuotactile batch DIR --out store/`` on the command line, on a Dask cluster with ``--workers``
or ``--scheduler``).  Here: four small shapes written as PLY files to a temporary folder, in this
process.
"""

import tempfile
from pathlib import Path

import matplotlib.pyplot as plt

import classify
from meshsal import Mesh, save_ply
from meshsal.objects import sdf
from tactile.picture import imprint_grid

shapes = {
    "ball": lambda P: sdf.sphere(P, [0, 0, 0], 40.0),
    "box": lambda P: sdf.round_box(P, [0, 0, 0], [45.0, 30.0, 20.0], rounding=4.0),
    "ring": lambda P: sdf.torus(P, [0, 0, 0], 40.0, 12.0),
    "capsule": lambda P: sdf.capsule(P, [-40, 0, 0], [40, 0, 0], 18.0),
}
folder = Path(tempfile.mkdtemp())
(folder / "meshes").mkdir()
for name, field in shapes.items():
    V, F = sdf.mesh_field(field, lo=[-60, -60, -60], hi=[60, 60, 60], spacing=4.0)
    save_ply(folder / "meshes" / f"{name}.ply", Mesh(V, F, name=name))
    print(f"{name}.ply: {len(V)} vertices, {len(F)} faces")

# %%
# One call runs them all; the summary says what was done, skipped and failed.
summary = classify.run_batch(folder / "meshes", folder / "store", quiet=True)
print(f"{summary.done} done, {summary.skipped} skipped, {summary.failed} failed")

# %%
# A second run finds every entry up to date and skips it.
again = classify.run_batch(folder / "meshes", folder / "store", quiet=True)
print(f"{again.done} done, {again.skipped} skipped, {again.failed} failed")

# %%
# :func:`classify.load_store` reads the store back: per mesh and method, ``meshsal.InterestPoints`` and a
# ``tactile.ImprintSet``.  The first five attention points' imprints of each shape:
store = classify.load_store(folder / "store")
fig, axes = plt.subplots(len(store), 1, figsize=(7, 2.1 * len(store)))
for ax, (name, entry) in zip(axes, store.items()):
    images = entry.imprints["attention"].imprints[:5]
    ax.imshow(imprint_grid(images, captions=[f"{name} {i + 1}" for i in range(len(images))], scale=5))
    ax.axis("off")
fig.tight_layout()
