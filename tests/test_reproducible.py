"""The kernel pin: what it sets and what it leaves alone, that it reaches every library in time, and that a
lower instruction set forced on a pinned process changes nothing, while without the pin it moves the cow's points."""

import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import kernel_probe
import numpy as np
import pytest

from classify.runtime.cluster import worker_env
from meshsal.util import reproducible
from meshsal.util.reproducible import (
    EMBREE_VARIABLE,
    KERNELS_VARIABLE,
    KernelPinWarning,
    cpu_flags,
    kernel_environment,
    kernels,
    pin_kernels,
)

TESTS = Path(__file__).resolve().parent
PIN_VARIABLES = (
    "OPENBLAS_CORETYPE",
    "OPENCV_CPU_DISABLE",
    "OPENCV_IPP",
    "NPY_DISABLE_CPU_FEATURES",
    EMBREE_VARIABLE,
    KERNELS_VARIABLE,
)
AVX2 = frozenset({"sse", "sse2", "pni", "ssse3", "sse4_1", "sse4_2", "popcnt", "avx", "f16c", "avx2", "fma"})
SKYLAKE_X = AVX2 | {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"}
X86_AVX2 = platform.machine().lower() in ("x86_64", "amd64") and "avx2" in (cpu_flags() or ())
needs_avx2 = pytest.mark.skipif(not X86_AVX2, reason="forces an x86-64 CPU with AVX2 down to lower instruction sets")


ICE_LAKE = SKYLAKE_X | {"avx512ifma", "avx512vbmi", "avx512_vbmi2", "avx512_vnni", "avx512_bitalg", "avx512_vpopcntdq"}


def env(environ=None, flags=AVX2, machine="x86_64", numpy_version=(2, 4), opencv_version=(5, 1)):
    return kernel_environment(
        {} if environ is None else environ,
        flags=flags,
        machine=machine,
        numpy_version=numpy_version,
        opencv_version=opencv_version,
    )


def test_an_avx2_cpu_gets_haswell_blas_and_every_other_library_its_baseline():
    assert env() == {
        "OPENBLAS_CORETYPE": "Haswell",
        "OPENCV_CPU_DISABLE": "SSSE3,SSE4.1,SSE4.2,POPCNT,AVX,FP16,AVX2,FMA3",
        "OPENCV_IPP": "sse42",
        "NPY_DISABLE_CPU_FEATURES": "X86_V3,X86_V4,AVX512_ICL,AVX512_SPR",
        EMBREE_VARIABLE: "isa=sse2",
    }


def test_an_avx512_cpu_also_has_opencvs_avx512_group_turned_off_not_just_its_flags():
    names = env(flags=SKYLAKE_X)["OPENCV_CPU_DISABLE"].split(",")
    # OpenCV dispatches on the group, which it derives before reading the variable.
    assert {"AVX512F", "AVX512VL", "AVX512-SKX"} <= set(names)
    assert "AVX512-ICL" not in names and "AVX512-KNL" not in names  # groups this CPU does not have
    assert len(names) == len(set(names))


def test_a_cpu_with_avx512_vnni_has_opencvs_cascade_lake_group_turned_off_too():
    # OpenCV 5.1's wheels dispatch filters to AVX512-CLX on such CPUs (an Intel Xeon of the Ice Lake kind, seen).
    names = env(flags=ICE_LAKE)["OPENCV_CPU_DISABLE"].split(",")
    assert {"AVX512VNNI", "AVX512-SKX", "AVX512-CLX", "AVX512-CNL", "AVX512-ICL"} <= set(names)
    assert "AVX512-CLX" not in env(flags=SKYLAKE_X)["OPENCV_CPU_DISABLE"].split(",")


def test_avx_vnni_is_turned_off_where_opencv_knows_its_name():
    flags = AVX2 | {"avx_vnni"}
    assert "AVX_VNNI" in env(flags=flags)["OPENCV_CPU_DISABLE"].split(",")
    assert "AVX_VNNI" in env(flags=flags, opencv_version=(4, 14))["OPENCV_CPU_DISABLE"].split(",")
    # OpenCV 4.13 and older do not know the name and would complain on stderr; they do not dispatch to it either.
    assert "AVX_VNNI" not in env(flags=flags, opencv_version=(4, 13))["OPENCV_CPU_DISABLE"].split(",")


def test_numpy_before_2_4_gets_its_feature_names_and_never_its_sse3_baseline():
    # Checked against NumPy 1.26.4 and 2.3.5 with -W error: all disabled, no warning.
    old = env(numpy_version=(1, 26))["NPY_DISABLE_CPU_FEATURES"].split(",")
    assert {"SSE41", "AVX2", "FMA3", "AVX512_SKX", "AVX512_ICL"} <= set(old)
    assert not {"SSE", "SSE2", "SSE3", "X86_V3", "AVX512_SPR"} & set(old)  # baseline: an error; unknown: a warning
    assert env(numpy_version=(2, 3))["NPY_DISABLE_CPU_FEATURES"].split(",") == old + ["AVX512_SPR"]


def test_a_cpu_without_avx2_keeps_its_own_blas_kernels_and_pins_the_rest():
    pinned = env(flags={"sse", "sse2", "ssse3", "sse4_1", "sse4_2", "popcnt", "avx"})
    assert "OPENBLAS_CORETYPE" not in pinned  # Haswell's kernels would not run
    assert pinned["OPENCV_CPU_DISABLE"] == "SSSE3,SSE4.1,SSE4.2,POPCNT,AVX"
    assert pinned[EMBREE_VARIABLE] == "isa=sse2" and pinned["NPY_DISABLE_CPU_FEATURES"]


def test_off_x86_64_nothing_is_pinned():
    assert env(machine="aarch64") == {} and env(machine="ppc64le") == {}


def test_without_cpu_flags_only_what_needs_none_is_pinned(monkeypatch):
    monkeypatch.setattr(reproducible, "_proc_cpu_flags", lambda: None)
    pinned = kernel_environment({}, machine="x86_64", numpy_version=(2, 4))
    assert set(pinned) == {EMBREE_VARIABLE, "NPY_DISABLE_CPU_FEATURES"}


def test_user_values_win_and_user_lists_of_features_to_disable_are_only_extended():
    user = {
        "OPENBLAS_CORETYPE": "Zen",
        "OPENCV_IPP": "disabled",
        EMBREE_VARIABLE: "max_isa=avx2",
        "OPENCV_CPU_DISABLE": "AVX2;NEON",
        "NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_SPR",
    }
    pinned = env(user)
    assert pinned["OPENBLAS_CORETYPE"] == "Zen" and pinned["OPENCV_IPP"] == "disabled"
    assert pinned[EMBREE_VARIABLE] == "max_isa=avx2"
    assert pinned["OPENCV_CPU_DISABLE"] == "AVX2,NEON,SSSE3,SSE4.1,SSE4.2,POPCNT,AVX,FP16,FMA3"
    assert pinned["NPY_DISABLE_CPU_FEATURES"] == "X86_V4,AVX512_SPR,X86_V3,AVX512_ICL"
    # NumPy refuses both of its variables at once: whoever chose what to enable keeps it.
    assert "NPY_DISABLE_CPU_FEATURES" not in env({"NPY_ENABLE_CPU_FEATURES": "X86_V3"})
    assert env({EMBREE_VARIABLE: ""})[EMBREE_VARIABLE] == ""  # empty: Embree chooses


def test_native_turns_the_pin_off_and_any_other_mode_is_refused_by_name():
    assert env({KERNELS_VARIABLE: "native"}) == {}
    assert env({KERNELS_VARIABLE: " Pinned "}) == env()
    with pytest.raises(ValueError, match=KERNELS_VARIABLE):
        env({KERNELS_VARIABLE: "fast"})


@needs_avx2
def test_this_test_process_was_pinned_in_time():
    from threadpoolctl import threadpool_info

    assert kernels() == {
        "openblas": "Haswell",
        "numpy": "baseline",
        "opencv": "baseline; IPP sse42",
        "embree": "isa=sse2",
    }
    assert {i["architecture"] for i in threadpool_info() if i["internal_api"] == "openblas"} == {"Haswell"}


@needs_avx2
def test_pinning_after_numpy_is_loaded_is_too_late_and_says_so(monkeypatch):
    import cv2  # noqa: F401  loaded too, as in any process that has done work

    for name in PIN_VARIABLES:
        monkeypatch.delenv(name, raising=False)
    late = r"too late to pin .*OPENBLAS_CORETYPE \(read by numpy.* before importing numpy"
    with pytest.warns(KernelPinWarning, match=late):
        now = pin_kernels()
    assert "OPENBLAS_CORETYPE" not in os.environ and "NPY_DISABLE_CPU_FEATURES" not in os.environ
    assert now == {EMBREE_VARIABLE: "isa=sse2"}  # read at each new device: never late


def _clean_env(**changes):
    """This process's environment without the pin, with ``changes``: a child that pins itself, or not."""
    environ = {k: v for k, v in os.environ.items() if k not in PIN_VARIABLES}
    return {**environ, "PYTHONPATH": os.pathsep.join([str(TESTS), *sys.path]), **changes}


def _python(code, **changes):
    return subprocess.run(
        [sys.executable, "-W", "error", "-c", code],
        env=_clean_env(**changes),
        capture_output=True,
        text=True,
        timeout=120,
    )


@needs_avx2
def test_a_process_pinned_first_runs_every_library_at_its_pin_and_none_complains():
    done = _python(
        "from meshsal.util.reproducible import pin_kernels, kernels; pin_kernels()\n"
        "import json, numpy, scipy.linalg, cv2\nfrom threadpoolctl import threadpool_info\n"
        "print(json.dumps([kernels(), sorted({i['architecture'] for i in threadpool_info()})]))"
    )
    assert done.returncode == 0 and done.stderr == "", done.stderr  # no OpenCV notice, no NumPy warning
    found, blas = json.loads(done.stdout)
    assert found == kernels() and blas == ["Haswell"]


@needs_avx2
def test_the_visuotactile_command_pins_before_anything_loads_numpy():
    done = _python(
        "import json, sys\nfrom classify.cli import main\ntry:\n    main(['--help'])\nexcept SystemExit:\n"
        "    pass\nfrom meshsal.util.reproducible import kernels\nprint(json.dumps(kernels()), file=sys.stderr)"
    )
    assert json.loads(done.stderr.strip().splitlines()[-1]) == kernels()


def test_every_opencv_feature_name_the_pin_may_use_is_known_to_this_opencv():
    every = frozenset(flag for _, needs in reproducible._OPENCV_GROUPS for flag in needs)
    every |= {flag for flag, _ in reproducible._OPENCV_FEATURES}
    names = reproducible._opencv_disable(every, reproducible._version(*reproducible._OPENCV_DISTRIBUTIONS))
    assert {name for _, name in reproducible._OPENCV_FEATURES} - set(names) <= set(reproducible._OPENCV_SINCE)
    done = _python("import cv2", OPENCV_CPU_DISABLE=",".join(names), VISUOTACTILE_KERNELS="native")
    assert done.returncode == 0 and "unknown CPU feature" not in done.stderr, done.stderr


@needs_avx2
def test_the_command_runs_a_program_pinned_and_without_one_prints_the_pin():
    module = [sys.executable, "-m", "meshsal.util.reproducible"]
    ran = subprocess.run(
        module + [sys.executable, "-c", "import os; print(os.environ['OPENCV_CPU_DISABLE'])"],
        env=_clean_env(),
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert ran.stdout.strip() == kernel_environment({})["OPENCV_CPU_DISABLE"]
    printed = subprocess.run(module, env=_clean_env(), capture_output=True, text=True, timeout=60).stdout
    assert dict(line.split("=", 1) for line in printed.split()) == kernel_environment({})


def test_local_cluster_workers_start_pinned_with_one_thread():
    environ = worker_env()
    assert environ["OMP_NUM_THREADS"] == environ["OPENBLAS_NUM_THREADS"] == "1"
    assert {k: environ[k] for k in kernel_environment()} == kernel_environment()


def _lower_isa() -> dict:
    """The variables that make NumPy, OpenCV and glibc's libm take the code of a CPU without AVX2 or FMA."""
    numpy = "X86_V3" if tuple(int(x) for x in np.__version__.split(".")[:2]) >= (2, 4) else "AVX2,FMA3,AVX,F16C"
    return {
        "OPENCV_CPU_DISABLE": "AVX2,FMA3,AVX,POPCNT",
        "NPY_DISABLE_CPU_FEATURES": numpy,
        "GLIBC_TUNABLES": "glibc.cpu.hwcaps=-AVX2,-FMA,-AVX",
    }


def _start(out_dir, *flags, **changes):
    return subprocess.Popen(
        [sys.executable, str(TESTS / "kernel_probe.py"), str(out_dir), *flags],
        env=_clean_env(**changes),
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )


def _finish(process) -> dict:
    out, err = process.communicate(timeout=600)
    assert process.returncode == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """The probe's outputs here, in a pinned child with a lower instruction set forced, and in two unpinned children."""
    tmp = tmp_path_factory.mktemp("kernels")
    children = {  # started first, so that they run while this process computes its own
        "lower": _start(tmp / "lower", **_lower_isa()),
        "native": _start(tmp / "native", "--points-only", VISUOTACTILE_KERNELS="native"),
        "native_lower": _start(tmp / "native_lower", "--points-only", VISUOTACTILE_KERNELS="native", **_lower_isa()),
    }
    found = {"here": kernel_probe.outputs(tmp / "here")}
    found.update({name: _finish(child) for name, child in children.items()})
    return found


@needs_avx2
def test_a_lower_instruction_set_changes_neither_the_toys_points_nor_results_csv(runs):
    here, lower = runs["here"], runs["lower"]
    assert lower["points"] == here["points"]
    assert lower["results_csv"] == here["results_csv"] and here["results_csv"].count("\n") > 10
    assert lower["kernels"] == here["kernels"]


@needs_avx2
def test_without_the_pin_the_lower_instruction_set_changes_the_cows_points(runs):
    native, lower = runs["native"], runs["native_lower"]
    assert "*AVX2?" in lower["kernels"]["opencv"] and "*AVX2 " in native["kernels"]["opencv"]  # the forcing took
    # Since the channels' rewrite the same vertices win here, but their scores (and so any tie) move.
    assert lower["points"]["cow"]["sha256"] != native["points"]["cow"]["sha256"]


def test_a_table_maker_warns_when_its_process_is_not_pinned(monkeypatch):
    import warnings

    from meshsal.util import reproducible

    monkeypatch.setattr(reproducible, "is_pinned", lambda environ=None: False)
    with pytest.warns(reproducible.KernelPinWarning, match="python -m meshsal.util.reproducible"):
        reproducible.warn_if_unpinned("run_experiment")
    monkeypatch.undo()
    assert reproducible.is_pinned()  # the test suite runs pinned (conftest)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        reproducible.warn_if_unpinned("run_experiment")
    assert reproducible.is_pinned({"VISUOTACTILE_KERNELS": "native"})
