"""Command-line subcommands of the hw package: ``capture``, ``export`` and ``plan``."""

from __future__ import annotations

import sys


def register(subparsers) -> None:
    """Add this package's subcommands to the ``visuotactile`` parser."""
    from hw import capture
    from meshsal.cli import QUIET_HELP, add_model, add_view_size, mesh_help
    from meshsal.points import POINT_METHODS
    from meshsal.util.arguments import HelpFormatter, add_renamed, output_file

    p = subparsers.add_parser(
        "capture",
        formatter_class=HelpFormatter,
        help="record presses from a tactile sensor on a serial port",
        description="Record presses from a tactile sensor on a serial port into a SQLite session: each press's "
        "peak frame (minus the rest baseline) is committed at once under the next point id; running "
        "again on the same session resumes it.  Try it with no hardware: python -m hw.simdevice.",
    )
    capture.add_arguments(p)
    p.set_defaults(func=capture.run)

    p = subparsers.add_parser(
        "export",
        formatter_class=HelpFormatter,
        help="write a capture session as an imprint set (.npz)",
        description="Write the presses of a capture session as a tactile.ImprintSet: labels from the object "
        "names, imprints resampled to ROWS x COLS by area averaging and scaled to [0, 1].",
    )
    p.add_argument("session", help="session file (.sqlite)")
    p.add_argument("--out", required=True, type=output_file, help="imprint set to write (.npz)")
    p.add_argument(
        "--full-scale",
        default="session",
        help="what maps to 1: 'session' (largest reading of the session, default), 'imprint' (each "
        "imprint's own maximum) or a count such as 4095 (the ADC maximum)",
    )
    p.add_argument("--rows", type=int, default=16, help="rows of the exported imprints")
    p.add_argument("--cols", type=int, default=16, help="columns of the exported imprints")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.set_defaults(func=_cmd_export)

    p = subparsers.add_parser(
        "plan",
        formatter_class=HelpFormatter,
        help="plan where a robot should press the sensor on an object",
        description="Write a probe plan: for each interest point its position, approach direction (-normal) and "
        "the sensor's orientation as a unit quaternion [w, x, y, z] (sensor z = approach), in the "
        "mesh file's frame and units, plus the sensor's dimensions; JSON and a CSV beside it.",
    )
    p.add_argument("mesh", help=mesh_help())
    p.add_argument("--out", required=True, type=output_file, help="plan to write (.json; the .csv goes beside it)")
    p.add_argument(
        "--size-mm",
        type=float,
        default=150.0,
        help="principal-frame box diagonal of the object for planning, mm",
    )
    add_renamed(p, "--n", p.add_argument("--n-points", type=int, default=15, help="number of points"))
    p.add_argument(
        "--method",
        default="attention",
        choices=POINT_METHODS.names(),
        help=f"interest point method: {POINT_METHODS.help_text()}",
    )
    add_model(p)
    add_view_size(p)
    p.add_argument("--seed", type=int, default=0, help="seed of the random methods")
    p.add_argument("--quiet", action="store_true", help=QUIET_HELP)
    p.set_defaults(func=_cmd_plan)


def _cmd_export(args) -> int:
    from hw.session import export_imprints

    imprint_set = export_imprints(args.session, rows=args.rows, cols=args.cols, full_scale=args.full_scale)
    imprint_set.save(args.out)
    counts = ", ".join(
        f"{name} {int((imprint_set.labels == i).sum())}" for i, name in enumerate(imprint_set.object_names)
    )
    if not args.quiet:
        print(f"export: {len(imprint_set.labels)} imprints ({counts}) -> {args.out}", file=sys.stderr)
    return 0


def _cmd_plan(args) -> int:
    from hw.plan import make_plan, save_plan
    from meshsal.cli import touch_model
    from meshsal.objects import load_object

    model = touch_model(args.method, args.model)
    mesh = load_object(args.mesh)
    plan = make_plan(
        mesh,
        n=args.n_points,
        method=args.method,
        size_mm=args.size_mm,
        seed=args.seed,
        quiet=args.quiet,
        source=args.mesh,
        model=model,
        view_size=args.view_size,
    )
    json_path, csv_path = save_plan(plan, args.out)
    if len(plan.points) < args.n_points:
        print(
            f"visuotactile plan: warning: {args.mesh}: {len(plan.points)} of the {args.n_points} points asked for "
            "(no more lie half a pad apart, touchable)",
            file=sys.stderr,
        )
    if not args.quiet:
        print(f"plan: {len(plan.points)} points on {args.mesh} -> {json_path}, {csv_path}", file=sys.stderr)
    return 0
