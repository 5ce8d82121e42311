"""The ``visuotactile`` command line.

classify sits at the end of the data flow (mesh -> points -> imprints ->
recognition), so it is the one package that may see all the others; each
package registers its own subcommands here.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import sys
import threading
import warnings
from concurrent.futures import BrokenExecutor

from meshsal.util.arguments import HelpFormatter, Subcommands, defer_options, output_folder


def register(subparsers) -> None:
    """Add the recognition subcommands (``experiment``, ``batch``).

    Their options name the registries' entries, which import the classifiers
    and scikit-learn: they are added when the subcommand is chosen
    (``meshsal.util.arguments.defer_options``).
    """
    p = subparsers.add_parser(
        "experiment",
        help="recognition experiment: interest points -> imprints -> five classifiers (Table 1)",
        description=(
            "Run the whole pipeline on the six toy objects (or --objects): interest points, simulated "
            "16x16 imprints, and recognition by kNN, naive Bayes, decision tree, evolutionary SVM and a "
            "deep network under the 'paper' protocol (one clean imprint per point, 5-fold CV grouped by "
            "point, repeated, similarity selection on training folds only: the paper's Table 1 like with "
            "like) and the 'instance' protocol (train on several fresh instances of each object: turned, "
            "resized, repainted, each touched in its own sessions; test on another instance after "
            "k = 1..n touches, calibrated posteriors multiplied). Rates come with 95 % bootstrap "
            "intervals over replicates and objects; with several --methods, paired differences against "
            "--baseline. Prints Markdown tables and writes results.json, results.csv, "
            "confusion_<classifier>.png and touches.png under --out (with a learned method, each "
            "replicate's touch model in touch_models/). With --real, reports recognition "
            "on a saved ImprintSet (the paper's Table 2 layout) instead."
        ),
    )
    p.set_defaults(func=_experiment)
    defer_options(subparsers, p, _experiment_options)

    b = subparsers.add_parser(
        "batch",
        help="points and imprints for every mesh of a folder, on a Dask cluster, into a resumable store",
        description=(
            "Compute interest points (per --methods) and their simulated imprints for every mesh file "
            "(.obj .ply .off .stl) under DIR, one task per mesh on a Dask cluster: a LocalCluster of "
            "--workers processes (default: one per core), or an existing cluster at --scheduler. Each "
            "mesh's entry is written atomically to STORE/meshes/<name>.npz; a rerun skips the meshes "
            "already there. Every mesh is read first: meshes that cannot be read are listed and nothing is computed "
            "unless --skip-bad; a mesh identical to another (as loaded) is stored once and listed in "
            "STORE/duplicates.jsonl; a mesh that fails later goes to STORE/failures.jsonl and does not stop the "
            "batch, and what loading repaired goes to STORE/repairs.jsonl. "
            "Load the store with classify.batch.load_store(STORE)."
        ),
    )
    b.set_defaults(func=_batch)
    defer_options(subparsers, b, _batch_options)


def _experiment_options(p) -> None:
    from classify.experiment import DEFAULT_REPLICATES, FULL_REPLICATES, REPLICATES_AT_ONCE
    from classify.experiment.config import CONTROLS, MISMATCHES
    from classify.experiment.protocols import PROTOCOL_REGISTRY, PROTOCOLS
    from classify.policies import POLICIES
    from classify.recognizers.classifiers import CLASSIFIERS
    from classify.recognizers.place import SCREENINGS
    from classify.recognizers.shortlist import EXACT_PLACES, SHORTLIST
    from meshsal.points import POINT_METHODS

    p.add_argument(
        "--objects",
        nargs="+",
        metavar="OBJECTS",
        help="object sets (toys, ycb), object names, mesh files (OBJ/PLY/OFF/STL), folders of mesh files "
        "or list files (.txt, one item per line), separated by spaces or commas, e.g. 'toys,ycb'; default: toys",
    )
    size = p.add_mutually_exclusive_group()
    size.add_argument(
        "--size-mm",
        type=float,
        default=150.0,
        help="nominal size: every object is scaled to this principal-frame box diagonal (mm)",
    )
    size.add_argument(
        "--real-size",
        action="store_true",
        help="keep the real size of objects with real units (the toys in mm, the YCB scans in metres), "
        "each instance still resized by +-5 %%, instead of --size-mm",
    )
    p.add_argument(
        "--methods",
        type=_csv_list,
        default=("attention",),
        help=f"comma-separated interest-point methods: {POINT_METHODS.help_text()}",
    )
    p.add_argument(
        "--policies",
        type=_csv_list,
        default=(),
        help=f"comma-separated touch policies, run touch by touch on the instance protocol's instances "
        f"and compared with the baseline's fixed plan: {POLICIES.help_text()}",
    )
    p.add_argument(
        "--baseline",
        default=None,
        help="the method the others are compared with (default: uniform if measured, else the first)",
    )
    p.add_argument(
        "--protocols",
        type=_csv_list,
        default=PROTOCOLS,
        help=f"comma-separated protocols: {PROTOCOL_REGISTRY.help_text()}",
    )
    p.add_argument(
        "--classifiers",
        type=_csv_list,
        default=None,
        help=f"comma-separated classifiers (default all): {CLASSIFIERS.help_text()}",
    )
    p.add_argument("--n-points", type=int, default=15, help="interest points per object instance")
    p.add_argument(
        "--replicates",
        type=int,
        default=None,
        help=f"instance-protocol replicates, each with fresh instances (default {DEFAULT_REPLICATES}, "
        f"a quick run; --full gives {FULL_REPLICATES})",
    )
    p.add_argument("--full", action="store_true", help=f"a full run: {FULL_REPLICATES} replicates")
    p.add_argument(
        "--replicates-at-once",
        type=int,
        default=REPLICATES_AT_ONCE,
        metavar="N",
        help=f"replicates whose instances are held in memory at a time (default {REPLICATES_AT_ONCE}): the "
        "memory grows with the objects, not with --replicates; results do not depend on it",
    )
    p.add_argument("--train-instances", type=int, default=3, help="training instances per object and replicate")
    p.add_argument("--train-sessions", type=int, default=2, help="acquisition sessions per training instance")
    p.add_argument("--folds", type=int, default=5, help="paper protocol: cross-validation folds")
    p.add_argument("--repeats", type=int, default=10, help="paper protocol: repeats with reshuffled folds")
    p.add_argument(
        "--view-size", type=int, default=None, help="rendered view size for the interest points (default: 128)"
    )
    p.add_argument(
        "--mode",
        choices=("contour", "pressure"),
        default=None,
        help="imprint mode of the simulated sensor (default: tactile.Sensor's)",
    )
    p.add_argument("--out", default="results", type=output_folder, help="output directory (default ./results)")
    p.add_argument(
        "--cache-dir",
        default="default",
        type=_cache_folder,
        help="cache of points, imprints and rates (default $XDG_CACHE_HOME/visuotactile or "
        "./.cache/visuotactile); 'none' disables it",
    )
    p.add_argument(
        "--seed", type=int, default=0, help="seed of every random choice: instances, sessions, folds, random baselines"
    )
    p.add_argument(
        "--features",
        choices=("raw", "polar"),
        default="raw",
        help="what the classifiers see: raw taxels (the paper's) or roll-invariant polar Fourier descriptors",
    )
    p.add_argument(
        "--jobs",
        type=int,
        default=2,
        help="local worker processes without --workers or --scheduler (default 2; results do not depend on it)",
    )
    p.add_argument(
        "--codebook-draws",
        type=int,
        default=8,
        help="place-aware recognizer: simulated touches per place and training instance in its codebooks",
    )
    p.add_argument(
        "--screening",
        choices=SCREENINGS,
        default="place",
        help=f"place-aware recognizer past {SHORTLIST} objects: score a touch in full under every object at its "
        "place located through the two surface frames ('place', the default), or under the "
        f"{SHORTLIST} objects its touch alone puts nearest, registering onto the {EXACT_PLACES} nearest ('touch')",
    )
    p.add_argument(
        "--mismatch",
        type=_csv_list,
        default=(),
        help="a mismatch arm: the test instances depart from what training simulates (several apply "
        f"together): {'; '.join(f'{k}: {v}' for k, v in MISMATCHES.items())}",
    )
    p.add_argument(
        "--control",
        choices=tuple(CONTROLS),
        default=None,
        help=f"a control run that must give chance: {'; '.join(f'{k}: {v}' for k, v in CONTROLS.items())}",
    )
    p.add_argument(
        "--skip-bad",
        action="store_true",
        help="run on the objects that load when some files do not (they are listed first); "
        "by default they stop the run before any work",
    )
    p.add_argument("--quiet", action="store_true", help="no progress bars")
    p.add_argument(
        "--real",
        metavar="SET.npz",
        help="a saved tactile.ImprintSet (e.g. from 'visuotactile export'): report recognition on it",
    )
    _add_cluster_options(p, default_workers=None)


def _batch_options(b) -> None:
    from meshsal.points import POINT_METHODS

    b.add_argument("directory", metavar="DIR", help="folder of meshes (searched recursively)")
    b.add_argument(
        "--out", required=True, type=output_folder, metavar="STORE", help="the store folder (created or resumed)"
    )
    b.add_argument(
        "--methods",
        type=_csv_list,
        default=("attention", "uniform"),
        help=f"comma-separated interest-point methods (default attention,uniform): {POINT_METHODS.help_text()}",
    )
    b.add_argument("--n-points", type=int, default=15, help="points (and imprints) per mesh and method")
    b.add_argument("--size-mm", type=float, default=150.0, help="nominal size: principal-frame box diagonal (mm)")
    b.add_argument("--view-size", type=int, default=128, help="rendered view size for the attention points")
    b.add_argument("--seed", type=int, default=0, help="seed of the random point methods")
    b.add_argument(
        "--skip-bad",
        action="store_true",
        help="run on the readable meshes when some cannot be read (they go to STORE/failures.jsonl)",
    )
    b.add_argument("--quiet", action="store_true", help="no progress bar")
    _add_cluster_options(b, default_workers=0)


def _add_cluster_options(p, default_workers):
    where = p.add_mutually_exclusive_group()
    where.add_argument(
        "--workers",
        type=int,
        default=None,
        metavar="N",
        help="run on a new Dask LocalCluster of N single-threaded worker processes"
        + (" (default: one per core; 1 runs in this process)" if default_workers == 0 else ""),
    )
    where.add_argument(
        "--scheduler",
        metavar="ADDRESS",
        help="run on an existing Dask cluster: tls://HOST:8786 with the --tls-* certificates, or "
        "tcp://127.0.0.1:8786 through an SSH tunnel (see 'Many meshes' in the README); a "
        "plain tcp:// scheduler runs the code of anyone who reaches it",
    )
    tls = p.add_argument_group("TLS (mutual; as 'dask scheduler' and 'dask worker' take them)")
    tls.add_argument(
        "--tls-ca-file", metavar="PEM", help="certificate authority that signed the cluster's certificates"
    )
    tls.add_argument("--tls-cert", metavar="PEM", help="this client's certificate (with --workers: every role's)")
    tls.add_argument("--tls-key", metavar="PEM", help="its private key, unless the certificate file holds it")
    p.add_argument(
        "--dashboard",
        metavar="ADDRESS",
        help="with --workers: serve the Dask dashboard at ADDRESS, e.g. 127.0.0.1:8787 (default: none)",
    )


def _cluster(args) -> dict:
    """``open_executor``'s security and dashboard from the cluster options."""
    from classify.runtime.cluster import tls_security

    given = [o for o, v in (("--tls-ca-file", args.tls_ca_file), ("--tls-cert", args.tls_cert)) if v]
    if args.tls_key and not args.tls_cert:
        raise ValueError("--tls-key needs --tls-cert")
    if len(given) == 1:
        raise ValueError(f"TLS needs both --tls-ca-file and --tls-cert; only {given[0]} was given")
    security = tls_security(args.tls_ca_file, args.tls_cert, args.tls_key) if given else None
    return {"security": security, "dashboard": args.dashboard}


def _batch(args) -> int:
    import os

    from classify.batch import BatchSettings, find_meshes, run_batch
    from classify.runtime.cluster import open_executor

    find_meshes(args.directory)  # a wrong folder stops the command before a cluster starts
    settings = BatchSettings(
        methods=args.methods, n_points=args.n_points, size_mm=args.size_mm, view_size=args.view_size, seed=args.seed
    )
    workers = None
    if not args.scheduler:
        workers = args.workers if args.workers is not None else (os.cpu_count() or 1)
        workers = workers if workers > 1 else None  # one worker: this process, no cluster
    with open_executor(workers=workers, scheduler=args.scheduler, **_cluster(args)) as executor:
        summary = run_batch(args.directory, args.out, settings, executor, args.quiet, args.skip_bad)
    print(summary.markdown())
    if summary.duplicates:
        print(
            f"{summary.duplicates} mesh(es) are the same mesh as another and are stored once: "
            f"see {args.out}/duplicates.jsonl",
            file=sys.stderr,
        )
    if summary.repaired:
        print(
            f"{summary.repaired} mesh(es) were repaired as they loaded: see {args.out}/repairs.jsonl", file=sys.stderr
        )
    if summary.failed:
        print(f"{summary.failed} mesh(es) failed: see {args.out}/failures.jsonl", file=sys.stderr)
    return 0


def _cache_folder(text: str) -> str | None:
    """``--cache-dir`` as ``run_experiment`` takes it: None for 'none' (no cache), 'default', or a folder that can
    be written (checked before any work)."""
    if text.lower() == "none":
        return None
    return text if text == "default" else str(output_folder(text))


def _csv_list(text: str) -> tuple:
    items = tuple(s.strip() for s in text.split(",") if s.strip())
    if not items:
        raise argparse.ArgumentTypeError("expected a comma-separated list")
    return items


def _experiment(args) -> int:
    import tactile
    from classify.experiment import (
        DEFAULT_REPLICATES,
        FULL_REPLICATES,
        ExperimentConfig,
        Settings,
        format_tables,
        run_experiment,
        run_real,
    )
    from classify.experiment.run import WORKER_MODULES
    from classify.recognizers.classifiers import NAMES
    from classify.runtime.cluster import open_executor

    if args.full and args.replicates is not None:
        raise ValueError("give --full or --replicates, not both")
    if args.replicates_at_once < 1:
        raise ValueError(f"--replicates-at-once must be at least 1, got {args.replicates_at_once}")
    if args.jobs < 1:
        raise ValueError(f"--jobs must be at least 1, got {args.jobs}")
    # 0 is a count to refuse, not "unset".
    replicates = DEFAULT_REPLICATES if args.replicates is None else args.replicates
    sensor = tactile.Sensor() if args.mode is None else tactile.Sensor(mode=args.mode)
    settings = Settings(
        n_points=args.n_points,
        size_mm=None if args.real_size else args.size_mm,
        view_size=args.view_size,
        sensor=sensor,
        train_instances=args.train_instances,
        train_sessions=args.train_sessions,
        seed=args.seed,
        codebook_draws=args.codebook_draws,
        mismatch=args.mismatch,
    )
    config = ExperimentConfig(
        methods=args.methods,
        protocols=args.protocols,
        classifiers=args.classifiers or NAMES,
        settings=settings,
        folds=args.folds,
        repeats=args.repeats,
        features=args.features,
        baseline=args.baseline,
        policies=args.policies,
        replicates=FULL_REPLICATES if args.full else replicates,
        control=args.control,
        params={} if args.screening == "place" else {"place": {"screening": args.screening}},
    )
    if args.real:
        result = run_real(args.real, config, out_dir=args.out, quiet=args.quiet, n_jobs=args.jobs)
        print(format_tables(result, title="Table 2 layout (real imprints)"))
        return 0
    with open_executor(
        workers=args.workers, scheduler=args.scheduler, n_jobs=args.jobs, preload=WORKER_MODULES, **_cluster(args)
    ) as executor:
        result = run_experiment(
            args.objects,
            config,
            executor=executor,
            cache_dir=args.cache_dir,
            out_dir=args.out,
            quiet=args.quiet,
            skip_bad=args.skip_bad,
            replicates_at_once=args.replicates_at_once,
        )
    print(format_tables(result))
    if not args.quiet:
        t, peak = result.timings, result.usage["total"]["peak_mb"]
        print(
            f"results written to {args.out}/ ({t['total']:.0f} s, {t['cpu_total']:.0f} s of CPU, {peak:.0f} MB at most; "
            "each stage's in results.json)",
            file=sys.stderr,
        )
    return 0


def build_parser(deferred: bool = False) -> argparse.ArgumentParser:
    """The ``visuotactile`` parser, every subcommand's options included.

    With ``deferred``, a subcommand whose options take heavy imports gets
    them only when the command line chooses it (``--help`` alone then starts
    in a fraction of a second): parse one command line with such a parser.
    """
    from hw import cli as hw_cli
    from meshsal import cli as meshsal_cli
    from tactile import cli as tactile_cli

    parser = argparse.ArgumentParser(
        prog="visuotactile",
        description="Recognize an object by touch, touching only where vision says it is worth touching.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True, action=Subcommands)
    meshsal_cli.register(sub)
    tactile_cli.register(sub)
    register(sub)
    hw_cli.register(sub)
    for command in sub.choices.values():  # every subcommand's --help shows its defaults
        command.formatter_class = HelpFormatter
    if not deferred:
        sub.complete()
    return parser


def main(argv: list[str] | None = None) -> int:
    """Run one subcommand; returns the exit status (0 success, 1 bad input or failure)."""
    from meshsal.util.reproducible import pin_kernels

    pin_kernels()
    args = build_parser(deferred=True).parse_args(argv)
    with warnings.catch_warnings(), _terminate_cleanly():
        # A user reads what was repaired in which file, not the line of our code that said so.
        warnings.showwarning = _warning_printer(args.command)
        return _run(args)


class _Terminated(BaseException):
    """SIGTERM arrived: raised in the main thread so that temporary folders and pools close on the way out.

    Not an ``Exception``, as ``KeyboardInterrupt`` is not: a batch that records a mesh's failure and goes on
    must not take the signal for one.
    """


@contextlib.contextmanager
def _terminate_cleanly():
    """Turn SIGTERM (a batch scheduler's time limit, ``kill``) into :class:`_Terminated` for the block.

    Python's default action ends the process at once, leaving a run's spilled places and task files in the
    temporary folder; an exception unwinds through the ``with`` blocks that delete them.
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminated(signum, frame):
        raise _Terminated

    previous = signal.signal(signal.SIGTERM, terminated)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


def _warning_printer(command: str):
    def show(message, category, filename, lineno, file=None, line=None):
        print(f"visuotactile {command}: warning: {message} ({category.__name__})", file=file or sys.stderr)

    return show


def _run(args) -> int:
    try:
        return int(args.func(args) or 0)
    except (ValueError, OSError) as exc:
        # Every reader's error (MeshError, NpzError, a JSON file's ValueError) names its file.
        print(f"visuotactile {args.command}: error: {exc}", file=sys.stderr)
        return 1
    except (RecursionError, MemoryError) as exc:
        # The readers' caps keep damaged files from getting here; this is the last guard against a traceback.
        problem = "out of memory" if isinstance(exc, MemoryError) else "recursion too deep"
        detail = f": {exc}" if str(exc) else ""
        print(f"visuotactile {args.command}: error: {problem} ({type(exc).__name__}{detail})", file=sys.stderr)
        return 1
    except BrokenExecutor:
        # A local worker process ended abruptly: the system's out-of-memory killer, a crash or a kill.
        after = (
            "nothing was cached (--cache-dir none): running the command again starts over"
            if getattr(args, "cache_dir", "default") is None
            else "what finished is cached: run the same command again to resume"
        )
        print(
            f"visuotactile {args.command}: error: a worker process ended abruptly (killed, e.g. by the system when "
            f"memory runs out, or crashed); {after}",
            file=sys.stderr,
        )
        return 1
    except KeyboardInterrupt:
        print(f"visuotactile {args.command}: interrupted", file=sys.stderr)
        return 130
    except _Terminated:
        print(f"visuotactile {args.command}: terminated", file=sys.stderr)
        return 128 + signal.SIGTERM


if __name__ == "__main__":
    sys.exit(main())
