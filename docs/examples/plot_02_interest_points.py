"""
Interest points on the cow
==========================

:func:`meshsal.interest_points` runs the paper's pipeline: the best set of four views by average
saliency, the salient peaks mapped onto the mesh exactly, ranked by how many of the 72 views agree,
and the first 15 that a pad pressed along the normal touches first, at least half a pad apart.
The baselines (``"uniform"``, ``"random"``, ``"mesh_saliency"``, ``"curvature"``) keep the same rules,
so whether vision helps is measurable.
"""

import matplotlib.pyplot as plt
import numpy as np

import meshsal
from meshsal.attention import attention_maps, view_channels
from meshsal.objects import toys
from meshsal.views.overlay import views_picture

mesh = toys.make("cow")

# %%
# ``meshsal.interest_points(mesh)`` does everything for one method.  For several methods on one
# mesh, :func:`~meshsal.points_by_method` shares one rendering; here it is passed the views and
# channels computed beforehand, which the picture below reuses.
seen = view_channels(mesh, size=128)
every = meshsal.points_by_method(mesh, ["attention", "uniform"], seen=seen)
points = every["attention"]
print(f"{len(points)} points by {points.method!r}, best view set {points.best_set}, ")
print(f"at least {points.min_spacing:.1f} mm apart; votes of the first five: {points.votes[:5].tolist()}")
print(f"{points.untouchable} candidates skipped: the pad would have met the cow elsewhere first")

# %%
# The best set's four views with their saliency and the points each one sees, numbered best first.
best = range(4 * points.best_set, 4 * points.best_set + 4)
picture = views_picture(seen.views, attention_maps(seen), best, points.positions)
fig, ax = plt.subplots(figsize=(8, 8))
ax.imshow(picture)
ax.axis("off")
fig.tight_layout()

# %%
# The same number of points by attention and by farthest-point sampling, the cow seen from its side:
# attention takes them where the maps peak; the baseline spreads them evenly over the surface.
fig, axes = plt.subplots(1, 2, figsize=(10, 4.2), sharex=True, sharey=True)
for ax, (method, chosen) in zip(axes, every.items()):
    ax.scatter(mesh.vertices[::5, 2], mesh.vertices[::5, 1], s=0.2, c="0.8")
    ax.scatter(chosen.positions[:, 2], chosen.positions[:, 1], c=np.arange(len(chosen)), cmap="viridis", s=40)
    for i, (z, y) in enumerate(chosen.positions[:, [2, 1]], start=1):
        ax.annotate(str(i), (z, y), textcoords="offset points", xytext=(3, 3), fontsize=7)
    ax.set_title(method)
    ax.set_aspect("equal")
    ax.set_xlabel("z (mm)")
axes[0].set_ylabel("y (mm)")
fig.tight_layout()
