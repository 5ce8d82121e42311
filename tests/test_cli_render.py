"""`visuotactile toys` and `visuotactile render` end to end."""

import cv2
import numpy as np
import pytest
from shapes import icosphere, write_obj

from classify.cli import main
from meshsal.mesh.io import save_ply


@pytest.fixture
def sphere_file(tmp_path):
    path = tmp_path / "sphere.ply"
    save_ply(path, icosphere(radius=10.0, subdivisions=2))
    return path


def test_render_writes_72_views_and_a_contact_sheet(sphere_file, tmp_path, capsys):
    out = tmp_path / "views"
    assert main(["render", str(sphere_file), "--out", str(out), "--view-size", "32", "--quiet"]) == 0
    views = sorted(out.glob("view_*.png"))
    assert len(views) == 72
    first = cv2.imread(str(views[0]))
    assert first.shape == (32, 32, 3) and first[16, 16].mean() > 100 and first[0, 0].max() == 0
    sheet = cv2.imread(str(out / "contact_sheet.png"))
    assert sheet.shape[0] > 32 * 6 and sheet.shape[1] > 32 * 12
    assert "wrote 72 views" in capsys.readouterr().out


def test_render_saliency_writes_the_map_and_eight_channels_per_view(sphere_file, tmp_path):
    from meshsal.attention import CHANNELS

    out = tmp_path / "views"
    assert main(["render", str(sphere_file), "--out", str(out), "--view-size", "32", "--saliency", "--quiet"]) == 0
    assert len(list(out.glob("view_*_saliency.png"))) == 72
    for name in CHANNELS:
        assert len(list(out.glob(f"view_*_{name}.png"))) == 72
    saliency = cv2.imread(str(out / "view_00_0_saliency.png"), cv2.IMREAD_GRAYSCALE)
    assert saliency.shape == (32, 32) and saliency[0, 0] == 0
    assert (out / "saliency_sheet.png").exists()


def test_render_shows_progress_on_stderr_unless_quiet(sphere_file, tmp_path, capsys):
    assert main(["render", str(sphere_file), "--out", str(tmp_path / "v"), "--view-size", "16"]) == 0
    assert "render [" in capsys.readouterr().err


def test_render_of_a_bad_mesh_fails_with_the_loaders_message(tmp_path, capsys):
    bad = tmp_path / "broken.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nf 1 2 7\n")
    out = tmp_path / "views"
    assert main(["render", str(bad), "--out", str(out), "--quiet"]) == 1
    err = capsys.readouterr().err
    assert "broken.obj" in err and "error" in err
    assert not out.exists() or not any(out.iterdir())


@pytest.mark.parametrize("command", ["render", "points", "plan"])
def test_a_tiny_view_size_is_refused_as_the_command_line_is_read(sphere_file, tmp_path, capsys, command):
    out = str(tmp_path / ("plan.json" if command == "plan" else "out"))
    with pytest.raises(SystemExit) as exit_info:
        main([command, str(sphere_file), "--out", out, "--view-size", "4", "--quiet"])
    assert exit_info.value.code == 2
    assert "argument --view-size: must be at least 16 pixels, got 4" in capsys.readouterr().err


def test_toys_writes_six_coloured_plys(tmp_path):
    from meshsal import load_mesh
    from meshsal.objects import toys

    assert main(["toys", "--out", str(tmp_path), "--quiet"]) == 0
    for name in toys.NAMES:
        mesh = load_mesh(tmp_path / f"{name}.ply")
        assert mesh.vertex_colors is not None and mesh.n_faces >= 5000
        assert np.ptp(mesh.vertices, axis=0).max() <= 250.0


def test_help_of_every_subcommand(capsys):
    with pytest.raises(SystemExit) as exit_info:
        main(["--help"])
    assert exit_info.value.code == 0
    commands = ["toys", "render", "points", "imprints", "experiment", "plan", "capture", "export"]
    for command in commands:
        with pytest.raises(SystemExit) as exit_info:
            main([command, "--help"])
        assert exit_info.value.code == 0
    assert "--out" in capsys.readouterr().out


@pytest.mark.parametrize("argv", [["--help"], ["toys", "--help"], ["render", "--help"], ["capture", "--help"]])
def test_help_and_light_subcommands_start_without_the_classifiers(argv):
    import subprocess
    import sys

    # A fresh interpreter: this one has imported scikit-learn already.
    code = (
        "import sys\n"
        "from classify.cli import main\n"
        "try:\n"
        f"    main({argv!r})\n"
        "except SystemExit as exit:\n"
        "    assert exit.code == 0, exit.code\n"
        "print(sorted(m for m in ('sklearn', 'classify.experiment', 'classify.recognizers') if m in sys.modules))\n"
    )
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert run.stdout.strip().splitlines()[-1] == "[]"


def test_a_chosen_subcommand_gets_its_deferred_options(capsys):
    from classify.cli import build_parser

    args = build_parser(deferred=True).parse_args(["experiment", "--objects", "cup", "--codebook-draws", "3"])
    assert args.objects == ["cup"] and args.codebook_draws == 3 and args.command == "experiment"
    args = build_parser(deferred=True).parse_args(["batch", "meshes", "--out", "store"])
    assert args.directory == "meshes" and args.methods == ("attention", "uniform")
    with pytest.raises(SystemExit):
        build_parser(deferred=True).parse_args(["experiment", "--no-such-option"])
    assert "unrecognized arguments: --no-such-option" in capsys.readouterr().err


@pytest.mark.parametrize(
    "argv, option, kind",
    [
        (["toys", "--out", "{file}"], "--out", "file"),
        (["render", "cup", "--out", "{file}/views"], "--out", "inside"),
        (["points", "cup", "--out", "{file}"], "--out", "file"),
        (["imprints", "cup", "--points", "p.json", "--out", "{folder}"], "--out", "folder"),
        (["plan", "cup", "--out", "{folder}"], "--out", "folder"),
        (["export", "s.sqlite", "--out", "{file}/set.npz"], "--out", "inside"),
        (["experiment", "--objects", "cup,hand", "--out", "{file}"], "--out", "file"),
        (["experiment", "--objects", "cup,hand", "--cache-dir", "{file}"], "--cache-dir", "file"),
        (["batch", "{folder}", "--out", "{file}"], "--out", "file"),
    ],
)
def test_an_output_that_cannot_be_written_is_refused_as_the_command_line_is_read(tmp_path, capsys, argv, option, kind):
    file, folder = tmp_path / "notes.txt", tmp_path / "folder"
    file.write_text("")
    folder.mkdir()
    argv = [a.format(file=file, folder=folder) for a in argv]
    with pytest.raises(SystemExit) as exit_info:
        main(argv + ["--quiet"])
    assert exit_info.value.code == 2
    problem = {
        "file": f"{file}: exists and is a file, not a folder",
        "folder": f"{folder}: exists and is a folder, not a file",
        "inside": f"cannot be written: {file} is a file, not a folder",
    }[kind]
    err = " ".join(capsys.readouterr().err.split())  # argparse wraps long messages
    assert f"visuotactile {argv[0]}: error: argument {option}: " in err and problem in err


def test_every_subcommand_takes_quiet_names_ycb_objects_and_shows_its_defaults():
    import argparse

    from classify.cli import build_parser

    commands = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)).choices
    for name, parser in commands.items():
        text = parser.format_help()
        assert "--quiet" in text and "%%" not in text, name
        for action in parser._actions:
            shown = action.default not in (None, (), argparse.SUPPRESS) and action.nargs != 0
            if shown and action.help != argparse.SUPPRESS:
                assert "default" in parser._get_formatter()._format_action(action), (name, action.dest)
        if any(a.dest == "mesh" for a in parser._actions):
            assert "foam_brick" in text and "dromedary" in text, name
    points = " ".join(commands["points"].format_help().split())
    assert "--n-points N_POINTS number of points (default: 15)" in points
    assert "--view-size VIEW_SIZE rendered view size in pixels (default: 128)" in points
    assert "95 % bootstrap" in " ".join(commands["experiment"].format_help().split())


def test_render_takes_a_toy_name_for_a_mesh(tmp_path):
    out = tmp_path / "cup"
    assert main(["render", "cup", "--out", str(out), "--view-size", "16", "--quiet"]) == 0
    assert len(list(out.glob("view_*.png"))) == 72


def test_a_missing_mesh_that_is_no_toy_fails_naming_it(tmp_path, capsys):
    assert main(["render", str(tmp_path / "teapot.obj"), "--out", str(tmp_path / "v"), "--quiet"]) == 1
    assert "teapot.obj" in capsys.readouterr().err


def test_a_repair_warning_names_the_file_and_not_our_source_line(tmp_path, capsys):
    mesh = icosphere(radius=10.0, subdivisions=2)
    path = tmp_path / "stray.obj"
    write_obj(path, mesh.replace(vertices=np.vstack([mesh.vertices, [99.0, 99, 99]])))
    assert main(["render", str(path), "--out", str(tmp_path / "v"), "--view-size", "16", "--quiet"]) == 0
    err = capsys.readouterr().err
    warned = [line for line in err.splitlines() if "warning" in line]
    assert len(warned) == 1, err
    assert warned[0].startswith("visuotactile render: warning: ") and str(path) in warned[0]
    assert "unreferenced" in warned[0] and warned[0].endswith("(MeshRepairWarning)")
    assert ".py:" not in err


@pytest.mark.parametrize(
    "argv, old, new, dest, value",
    [
        (["render", "cup", "--out", "o", "--size", "64"], "--size", "--view-size", "view_size", 64),
        (["points", "cup", "--out", "o", "--n", "4"], "--n", "--n-points", "n_points", 4),
        (["plan", "cup", "--out", "o.json", "--n", "4"], "--n", "--n-points", "n_points", 4),
        (["capture", "--port", "p", "--session", "s", "--object", "cup", "--threshold", "40"], "--threshold",
         "--press-threshold", "press_threshold", 40.0),
    ],
)  # fmt: skip
def test_a_renamed_option_keeps_its_old_spelling_for_a_release(capsys, argv, old, new, dest, value):
    from classify.cli import build_parser

    assert getattr(build_parser().parse_args(argv), dest) == value
    assert f"visuotactile {argv[0]}: warning: {old} is deprecated and goes in 0.3: use {new}" in capsys.readouterr().err


@pytest.mark.parametrize("screening, params", [(None, {}), ("place", {}), ("touch", {"place": {"screening": "touch"}})])
def test_experiment_passes_the_place_aware_screening_to_the_recognizer(monkeypatch, tmp_path, screening, params):
    import classify.experiment
    from classify.cli import main

    seen = []

    def stop(objects, config, **_):
        seen.append(config)
        raise SystemExit(7)

    monkeypatch.setattr(classify.experiment, "run_experiment", stop)
    argv = ["experiment", "--objects", "cup,hand", "--jobs", "1", "--out", str(tmp_path / "out"), "--quiet"]
    with pytest.raises(SystemExit) as exit_:
        main(argv + ([] if screening is None else ["--screening", screening]))
    assert exit_.value.code == 7 and seen[0].params == params


def test_experiment_refuses_an_unknown_screening(capsys):
    from classify.cli import build_parser

    with pytest.raises(SystemExit):
        build_parser(deferred=True).parse_args(["experiment", "--screening", "sight"])
    assert "argument --screening: invalid choice: 'sight'" in capsys.readouterr().err
