"""Which instructions that Intel and AMD round differently a run executes, library by library.

The approximate reciprocals and square roots (``rcpps``, ``rsqrtps``, their
scalar forms, and with ``--vex`` their VEX and AVX-512 forms) and the x87
transcendentals (``fsin``, ``fcos``, ``fptan``, ``fpatan``, ``f2xm1``, ``fyl2x``...)
are specified only to a bound: each vendor rounds them with its own tables, so
the same program, kernels pinned, computes other bits on the two.  Every other
floating-point instruction is exactly specified.

This runs ``visuotactile experiment`` in one process (``--jobs 1``; the demo's six
toys by default, pinned as the command pins itself) under gdb, with a breakpoint
on every such instruction of every shared library loaded once the toolkit and
its libraries are imported, and prints, per library, how many it holds and how
many of them ran (each site counted once).  The VEX and AVX-512 forms are left
out unless ``--vex``: pinned, no library runs AVX code, and Embree alone holds
tens of thousands of them (gdb takes minutes to place those breakpoints).
Needs gdb (``apt-get install gdb``).

    .venv/bin/python scripts/approximate_instructions.py [--page PAGE] [--vex] [-- EXPERIMENT ARGUMENTS...]
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

#: The mnemonics objdump prints for the instructions this looks for.
LEGACY = r"rcpps|rcpss|rsqrtps|rsqrtss|fsin|fcos|fsincos|fptan|fpatan|f2xm1|fyl2x|fyl2xp1"
VEX = r"vrcpps|vrcpss|vrsqrtps|vrsqrtss|vrcp14ps|vrcp14ss|vrsqrt14ps|vrsqrt14ss|vrcp14pd|vrsqrt14pd"

# Run by gdb: stop at the inferior's SIGTRAP, set a temporary breakpoint on each instruction, count the ones hit.
_GDB_SCRIPT = r"""
import json, os, re, subprocess
import gdb

pattern = re.compile(r"^\s*([0-9a-f]+):\s+(" + os.environ["PROBE_MNEMONICS"] + r")\b")
gdb.execute("set pagination off")
gdb.execute("set confirm off")
gdb.execute("handle SIGTRAP stop nopass")
gdb.execute("run")
pid = gdb.selected_inferior().pid
bases = {}
with open(f"/proc/{pid}/maps") as maps:
    for line in maps:
        parts = line.split()
        if len(parts) >= 6 and int(parts[2], 16) == 0 and (".so" in os.path.basename(parts[5])):
            bases.setdefault(parts[5], int(parts[0].split("-")[0], 16))
sites, found = {}, {}
for path, base in sorted(bases.items()):
    listing = subprocess.run(["objdump", "-d", "--no-show-raw-insn", path], capture_output=True, text=True).stdout
    count = 0
    for line in listing.splitlines():
        match = pattern.match(line)
        if match:
            sites[base + int(match.group(1), 16)] = (path, match.group(2))
            count += 1
    if count:
        found[path] = count
for address in sites:
    gdb.Breakpoint(f"*{address:#x}", internal=True, temporary=True)
# A breakpoint is temporary: each site that runs stops the run once.
ran = set()

def stopped(event):
    if isinstance(event, gdb.BreakpointEvent):
        pc = int(gdb.selected_frame().pc())
        if pc in sites:
            ran.add(pc)

gdb.events.stop.connect(stopped)
state = {"exit_code": None}
gdb.events.exited.connect(lambda event: state.update(exit_code=getattr(event, "exit_code", 0)))
while state["exit_code"] is None:
    try:
        gdb.execute("continue")
    except gdb.error:
        break
with open(os.environ["PROBE_OUT"], "w") as out:
    where = [[*sites[pc], hex(pc - bases[sites[pc][0]])] for pc in sorted(ran)]
    json.dump({"found": found, "ran": where, "exit_code": state["exit_code"]}, out)
"""


def inferior(experiment: list[str]) -> int:
    """The run gdb watches: import what the experiment loads, let gdb place its breakpoints, then run it."""
    import signal

    from meshsal.util.reproducible import pin_kernels

    pin_kernels()
    import igl  # noqa: F401
    import pymeshlab  # noqa: F401
    import sklearn.naive_bayes  # noqa: F401
    import sklearn.neighbors  # noqa: F401
    import sklearn.tree  # noqa: F401

    import classify.experiment.run  # noqa: F401
    import meshsal
    from classify.cli import main
    from meshsal.mesh.embree import embree_scene

    embree_scene(meshsal.objects.toys.make("cow"))  # loads Embree's library
    os.kill(os.getpid(), signal.SIGTRAP)
    return main(["experiment", "--jobs", "1", "--quiet", *experiment])


def table(report: dict) -> str:
    """The Markdown table of a report: each library's instructions of the kind, and the sites that ran, by mnemonic."""
    sites = collections.Counter((path, mnemonic) for path, mnemonic, _ in report["ran"])  # -> sites that ran
    ran = collections.Counter(path for path, _ in sites.elements())
    lines = [
        "| library | such instructions | of them ran (sites) | which |",
        "|---|---:|---:|---|",
    ]
    for path, count in sorted(report["found"].items(), key=lambda kv: (-ran[kv[0]], kv[0])):
        which = ", ".join(f"{m} ({n})" for (p, m), n in sorted(sites.items()) if p == path) or "-"
        lines.append(f"| {Path(path).name} | {count} | {ran[path]} | {which} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["--inferior"]:
        return inferior(argv[1:])
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--page", help="also write the table to this Markdown page, with its provenance")
    parser.add_argument("--vex", action="store_true", help="watch the VEX and AVX-512 forms too (slow)")
    parser.add_argument("experiment", nargs="*", help="arguments for `visuotactile experiment` (after --)")
    args = parser.parse_args(argv)
    if shutil.which("gdb") is None or shutil.which("objdump") is None:
        print("approximate_instructions: error: needs gdb and objdump (apt-get install gdb binutils)", file=sys.stderr)
        return 1
    with tempfile.TemporaryDirectory(prefix="visuotactile-probe-") as folder:
        script, out = Path(folder) / "probe.py", Path(folder) / "report.json"
        script.write_text(_GDB_SCRIPT)
        env = {**os.environ, "PROBE_OUT": str(out), "PROBE_MNEMONICS": f"{VEX}|{LEGACY}" if args.vex else LEGACY}
        run = ["--out", f"{folder}/run", "--cache-dir", f"{folder}/cache", *args.experiment]
        command = ["gdb", "-q", "-batch", "-x", str(script), "--args", sys.executable, __file__, "--inferior", *run]
        # gdb's own chatter (declined auto-loads, threads) says nothing about the run; its last lines go with a failure.
        done = subprocess.run(command, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
        tail = "\n".join(done.stderr.strip().splitlines()[-5:])
        if not out.exists():
            print(
                f"approximate_instructions: error: gdb wrote no report (is ptrace allowed here?)\n{tail}",
                file=sys.stderr,
            )
            return 1
        report = json.loads(out.read_text())
    if report["exit_code"] != 0:
        print(
            f"approximate_instructions: error: the experiment exited with {report['exit_code']}\n{tail}",
            file=sys.stderr,
        )
        return 1
    experiment = " ".join(["visuotactile experiment --jobs 1", *args.experiment])
    body = (
        f"`{experiment}`, in one process under gdb: every {'VEX, AVX-512, ' if args.vex else ''}SSE and x87 "
        f"approximate reciprocal, square root and transcendental of every library loaded once the toolkit is "
        f"imported, and the sites that ran.\n\n{table(report)}"
    )
    print(body)
    if args.page:
        from meshsal.util.pages import write_page

        title = (
            f"Instructions each CPU vendor rounds its own way, in {'an experiment' if args.experiment else 'the demo'}"
        )
        write_page(args.page, title, body, command=["scripts/approximate_instructions.py", *argv])
    return 0


if __name__ == "__main__":
    sys.exit(main())
