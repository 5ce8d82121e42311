"""Maintainer script: embed the ten YCB objects of ../shared/meshes/ycb as meshsal/objects/data/ycb/*.ply.

Each OBJ is loaded with meshsal.load_mesh; a texture, where there is one, is
baked into vertex colours (the mean of the texture at the vertex's face
corners); the mesh is written as binary PLY in the file's own frame and units
(metres).  Run from the checkout: ``.venv/bin/python scripts/embed_ycb.py [SOURCE_DIR]``.
"""

import sys
from pathlib import Path

import numpy as np

import meshsal
from meshsal.mesh.io import save_ply


def baked_colors(mesh: meshsal.Mesh) -> np.ndarray:
    """(n, 3) float32: the texture sampled at each face corner, averaged per vertex."""
    T = mesh.texture
    h, w = T.shape[:2]
    uv = mesh.uv.reshape(-1, 2)
    cols = np.clip(np.round(uv[:, 0] * (w - 1)), 0, w - 1).astype(int)
    rows = np.clip(np.round((1.0 - uv[:, 1]) * (h - 1)), 0, h - 1).astype(int)
    rgb = T[rows, cols].astype(np.float64) / 255.0
    total = np.zeros((mesh.n_vertices, 3))
    count = np.zeros(mesh.n_vertices)
    np.add.at(total, mesh.faces.reshape(-1), rgb)
    np.add.at(count, mesh.faces.reshape(-1), 1.0)
    return (total / np.maximum(count, 1.0)[:, None]).astype(np.float32)


def main(source: Path) -> None:
    target = Path(__file__).resolve().parents[1] / "meshsal" / "objects" / "data" / "ycb"
    for obj in sorted(source.glob("*.obj")):
        mesh = meshsal.load_mesh(obj)
        colors = baked_colors(mesh) if mesh.texture is not None else mesh.vertex_colors
        plain = meshsal.Mesh(mesh.vertices, mesh.faces, vertex_colors=colors, name=obj.stem)
        save_ply(target / f"{obj.stem}.ply", plain)
        print(f"{obj.stem}: {plain.n_vertices} vertices, {plain.n_faces} faces, colours: {colors is not None}")


if __name__ == "__main__":
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parents[2] / "shared" / "meshes" / "ycb")
