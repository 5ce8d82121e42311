"""The same numbers on every x86-64 CPU: one BLAS kernel for all of them.

NumPy's and SciPy's OpenBLAS pick their matrix kernels by CPU at load time,
so an AVX-512 machine and an AVX2 one sum in different orders and differ in
the last bits, enough to flip a tie or an evolution strategy's choice.
:func:`pin_blas_kernel` asks OpenBLAS for its Haswell (AVX2) kernels on
every CPU that has AVX2.  It must run before NumPy is first imported; the
``visuotactile`` command and the test suite call it first thing.
"""

from __future__ import annotations

import os
import platform
import sys

__all__ = ["pin_blas_kernel"]


def _has_avx2() -> bool:
    try:
        with open("/proc/cpuinfo") as fh:
            return any(line.startswith("flags") and " avx2" in line for line in fh)
    except OSError:
        return False


def pin_blas_kernel() -> bool:
    """Set ``OPENBLAS_CORETYPE=Haswell`` when it can still take effect; True if it is in force.

    Left alone: a value the user set, a CPU without AVX2 or not x86-64, and
    a process that has already loaded NumPy (too late to matter).
    """
    if "OPENBLAS_CORETYPE" in os.environ:
        return os.environ["OPENBLAS_CORETYPE"].lower() == "haswell"
    if "numpy" in sys.modules or platform.machine().lower() not in ("x86_64", "amd64") or not _has_avx2():
        return False
    os.environ["OPENBLAS_CORETYPE"] = "Haswell"
    return True
