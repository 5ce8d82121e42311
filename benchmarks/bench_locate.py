"""Benchmark: how well a place of one instance is found on another tessellation of its shape, three ways.

Under the hypothesis "the object is j" the place-aware recognizer finds
where a touch of the test instance lies among j's trained places, by
signature (distances to eight landmarks over the spacing of the first
two, ``meshsal.points.places.signatures``).  The landmarks it measures
against decide everything.  For the first ``--objects`` corpus objects
(``../shared/corpus/random-objects``, 150 mm), each object's mesh A and a
test instance B of it, ``decimated`` or ``subdivided``
(``meshsal.objects.instances.retessellate``), then turned, resized and
moved by a seeded similarity.  Every candidate place of B (5 points' worth,
as ``bench_scaling.py`` asks) is located on A's places against:

* **B's own landmarks** (its first eight places): farthest-point samples,
  whose order another tessellation can change;
* **A's landmarks laid onto B through the two surface frames**
  (``meshsal.points.frames``: what the recognizer does past its shortlist);
* **A's landmarks laid onto B by registration**
  (``meshsal.points.places.landmarks_in``: what it does within it).

A place is found when the A place it is matched to lies within 5 % of A's
landmark spacing of the A place nearest it in space (the two meshes have
different vertices, so that nearest place is the best any location can
do).  The table gives the share found, the mean excess distance (in
landmark spacings) and the time per instance, median of ``--repeats``.

    python -m meshsal.util.reproducible .venv/bin/python benchmarks/bench_locate.py [--objects 64] [--repeats 3]
"""

from __future__ import annotations

import statistics
import sys
import time
import warnings

import numpy as np
from benchlib import CORPUS, arguments, corpus_files, run

#: How close a matched place must lie to the best one, in landmark spacings.
FOUND = 0.05
#: Points an instance asks for: the candidate places are 20 + 2 per point.
POINTS = 5


def _instances(files: list, kind: str, seed: int) -> list:
    """:func:`_pair` per object: its mesh, a turned, resized, moved retessellation, and B's positions back in A's."""
    import meshsal
    from meshsal.mesh import MeshError
    from meshsal.mesh.transform import scale_to
    from meshsal.objects.instances import retessellate

    rng = np.random.default_rng(seed)
    out = []
    for path in files:
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                A = scale_to(meshsal.load_mesh(path), 150.0)
                B = retessellate(A, kind)
        except (MeshError, ValueError) as exc:  # the corpus holds a mesh that does not load
            print(f"bench_locate: {path} left out: {exc}", file=sys.stderr)
            continue
        Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        R, s, t = Q * np.sign(np.linalg.det(Q)), rng.uniform(0.5, 2.0), rng.uniform(-100.0, 100.0, 3)
        B = B.replace(vertices=s * B.vertices @ R.T + t)
        out.append(_pair(A, B, lambda X, R=R, s=s, t=t: ((X - t) / s) @ R))
    return out


def _pair(A, B, undo) -> tuple:
    """(A, B, XA, XB, undo): the two meshes with their candidate places' positions, found once for every way
    and repeat, and ``undo``, B's positions back in A's frame."""
    from meshsal.mesh.curvature import mesh_saliency
    from meshsal.points.places import candidate_places

    XA, XB = (m.vertices[candidate_places(m, mesh_saliency(m), POINTS)] for m in (A, B))
    return A, B, XA, XB, undo


def _located(pair: tuple, how: str) -> tuple[np.ndarray, float]:
    """Each of B's places' excess distance from the best A place (landmark spacings), and the seconds it took."""
    from meshsal.points.frames import lay_landmarks, shape_frame
    from meshsal.points.places import LANDMARKS, landmarks_in, signatures

    A, B, XA, XB, undo = pair
    LA = XA[:LANDMARKS]
    start = time.perf_counter()
    if how == "own":
        LB = XB[:LANDMARKS]
    elif how == "frames":
        LB = lay_landmarks(shape_frame(B.vertices, B.faces), shape_frame(A.vertices, A.faces), LA)
    else:
        LB = landmarks_in(XB, XA)
    gA, gB = signatures(XA, LA), signatures(XB, LB)
    pick = np.argmin(((gB[:, None] - gA[None]) ** 2).sum(axis=2), axis=1)
    seconds = time.perf_counter() - start
    spacing = np.linalg.norm(LA[1] - LA[0])
    back = undo(XB)
    best = np.linalg.norm(back[:, None] - XA[None], axis=2).min(axis=1)
    return (np.linalg.norm(back - XA[pick], axis=1) - best) / spacing, seconds


def main(argv=None) -> int:
    parser = arguments(__doc__, repeats=3, meshes_dir=False)
    parser.add_argument("--objects", type=int, default=64, help="corpus objects (default 64)")
    args = parser.parse_args(argv)
    if not CORPUS.is_dir():
        print(f"bench_locate: error: {CORPUS} not found", file=sys.stderr)
        return 1
    files = corpus_files(args.objects)
    print(f"{len(files)} corpus files, candidate places for {POINTS} points, seed 0; found: within {FOUND} of the")
    print("landmark spacing of the best place\n")
    print("| tessellation | landmarks | places found (%) | mean excess (spacings) | ms per instance |")
    print("|---|---|---:|---:|---:|")
    labels = {"own": "the instance's own", "frames": "laid through the surface frames", "registration": "registered"}
    for kind in ("decimated", "subdivided"):
        pairs = _instances(files, kind, seed=0)
        label = f"{kind} ({len(pairs)} objects)"
        for how, landmarks in labels.items():
            excess, times = [], []
            for pair in pairs:
                runs = [_located(pair, how) for _ in range(args.repeats)]
                excess.append(runs[0][0])
                times.append(statistics.median(r[1] for r in runs))
            e = np.concatenate(excess)
            ms = 1000 * statistics.median(times)
            print(f"| {label} | {landmarks} | {100 * np.mean(e < FOUND):.1f} | {e.mean():.3f} | {ms:.2f} |")
    return 0


if __name__ == "__main__":
    run("bench_locate", "Finding a place on another tessellation: own landmarks, surface frames, registration", main)
