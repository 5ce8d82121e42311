"""The experiment end to end: twins at chance, the same tables for any thread count, the CLI, bad input."""

import csv
import dataclasses
import json

import numpy as np
import pytest
import quick
import shapes
from quick import QUICK, SMALL

import meshsal
import tactile
from classify import experiment
from classify.cli import main
from classify.experiment.samples import Settings
from classify.recognizers.classifiers import NAMES
from classify.reporting.report import CSV_COLUMNS
from meshsal.objects.instances import random_rotation


def _cup(name, turn=None):
    cup = meshsal.objects.toys.make("cup")
    V = cup.vertices if turn is None else cup.vertices @ turn.T
    return meshsal.Mesh(V, cup.faces, vertex_colors=cup.vertex_colors, name=name)


def test_two_copies_of_one_mesh_cannot_be_told_apart_but_two_objects_can():
    config = QUICK.replace(methods=("uniform",), protocols=("instance",), replicates=4)
    twins = [_cup("cup_a"), _cup("cup_b", random_rotation(np.random.default_rng(9)))]
    r = quick.run(twins, config)
    chance = r.cell("uniform", "instance", "knn", 2, False, 1)
    assert chance.ci_low <= 50.0 <= chance.ci_high, chance  # a leak of pose or point would show here
    fused = r.cell("uniform", "instance", "knn", 2, False, 6)
    assert fused.ci_low <= 50.0 <= fused.ci_high, fused
    other = [_cup("cup_a"), shapes.sphere(radius=50.0, n=24).replace(name="ball")]
    r = quick.run(other, config)
    assert r.cell("uniform", "instance", "knn", 2, False, 1).mean > 65.0
    assert r.cell("uniform", "instance", "knn", 2, False, 6).ci_low > 80.0


def _objects():
    return [
        shapes.box(half=40.0, n=20).replace(name="box"),
        shapes.sphere(radius=50.0, n=24).replace(name="ball"),
        shapes.cylinder(radius=25.0, length=120.0, around=48, along=8).replace(name="rod"),
    ]


def test_the_rates_of_an_object_set_do_not_depend_on_the_order_objects_are_given_in():
    config = QUICK.replace(methods=("random",), classifiers=("knn", "naive_bayes"))
    given = quick.run(_objects(), config, n_jobs=1)
    flipped = quick.run(_objects()[::-1], config, n_jobs=1)
    for protocol, k in (("paper", 1), ("instance", 1), ("instance", 4)):
        for c in ("knn", "naive_bayes"):
            key = ("random", protocol, c, 3, True, k)
            np.testing.assert_array_equal(given.rates[key], flipped.rates[key][:, ::-1])


def test_results_csv_does_not_depend_on_the_order_objects_are_given_in(tmp_path):
    config = QUICK.replace(methods=("random", "uniform"), replicates=3)
    quick.run(_objects(), config, n_jobs=1, out_dir=tmp_path / "given")
    quick.run(_objects()[::-1], config, n_jobs=1, out_dir=tmp_path / "flipped")
    given = (tmp_path / "given" / "results.csv").read_text()
    assert given == (tmp_path / "flipped" / "results.csv").read_text()  # means, intervals, comparisons


def test_results_csv_is_identical_for_one_and_two_jobs(tmp_path):
    config = QUICK.replace(methods=("random",), classifiers=NAMES)
    one = quick.run(_objects(), config, n_jobs=1, out_dir=tmp_path / "one")
    two = quick.run(_objects(), config, n_jobs=2, out_dir=tmp_path / "two")
    assert (tmp_path / "one" / "results.csv").read_text() == (tmp_path / "two" / "results.csv").read_text()
    # The paper's five with and without selection in both protocols; the place-aware one in the instance protocol.
    assert one.rates.keys() == two.rates.keys() and len(one.rates) == 5 * 2 * (1 + 6) + 6


def test_every_rate_has_an_interval_and_methods_a_paired_comparison(tmp_path):
    config = QUICK.replace(methods=("random", "uniform"), classifiers=("knn", "naive_bayes"), replicates=3)
    r = quick.run(_objects(), config, out_dir=tmp_path)
    for c in r.cells:
        assert c.ci_low <= c.mean <= c.ci_high and 0.0 <= c.ci_low and c.ci_high <= 100.0
        assert c.replicates == (3 if c.protocol == "instance" else 2)
    assert {c.baseline for c in r.comparisons} == {"uniform"} and {c.method for c in r.comparisons} == {"random"}
    for d in r.comparisons:
        R = r.rates[(d.method, d.protocol, d.classifier, d.n_objects, d.selection, d.touches)]
        B = r.rates[("uniform", d.protocol, d.classifier, d.n_objects, d.selection, d.touches)]
        assert d.diff == pytest.approx(float((R - B).mean()))
        assert d.ci_low <= d.diff <= d.ci_high and 0.0 <= d.p_value <= 1.0
    with open(tmp_path / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert tuple(rows[0].keys()) == CSV_COLUMNS
    assert all(row["baseline"] == "uniform" for row in rows if row["method"] == "random")
    assert all(row["diff"] == "" for row in rows if row["method"] == "uniform")
    sets = {int(row["touches"]): int(row["touch_sets"]) for row in rows if row["protocol"] == "instance"}
    assert sets[6] == 1 and sets[5] == 6  # C(6, 6) and C(6, 5): all there are
    printed = experiment.format_tables(r)
    assert "paired difference" in printed and "fewer distinct sets" in printed


def test_cli_experiment_writes_every_file_and_a_cached_rerun_equals_a_fresh_run(tmp_path, capsys):
    files = []
    for mesh in _objects()[:2]:
        path = tmp_path / f"{mesh.name}.obj"
        shapes.write_obj(path, mesh)
        files.append(str(path))
    cache = tmp_path / "cache"

    def argv(out_dir, cache_dir):
        return [
            "experiment",
            "--objects",
            *files,
            "--n-points",
            "6",
            "--repeats",
            "2",
            "--folds",
            "3",
            "--replicates",
            "2",
            "--train-instances",
            "2",
            "--train-sessions",
            "1",
            "--methods",
            "uniform",
            "--out",
            str(out_dir),
            "--cache-dir",
            str(cache_dir),
            "--quiet",
        ]

    assert main(argv(tmp_path / "first", cache)) == 0
    printed = capsys.readouterr().out
    assert "| classifier | 2 objects, no selection | 2 objects, selection |" in printed
    assert "uniform points, paper protocol" in printed and "uniform points, instance protocol" in printed
    out = tmp_path / "first"
    assert {"results.json", "results.csv", "touches.png"} <= {p.name for p in out.iterdir()}
    assert {f"confusion_{c}.png" for c in ("knn", "naive_bayes", "decision_tree", "evolutionary_svm", "deep")} <= {
        p.name for p in out.iterdir()
    }
    document = json.loads((out / "results.json").read_text())
    assert document["settings"]["objects"] == ["box", "ball"] and document["settings"]["replicates"] == 2
    assert set(document["settings"]["libraries"]) >= {"numpy", "scikit-learn", "embreex", "libigl", "pymeshlab"}
    assert any(len(entry["replicate_by_object"]) == 2 for entry in document["rates"])
    capsys.readouterr()
    assert main(argv(tmp_path / "cached", cache)[:-1]) == 0  # read back from the cache, not quiet
    said = capsys.readouterr().err
    assert f"results written to {tmp_path / 'cached'}/" in said and " MB at most; each stage's in results.json" in said
    assert set(json.loads((tmp_path / "cached" / "results.json").read_text())["usage"]) >= {"paper", "total"}
    # The first run computed everything from nothing (its cache was empty).
    assert (tmp_path / "cached" / "results.csv").read_text() == (out / "results.csv").read_text()


def test_bad_mesh_stops_the_run_before_any_work_naming_the_file(tmp_path, capsys):
    bad = tmp_path / "broken.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    out = tmp_path / "o"
    code = main(["experiment", "--objects", "cow", str(bad), "--out", str(out), "--cache-dir", "none", "--quiet"])
    err = capsys.readouterr().err
    assert code != 0
    assert "visuotactile experiment: error:" in err and "broken.obj" in err
    assert not out.exists()


def test_unknown_object_method_or_baseline_is_refused_by_name(capsys):
    assert main(["experiment", "--objects", "unicorn", "--quiet"]) != 0
    assert "unicorn" in capsys.readouterr().err
    with pytest.raises(ValueError, match="telepathy"):
        experiment.run_experiment(_objects(), methods=("telepathy",), quiet=True, cache_dir=None)
    with pytest.raises(ValueError, match="baseline 'random'"):
        experiment.run_experiment(_objects(), methods=("uniform",), baseline="random", quiet=True, cache_dir=None)
    assert main(["experiment", "--objects", "cow,cup", "--replicates-at-once", "0", "--quiet"]) != 0
    assert "--replicates-at-once must be at least 1, got 0" in capsys.readouterr().err


@pytest.mark.parametrize(
    "option, value, message",
    [
        ("--replicates", "0", "replicates must be at least 1, got 0"),
        ("--repeats", "0", "repeats must be at least 1, got 0"),
        ("--folds", "1", "folds must be at least 2, got 1"),
        ("--jobs", "0", "--jobs must be at least 1, got 0"),
        ("--view-size", "0", "view_size must be an integer of at least 16 pixels, got 0"),
        ("--view-size", "8", "view_size must be an integer of at least 16 pixels, got 8"),
        ("--seed", "-1", "seed must be a non-negative integer, got -1"),
    ],
)
def test_a_count_out_of_range_is_refused_by_name_before_any_work(tmp_path, capsys, option, value, message):
    # None of these may fall back to a default (0 is no "unset") or fail later, mid-run.
    out = tmp_path / "o"
    argv = ["experiment", "--objects", "cow,cup", option, value, "--out", str(out), "--cache-dir", "none", "--quiet"]
    assert main(argv) == 1
    assert f"visuotactile experiment: error: {message}" in capsys.readouterr().err
    assert not out.exists()


def test_a_results_or_cache_folder_with_a_file_in_its_way_stops_run_experiment_before_any_work(tmp_path):
    file = tmp_path / "notes.txt"
    file.write_text("")
    for where in ({"out_dir": file / "results", "cache_dir": tmp_path / "cache"}, {"cache_dir": file}):
        with pytest.raises(ValueError, match=f"{file} is a file, not a folder|{file}: exists and is a file"):
            experiment.run_experiment(["cow", "cup"], quiet=True, **where)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["notes.txt"]  # no cache, nothing loaded or written


def test_an_object_with_fewer_places_than_landmarks_is_refused_by_name_before_any_work(monkeypatch):
    from classify.experiment import run

    corners = [[0, 0, 0], [60, 0, 0], [0, 60, 0], [0, 0, 60]]
    tet = meshsal.Mesh(vertices=corners, faces=[[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], name="tet")
    ball = shapes.sphere(radius=50.0, n=12).replace(name="ball")
    for stage in ("_paper_measurements", "instance_stage"):
        monkeypatch.setattr(run, stage, lambda *args, **kwargs: pytest.fail("work began"))
    for config in ({}, {"classifiers": ("knn",), "policies": ("random",)}):
        with pytest.raises(ValueError, match="locate a touch by 8 landmarks.*; tet has 4: give a finer mesh"):
            experiment.run_experiment([tet, ball], quiet=True, cache_dir=None, n_jobs=1, **config)
    monkeypatch.undo()
    # The paper protocol folds the points themselves: its error names the object with too few.
    with pytest.raises(ValueError, match="5-fold cross-validation needs at least 5 points per object; tet has 4 "):
        experiment.run_experiment(
            [tet, ball],
            protocols=("paper",),
            classifiers=("knn",),
            settings=SMALL,
            quiet=True,
            cache_dir=None,
            n_jobs=1,
        )


def test_real_imprint_set_gives_table_2_with_folds_grouped_by_point(tmp_path, capsys):
    rng = np.random.default_rng(4)
    labels = np.repeat(np.arange(3), 10)
    imprints = rng.uniform(0, 0.2, (30, 16, 16)).astype(np.float32)
    for i, c in enumerate(labels):
        imprints[i, 4 * c : 4 * c + 4, 4:8] = 0.9  # each object presses its own patch
    sset = tactile.ImprintSet(
        imprints=imprints,
        labels=labels.astype(np.int64),
        object_names=("mug", "ball", "box"),
        point_ids=np.tile(np.arange(10), 3),
        positions=np.zeros((30, 3)),
        normals=np.tile([0.0, 0.0, 1.0], (30, 1)),
        sensor=tactile.Sensor(),
        perturbation=None,
        seed=None,
        source="test",
    )
    path = tmp_path / "real.npz"
    sset.save(path)
    out = tmp_path / "real_out"
    assert main(["experiment", "--real", str(path), "--repeats", "2", "--out", str(out), "--quiet"]) == 0
    printed = capsys.readouterr().out
    assert "Table 2" in printed and "| classifier | 3 objects, no selection | 3 objects, selection |" in printed
    with open(out / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    assert len(rows) == 5 * 2 and all(r["method"] == "real" for r in rows)
    knn = [r for r in rows if r["classifier"] == "knn" and r["selection"] == "false"][0]
    assert float(knn["mean"]) == 100.0


def test_results_csv_is_identical_in_process_on_a_local_cluster_and_on_a_tcp_cluster(tmp_path, dask_cluster):
    from classify.runtime.cluster import open_executor, shares_disk

    config = QUICK.replace(methods=("uniform",), classifiers=("knn", "naive_bayes", "decision_tree"))
    quick.run(_objects(), config, n_jobs=1, out_dir=tmp_path / "serial")
    with open_executor(workers=2) as executor:
        quick.run(_objects(), config, executor=executor, out_dir=tmp_path / "local")
    with open_executor(scheduler=dask_cluster.address) as executor:
        assert not shares_disk(executor)  # a cluster by address may run elsewhere: places stay in memory
        quick.run(_objects(), config, executor=executor, out_dir=tmp_path / "tcp")
    serial = (tmp_path / "serial" / "results.csv").read_text()
    assert serial == (tmp_path / "local" / "results.csv").read_text() == (tmp_path / "tcp" / "results.csv").read_text()


def test_real_size_keeps_the_objects_own_millimetres_and_refuses_a_file_without_units(tmp_path):
    from classify.experiment.stages import load_objects
    from meshsal.mesh.transform import principal_diagonal
    from meshsal.objects import ycb

    real = load_objects(["banana", "cup"], Settings(size_mm=None))
    banana = ycb.load("banana")
    metres = principal_diagonal(banana.vertices, banana.faces)[1]
    assert principal_diagonal(real.nominal[0].vertices, real.nominal[0].faces)[1] == pytest.approx(1000.0 * metres)
    cup = meshsal.objects.toys.make("cup")
    assert np.ptp(real.nominal[1].vertices, axis=0) == pytest.approx(np.ptp(cup.vertices, axis=0))
    path = tmp_path / "unitless.obj"
    shapes.write_obj(path, shapes.box(half=2.0, n=4))
    with pytest.raises(ValueError, match="unitless.*units are not known"):
        load_objects(["cup", str(path)], Settings(size_mm=None))


class _RecordingPool:
    """A pool that maps in this process and remembers what it was given."""

    def __init__(self):
        self.given = []

    def map(self, fn, items):
        items = list(items)
        self.given += items
        return map(fn, items)


def _same_meshes(a, b):
    assert a.names == b.names
    for x, y in zip(a.nominal, b.nominal):
        np.testing.assert_array_equal(x.vertices, y.vertices)
        np.testing.assert_array_equal(x.faces, y.faces)
        np.testing.assert_array_equal(x.vertex_colors, y.vertex_colors)


def test_a_pool_builds_the_toys_alone_and_spawned_workers_build_the_same_meshes(tmp_path):
    from classify.experiment.stages import load_objects
    from classify.runtime.cluster import worker_pool

    path = tmp_path / "box.obj"
    shapes.write_obj(path, shapes.box(half=20.0, n=4))
    names = ["cup", "banana", str(path), "plane"]
    here = load_objects(names, Settings())
    recording = _RecordingPool()
    _same_meshes(load_objects(names, Settings(), recording), here)
    # Files and the YCB scans are read here, where their repair warnings and errors are raised.
    assert [r.name for r in recording.given] == ["cup", "plane"]
    with worker_pool(2) as pool:
        _same_meshes(load_objects(names, Settings(), pool), here)


def test_the_command_line_s_local_workers_build_the_toys_and_a_cluster_s_do_not(monkeypatch):
    import classify.experiment.run as run_mod
    from classify.runtime.cluster import Inline, open_executor

    given = []

    class Loaded(Exception):
        pass

    def loading(objects, settings, pool=None, skip_bad=False):
        given.append(pool)
        raise Loaded

    monkeypatch.setattr(run_mod, "load_objects", loading)
    # What `visuotactile experiment` passes: the executor of open_executor, here local processes.
    with open_executor(n_jobs=2) as executor, pytest.raises(Loaded):
        run_mod.run_experiment(["cup", "plane"], QUICK, executor=executor, cache_dir=None, quiet=True)
    assert given == [executor]

    class ByAddress:  # a cluster's executor: its workers need not run with this process's pin
        def map(self, fn, *iterables):
            return map(fn, *iterables)

    with pytest.raises(Loaded):
        run_mod.run_experiment(["cup", "plane"], QUICK, executor=ByAddress(), cache_dir=None, quiet=True)
    with pytest.raises(Loaded):
        run_mod.run_experiment(["cup", "plane"], QUICK, n_jobs=1, cache_dir=None, quiet=True)
    assert given[1] is None and isinstance(given[2], Inline)


def test_touch_policies_run_paired_with_the_fixed_plans_and_write_their_rows(tmp_path):
    config = QUICK.replace(
        methods=("uniform", "mesh_saliency"),
        policies=("info_gain", "random"),
        protocols=("instance",),
        features="polar",
    )
    r = quick.run(_objects()[:2], config, n_jobs=1, out_dir=tmp_path)
    with open(tmp_path / "results.csv") as fh:
        rows = list(csv.DictReader(fh))
    sequential = [row for row in rows if row["protocol"] == "sequential"]
    assert {row["method"] for row in sequential} == {"info_gain", "random"}
    assert {int(row["touches"]) for row in sequential} == set(range(1, SMALL.n_points + 1))
    assert all(row["baseline"] == "uniform" and row["diff"] != "" for row in sequential)
    # Paired: the same replicates and objects as the baseline's fixed plan.
    for key, R in r.rates.items():
        if key[1] == "sequential":
            assert R.shape == r.rates[("uniform", "instance") + key[2:]].shape
    with open(tmp_path / "stopping.csv") as fh:
        stops = list(csv.DictReader(fh))
    assert {(s["method"], s["protocol"]) for s in stops} >= {("info_gain", "sequential"), ("uniform", "instance")}
    for s in stops:
        assert 1.0 <= float(s["touches"]) <= SMALL.n_points and 0.0 <= float(s["accuracy"]) <= 100.0
    assert "policy info_gain" in experiment.format_tables(r) and "touches at 95 %" in experiment.format_tables(r)


def test_every_method_and_classifier_of_a_replicate_meets_the_same_instances_devices_and_touch_sets(monkeypatch):
    from collections import Counter, defaultdict

    from classify.experiment import protocols, stages
    from classify.experiment import run as run_module
    from classify.runtime import cache as cache_module

    acquired, touch_sets, current = Counter(), defaultdict(list), {}
    real_acquire, real_recognition = tactile.acquire_all, run_module.instance_recognition
    real_job, real_sets = stages.instance_job, protocols.touch_sets

    def spy_acquire(mesh, requests, *args, **kwargs):
        # The instance (its mesh) and each session's stream (hence its device), before any draw.
        for r in requests:
            acquired[cache_module.hash_arrays(mesh.vertices), repr(r.rng.bit_generator.state)] += 1
        return real_acquire(mesh, requests, *args, **kwargs)

    def spy_recognition(method, *args):
        current["method"] = method
        return real_recognition(method, *args)

    def spy_job(job):
        current["classifier"], current["replicate"] = job.recognizer.classifier, job.replicate
        return real_job(job)

    def spy_sets(n, k, count, rng):
        out = real_sets(n, k, count, rng)
        touch_sets[current["method"], current["classifier"]].append((current["replicate"], k, n, out.tobytes()))
        return out

    monkeypatch.setattr(tactile, "acquire_all", spy_acquire)
    monkeypatch.setattr(run_module, "instance_recognition", spy_recognition)
    monkeypatch.setattr(stages, "instance_job", spy_job)
    monkeypatch.setattr(protocols, "touch_sets", spy_sets)
    methods = ("uniform", "mesh_saliency")
    config = QUICK.replace(methods=methods, protocols=("instance",), classifiers=("knn", "naive_bayes"))
    quick.run(_objects()[:2], config, n_jobs=1)
    # 2 objects x 2 replicates x (1 test + 2 training sessions) session streams, each met once by every method.
    assert len(acquired) == 2 * 2 * 3 and set(acquired.values()) == {len(methods)}
    runs = list(touch_sets.values())
    assert len(runs) == 4 and all(sorted(run) == sorted(runs[0]) for run in runs)


def test_the_place_aware_recognizer_runs_every_plan_and_policy_and_a_shuffled_control_is_at_chance(tmp_path):
    config = QUICK.replace(
        methods=("uniform",),
        protocols=("instance",),
        classifiers=("knn", "place"),
        policies=("info_gain",),
        replicates=3,
    )
    # The control's instances, points and imprints are the run's own: read back from the run's cache.
    r = quick.run(_objects(), config, out_dir=tmp_path, cache_dir=tmp_path / "cache")
    for method, protocol in (("uniform", "instance"), ("info_gain", "sequential")):
        assert r.cell(method, protocol, "place", 3, False, 3).mean > 100.0 / 3
    with open(tmp_path / "results.csv") as fh:
        rows = [row for row in csv.DictReader(fh) if row["classifier"] == "place"]
    assert {(row["method"], row["protocol"], row["selection"]) for row in rows} == {
        ("uniform", "instance", "false"),
        ("info_gain", "sequential", "false"),
    }
    shuffled = quick.run(_objects(), config.replace(control="shuffled"), cache_dir=tmp_path / "cache")
    for method, protocol in (("uniform", "instance"), ("info_gain", "sequential")):
        for c in ("knn", "place"):
            for k in (1, 3):
                cell = shuffled.cell(method, protocol, c, 3, False, k)
                assert cell.ci_low <= 100.0 / 3, (method, c, k, cell)  # never above chance


def test_a_mismatch_arm_changes_the_test_instances_only():
    from classify.experiment.samples import SampleTask, instance_samples, nominal_mesh

    ball = nominal_mesh(shapes.sphere(radius=50.0, n=24).replace(name="ball"), SMALL)
    arm = dataclasses.replace(SMALL, mismatch=("subdivided", "noise_double"))

    def sample(settings, index):
        return instance_samples(SampleTask(ball, "ball", ("uniform",), settings, 0, index, places=True))

    for a, b in zip(sample(SMALL, 1).places.to_arrays().values(), sample(arm, 1).places.to_arrays().values()):
        np.testing.assert_array_equal(a, b)  # a training instance is the same in every arm
    plain, other = sample(SMALL, 0), sample(arm, 0)
    assert other.places.places.vertex_ids.max() > plain.places.places.vertex_ids.max()  # four times the faces
    with pytest.raises(ValueError, match="unknown mismatch"):
        Settings(mismatch=("warped",))
    with pytest.raises(ValueError, match="contradict"):
        Settings(mismatch=("decimated", "subdivided"))


def test_objects_from_a_folder_or_a_list_with_twins_and_bad_files(tmp_path):
    from classify.experiment.stages import load_objects

    folder = tmp_path / "shelf"
    (folder / "deep").mkdir(parents=True)
    for mesh, where in zip(_objects(), ("box.obj", "deep/ball.obj", "rod.obj")):
        shapes.write_obj(folder / where, mesh)
    (folder / "copy_of_box.obj").write_bytes((folder / "box.obj").read_bytes())
    with pytest.warns(UserWarning, match=r"same bytes are one object: copy_of_box \(= box\)"):
        found = load_objects([str(folder)], SMALL)
    assert found.names == ("box", "ball", "rod")  # by path: box.obj, (copy_of_box.obj,) deep/ball.obj, rod.obj
    listing = tmp_path / "objects.txt"
    listing.write_text("# my shelf\nshelf/rod.obj\n\nshelf/box.obj  # the box\n")
    assert load_objects([str(listing)], SMALL).names == ("rod", "box")
    (folder / "broken.obj").write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    with pytest.raises(ValueError, match=r"1 of 4 objects do not load \(--skip-bad runs on the rest\).*broken.obj"):
        load_objects([str(folder)], SMALL)
    with pytest.warns(UserWarning, match="left out 1 of 4 objects"):
        assert load_objects([str(folder)], SMALL, skip_bad=True).names == ("box", "ball", "rod")


def test_a_result_read_back_from_its_json_prints_the_same_tables(tmp_path):
    from classify.reporting.results import ExperimentResult

    config = QUICK.replace(methods=("random", "uniform"), classifiers=("knn",), replicates=2)
    r = quick.run(_objects()[:2], config, out_dir=tmp_path)
    again = ExperimentResult.from_json(json.loads((tmp_path / "results.json").read_text()))
    assert experiment.format_tables(again) == experiment.format_tables(r)
    assert again.cell("uniform", "instance", "knn", 2, False, 3) == r.cell("uniform", "instance", "knn", 2, False, 3)
    assert again.usage == r.usage
    assert len(again.confusions) == len(r.confusions) > 0
    for read, measured in zip(again.confusions, r.confusions):
        assert read.object_names == measured.object_names and read.method == measured.method
        np.testing.assert_array_equal(read.pairs, measured.pairs)


def test_a_run_reports_each_stages_wall_and_cpu_time_and_peak_memory(tmp_path):
    config = QUICK.replace(methods=("uniform",), protocols=("paper", "instance"), classifiers=("knn",), replicates=2)
    r = quick.run(_objects()[:2], config)
    stages = ("paper", "instance_points_and_imprints", "instance_recognition")
    assert set(r.usage) == {*stages, "total"}
    for name in stages:
        assert r.usage[name]["wall_s"] == r.timings[name]
        assert r.usage[name]["cpu_s"] > 0
        # At least this process: the libraries loaded and the objects held.
        assert 50 < r.usage[name]["peak_mb"] <= r.usage["total"]["peak_mb"]
    assert r.usage["total"]["wall_s"] == r.timings["total"]
    assert r.usage["total"]["cpu_s"] == r.timings["cpu_total"]


def _comparable(path):
    """A results.json without what changes from run to run (timings, provenance)."""
    document = json.loads(path.read_text())
    document.pop("timings_s")
    document.pop("usage")
    document["settings"].pop("provenance")
    return document


def test_replicates_measured_a_few_at_a_time_give_the_results_of_all_at_once_and_hold_one_block(
    tmp_path, monkeypatch, capsys
):
    import gc
    import weakref

    from classify.experiment import run as run_mod

    config = QUICK.replace(
        methods=("uniform", "learned"),
        protocols=("instance",),
        classifiers=("knn", "place"),
        policies=("info_gain",),
        replicates=3,
    )
    whole = quick.run(_objects()[:2], config, out_dir=tmp_path / "whole", replicates_at_once=3, n_jobs=1)
    stages, asked = [], []
    build = run_mod.instance_stage

    def one_block_alive(objects, methods, settings, replicates, runtime, **options):
        gc.collect()
        assert all(s() is None for s in stages), "a finished block's instances are still held"
        asked.append(tuple(replicates))
        stage = build(objects, methods, settings, replicates, runtime, **options)
        stages.append(weakref.ref(stage))
        return stage

    monkeypatch.setattr(run_mod, "instance_stage", one_block_alive)
    single = experiment.run_experiment(
        _objects()[:2], config, cache_dir=None, out_dir=tmp_path / "single", replicates_at_once=1, n_jobs=1
    )
    assert asked == [(0,), (1,), (2,)]
    told = capsys.readouterr().err.splitlines()
    assert any(line.startswith("replicates 2 of 3: instances: points+imprints [") for line in told)
    ends = [line for line in told if " measured in " in line]
    assert [line.split(" measured")[0] for line in ends] == [f"replicates 1-{r} of 3" for r in (1, 2, 3)]
    assert ends[0].endswith(" left") and not ends[-1].endswith(" left")
    assert _comparable(tmp_path / "single" / "results.json") == _comparable(tmp_path / "whole" / "results.json")
    for name in ("results.csv", "stopping.csv", "confusion_place.png", "touches.png"):
        assert (tmp_path / "single" / name).read_bytes() == (tmp_path / "whole" / name).read_bytes(), name
    assert sorted(p.name for p in (tmp_path / "single" / "touch_models").iterdir()) == [
        f"replicate_{r:02d}.json" for r in range(3)
    ]
    for key, R in whole.rates.items():
        np.testing.assert_array_equal(single.rates[key], R)
    assert single.selection_kept == whole.selection_kept and whole.selection_kept
    with pytest.raises(ValueError, match="replicates_at_once must be at least 1"):
        quick.run(_objects(), config, replicates_at_once=0)


def test_joined_blocks_of_replicates_sum_as_one_block_bit_for_bit():
    from classify.experiment.stages import Measurement, join_replicates
    from classify.reporting import stats
    from classify.reporting.confusion import ConfusionMatrix, counts_pairs

    rng = np.random.default_rng(3)
    R, K, n, L = 7, 4, 9, 3
    back = rng.permutation(n)
    rng_rates, rng_stop = rng.random((R, K, n)) / 3.0, rng.random((R, L, n)) * 7.0
    rng_counts, rng_sets = rng.integers(0, 5, (R, n, n)), rng.integers(1, 20, (R, K))
    rng_kept = rng.random(R)

    def measured(replicates):
        # As the recognition stages build one: np.stack of per-replicate outcomes, objects put back in order.
        rates = np.stack([100.0 * rng_rates[r] for r in replicates])[:, :, back]
        stop = np.stack([rng_stop[r] for r in replicates])[:, :, back]
        counts = sum(rng_counts[r] for r in replicates)
        return Measurement(
            "uniform",
            "instance",
            "knn",
            n,
            True,
            {k: rates[:, k - 1, :] for k in range(1, K + 1)},
            {k: int(min(rng_sets[r][k - 1] for r in replicates)) for k in range(1, K + 1)},
            ConfusionMatrix("uniform", "instance", "knn", n, True, tuple("abcdefghi"), counts_pairs(counts)),
            tuple(float(rng_kept[r]) for r in replicates),
            (stop, stop + 1.0),
        )

    whole = measured(range(R))
    (joined,) = join_replicates([[measured(b)] for b in ((0, 1, 2), (3,), (4, 5), (6,))])
    for k, rates in whole.rates.items():
        np.testing.assert_array_equal(joined.rates[k], rates)
        assert stats.summarize(joined.rates[k], 0) == stats.summarize(rates, 0)  # the same sums, in the same order
        assert stats.paired_difference(joined.rates[k], whole.rates[1], 0) == stats.paired_difference(
            rates, whole.rates[1], 0
        )
    for mine, theirs in zip(joined.stopping, whole.stopping):
        np.testing.assert_array_equal(mine, theirs)
        assert stats.summarize(mine[:, 1], 0) == stats.summarize(theirs[:, 1], 0)
    np.testing.assert_array_equal(joined.confusion.pairs, whole.confusion.pairs)
    np.testing.assert_array_equal(joined.confusion.counts, sum(rng_counts))
    assert joined.touch_sets == whole.touch_sets and joined.kept == whole.kept
    assert join_replicates([[whole]]) == [whole]
    other = dataclasses.replace(whole, method="random")
    with pytest.raises(ValueError, match="measured different things"):
        join_replicates([[whole], [other]])
