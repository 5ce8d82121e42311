"""Shared fixtures: where the public test meshes and the corpus live.

Tests that need ``../shared`` skip, saying why, when it is absent; with the
``CI`` environment variable set they fail instead, so a moved folder cannot
quietly skip a dozen checks.
"""

import os
from pathlib import Path

import pytest

from meshsal.util.reproducible import pin_kernels

pin_kernels()  # before anything imports NumPy or OpenCV: the same kernels, hence numbers, on every x86-64 CPU

_SHARED = Path(__file__).resolve().parents[1].parent / "shared"


def _shared_dir() -> Path:
    return Path(os.environ.get("VISUOTACTILE_SHARED_MESHES", _SHARED / "meshes"))


def _corpus_dir() -> Path:
    return Path(os.environ.get("VISUOTACTILE_SHARED_CORPUS", _SHARED / "corpus" / "random-objects"))


def in_ci() -> bool:
    """True when the ``CI`` environment variable is set to anything but empty, 0 or false."""
    return os.environ.get("CI", "").strip().lower() not in ("", "0", "false", "no")


def missing(reason: str):
    """Skip the test, or fail it under CI, where nothing shared may be missing."""
    if in_ci():
        pytest.fail(f"{reason} (CI is set, so this fails instead of skipping)", pytrace=False)
    pytest.skip(reason)


@pytest.fixture(scope="session")
def shared_meshes() -> Path:
    """The folder of public test meshes (``../shared/meshes``; override with VISUOTACTILE_SHARED_MESHES)."""
    path = _shared_dir()
    if not path.is_dir():
        missing(f"public test meshes not found at {path} (set VISUOTACTILE_SHARED_MESHES)")
    return path


@pytest.fixture(scope="session")
def shared_mesh(shared_meshes):
    """A function: file name inside the shared folder -> Path (skipped or failed when missing)."""

    def find(name: str) -> Path:
        path = shared_meshes / name
        if not path.exists():
            missing(f"public test mesh {path} is absent")
        return path

    return find


@pytest.fixture(scope="session")
def shared_corpus() -> Path:
    """The corpus of 1,000 small meshes (``../shared/corpus/random-objects``; override with
    VISUOTACTILE_SHARED_CORPUS)."""
    path = _corpus_dir()
    if not path.is_dir():
        missing(f"mesh corpus not found at {path} (set VISUOTACTILE_SHARED_CORPUS)")
    return path


@pytest.fixture
def dask_cluster(tmp_path):
    """A scheduler and two single-threaded workers without nannies (so a killed worker stays dead)."""
    from dask_cluster import DaskCluster

    cluster = DaskCluster(tmp_path)
    yield cluster
    cluster.close()


@pytest.fixture(scope="module")
def tls_dask_cluster(tmp_path_factory):
    """A scheduler and two workers as :func:`dask_cluster`, over TLS with certificates made for the test (by the
    ``openssl`` command) and started in a folder of their own, so relative paths would resolve elsewhere."""
    import shutil

    from dask_cluster import DaskCluster, make_certificates

    if shutil.which("openssl") is None:
        missing("the openssl command, which makes the test certificates, is not installed")
    folder = tmp_path_factory.mktemp("tls-cluster")
    (folder / "workers-cwd").mkdir()
    cluster = DaskCluster(folder, make_certificates(folder / "certs"), cwd=folder / "workers-cwd")
    yield cluster
    cluster.close()
