"""
Imprints: what the pad feels
============================

A simulated 16 x 16 force-resistive array, 2 mm between taxels, pressed 3 mm into the surface at each
point along its normal.  In the paper's ``"contour"`` mode, four planes parallel to the pad slice
the surface at a quarter, half, three quarters and all of the press depth, and each contour is
drawn at its own grey level; ``"pressure"`` fills in how deep the surface reaches into the pad,
which is what a real array reports.  :func:`tactile.acquire` adds what a robot and an ADC add.
"""

import matplotlib.pyplot as plt

import meshsal
import tactile
from meshsal.objects import toys
from tactile.picture import imprint_grid

mesh = toys.make("cow")
points = meshsal.interest_points(mesh, n=10)
sensor = tactile.Sensor()
print(f"pad {sensor.rows} x {sensor.cols} taxels, {sensor.width_mm} mm wide, pressed {sensor.depth_mm} mm")

# %%
# The ten attention points of the cow, touched in both modes.
contour = tactile.imprints(mesh, points.positions, points.normals, sensor)
pressure = tactile.imprints(mesh, points.positions, points.normals, tactile.Sensor(mode="pressure"))
print(f"imprints {contour.shape} {contour.dtype}, readings in [{contour.min():.0f}, {contour.max():.0f}]")

fig, axes = plt.subplots(2, 1, figsize=(9, 8))
for ax, (title, images) in zip(axes, (("contour", contour), ("pressure", pressure))):
    ax.imshow(imprint_grid(images, captions=[f"point {i + 1}" for i in range(len(images))], scale=6))
    ax.set_title(title)
    ax.axis("off")
fig.tight_layout()

# %%
# The same points as a robot would acquire them: placement and tilt errors, a random roll of the
# pad, gain spread, noise, dead taxels and an 8-bit ADC (``Perturbation.typical()``, assumed figures).
# The same seed gives the same device and the same readings.
acquired = tactile.acquire(mesh, points.positions, points.normals, sensor, tactile.Perturbation.typical(), rng=0)
fig, ax = plt.subplots(figsize=(9, 4))
ax.imshow(imprint_grid(acquired, captions=[f"point {i + 1}" for i in range(len(acquired))], scale=6))
ax.set_title("contour, acquired")
ax.axis("off")
fig.tight_layout()
