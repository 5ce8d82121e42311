"""Ten scanned household objects of the YCB set, embedded: real shapes to recognize by touch.

banana, cracker_box, foam_brick, gelatin_box, master_chef_can, mustard_bottle,
potted_meat_can, power_drill, scissors and tomato_soup_can, from the YCB
Object and Model Set (Calli et al. 2015, CC BY 4.0) as simplified for
simulation in eleramp/pybullet-object-models: 15,728 faces each, in metres,
in their files' own frames.  Banana and scissors carry their textures baked
into vertex colours; the others are geometry only.  Licence and
attribution: ``meshsal/objects/data/ycb/LICENSE.md``.
"""

from __future__ import annotations

from pathlib import Path

from meshsal.mesh import Mesh

__all__ = ["NAMES", "path", "load"]

_DIR = Path(__file__).resolve().parent / "data" / "ycb"

NAMES = (
    "banana",
    "cracker_box",
    "foam_brick",
    "gelatin_box",
    "master_chef_can",
    "mustard_bottle",
    "potted_meat_can",
    "power_drill",
    "scissors",
    "tomato_soup_can",
)


def path(name: str) -> Path:
    """The embedded binary PLY of one object.

    Examples
    --------
    >>> path("banana").name
    'banana.ply'
    """
    if name not in NAMES:
        raise ValueError(f"unknown YCB object {name!r}; valid names are: {', '.join(NAMES)}")
    return _DIR / f"{name}.ply"


def load(name: str) -> Mesh:
    """One embedded object as a mesh in metres, named ``name``.

    Examples
    --------
    >>> m = load("power_drill")
    >>> m.name, m.n_faces
    ('power_drill', 15728)
    """
    from meshsal.mesh.io import load_mesh

    return load_mesh(path(name)).replace(name=name)
