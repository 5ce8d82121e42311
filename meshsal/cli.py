"""Command-line subcommands of meshsal: ``toys``, ``render`` and ``points``."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from meshsal.points.rules import MIN_VIEW_SIZE
from meshsal.util.arguments import HelpFormatter, add_renamed, output_folder

#: Rendered view size in pixels of every subcommand that renders (``PointOptions.size``).
VIEW_SIZE = 128


def mesh_help() -> str:
    """What a MESH argument may be: a file or an embedded object's name."""
    from meshsal.objects import toys, ycb

    return (
        f"mesh file (OBJ, PLY, OFF, STL) or an embedded object's name: a toy ({', '.join(toys.NAMES)}) "
        f"or a YCB scan ({', '.join(ycb.NAMES)})"
    )


def add_model(p) -> None:
    """``--model``, the touch model file the learned methods read."""
    p.add_argument(
        "--model",
        type=Path,
        default=None,
        help="touch model JSON (written by 'visuotactile experiment' to touch_models/) for the learned methods",
    )


def touch_model(method: str, path):
    """The touch model ``--method`` reads, from ``--model``; None for a method that reads none."""
    from meshsal.points import MODEL_METHODS
    from meshsal.points.learned import TouchModel

    if method in MODEL_METHODS and path is None:
        raise ValueError(
            f"--method {method} needs --model FILE, a touch model written by 'visuotactile experiment' "
            "(its touch_models/ folder)"
        )
    return None if path is None else TouchModel.load(path)


def add_view_size(p) -> None:
    """``--view-size``, and ``--size``, its deprecated spelling until 0.3."""
    add_renamed(
        p,
        "--size",
        p.add_argument("--view-size", type=_view_size, default=VIEW_SIZE, help="rendered view size in pixels"),
    )


def _view_size(text: str) -> int:
    size = int(text)
    if size < MIN_VIEW_SIZE:
        raise argparse.ArgumentTypeError(f"must be at least {MIN_VIEW_SIZE} pixels, got {size}")
    return size


def register(subparsers) -> None:
    """Add meshsal's subcommands to the ``visuotactile`` parser."""
    _add_toys(subparsers)
    _add_render(subparsers)
    _add_points(subparsers)


def _add_toys(subparsers) -> None:
    p = subparsers.add_parser(
        "toys",
        formatter_class=HelpFormatter,
        help="write the six embedded toy objects as PLY",
        description="Write the six procedural toys (cow, glasses, cup, hand, plane, dromedary) "
        "as binary PLY files with vertex colors, in millimetres.",
    )
    p.add_argument("--out", required=True, type=output_folder, help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the toys' random details")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.set_defaults(func=_cmd_toys)


def _cmd_toys(args) -> int:
    from meshsal.mesh.io import save_ply
    from meshsal.objects import toys
    from meshsal.util.progress import progress

    for name in progress(toys.NAMES, desc="toys", quiet=args.quiet):
        save_ply(args.out / f"{name}.ply", toys.make(name, seed=args.seed))
    print(f"wrote {len(toys.NAMES)} toys to {args.out}")
    return 0


#: ``--quiet`` means the same in every subcommand.
QUIET_HELP = "no progress bars or status lines on stderr (warnings and errors are still printed)"


def _mesh_subcommand(subparsers, name: str, summary: str, description: str):
    """A subcommand that reads one MESH and writes into the folder --out."""
    p = subparsers.add_parser(name, help=summary, description=description, formatter_class=HelpFormatter)
    p.add_argument("mesh", type=Path, help=mesh_help())
    p.add_argument("--out", required=True, type=output_folder, help="output folder")
    return p


def _add_render(subparsers) -> None:
    p = _mesh_subcommand(
        subparsers,
        "render",
        "render a mesh from the 72 viewpoints",
        "Render MESH from the 72 viewpoints of the rig (18 sets of 4 views 90 degrees apart) "
        "as PNG files view_SS_K.png, plus contact_sheet.png. With --saliency, also each "
        "view's saliency map and its eight channel maps.",
    )
    add_view_size(p)
    p.add_argument("--saliency", action="store_true", help="also write saliency and channel maps")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.set_defaults(func=_cmd_render)


def _to_uint8(image: np.ndarray) -> np.ndarray:
    return (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def _cmd_render(args) -> int:
    from meshsal.objects import load_object
    from meshsal.util.atomic import write_png
    from meshsal.util.errors import naming
    from meshsal.util.progress import progress
    from meshsal.views.cameras import view_rig
    from meshsal.views.overlay import tile
    from meshsal.views.render import render_views

    with naming(args.mesh):
        mesh = load_object(args.mesh)
        cameras = [c for s in view_rig() for c in s]
        views = render_views(mesh, cameras, size=args.view_size)
        results = [None] * len(views)
        if args.saliency:
            from meshsal.attention import saliency_views

            results = saliency_views(views, mesh)
        maps = []
        for view, result in progress(zip(views, results), total=len(views), desc="render", quiet=args.quiet):
            stem = f"view_{view.camera.set_index:02d}_{view.camera.view_index % 4}"
            write_png(args.out / f"{stem}.png", _to_uint8(view.rgb))
            if result is not None:
                maps.append(_to_uint8(result.map))
                write_png(args.out / f"{stem}_saliency.png", maps[-1])
                for name, channel in result.channels.items():
                    write_png(args.out / f"{stem}_{name}.png", _to_uint8(channel))
        write_png(args.out / "contact_sheet.png", tile([_to_uint8(v.rgb) for v in views], columns=12))
        if maps:
            write_png(args.out / "saliency_sheet.png", tile(maps, columns=12))
    print(f"wrote {len(views)} views of {args.mesh} to {args.out}")
    return 0


def _add_points(subparsers) -> None:
    from meshsal.points import COMBINATIONS, POINT_METHODS

    p = _mesh_subcommand(
        subparsers,
        "points",
        "choose interest points on a mesh by visual attention (or a baseline)",
        "Scale MESH to --size-mm (principal-frame box diagonal), render the 72 views, compute their saliency and "
        "choose --n-points interest points (the paper's pipeline, or a baseline with --method). Writes "
        "saliency.ply (mesh saliency as vertex quality and colours), points.json and points.csv "
        "(ids from 0, in the mesh file's own units and frame), views.png (the best set's four "
        "views, saliency overlaid, points numbered) and contact_sheet.png (all 72 saliency maps). "
        "Fewer points than asked (the mesh cannot hold more that far apart and touchable) is a warning; "
        "none is an error.",
    )
    add_renamed(p, "--n", p.add_argument("--n-points", type=int, default=15, help="number of points"))
    p.add_argument(
        "--method",
        choices=POINT_METHODS.names(),
        default="attention",
        help=f"how to choose them: {POINT_METHODS.help_text()}",
    )
    p.add_argument(
        "--size-mm",
        type=float,
        default=150.0,
        help="scale the mesh to this principal-frame box diagonal in mm first, as the experiment does",
    )
    p.add_argument("--pad-mm", type=float, default=32.0, help="width of the tactile pad in mm (16 x 16 taxels at 2 mm)")
    p.add_argument(
        "--min-spacing-mm",
        type=float,
        default=None,
        help="no two points closer than this, in mm after scaling (default: half of --pad-mm)",
    )
    p.add_argument(
        "--combination",
        choices=COMBINATIONS,
        default="equal",
        help="deprecated, goes in 0.3: --method attention_itti or attention_learned choose the combination",
    )
    add_model(p)
    p.add_argument(
        "--no-touch-check",
        dest="touch",
        action="store_false",
        help="keep points the pad, pressed along the normal, would not meet first",
    )
    add_view_size(p)
    add_renamed(
        p,
        "--threshold",
        p.add_argument(
            "--peak-threshold",
            type=float,
            default=0.5,
            help="peaks and salient pixels exceed this fraction of their map's maximum",
        ),
    )
    p.add_argument("--seed", type=int, default=0, help="seed of the random baselines")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.set_defaults(func=_cmd_points)


def _cmd_points(args) -> int:
    from meshsal.attention import plateau_fraction
    from meshsal.mesh import Similarity
    from meshsal.mesh.curvature import mesh_saliency
    from meshsal.mesh.io import save_ply
    from meshsal.mesh.transform import scale_to_principal
    from meshsal.objects import load_object
    from meshsal.points import (
        ATTENTION_METHODS,
        attention_combination,
        attention_maps,
        best_view_set,
        points_by_method,
        view_channels,
    )
    from meshsal.util.atomic import write_png
    from meshsal.util.errors import naming
    from meshsal.views import overlay

    if args.combination != "equal":
        method = next(m for m, c in ATTENTION_METHODS.items() if c == args.combination)
        print(
            f"visuotactile points: warning: --combination is deprecated and goes in 0.3: use --method {method} "
            "(FutureWarning)",
            file=sys.stderr,
        )
        if args.method == "attention":
            args.method = method
    combination = attention_combination(args.method)
    model = touch_model(args.method, args.model)
    with naming(args.mesh):
        mesh = scale_to_principal(load_object(args.mesh), args.size_mm)
        vertex_saliency = mesh_saliency(mesh)
        seen = view_channels(mesh, size=args.view_size, vertex_saliency=vertex_saliency, quiet=args.quiet)
        weights = model.channel_weights if combination == "learned" else None
        rule = {
            "min_spacing": args.min_spacing_mm,
            "threshold": args.peak_threshold,
            "pad_width": args.pad_mm,
            "touch": args.touch,
        }
        pts = points_by_method(
            mesh,
            [args.method],
            n=args.n_points,
            seed=args.seed,
            size=args.view_size,
            vertex_saliency=vertex_saliency,
            seen=seen,
            model=model,
            **rule,
        )[args.method]
        _fewer_points(args, pts)
        views, maps = seen.views, attention_maps(seen, combination, weights)

        to_source = mesh.transform.to_source
        top = float(vertex_saliency.max())
        colors = overlay.colormap(vertex_saliency / top if top > 0 else vertex_saliency) / np.float32(255.0)
        source_mesh = mesh.replace(vertices=to_source(mesh.vertices), vertex_colors=colors, transform=Similarity())
        save_ply(args.out / "saliency.ply", source_mesh, quality=vertex_saliency)

        settings = {
            "n_points": args.n_points,
            "method": args.method,
            "size_mm": args.size_mm,
            "view_size": args.view_size,
            "peak_threshold": args.peak_threshold,
            "seed": args.seed,
            "combination": combination,
            "pad_mm": args.pad_mm,
            "touch_check": args.touch,
            "model": None if args.model is None else str(args.model),
            "channel_weights": weights,
        }
        pts.save(args.out / "points.json", frame=mesh.transform, source=str(args.mesh), settings=settings)
        pts.save_csv(args.out / "points.csv", frame=mesh.transform)

        best = pts.best_set if pts.best_set >= 0 else best_view_set(maps)
        write_png(
            args.out / "views.png", overlay.views_picture(views, maps, range(4 * best, 4 * best + 4), pts.positions)
        )
        write_png(args.out / "contact_sheet.png", overlay.contact_sheet(maps, [v.mask for v in views]))
        plateau = np.median([plateau_fraction(m, v.mask) for m, v in zip(maps, views)])
    lost = f", {pts.untouchable} candidates the pad could not touch first skipped" if pts.untouchable > 0 else ""
    print(
        f"wrote {len(pts)} {args.method} points of {args.mesh} to {args.out}{lost}; "
        f"saliency maps ({combination}): median {100 * plateau:.0f} % of the silhouette above half "
        f"the maximum"
    )
    return 0


def _fewer_points(args, pts) -> None:
    """Say on stderr that a mesh held fewer points than asked, and why; none at all is an error."""
    why = []
    if pts.untouchable > 0:
        why.append(f"{pts.untouchable} candidates the pad could not touch first were skipped")
    if len(pts) == 0:
        raise ValueError(f"{args.mesh}: no {args.method} point found ({'; '.join(why) or 'no candidate'})")
    if len(pts) < args.n_points:
        spacing = args.min_spacing_mm if args.min_spacing_mm is not None else args.pad_mm / 2
        why.append(f"no more lie {spacing:g} mm apart on the mesh at {args.size_mm:g} mm")
        print(
            f"visuotactile points: warning: {args.mesh}: {len(pts)} of the {args.n_points} {args.method} points "
            f"asked for ({'; '.join(why)})",
            file=sys.stderr,
        )
