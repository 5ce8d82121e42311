"""pymeshlab first used in a thread that ends (a Dask worker's task thread): the process must still exit cleanly."""

import os
import shutil
import subprocess
import sys
import textwrap

from conftest import missing

TETRAHEDRON = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n"

# Loads a mesh in a thread that ends before the process does; pymeshlab is not imported before.
LOAD_IN_A_THREAD = textwrap.dedent(
    """
    import sys, threading
    from meshsal.mesh.io import load_mesh
    assert "pymeshlab" not in sys.modules
    loaded = []
    worker = threading.Thread(target=lambda: loaded.append(load_mesh(sys.argv[1])))
    worker.start()
    worker.join()
    print("faces", loaded[0].n_faces, "threads alive", [t.daemon for t in threading.enumerate()])
    """
)


def _python(script, *args, prefix=()):
    env = {**os.environ, "PYTHONMALLOC": "malloc"}  # valgrind sees every allocation, not pymalloc's arenas
    return subprocess.run(
        [*prefix, sys.executable, "-c", script, *map(str, args)], capture_output=True, text=True, env=env, timeout=600
    )


def test_the_thread_that_imports_pymeshlab_outlives_a_worker_thread_that_asked_for_it(tmp_path):
    (tmp_path / "tet.obj").write_text(TETRAHEDRON)
    run = _python(LOAD_IN_A_THREAD, tmp_path / "tet.obj")
    assert run.returncode == 0, run.stderr
    # The main thread and the daemon thread that imported pymeshlab, waiting until the process exits.
    assert "faces 4 threads alive [False, True]" in run.stdout, run.stdout


def test_main_thread_imports_pymeshlab_itself():
    script = (
        "import threading; from meshsal.util.meshlab import import_pymeshlab as f; f(); print(threading.active_count())"
    )
    run = _python(script)
    assert run.returncode == 0 and run.stdout.split() == ["1"], (run.stdout, run.stderr)


def test_no_exit_time_destructor_touches_freed_memory_after_a_load_in_a_finished_thread(tmp_path):
    """pymeshlab's plugins, imported by a thread that has ended, wrote into freed Qt thread data at exit
    (``QThreadData::deref``), and glibc aborted the finished process in most ``visuotactile batch`` runs.
    valgrind sees the write every time; the abort came only with some heap layouts."""
    if shutil.which("valgrind") is None:
        missing("valgrind is not installed (apt-get install valgrind)")
    (tmp_path / "tet.obj").write_text(TETRAHEDRON)
    run = _python(LOAD_IN_A_THREAD, tmp_path / "tet.obj", prefix=("valgrind", "--error-limit=no"))
    assert run.returncode == 0 and "faces 4" in run.stdout, run.stderr[-3000:]
    assert "ERROR SUMMARY" in run.stderr
    assert "QThreadData" not in run.stderr and "PluginManager" not in run.stderr, run.stderr[-6000:]
