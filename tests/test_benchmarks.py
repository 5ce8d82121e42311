"""The benchmarks' measuring code against the library it measures: a benchmark that reaches for an attribute the
library no longer has fails here, on tiny inputs, and not at the end of an hour's run."""

import importlib
import sys
from pathlib import Path

import pytest
import shapes

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _benchmark(monkeypatch, name: str):
    """The benchmark script ``name`` imported as a module, then forgotten."""
    monkeypatch.syspath_prepend(str(BENCHMARKS))  # the benchmarks import their helpers as 'benchlib'
    yield importlib.import_module(name)
    sys.modules.pop(name, None)


@pytest.fixture
def bench_batch(monkeypatch):
    yield from _benchmark(monkeypatch, "bench_batch")


def test_bench_batch_counts_the_meshes_and_the_cpu_time_of_every_process(bench_batch, tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    for i in range(2):
        shapes.write_obj(folder / f"m{i}.obj", shapes.icosphere(radius=1.0 + i, subdivisions=2))
    run = bench_batch._run(folder, 1, tmp_path / "store")
    assert run["workers"] == 1 and run["done"] == 2
    # The CPU time of every process holds the tasks' own, which the worker measured.
    assert run["cpu"] >= run["tasks"] > 0
    assert run["wall"] > 0 and run["peak_mb"] > 0
    assert set(run["stages"]) == set(bench_batch.STAGES)


def test_bench_batch_measures_the_same_meshes_in_its_own_process(bench_batch, tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    for i in range(2):
        shapes.write_obj(folder / f"m{i}.obj", shapes.icosphere(radius=1.0 + i, subdivisions=2))
    here = bench_batch._in_process(folder, tmp_path / "store")
    assert set(here["stages"]) == set(bench_batch.STAGES) and here["cpu_per_mesh"] > 0
    # A worker whose tasks took 1.5 times the CPU: the ratio is the worker's over this process's.
    one = [{"stages": here["stages"], "tasks": 3 * here["cpu_per_mesh"], "done": 2}]
    ycb = dict.fromkeys(bench_batch.STAGES, 0.001)
    assert "1.50x: what a Dask worker adds to a task" in bench_batch._stages(one, [here], ycb)


def test_bench_batch_runs_the_whole_corpus_command_and_reads_its_tables(bench_batch, tmp_path):
    folder = tmp_path / "meshes"
    folder.mkdir()
    shapes.write_obj(folder / "ball.obj", shapes.icosphere(radius=1.0, subdivisions=2))
    (folder / "broken.obj").write_text("v 0 0 0\nf 1 2 3\n")
    run = bench_batch._whole_corpus_run(folder, tmp_path / "store")
    # The unreadable mesh is skipped, as the benchmark asks: the command still succeeds.
    assert run["status"] == 0, run["notes"]
    assert run["wall"] > 0 and run["cpu"] > 0
    assert run["table"].startswith("| meshes done") and "failed: see" in run["notes"]


def test_bench_batch_judges_the_whole_corpus_by_the_median_of_its_runs(bench_batch, tmp_path, monkeypatch):
    walls = iter([250.0, 230.0, 236.0])
    monkeypatch.setattr(
        bench_batch,
        "_whole_corpus_run",
        lambda corpus, store: {
            "wall": next(walls),
            "cpu": 460.0,
            "load": 1.0,
            "status": 0,
            "table": "| meshes done |",
            "notes": "1 mesh(es) failed: see /gone/failures.jsonl",
        },
    )
    page = bench_batch._whole_corpus(tmp_path, tmp_path, 3)
    assert "Median wall: 3.93 min (236.0 s); goal <= 4 min on 2 workers: met." in page
    assert page.count("| 460 s | 1.84 |") == 1 and "| 3 | 236.0 s |" in page
    # The notes' paths point into a store the benchmark removes: the counts stay, the paths go.
    assert "1 mesh(es) failed\n" in page and "/gone" not in page


@pytest.fixture
def bench_locate(monkeypatch):
    yield from _benchmark(monkeypatch, "bench_locate")


def test_bench_locate_finds_every_place_of_a_turned_copy_and_puts_it_back_in_the_meshs_frame(bench_locate):
    import numpy as np

    # A ball stretched and rippled out of every symmetry, turned, resized and moved: the same vertices, so every
    # way of locating finds every place exactly, and the benchmark's undo brings the copy back onto the mesh.
    ball = shapes.icosphere(radius=40.0, subdivisions=3)
    V = ball.vertices * [1.0, 0.7, 0.45]
    V *= 1.0 + 0.2 * np.sin(V @ [0.071, 0.043, 0.029] + 0.3)[:, None]
    mesh = ball.replace(vertices=V)
    Q, _ = np.linalg.qr(np.random.default_rng(1).normal(size=(3, 3)))
    R = Q * np.sign(np.linalg.det(Q))
    copy = mesh.replace(vertices=1.7 * V @ R.T + 5.0)
    undo = lambda X: ((X - 5.0) / 1.7) @ R  # noqa: E731
    np.testing.assert_allclose(undo(copy.vertices), V, atol=1e-9)
    for how in ("own", "frames", "registration"):
        excess, seconds = bench_locate._located(bench_locate._pair(mesh, copy, undo), how)
        assert excess.size > 20 and np.abs(excess).max() < 1e-6 and seconds > 0, how


@pytest.fixture
def bench_scaling(monkeypatch):
    yield from _benchmark(monkeypatch, "bench_scaling")


def test_bench_scaling_names_its_page_by_the_screening_it_runs(bench_scaling):
    from classify.recognizers.place import SCREENINGS, PlaceAware

    # With no screening asked, the recognizer's default runs, and the page says which: it keeps its name and its
    # figures when the default changes.
    assert bench_scaling._page(None) == f"bench_scaling_{PlaceAware().screening}" == "bench_scaling_place"
    assert [bench_scaling._page(s) for s in SCREENINGS] == ["bench_scaling_place", "bench_scaling_touch"]
    assert bench_scaling.parser().parse_args(["--screening", "touch"]).screening == "touch"
    with pytest.raises(SystemExit):
        bench_scaling.parser().parse_args(["--screening", "sight"])


@pytest.fixture
def benchlib(monkeypatch):
    yield from _benchmark(monkeypatch, "benchlib")


def test_a_benchmark_that_fails_leaves_the_page_of_its_last_good_run(benchlib, monkeypatch, capsys):
    written = []
    monkeypatch.setattr(benchlib, "write_page", lambda name, title, body: written.append((name, body)))

    def missing_corpus():
        print("bench_x: error: the corpus is not there", file=sys.stderr)
        return 1

    with pytest.raises(SystemExit) as failed:
        benchlib.run("bench_x", "X", missing_corpus)
    assert failed.value.code == 1 and written == []
    assert "docs/benchmarks/bench_x.md not written" in capsys.readouterr().err
    with pytest.raises(SystemExit) as done:
        benchlib.run("bench_x", "X", lambda: print("| figure |") or 0)
    assert done.value.code == 0 and written[0][0] == "bench_x" and "| figure |" in written[0][1]


@pytest.fixture
def bench_results_json(monkeypatch):
    yield from _benchmark(monkeypatch, "bench_results_json")


def test_bench_results_json_writes_the_peer_with_every_confusion_dense(bench_results_json):
    import numpy as np

    from classify.reporting import report
    from classify.reporting.confusion import ConfusionMatrix, confusion_pairs
    from classify.reporting.results import ExperimentResult

    names = tuple(f"o{i}" for i in range(40))
    truth = np.repeat(np.arange(40), 3)
    pairs = confusion_pairs(truth, (truth + np.arange(truth.size) % 2) % 40)
    result = ExperimentResult(
        cells=(),
        comparisons=(),
        confusions=(ConfusionMatrix("uniform", "instance", "knn", 40, False, names, pairs),),
        object_names=names,
        object_sets=(40,),
        classifiers=("knn",),
    )
    every, confusions = bench_results_json._dense(result)
    # 1,600 cells, each a line of its own, against the 80 pairs the toolkit writes.
    assert len(pairs) == 80 and every > confusions > 1600 * 8
    assert confusions > 5 * len(report.json_text(result.to_json()["confusions"]))
