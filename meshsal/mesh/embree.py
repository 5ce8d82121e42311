"""The Embree ray-casting scene shared by the renderer, point projection and tactile imprints.

embreex copies a mesh into Embree one element at a time through Python
indexing: 50 ms of a 77 ms build for 100k faces.  Where the layout of its
scene object is the one checked below, :func:`embree_scene` instead hands
the vertex and index buffers to the Embree library embreex ships, through
ctypes, in one copy each (1 ms); anywhere else it falls back to embreex's
own path.  The scenes are the same either way.

Embree picks SSE2, AVX, AVX2 or AVX-512 kernels by CPU, and they round
differently: a hit's distance and barycentrics change in the last bits, and
with them renders, imprints and points.  Embree 4 takes its instruction set
only from the configuration string of the device a scene is created in
(``isa=sse2``, ``max_isa=avx2``...; it reads no environment variable or
file), and embreex creates every device without one.  So every scene here
is created in one device per process made with ``$VISUOTACTILE_EMBREE_CONFIG``
(``isa=sse2`` once :func:`meshsal.util.reproducible.pin_kernels` has run),
handed to embreex through ctypes.  With the variable unset or empty, Embree
chooses.

Even with one instruction set, Embree's SSE kernels divide by the CPU's
approximate reciprocal (``rcpps`` and a Newton step), which Intel and AMD
round with their own tables.  So every scene here is a :class:`Scene`, whose
hits' distances and barycentrics are computed again from their faces with
NumPy's correctly rounded arithmetic: the same on every x86-64 CPU.
"""

from __future__ import annotations

import ctypes
import functools
import os
import threading
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from meshsal.mesh import Mesh
from meshsal.util.reproducible import EMBREE_VARIABLE

# Embree 4 constants (rtcore_geometry.h, rtcore_buffer.h, rtcore_common.h).
_GEOMETRY_TYPE_TRIANGLE = 0
_BUFFER_TYPE_INDEX, _BUFFER_TYPE_VERTEX = 0, 1
_FORMAT_UINT3, _FORMAT_FLOAT3 = 0x5003, 0x9003
_SCENE_FLAG_ROBUST = 1 << 2


@functools.cache
def _library():
    """The Embree library that embreex loaded, with the few signatures used here, or None."""
    try:
        import embreex
    except ImportError:
        return None
    shipped = sorted((Path(embreex.__file__).parent.parent / "embreex.libs").glob("libembree4*.so*"))
    if not shipped:
        return None
    try:
        lib = ctypes.CDLL(str(shipped[0]))  # the same file embreex loaded: the same library state
    except OSError:
        return None
    handle = ctypes.c_void_p
    signatures = {
        "rtcNewDevice": (handle, [ctypes.c_char_p]),
        "rtcGetSceneDevice": (handle, [handle]),
        "rtcReleaseDevice": (None, [handle]),
        "rtcGetDeviceError": (ctypes.c_int, [handle]),
        "rtcGetDeviceLastErrorMessage": (ctypes.c_char_p, [handle]),
        "rtcNewGeometry": (handle, [handle, ctypes.c_int]),
        "rtcSetNewGeometryBuffer": (
            handle,
            [handle, ctypes.c_int, ctypes.c_uint, ctypes.c_int, ctypes.c_size_t, ctypes.c_size_t],
        ),
        "rtcCommitGeometry": (None, [handle]),
        "rtcAttachGeometry": (ctypes.c_uint, [handle, handle]),
        "rtcReleaseGeometry": (None, [handle]),
        "rtcGetSceneFlags": (ctypes.c_int, [handle]),
    }
    for name, (restype, argtypes) in signatures.items():
        function = getattr(lib, name, None)
        if function is None:
            return None
        function.restype, function.argtypes = restype, argtypes
    return lib


def _scene_handle(scene) -> int | None:
    """The RTCScene inside an embreex ``EmbreeScene``, or None if its layout is not the expected one.

    embreex declares the object as the Python object header, then ``RTCScene
    scene_i``, then ``int is_committed`` (rtcore_scene.pxd).  Writing two
    values to the public ``is_committed`` and reading them back at its
    expected place proves the layout before the pointer next to it is used.
    """
    header = object.__basicsize__
    if type(scene).__basicsize__ < header + 16:
        return None
    field = id(scene) + header + 8
    saved = scene.is_committed
    try:
        seen = []
        for probe in (0x5A17, 0x1CE):
            scene.is_committed = probe
            seen.append(ctypes.c_int.from_address(field).value)
    finally:
        scene.is_committed = saved
    if seen != [0x5A17, 0x1CE]:
        return None
    return ctypes.c_void_p.from_address(id(scene) + header).value


def _attach_directly(scene, mesh: Mesh) -> bool:
    """Add the mesh's triangles to an empty, uncommitted embreex scene in one copy per buffer.

    Returns False, having attached nothing usable, where this cannot be done.
    """
    lib = _library()
    handle = _scene_handle(scene) if lib is not None else None
    if not handle:
        return False
    device = lib.rtcGetSceneDevice(handle)
    try:
        geometry = lib.rtcNewGeometry(device, _GEOMETRY_TYPE_TRIANGLE)
        if not geometry:
            return False
        # Vertices padded to 16 bytes, as embreex lays them out.
        vertices = np.zeros((mesh.n_vertices, 4), np.float32)
        vertices[:, :3] = mesh.vertices
        faces = np.ascontiguousarray(mesh.faces, dtype=np.uint32)
        for kind, fmt, array in (
            (_BUFFER_TYPE_VERTEX, _FORMAT_FLOAT3, vertices),
            (_BUFFER_TYPE_INDEX, _FORMAT_UINT3, faces),
        ):
            target = lib.rtcSetNewGeometryBuffer(geometry, kind, 0, fmt, array.strides[0], len(array))
            if not target:
                lib.rtcReleaseGeometry(geometry)
                return False
            ctypes.memmove(target, array.ctypes.data, array.nbytes)
        lib.rtcCommitGeometry(geometry)
        lib.rtcAttachGeometry(handle, geometry)
        lib.rtcReleaseGeometry(geometry)
        return lib.rtcGetDeviceError(device) == 0
    finally:
        lib.rtcReleaseDevice(device)


def _device_slot(device):
    """Where an embreex ``EmbreeDevice`` keeps its RTCDevice (a ctypes pointer), or None if that is not proven.

    embreex declares the object as the Python object header, then ``RTCDevice
    device`` (rtcore.pxd).  A scene created in the device reports the device
    it belongs to (``rtcGetSceneDevice``): equal to the pointer at that place,
    it proves the layout.
    """
    from embreex import rtcore_scene as rtcs

    lib = _library()
    header = object.__basicsize__
    if lib is None or type(device).__basicsize__ < header + 8:
        return None
    handle = _scene_handle(rtcs.EmbreeScene(device=device))
    if not handle:
        return None
    owner = lib.rtcGetSceneDevice(handle)
    try:
        slot = ctypes.c_void_p.from_address(id(device) + header)
        return slot if owner and slot.value == owner else None
    finally:
        lib.rtcReleaseDevice(owner)


_device_lock = threading.Lock()


@functools.cache
def _configured_device(config: str):
    """One embreex ``EmbreeDevice`` made with ``config``, or None where embreex's layout is not the one checked."""
    from embreex import rtcore as rtc

    device = rtc.EmbreeDevice()
    slot = _device_slot(device)
    if slot is None:
        warnings.warn(
            f"${EMBREE_VARIABLE}={config!r} is not applied: this embreex's device is not the one "
            f"meshsal.mesh.embree knows, so Embree picks its kernels by CPU",
            RuntimeWarning,
            stacklevel=3,
        )
        return None
    lib = _library()
    made = lib.rtcNewDevice(config.encode())
    if not made:
        message = (lib.rtcGetDeviceLastErrorMessage(None) or b"no message").decode(errors="replace")
        raise ValueError(f"Embree refuses the device configuration ${EMBREE_VARIABLE}={config!r}: {message}")
    replaced, slot.value = slot.value, made
    lib.rtcReleaseDevice(replaced)
    return device


def embree_device():
    """The embreex device every scene is created in: made with ``$VISUOTACTILE_EMBREE_CONFIG``, or None.

    None when the variable is unset or empty (embreex then makes a device
    per scene, and Embree picks its kernels by CPU).

    Raises
    ------
    ValueError
        If Embree refuses the configuration (e.g. ``isa=avx512`` on a CPU without it).
    """
    config = os.environ.get(EMBREE_VARIABLE, "").strip()
    if not config:
        return None
    with _device_lock:
        return _configured_device(config)


def is_robust(scene) -> bool:
    """Whether the scene is known to trace robustly: no ray slips between two triangles sharing an edge.

    False for a scene built with ``robust=False``, and for any scene whose
    flags cannot be read.
    """
    lib = _library()
    handle = _scene_handle(getattr(scene, "embree", scene)) if lib is not None else None
    return bool(handle) and bool(lib.rtcGetSceneFlags(handle) & _SCENE_FLAG_ROBUST)


@dataclass(frozen=True, eq=False)
class Scene:
    """An Embree scene whose hits are the same on every x86-64 CPU.

    Embree's ``tfar``, ``u`` and ``v`` are quotients taken with the CPU's
    approximate reciprocal, so :meth:`run` computes them again from the face's
    float32 corners, the ray's origin and its direction (Cramer's rule in
    float64, rounded once to float32): the same on every CPU, and nearer the
    exact crossing than Embree's own.  The face (``primID``) and its geometric
    normal (``Ng``, a cross product) are Embree's: it picks the face by
    comparisons without division, except between faces within a unit in the
    last place of each other along the ray.

    Attributes
    ----------
    embree : embreex ``EmbreeScene``
    corners : (12, m) float64
        Each face's first corner, its edges to the second and the third
        corners, and their cross product: 96 bytes a face, beside Embree's
        own hundred or so.
    """

    embree: object
    corners: np.ndarray

    @property
    def is_committed(self) -> int:
        return self.embree.is_committed

    def run(self, origins, directions, dists=None, query="INTERSECT", output=None):
        """embreex's ``EmbreeScene.run``, with each hit's ``tfar``, ``u`` and ``v`` computed again (see :class:`Scene`).

        Parameters
        ----------
        origins : (k, 3) float32
        directions : (k, 3) float32, or (1, 3) shared by every ray
        dists : float or (k,) float32, optional
            How far each ray looks (``tfar`` on entry).
        query : str
        output : int, optional
            1 for the dict of hits described in :func:`embree_scene`; else
            what embreex gives (the face ids).
        """
        hit = self.embree.run(origins, directions, dists=dists, query=query, output=output)
        if isinstance(hit, dict):
            _settle(hit, origins, directions, self.corners)
        return hit


def _corners(mesh: Mesh) -> np.ndarray:
    """(12, m) float64: each face's first corner ``a``, its edges ``e``, ``f`` to the others and ``n = e x f``.

    From the float32 vertices Embree holds.
    """
    V = np.asarray(mesh.vertices, np.float32).astype(np.float64)
    a, b, c = (np.take(V, corner, axis=0) for corner in np.asarray(mesh.faces).T)
    e, f = b - a, c - a
    n = np.stack(
        [
            e[:, 1] * f[:, 2] - e[:, 2] * f[:, 1],
            e[:, 2] * f[:, 0] - e[:, 0] * f[:, 2],
            e[:, 0] * f[:, 1] - e[:, 1] * f[:, 0],
        ],
        axis=1,
    )
    return np.ascontiguousarray(np.concatenate([a, e, f, n], axis=1).T)


def _crossing(faces: np.ndarray, origins: np.ndarray, directions: np.ndarray) -> tuple:
    """``(t, u, v)`` float64 solving ``o + t d = a + u e + v f`` for the (12, k) ``faces`` of :func:`_corners`.

    Cramer's rule with ``m = s x d``, ``s = o - a``: ``t = -(s . n) / (d . n)``,
    ``u = -(f . m) / (d . n)``, ``v = (e . m) / (d . n)``.  Elementwise
    arithmetic only (no dot products, whose summation order and fused
    multiply-adds vary by library), each operation correctly rounded.
    """
    ax, ay, az, ex, ey, ez, fx, fy, fz, nx, ny, nz = faces
    ox, oy, oz = origins.astype(np.float64).T
    dx, dy, dz = directions.astype(np.float64).T
    sx, sy, sz = ox - ax, oy - ay, oz - az
    mx = sy * dz
    mx -= sz * dy
    my = sz * dx
    my -= sx * dz
    mz = sx * dy
    mz -= sy * dx
    dn = dx * nx
    dn += dy * ny
    dn += dz * nz
    t, u, v = sx * nx, fx * mx, ex * mx
    t += sy * ny
    t += sz * nz
    u += fy * my
    u += fz * mz
    v += ey * my
    v += ez * mz
    with np.errstate(divide="ignore", invalid="ignore"):
        for quotient in (t, u, v):
            quotient /= dn
    np.negative(t, out=t)
    np.negative(u, out=u)
    return t, u, v


def _settle(hit: dict, origins: np.ndarray, directions: np.ndarray, corners: np.ndarray) -> None:
    """Overwrite each hit's ``tfar``, ``u``, ``v`` with their values computed again (see :class:`Scene`)."""
    hits = np.flatnonzero(hit["primID"] >= 0)
    if hits.size == 0:
        return
    origins = origins if len(origins) == 1 else np.take(origins, hits, axis=0)
    directions = directions if len(directions) == 1 else np.take(directions, hits, axis=0)
    faces = np.take(corners, hit["primID"][hits], axis=1)
    for key, values in zip(("tfar", "u", "v"), _crossing(faces, origins, directions)):
        if np.isfinite(values).all():
            hit[key][hits] = values
        else:  # a face parallel to the ray in float64 too is degenerate: Embree's own value stays
            keep = np.isfinite(values)
            hit[key][hits[keep]] = values[keep]


def embree_scene(mesh: Mesh, robust: bool = True):
    """A :class:`Scene` of the mesh's triangles, built and ready for concurrent queries.

    ``scene.run(origins, directions, output=1)`` takes (k, 3) float32 arrays
    and returns a dict with ``primID`` (-1 on a miss), ``u``, ``v`` (the hit's
    barycentrics on the triangle's 2nd and 3rd corners), ``tfar`` and ``Ng``,
    the same on every x86-64 CPU.
    Embree releases the GIL while tracing, so threads may share one scene.
    Every scene is created in :func:`embree_device`, whose instruction set
    ``$VISUOTACTILE_EMBREE_CONFIG`` chooses.

    A robust scene (the default) is watertight: a ray through an edge or a
    vertex meets one of the faces there.  ``robust=False`` traces about a
    fifth faster, but a few rays in a million slip through such cracks.

    Examples
    --------
    >>> tri = Mesh(vertices=[[0, 0, 0], [1, 0, 0], [0, 1, 0]], faces=[[0, 1, 2]])
    >>> hit = embree_scene(tri).run(np.array([[0.2, 0.2, 1]], np.float32),
    ...                             np.array([[0, 0, -1]], np.float32), output=1)
    >>> int(hit["primID"][0]), round(float(hit["tfar"][0]), 5)       # float32 arithmetic: 1.0 within rounding
    (0, 1.0)
    """
    from embreex import rtcore_scene as rtcs
    from embreex.mesh_construction import TriangleMesh

    device = embree_device()
    scene = rtcs.EmbreeScene(device=device, robust=robust)
    if mesh.n_faces == 0 or not _attach_directly(scene, mesh):
        scene = rtcs.EmbreeScene(device=device, robust=robust)
        TriangleMesh(
            scene,
            np.ascontiguousarray(mesh.vertices, dtype=np.float32),
            np.ascontiguousarray(mesh.faces, dtype=np.int32),
        )
    # The first query commits (builds) the scene: do it before threads share it.
    scene.run(np.zeros((1, 3), np.float32), np.ones((1, 3), np.float32), output=0)
    return Scene(embree=scene, corners=_corners(mesh))
