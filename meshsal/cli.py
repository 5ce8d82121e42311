"""Command-line subcommands of meshsal: ``toys``, ``render`` and ``points``."""

from __future__ import annotations

from pathlib import Path

import numpy as np


def register(subparsers) -> None:
    """Add meshsal's subcommands to the ``visuotactile`` parser."""
    _add_toys(subparsers)
    _add_render(subparsers)


def _add_toys(subparsers) -> None:
    p = subparsers.add_parser(
        "toys", help="write the six embedded toy objects as PLY",
        description="Write the six procedural toys (cow, glasses, cup, hand, plane, dromedary) "
                    "as binary PLY files with vertex colors, in millimetres.")
    p.add_argument("--out", required=True, type=Path, help="output folder")
    p.add_argument("--seed", type=int, default=0, help="seed of the toys' random details (default 0)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_toys)


def _cmd_toys(args) -> int:
    from . import toys
    from .io import save_ply
    from .progress import progress

    for name in progress(toys.NAMES, desc="toys", quiet=args.quiet):
        save_ply(args.out / f"{name}.ply", toys.make(name, seed=args.seed))
    print(f"wrote {len(toys.NAMES)} toys to {args.out}")
    return 0


def _add_render(subparsers) -> None:
    p = subparsers.add_parser(
        "render", help="render a mesh from the 72 viewpoints",
        description="Render MESH from the 72 viewpoints of the rig (18 sets of 4 views 90 degrees apart) "
                    "as PNG files view_SS_K.png, plus contact_sheet.png. With --saliency, also each "
                    "view's saliency map and its eight channel maps.")
    p.add_argument("mesh", type=Path, help="mesh file (OBJ, PLY, OFF, STL)")
    p.add_argument("--out", required=True, type=Path, help="output folder")
    p.add_argument("--size", type=int, default=256, help="image size in pixels (default 256)")
    p.add_argument("--saliency", action="store_true", help="also write saliency and channel maps")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=_cmd_render)


def _to_uint8(image: np.ndarray) -> np.ndarray:
    return (np.clip(image, 0.0, 1.0) * 255.0 + 0.5).astype(np.uint8)


def contact_sheet(images, columns: int = 12, gap: int = 2) -> np.ndarray:
    """Tile equally sized (H,W) or (H,W,3) uint8 images into one RGB sheet, row-major."""
    images = [np.repeat(im[..., None], 3, axis=2) if im.ndim == 2 else im for im in images]
    h, w = images[0].shape[:2]
    rows = -(-len(images) // columns)
    sheet = np.full((rows * (h + gap) + gap, columns * (w + gap) + gap, 3), 255, np.uint8)
    for k, im in enumerate(images):
        r, c = divmod(k, columns)
        sheet[gap + r * (h + gap): gap + r * (h + gap) + h, gap + c * (w + gap): gap + c * (w + gap) + w] = im
    return sheet


def _cmd_render(args) -> int:
    from .atomic import write_png
    from .io import load_mesh
    from .progress import progress
    from .render import render_views, view_rig

    if args.size < 16:
        raise ValueError(f"--size must be at least 16 pixels, got {args.size}")
    mesh = load_mesh(args.mesh)
    cameras = [c for s in view_rig() for c in s]
    views = render_views(mesh, cameras, size=args.size)
    vertex_saliency = None
    if args.saliency:
        from .curvature import mesh_saliency

        vertex_saliency = mesh_saliency(mesh)
    maps = []
    for view in progress(views, desc="render", quiet=args.quiet):
        stem = f"view_{view.camera.set_index:02d}_{view.camera.view_index % 4}"
        write_png(args.out / f"{stem}.png", _to_uint8(view.rgb))
        if args.saliency:
            from .attention import saliency

            result = saliency(view, mesh, vertex_saliency=vertex_saliency)
            maps.append(_to_uint8(result.map))
            write_png(args.out / f"{stem}_saliency.png", maps[-1])
            for name, channel in result.channels.items():
                write_png(args.out / f"{stem}_{name}.png", _to_uint8(channel))
    write_png(args.out / "contact_sheet.png", contact_sheet([_to_uint8(v.rgb) for v in views]))
    if maps:
        write_png(args.out / "saliency_sheet.png", contact_sheet(maps))
    print(f"wrote {len(views)} views of {args.mesh} to {args.out}")
    return 0
