"""What the benchmarks share: the machine they ran on, timing, and the concave test meshes.

Another 2-core machine can be twice as slow, and the machines these run on
are shared: every benchmark runs in :func:`page`, which prints :func:`machine`
(CPU model, cores, load average) before and after its figures and writes
what it printed to ``docs/benchmarks/`` with :func:`write_page` (command,
commit, machine and date in the header); it times with :func:`timed` (wall
and process CPU time of all threads).
"""

from __future__ import annotations

import argparse
import contextlib
import io
import sys
import time
from pathlib import Path

import numpy as np

from meshsal.util import pages

DEFAULT_MESHES = Path(__file__).resolve().parents[2] / "shared" / "meshes"
#: The 1,000-mesh corpus beside the public meshes.
CORPUS = DEFAULT_MESHES.parent / "corpus" / "random-objects"


def corpus_files(count: int) -> list[str]:
    """The first ``count`` mesh files of :data:`CORPUS`, sorted by name (a file that does not load is left out by
    the run that reads them: ``skip_bad``)."""
    found = sorted(p for p in CORPUS.iterdir() if p.suffix.lower() in (".obj", ".ply", ".off", ".stl"))
    return [str(p) for p in found[:count]]


def machine() -> str:
    """One line: CPU model, core count, load average over 1 / 5 / 15 minutes."""
    return f"machine: {pages.machine()}"


def write_page(name: str, title: str, body: str) -> None:
    """The benchmark's tables as ``docs/benchmarks/NAME.md``, with the command, commit, machine and date."""
    pages.write_page(Path(__file__).resolve().parents[1] / "docs" / "benchmarks" / f"{name}.md", title, body)


class _Tee(io.TextIOBase):
    """Writes to the terminal and keeps a copy."""

    def __init__(self, terminal):
        self.terminal, self.copy = terminal, io.StringIO()

    def write(self, text: str) -> int:
        self.copy.write(text)
        return self.terminal.write(text)

    def flush(self) -> None:
        self.terminal.flush()


class _Outcome:
    """What :func:`page` writes: the page, unless the benchmark failed."""

    failed = False


@contextlib.contextmanager
def page(name: str, title: str):
    """Run a benchmark: its machine line before and after, and everything it prints as ``docs/benchmarks/NAME.md``.

    The page is written only when the benchmark finishes and succeeds: not on
    an error, ``--help``, or when the block marks the yielded outcome
    ``failed`` (a non-zero exit status), so a failed run leaves the page of
    the last good one.
    """
    tee, outcome = _Tee(sys.stdout), _Outcome()
    with contextlib.redirect_stdout(tee):
        print(f"{machine()}\n", flush=True)
        yield outcome
        print(f"\n{machine()}", flush=True)
    if outcome.failed:
        print(f"docs/benchmarks/{name}.md not written: the benchmark failed", file=sys.stderr)
        return
    write_page(name, title, tee.copy.getvalue())
    print(f"wrote docs/benchmarks/{name}.md", file=sys.stderr)


def run(name: str, title: str, main) -> None:
    """``python benchmarks/NAME.py``: ``main()`` inside :func:`page`, its return value the exit status."""
    with page(name, title) as outcome:
        status = main()
        outcome.failed = bool(status)
    raise SystemExit(status)


def arguments(doc: str, repeats: int, meshes_dir: bool = True, repeats_help: str = "") -> argparse.ArgumentParser:
    """The options every benchmark takes: ``--repeats`` and, with ``meshes_dir``, ``--meshes-dir``.

    The description is the first line of ``doc`` (the benchmark's docstring).
    """
    parser = argparse.ArgumentParser(description=doc.splitlines()[0])
    if meshes_dir:
        parser.add_argument(
            "--meshes-dir", type=Path, default=DEFAULT_MESHES, help=f"the public test meshes (default {DEFAULT_MESHES})"
        )
    help = repeats_help or "timed runs; the figures are their medians"
    parser.add_argument("--repeats", type=int, default=repeats, help=f"{help} (default {repeats})")
    return parser


def scaling_config(params: dict | None = None, control: str | None = None, mismatch=()):
    """The experiment the scaling, screening and results.json benchmarks run on corpus objects.

    2 replicates of the instance protocol, uniform and mesh-saliency points,
    kNN and the place-aware recognizer (``params``: the classifiers'
    parameters), polar features, ``info_gain``, 5 points per instance, 64 px
    views, seed 0; ``control`` and ``mismatch`` as ``ExperimentConfig`` and
    ``Settings`` take them.
    """
    from classify.experiment import ExperimentConfig, Settings

    return ExperimentConfig(
        methods=("mesh_saliency", "uniform"),
        protocols=("instance",),
        classifiers=("knn", "place"),
        features="polar",
        policies=("info_gain",),
        replicates=2,
        control=control,
        settings=Settings(n_points=5, view_size=64, seed=0, mismatch=tuple(mismatch)),
        params=params or {},
    )


def timed(fn):
    """``(result, wall seconds, CPU seconds of the process)`` of ``fn()``."""
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - wall, time.process_time() - cpu


def hand_150mm():
    """The hand toy at a 150 mm diagonal (40k faces): deep creases between the fingers, where a pad
    cannot reach, so the attention method refuses hundreds of candidates and reaches the fill from
    every vertex, where a touch check that asks about candidates one at a time is slowest."""
    from meshsal import scale_to
    from meshsal.objects import toys

    return scale_to(toys.make("hand"))


def hand_124k():
    """The hand toy refined to the size of a large scan: Loop-subdivided once (its colours with it),
    decimated to 124,000 faces (pymeshlab's quadric edge collapse), 150 mm."""
    import igl
    import pymeshlab

    from meshsal import Mesh, scale_to
    from meshsal.objects import toys

    hand = toys.make("hand")
    both, F = igl.loop(np.hstack([hand.vertices, hand.vertex_colors]), np.asarray(hand.faces, np.int64))
    colours = np.clip(both[:, 3:], 0.0, 1.0)
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(both[:, :3], F.astype(np.int32), v_color_matrix=np.c_[colours, np.ones(len(colours))]))
    ms.meshing_decimation_quadric_edge_collapse(targetfacenum=124_000, preservetopology=True, preservenormal=True)
    ms.meshing_remove_unreferenced_vertices()
    out = ms.current_mesh()
    return scale_to(
        Mesh(
            vertices=out.vertex_matrix(),
            faces=out.face_matrix(),
            vertex_colors=out.vertex_color_matrix()[:, :3],
            name="hand, 124k faces",
        )
    )
