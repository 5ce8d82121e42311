"""Whether an experiment's tables depend on how the CPU rounds Embree's hits: the run, as another CPU may round.

Runs ``visuotactile experiment`` (the demo's six toys by default) three times,
each in a process of its own, in process (``--jobs 1``), nothing cached:

- as it is;
- with every Embree scene's hits rounded otherwise *inside* the settling
  (``meshsal.mesh.rounding.rounded_otherwise(where="embree")``): every hit's
  distance and barycentrics a unit in the last place off, at seeded random,
  and every hit within a ten-thousandth of an edge's length of an edge of two
  faces on the face across it, as another vendor's ``rcpps`` may give them;
- with the same rounding *around* the settled hits (``where="settled"``): what
  the tables would be if Embree's hits were taken as they come.

Then it compares each run's ``results.csv`` with the first's, byte for byte,
and prints (and with ``--page`` writes) a table: the values moved, the hits
turned, and how many rows of ``results.csv`` differ.

    .venv/bin/python scripts/other_rounding.py [--share 1.0] [--seed 0] [--page PAGE] [-- EXPERIMENT ARGUMENTS...]
"""

from __future__ import annotations

import argparse
import contextlib
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

#: The runs: name -> where the stand-in sits (None: no stand-in).
ARMS = {
    "as it is": None,
    "rounded otherwise inside the settling": "embree",
    "the same, around the settled hits": "settled",
}


def arm(where: str | None, share: float, seed: int, out: Path, experiment: list[str]) -> int:
    """One run, in this process: the experiment with its scenes rounded otherwise at ``where`` (or not)."""
    from meshsal.util.reproducible import pin_kernels

    pin_kernels()
    from classify.cli import main
    from meshsal.mesh.rounding import rounded_otherwise

    argv = ["experiment", *experiment, "--jobs", "1", "--cache-dir", "none", "--quiet", "--out", str(out)]
    with rounded_otherwise(share, seed, where) if where else contextlib.nullcontext([]) as stand_ins:
        status = main(argv)
    counts = {"moved": sum(s.moved for s in stand_ins), "turned": sum(s.turned for s in stand_ins)}
    (out / "rounding.json").write_text(json.dumps({**counts, "scenes": len(stand_ins), "exit_code": status}))
    return status


def differing_rows(ours: Path, theirs: Path) -> tuple[int, int]:
    """How many lines of ``theirs`` differ from ``ours`` (position by position), and how many ``ours`` has."""
    a, b = ours.read_text().splitlines(), theirs.read_text().splitlines()
    return sum(x != y for x, y in zip(a, b)) + abs(len(a) - len(b)), len(a)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    experiment = argv[argv.index("--") + 1 :] if "--" in argv else []
    own = argv[: argv.index("--")] if "--" in argv else argv
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--share", type=float, default=1.0, help="share of hit values moved a unit (default 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--page", help="also write the table to this Markdown page, with its provenance")
    parser.add_argument("--arm", choices=[w for w in ARMS.values() if w] + ["none"], help=argparse.SUPPRESS)
    parser.add_argument("--out", type=Path, help=argparse.SUPPRESS)
    args = parser.parse_args(own)
    if not 0.0 <= args.share <= 1.0:
        parser.error(f"--share must lie in [0, 1], got {args.share}")
    if args.arm:
        return arm(None if args.arm == "none" else args.arm, args.share, args.seed, args.out, experiment)

    rows = []
    with tempfile.TemporaryDirectory(prefix="other-rounding-") as tmp:
        outs = {}
        for name, where in ARMS.items():
            out = outs[name] = Path(tmp) / (where or "none")
            out.mkdir()
            command = [sys.executable, __file__, "--arm", where or "none", "--out", str(out)]
            command += ["--share", str(args.share), "--seed", str(args.seed), "--", *experiment]
            start = time.perf_counter()
            with open(out / "printed.txt", "w") as printed:  # its tables: the comparison below is what counts
                done = subprocess.run(command, env=os.environ.copy(), stdout=printed)
            seconds = time.perf_counter() - start
            report = json.loads((out / "rounding.json").read_text()) if (out / "rounding.json").exists() else {}
            if done.returncode or report.get("exit_code"):
                tail = (out / "printed.txt").read_text().splitlines()[-20:]
                print(
                    *tail, f"{name}: the experiment failed (exit status {done.returncode})", sep="\n", file=sys.stderr
                )
                return 1
            rows.append((name, report, seconds))
        plain = outs["as it is"] / "results.csv"
        lines = [
            "| run | scenes rounded otherwise | hit values moved a unit | hits turned across an edge | "
            "rows of results.csv that differ from the run as it is | seconds |",
            "|---|---:|---:|---:|---:|---:|",
        ]
        for name, report, seconds in rows:
            differ, total = differing_rows(plain, outs[name] / "results.csv")
            lines.append(
                f"| {name} | {report['scenes']} | {report['moved']:,} | {report['turned']:,} | "
                f"{differ} of {total} | {seconds:.0f} |"
            )
    what = " ".join(experiment) or "(the demo: the six toys)"
    body = "\n".join(
        [
            f"`visuotactile experiment {what}`, in process, nothing cached; share {args.share}, seed {args.seed}.",
            "",
            *lines,
            "",
            "Inside the settling (`meshsal.mesh.embree.Scene`), the rounding is what another CPU's Embree may "
            "give; around the settled hits it shows what the tables would be if Embree's hits were taken as they "
            "come.",
        ]
    )
    print(body)
    if args.page:
        from meshsal.util.pages import write_page

        title = "The tables when Embree's hits are rounded as another CPU may round them"
        write_page(args.page, title, body, command=["scripts/other_rounding.py", *argv])
    return 0


if __name__ == "__main__":
    sys.exit(main())
