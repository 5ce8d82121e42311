"""Shared fixtures: where the public test meshes live."""

import os
from pathlib import Path

import pytest

from meshsal.reproducible import pin_blas_kernel

pin_blas_kernel()   # before anything imports NumPy: the same BLAS kernels, hence numbers, on every x86-64 CPU

_DEFAULT_SHARED = Path(__file__).resolve().parents[1].parent / "shared" / "meshes"


def _shared_dir() -> Path:
    return Path(os.environ.get("VISUOTACTILE_SHARED_MESHES", _DEFAULT_SHARED))


@pytest.fixture(scope="session")
def shared_meshes() -> Path:
    """The folder of public test meshes (``../shared/meshes``; override with
    VISUOTACTILE_SHARED_MESHES); tests using it skip when it is absent."""
    path = _shared_dir()
    if not path.is_dir():
        pytest.skip(f"public test meshes not found at {path} (set VISUOTACTILE_SHARED_MESHES)")
    return path


@pytest.fixture(scope="session")
def shared_mesh(shared_meshes):
    """A function: file name inside the shared folder -> Path, skipping when missing."""

    def find(name: str) -> Path:
        path = shared_meshes / name
        if not path.exists():
            pytest.skip(f"public test mesh {path} is absent")
        return path

    return find
