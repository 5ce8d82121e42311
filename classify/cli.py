"""The ``visuotactile`` command line.

classify sits at the end of the data flow (mesh -> points -> imprints ->
recognition), so it is the one package that may see all the others; each
package registers its own subcommands here.
"""

from __future__ import annotations

import argparse
import sys


def register(subparsers) -> None:
    """Add the recognition subcommands (``experiment``)."""
    p = subparsers.add_parser(
        "experiment",
        help="recognition experiment: interest points -> imprints -> five classifiers (Table 1)",
        description=("Run the whole pipeline on the six toy objects (or --objects MESH ...): interest points, "
                     "simulated 16x16 imprints, and recognition by kNN, naive Bayes, decision tree, "
                     "evolutionary SVM and a deep network under the 'paper' protocol (stratified 5-fold CV "
                     "repeated 10x, similarity selection on training folds only) and the 'retouch' protocol "
                     "(train on clean imprints, test on perturbed re-acquisitions, k-touch fusion). Prints the "
                     "paper's Table 1 layout and writes results.json, results.csv, confusion_<classifier>.png "
                     "and touches.png under --out. With --real, reports recognition on a saved ImprintSet "
                     "(the paper's Table 2 layout) instead."),
    )
    p.add_argument("--objects", nargs="+", metavar="MESH",
                   help="mesh files (OBJ/PLY/OFF/STL) or toy names; default: the six toys")
    p.add_argument("--size-mm", type=float, default=150.0, help="scale every object to this diagonal (mm)")
    p.add_argument("--methods", type=_csv_list, default=("attention",),
                   help="comma-separated interest-point methods: attention,random,uniform,mesh_saliency,curvature")
    p.add_argument("--protocols", type=_csv_list, default=("paper", "retouch"),
                   help="comma-separated protocols: paper,retouch")
    p.add_argument("--classifiers", type=_csv_list, default=None,
                   help="comma-separated subset of knn,naive_bayes,decision_tree,evolutionary_svm,deep")
    p.add_argument("--n-points", type=int, default=15, help="interest points per object")
    p.add_argument("--folds", type=int, default=5, help="cross-validation folds")
    p.add_argument("--repeats", type=int, default=10, help="repeats (seeds) of each protocol")
    p.add_argument("--view-size", type=int, default=None, help="rendered view size for the interest points")
    p.add_argument("--mode", choices=("contour", "pressure"), default=None,
                   help="imprint mode of the simulated sensor (default: tactile.Sensor's)")
    p.add_argument("--out", default="results", help="output directory (default ./results)")
    p.add_argument("--cache-dir", default=None,
                   help="cache of points and imprints (default $XDG_CACHE_HOME/visuotactile or "
                        "./.cache/visuotactile); 'none' disables it")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--jobs", type=int, default=2, help="threads fitting classifiers")
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument("--real", metavar="SET.npz",
                   help="a saved tactile.ImprintSet (e.g. from 'visuotactile export'): report recognition on it")
    p.set_defaults(func=_experiment)


def _csv_list(text: str) -> tuple:
    items = tuple(s.strip() for s in text.split(",") if s.strip())
    if not items:
        raise argparse.ArgumentTypeError("expected a comma-separated list")
    return items


def _experiment(args) -> int:
    from classify import NAMES
    from classify.experiment import format_tables, run_experiment, run_real

    classifiers = args.classifiers or NAMES
    if args.real:
        result = run_real(args.real, folds=args.folds, repeats=args.repeats, seed=args.seed,
                          classifiers=classifiers, out_dir=args.out, quiet=args.quiet, n_jobs=args.jobs)
        print(format_tables(result, title="Table 2 layout (real imprints)"))
        return 0
    cache_dir = "default" if args.cache_dir is None else (None if args.cache_dir.lower() == "none"
                                                          else args.cache_dir)
    sensor = None
    if args.mode is not None:
        import tactile

        sensor = tactile.Sensor(mode=args.mode)
    result = run_experiment(objects=args.objects, size_mm=args.size_mm, methods=args.methods, protocols=args.protocols,
                            n_points=args.n_points, folds=args.folds, repeats=args.repeats, seed=args.seed,
                            view_size=args.view_size, out_dir=args.out, cache_dir=cache_dir, quiet=args.quiet,
                            classifiers=classifiers, sensor=sensor, n_jobs=args.jobs)
    print(format_tables(result))
    if not args.quiet:
        print(f"results written to {args.out}/", file=sys.stderr)
    return 0


def build_parser() -> argparse.ArgumentParser:
    from hw import cli as hw_cli
    from meshsal import cli as meshsal_cli
    from tactile import cli as tactile_cli

    parser = argparse.ArgumentParser(
        prog="visuotactile",
        description="Recognize an object by touch, touching only where vision says it is worth touching.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    meshsal_cli.register(sub)
    tactile_cli.register(sub)
    register(sub)
    hw_cli.register(sub)
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; returns the exit status (0 success, 1 bad input or failure)."""
    args = build_parser().parse_args(argv)
    try:
        return int(args.func(args) or 0)
    except (ValueError, OSError) as exc:
        print(f"visuotactile {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print(f"visuotactile {args.command}: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
