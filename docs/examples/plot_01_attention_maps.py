"""
Attention maps of the cow
=========================

The attention model looks at a mesh from 72 viewpoints (18 sets of 4 views, 90 degrees apart) and
computes eight conspicuity maps for each view: intensity, colour opponency, orientation, DKL colour,
mirror symmetry, curvature (mesh saliency), entropy and contrast.  Their equal-weight sum, masked to
the object, is the view's saliency map.

Here on the embedded toy cow, painted with patches like the paper's textured cow; a mesh file
(``meshsal.load_mesh("spot.obj")``, textured OBJ, PLY, OFF or STL) goes through the same calls.
"""

import matplotlib.pyplot as plt
import numpy as np

from meshsal.attention import CHANNELS, attention_maps, view_channels
from meshsal.objects import toys
from meshsal.views.overlay import contact_sheet, saliency_overlay

mesh = toys.make("cow")
extent = np.ptp(mesh.vertices, axis=0)
print(f"{mesh.name}: {mesh.n_vertices} vertices, {mesh.n_faces} faces, {extent.round(1)} mm")

# %%
# Render the rig once and compute every view's channels once; :func:`~meshsal.attention.attention_maps`
# then combines them as a method asks (the paper's equal weights here, ``"itti"`` for Itti's N(.)).
seen = view_channels(mesh, size=128)
maps = attention_maps(seen)
print(f"{len(seen.views)} views, maps {maps.shape} {maps.dtype}")

# %%
# One view: what the renderer sees, the eight channels, and their combination.
k = 1
view, channels = seen.views[k], seen.results[k].channels
fig, axes = plt.subplots(2, 5, figsize=(11, 4.6))
panels = [("rendered", view.rgb)] + [(name, channels[name]) for name in CHANNELS]
panels.append(("saliency", saliency_overlay(view.rgb, maps[k], view.mask)))
for ax, (title, image) in zip(axes.flat, panels):
    ax.imshow(image, cmap="turbo", vmin=0, vmax=1)
    ax.set_title(title, fontsize=9)
    ax.axis("off")
fig.tight_layout()

# %%
# All 72 saliency maps, set by set (a row holds three sets of four views).
sheet = contact_sheet(maps, [v.mask for v in seen.views], columns=12)
fig, ax = plt.subplots(figsize=(11, 5.6))
ax.imshow(sheet)
ax.axis("off")
fig.tight_layout()
