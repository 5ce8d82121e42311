"""Command-line subcommands of the tactile package: ``imprints``."""

from __future__ import annotations

from pathlib import Path


def register(subparsers) -> None:
    """Add this package's subcommands to the ``visuotactile`` parser."""
    from meshsal.cli import QUIET_HELP, mesh_help
    from meshsal.util.arguments import HelpFormatter, output_file
    from tactile.sensor import SENSOR_MODES, SENSOR_PLANES, Sensor

    default = Sensor()
    p = subparsers.add_parser(
        "imprints",
        formatter_class=HelpFormatter,
        help="simulate the tactile imprints at interest points of a mesh",
        description="Scale MESH to --size-mm, press a simulated 16x16 tactile pad at each point of POINTS "
        "(the points.json written by 'visuotactile points': positions and normals in the mesh "
        "file's units) and write the imprint set (.npz) and imprints.png, a labelled grid of "
        "the imprints, beside it. An imprint set in which the pad touched nothing is an error.",
    )
    p.add_argument("mesh", type=Path, metavar="MESH", help=mesh_help())
    p.add_argument(
        "--points", type=Path, required=True, metavar="POINTS", help="points.json from 'visuotactile points'"
    )
    p.add_argument("--out", type=output_file, required=True, metavar="SET.npz", help="imprint set to write")
    p.add_argument(
        "--size-mm",
        type=float,
        default=150.0,
        help="principal-frame box diagonal the mesh is scaled to, in mm, as 'visuotactile points' and the "
        "experiment do",
    )
    p.add_argument("--mode", choices=SENSOR_MODES.names(), default=default.mode, help=SENSOR_MODES.help_text())
    p.add_argument("--plane", choices=SENSOR_PLANES.names(), default=default.plane, help=SENSOR_PLANES.help_text())
    p.add_argument("--pitch-mm", type=float, default=default.pitch_mm, help="taxel spacing in mm")
    p.add_argument("--depth-mm", type=float, default=default.depth_mm, help="pressing depth beyond first contact in mm")
    p.add_argument("--supersample", type=int, default=default.supersample, help="rays per taxel side")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.set_defaults(func=_cmd_imprints)


def read_points(path) -> tuple:
    """Positions (k,3), unit normals (k,3) and ids (k,) from a points.json, in the file's frame.

    ``meshsal.InterestPoints.load`` reads and checks it (ValueError naming the file).
    """
    from meshsal.points import InterestPoints

    pts = InterestPoints.load(path)
    return pts.positions, pts.normals, pts.ids


def _cmd_imprints(args) -> int:
    from meshsal.mesh.transform import scale_to_principal
    from meshsal.objects import load_object
    from meshsal.util.atomic import write_png
    from meshsal.util.errors import naming
    from tactile.imprint_set import ImprintSet
    from tactile.picture import imprint_grid
    from tactile.raycast import imprints
    from tactile.sensor import Sensor

    if args.out.suffix != ".npz":
        raise ValueError(f"--out must name a .npz file, got {args.out}")
    sensor = Sensor(
        pitch_mm=args.pitch_mm, depth_mm=args.depth_mm, mode=args.mode, supersample=args.supersample, plane=args.plane
    )
    source_positions, normals, ids = read_points(args.points)
    with naming(args.mesh):
        mesh = scale_to_principal(load_object(args.mesh), args.size_mm)
        positions = mesh.transform.apply(source_positions)
        normals = mesh.transform.apply_direction(normals)
        _check_on_surface(mesh, positions, ids, args)
        images = imprints(mesh, positions, normals, sensor)
        _check_contact(mesh, positions, normals, sensor, args)
        result = ImprintSet(
            imprints=images,
            labels=[0] * len(images),
            object_names=(mesh.name or args.mesh.stem,),
            point_ids=ids,
            positions=positions,
            normals=normals,
            sensor=sensor,
            source=f"{args.mesh} at {args.points}, scaled to {args.size_mm:g} mm",
        )
        result.save(args.out)
        picture = args.out.parent / "imprints.png"
        write_png(picture, imprint_grid(images, [f"#{i}" for i in ids]))
    print(f"wrote {len(images)} {sensor.mode} imprints of {args.mesh} to {args.out} and {picture}")
    return 0


# Points are exact surface points; a thousandth of the object's size leaves room for the loader's vertex merging.
_ON_SURFACE = 1e-3


def _check_on_surface(mesh, positions, ids, args) -> None:
    """Refuse points that are not on this mesh: pressed from off the surface, the pad would feel nothing real."""
    import numpy as np

    from meshsal.mesh.geometry import surface_distance

    off = surface_distance(mesh.vertices, mesh.faces, positions)
    far = np.flatnonzero(off > _ON_SURFACE * args.size_mm)
    if far.size:
        worst = far[np.argmax(off[far])]
        raise ValueError(
            f"{args.points}: {far.size} of {len(off)} points lie off the surface of {args.mesh} (point #{ids[worst]} "
            f"by {off[worst]:.3g} mm at {args.size_mm:g} mm): they were chosen on another mesh, or on another "
            "version of this one"
        )


def _check_contact(mesh, positions, normals, sensor, args) -> None:
    """Refuse an imprint set in which the pad met the surface nowhere: its imprints would be silent zeros.

    Contact is read from the depths under the pads, not from the images: a
    contour image of a flat contact is blank.
    """
    import numpy as np

    from tactile.raycast import cast_depths
    from tactile.sensor import sensor_poses

    depth = cast_depths(mesh, sensor_poses(mesh, positions, normals, sensor), sensor)
    if not np.isfinite(depth).any():
        raise ValueError(
            f"{args.points}: the pad met {args.mesh} at none of its {len(positions)} points ({sensor.width_mm:g} mm "
            f"pad, {sensor.pitch_mm:g} mm pitch, the mesh scaled to {args.size_mm:g} mm): no imprint set written"
        )
