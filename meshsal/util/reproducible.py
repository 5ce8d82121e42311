"""The same numbers on every x86-64 CPU: every library that picks its kernels by CPU is told which to pick.

Four libraries choose their machine code by the CPU they run on, and on this
toolkit's data three of those choices change the numbers (README, "The same
tables on every machine"):

* **OpenBLAS** (NumPy's, SciPy's and OpenCV's copies) picks its matrix
  kernels: the toys' meshes, the renders, mesh saliency and the points move
  with it.  Pinned to its Haswell (AVX2) kernels, ``OPENBLAS_CORETYPE=Haswell``,
  on CPUs with AVX2; other CPUs cannot run them and are left alone.
* **OpenCV** dispatches its filters to SSE4.1, SSE4.2, AVX, AVX2 or AVX-512
  code: the attention channels, and with them the cow's points, change with
  it.  Pinned to the build's baseline (SSE3 in the PyPI wheels) by
  ``OPENCV_CPU_DISABLE`` listing every feature above it that the CPU has (a
  feature it lacks would make OpenCV complain on stderr), and its Intel IPP
  to IPP's SSE4.2 code, ``OPENCV_IPP=sse42`` (on AVX2 the tables do not depend on it).
* **Embree** traces with SSE2, AVX, AVX2 or AVX-512 kernels: renders and
  imprints change.  Embree 4 reads no environment variable and no
  configuration file, only the configuration string of the device it is
  created with, so ``meshsal.mesh.embree`` creates its device with
  ``$VISUOTACTILE_EMBREE_CONFIG``, which the pin sets to ``isa=sse2``.
* **NumPy** dispatches its loops to AVX2 or AVX-512 code (on AVX-512 some
  transcendental functions to Intel's SVML, which rounds differently).  Its
  AVX2 loops and its baseline give the same tables; it is pinned to the
  baseline with ``NPY_DISABLE_CPU_FEATURES`` all the same.

Libraries read these variables when they load, so :func:`pin_kernels` must
run before NumPy, SciPy or OpenCV is first imported; the ``visuotactile``
command, the test suite and LocalCluster workers do so.  Any other process
can be started pinned: ``python -m meshsal.util.reproducible COMMAND...``
(e.g. ``dask worker``) runs the command with the pin in its environment, and
without a command prints the variables.  ``VISUOTACTILE_KERNELS=native``
turns the pin off.
"""

from __future__ import annotations

import functools
import os
import platform
import sys
import warnings

__all__ = [
    "KERNELS_VARIABLE",
    "EMBREE_VARIABLE",
    "KernelPinWarning",
    "cpu_flags",
    "kernel_environment",
    "pin_kernels",
    "kernels",
    "is_pinned",
    "warn_if_unpinned",
    "main",
]

#: "pinned" (the default) or "native": every library picks its kernels by CPU.
KERNELS_VARIABLE = "VISUOTACTILE_KERNELS"
#: The configuration string of the Embree device of ``meshsal.mesh.embree`` (empty: Embree's own choice).
EMBREE_VARIABLE = "VISUOTACTILE_EMBREE_CONFIG"
EMBREE_PIN = "isa=sse2"
BLAS_PIN = "Haswell"
IPP_PIN = "sse42"

#: OpenCV's name of each CPU feature above its x86-64 wheels' SSE3 baseline, by its /proc/cpuinfo flag.
_OPENCV_FEATURES = (
    ("ssse3", "SSSE3"),
    ("sse4_1", "SSE4.1"),
    ("sse4_2", "SSE4.2"),
    ("popcnt", "POPCNT"),
    ("avx", "AVX"),
    ("f16c", "FP16"),
    ("avx2", "AVX2"),
    ("fma", "FMA3"),
    ("avx512f", "AVX512F"),
    ("avx512cd", "AVX512CD"),
    ("avx512bw", "AVX512BW"),
    ("avx512dq", "AVX512DQ"),
    ("avx512vl", "AVX512VL"),
    ("avx512er", "AVX512ER"),
    ("avx512pf", "AVX512PF"),
    ("avx512ifma", "AVX512IFMA"),
    ("avx512vbmi", "AVX512VBMI"),
    ("avx512_vbmi2", "AVX512VBMI2"),
    ("avx512_vnni", "AVX512VNNI"),
    ("avx512_bitalg", "AVX512BITALG"),
    ("avx512_vpopcntdq", "AVX512VPOPCNTDQ"),
    ("avx512_4vnniw", "AVX5124VNNIW"),
    ("avx512_4fmaps", "AVX5124FMAPS"),
    ("avx_vnni", "AVX_VNNI"),
)
#: The first OpenCV version naming each feature that older ones do not know (naming an unknown feature is a
#: complaint on stderr): read from the wheels' feature tables, 4.8 to 5.1.
_OPENCV_SINCE = {"AVX_VNNI": (4, 14)}
#: The distributions that install ``cv2``, the project's own first.
_OPENCV_DISTRIBUTIONS = (
    "opencv-contrib-python-headless",
    "opencv-contrib-python",
    "opencv-python-headless",
    "opencv-python",
)
#: OpenCV's AVX-512 groups and the flags each needs, as its CPU detection combines them (disabling a flag
#: leaves a group on); every OpenCV from 4.8 to 5.1 names them.  OpenCV 5.1's wheels dispatch filters to
#: AVX512-CLX on CPUs with AVX-512 VNNI (Cascade Lake, Ice Lake, Zen 4), which moves the attention's bits.
_OPENCV_GROUPS = (
    ("AVX512-SKX", {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"}),
    ("AVX512-CLX", {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl", "avx512_vnni"}),
    ("AVX512-KNL", {"avx512f", "avx512cd", "avx512er", "avx512pf"}),
    (
        "AVX512-KNM",
        {"avx512f", "avx512cd", "avx512er", "avx512pf", "avx512_4fmaps", "avx512_4vnniw", "avx512_vpopcntdq"},
    ),
    ("AVX512-CNL", {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl", "avx512ifma", "avx512vbmi"}),
    (
        "AVX512-ICL",
        {
            "avx512f",
            "avx512cd",
            "avx512bw",
            "avx512dq",
            "avx512vl",
            "avx512ifma",
            "avx512vbmi",
            "avx512_vnni",
            "avx512_vbmi2",
            "avx512_bitalg",
            "avx512_vpopcntdq",
        },
    ),
)
#: NumPy's dispatch targets above its x86-64 baseline, by the first version that has them: grouped by x86-64
#: level from 2.4, by feature in earlier versions (a name NumPy does not dispatch is an ImportWarning, its baseline
#: an error).
_NUMPY_TARGETS = {
    (2, 4): "X86_V3 X86_V4 AVX512_ICL AVX512_SPR",
    (2, 0): "SSSE3 SSE41 POPCNT SSE42 AVX F16C FMA3 AVX2 AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX "
    "AVX512_CLX AVX512_CNL AVX512_ICL AVX512_SPR",
    (1, 0): "SSSE3 SSE41 POPCNT SSE42 AVX F16C FMA3 AVX2 AVX512F AVX512CD AVX512_KNL AVX512_KNM AVX512_SKX "
    "AVX512_CLX AVX512_CNL AVX512_ICL",
}
#: The modules whose loading reads each variable: after that, setting it changes nothing in this process.
_READ_BY = {
    "OPENBLAS_CORETYPE": ("numpy", "scipy", "cv2"),
    "NPY_DISABLE_CPU_FEATURES": ("numpy",),
    "OPENCV_CPU_DISABLE": ("cv2",),
    "OPENCV_IPP": ("cv2",),
    EMBREE_VARIABLE: (),
}
#: The SIMD flags that decide which kernels a library picks when nothing is pinned.
_SIMD_FLAGS = ("sse4_1", "sse4_2", "avx", "avx2", "fma", "avx_vnni", "avx512f", "avx512bw", "avx512vl", "avx512_vnni")


class KernelPinWarning(UserWarning):
    """The kernels could not be pinned in this process (a library was already loaded)."""


@functools.cache
def _proc_cpu_flags() -> frozenset | None:
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("flags"):
                    return frozenset(line.partition(":")[2].split())
    except OSError:
        pass
    return None


def cpu_flags() -> frozenset | None:
    """This CPU's feature flags as Linux names them in /proc/cpuinfo (None where there is none)."""
    return _proc_cpu_flags()


def _is_x86_64(machine: str) -> bool:
    return machine.lower() in ("x86_64", "amd64")


def _version(*distributions: str) -> tuple[int, int] | None:
    """(major, minor) of the first of the distributions installed, read from its metadata without importing it."""
    from importlib import metadata

    for distribution in distributions:
        try:
            major, minor = metadata.version(distribution).split(".")[:2]
            return int(major), int(minor)
        except metadata.PackageNotFoundError:
            continue
        except ValueError:
            return None
    return None


def _numpy_version() -> tuple[int, int] | None:
    return _version("numpy")


def _opencv_disable(flags: frozenset, version: tuple | None) -> list[str]:
    """OpenCV's names of the features above its baseline this CPU has, those this OpenCV knows (all when its
    version is unknown)."""
    names = [name for flag, name in _OPENCV_FEATURES if flag in flags]
    names += [name for name, needs in _OPENCV_GROUPS if needs <= flags]
    return [name for name in names if version is None or version >= _OPENCV_SINCE.get(name, (0, 0))]


def _merged(user: str | None, ours: list[str], separator: str) -> str:
    """The user's list of features to disable with ours added (the pin only ever disables more)."""
    seen = [name for name in (user or "").replace(";", ",").replace(",", " ").split() if name]
    return separator.join(seen + [name for name in ours if name not in seen])


def kernel_environment(
    environ=None, flags=None, machine: str | None = None, numpy_version=None, opencv_version=None
) -> dict[str, str]:
    """The environment that pins every library's kernels on this machine: variable -> value.

    A value the user set is kept: their ``OPENBLAS_CORETYPE``, ``OPENCV_IPP``
    and Embree configuration win, and their lists of features to disable are
    extended, never shortened.  ``VISUOTACTILE_KERNELS=native`` gives ``{}``.

    Parameters
    ----------
    environ : mapping, optional
        The environment to start from (default ``os.environ``).
    flags : set of str, optional
        The CPU's /proc/cpuinfo flags (default this CPU's; None where unknown:
        then OpenBLAS and OpenCV are left alone, as which features to name is
        unknown).
    machine : str, optional
        ``platform.machine()`` by default; nothing is pinned off x86-64.
    numpy_version : (major, minor), optional
        The installed NumPy's (read from its metadata without importing it).
    opencv_version : (major, minor), optional
        The installed OpenCV's, likewise: an OpenCV older than a feature's
        name is not told it (``AVX_VNNI`` from 4.14).

    Returns
    -------
    dict of the variables to have in the environment (user values included)

    Raises
    ------
    ValueError
        If ``VISUOTACTILE_KERNELS`` is neither "pinned" nor "native".

    Examples
    --------
    >>> env = kernel_environment({}, flags={"sse4_1", "sse4_2", "popcnt", "avx", "avx2", "fma"},
    ...                          machine="x86_64", numpy_version=(2, 4))
    >>> env["OPENBLAS_CORETYPE"], env["OPENCV_CPU_DISABLE"]
    ('Haswell', 'SSE4.1,SSE4.2,POPCNT,AVX,AVX2,FMA3')
    >>> kernel_environment({}, flags=set(), machine="aarch64")
    {}
    """
    environ = os.environ if environ is None else environ
    mode = environ.get(KERNELS_VARIABLE, "pinned").strip().lower() or "pinned"
    if mode not in ("pinned", "native"):
        raise ValueError(f"{KERNELS_VARIABLE}={environ[KERNELS_VARIABLE]!r}: expected 'pinned' or 'native'")
    machine = platform.machine() if machine is None else machine
    if mode == "native" or not _is_x86_64(machine):
        return {}
    flags = cpu_flags() if flags is None else frozenset(flags)
    env = {EMBREE_VARIABLE: environ.get(EMBREE_VARIABLE, EMBREE_PIN)}
    version = _numpy_version() if numpy_version is None else tuple(numpy_version)
    if version is not None and "NPY_ENABLE_CPU_FEATURES" not in environ:
        # NumPy refuses both variables at once; a user who chose what to enable keeps it.
        targets = next(names for first, names in _NUMPY_TARGETS.items() if version >= first).split()
        env["NPY_DISABLE_CPU_FEATURES"] = _merged(environ.get("NPY_DISABLE_CPU_FEATURES"), targets, ",")
    if "OPENBLAS_CORETYPE" in environ:
        env["OPENBLAS_CORETYPE"] = environ["OPENBLAS_CORETYPE"]
    elif flags is not None and "avx2" in flags:
        env["OPENBLAS_CORETYPE"] = BLAS_PIN
    opencv = _version(*_OPENCV_DISTRIBUTIONS) if opencv_version is None else tuple(opencv_version)
    disable = _merged(environ.get("OPENCV_CPU_DISABLE"), _opencv_disable(flags or frozenset(), opencv), ",")
    if disable:
        env["OPENCV_CPU_DISABLE"] = disable
    if flags is not None or "OPENCV_IPP" in environ:
        env["OPENCV_IPP"] = environ.get("OPENCV_IPP", IPP_PIN)
    return env


def pin_kernels() -> dict[str, str]:
    """Put :func:`kernel_environment` into ``os.environ`` where it can still take effect.

    Returns the pinning variables now in this process's environment.  A
    variable whose library is already loaded is not set (this process would
    not follow it, its children would), and a :class:`KernelPinWarning` says
    which and what to do.

    Examples
    --------
    >>> env = pin_kernels()      # first thing in a program, before NumPy is imported
    """
    late = {}
    for name, value in kernel_environment().items():
        if os.environ.get(name) == value:
            continue
        loaded = [module for module in _READ_BY.get(name, ()) if module in sys.modules]
        if loaded:
            late[name] = loaded
        else:
            os.environ[name] = value
    if late:
        what = ", ".join(f"{name} (read by {'/'.join(mods)})" for name, mods in late.items())
        warnings.warn(
            f"too late to pin {what}: already loaded, so this process keeps its CPU's own kernels. "
            f"Call meshsal.util.reproducible.pin_kernels() before importing numpy, scipy or cv2, "
            f"or run under `python -m meshsal.util.reproducible`",
            KernelPinWarning,
            stacklevel=2,
        )
    return {name: os.environ[name] for name in _READ_BY if name in os.environ}


def is_pinned(environ=None) -> bool:
    """True when this process's environment holds every pinning variable :func:`kernel_environment` asks for
    (as under ``python -m meshsal.util.reproducible`` or the ``visuotactile`` command)."""
    environ = os.environ if environ is None else environ
    return all(environ.get(name) == value for name, value in kernel_environment(environ).items())


def warn_if_unpinned(what: str) -> None:
    """A :class:`KernelPinWarning` when ``what`` (e.g. "run_experiment") runs with the CPU's own kernels: its
    numbers may then differ in their last digits from the pinned tables of the ``visuotactile`` command."""
    if not is_pinned():
        warnings.warn(
            f"{what} runs with this CPU's own kernels, so its numbers may differ from the pinned tables of the "
            f"visuotactile command and the documentation; run the script under `python -m meshsal.util.reproducible "
            f"python SCRIPT`, or call meshsal.util.reproducible.pin_kernels() before importing numpy, scipy or cv2 "
            f"({KERNELS_VARIABLE}=native silences this)",
            KernelPinWarning,
            stacklevel=3,
        )


def _simd_signature() -> str:
    flags = cpu_flags()
    return "by CPU (" + (" ".join(f for f in _SIMD_FLAGS if f in flags) if flags is not None else "unknown") + ")"


def kernels() -> dict[str, str]:
    """Which kernels each library runs in this process: equal strings, equal numbers.

    A pinned library reports its pin, the same on every CPU; one left to
    pick by CPU reports the CPU's SIMD features.  Imports NumPy and OpenCV.
    """
    import cv2

    try:
        from numpy._core._multiarray_umath import __cpu_dispatch__, __cpu_features__
    except ImportError:  # NumPy 1.x
        from numpy.core._multiarray_umath import __cpu_dispatch__, __cpu_features__

    numpy = [f for f in __cpu_dispatch__ if __cpu_features__.get(f)]
    line = cv2.getCPUFeaturesLine()
    opencv = [f for f in line.split() if f.startswith("*") and not f.endswith("?")]
    return {
        "openblas": os.environ.get("OPENBLAS_CORETYPE") or _simd_signature(),
        "numpy": "baseline" if not numpy else " ".join(numpy),
        "opencv": ("baseline" if not opencv else line) + f"; IPP {os.environ.get('OPENCV_IPP', 'by CPU')}",
        "embree": os.environ.get(EMBREE_VARIABLE) or _simd_signature(),
    }


def main(argv=None) -> int:
    """``python -m meshsal.util.reproducible [COMMAND ARGS...]``: run a command pinned, or print the pin."""
    argv = sys.argv[1:] if argv is None else list(argv)
    env = kernel_environment()
    if not argv:
        for name, value in env.items():
            print(f"{name}={value}")
        return 0
    try:
        os.execvpe(argv[0], argv, {**os.environ, **env})
    except OSError as exc:
        print(f"meshsal.util.reproducible: cannot run {argv[0]!r}: {exc}", file=sys.stderr)
        return 127


if __name__ == "__main__":
    sys.exit(main())
