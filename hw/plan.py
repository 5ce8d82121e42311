"""Probe plans: where and how a robot should press the sensor on an object.

For each interest point the plan gives the position, the approach direction
(-normal: into the surface) and the sensor's orientation as a unit quaternion
[w, x, y, z], all in the mesh file's own frame and units, plus the sensor's
dimensions.  The sensor frame is tactile's pad at in-plane angle 0
(:func:`sensor_rotations`): x along increasing columns, y along increasing
rows, z along the approach direction.  The approach is the normal of the
plane tactile fits under the pad (``tactile.sensor_poses``), so a robot
following the plan holds the sensor as the simulation does.  Written as JSON
(an object with ``sensor`` and a ``points`` list) and as CSV beside it.
"""

from __future__ import annotations

import csv
import io
import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from meshsal.mesh import Similarity
from meshsal.util.jsonfile import read_json

__all__ = [
    "FORMAT",
    "ProbePoint",
    "Plan",
    "sensor_rotations",
    "quaternion_from_matrix",
    "matrix_from_quaternion",
    "make_plan",
    "save_plan",
    "load_plan",
]

FORMAT = "visuotactile-probe-plan"
VERSION = 1


@dataclass(frozen=True, eq=False)
class ProbePoint:
    """One planned press (mesh file frame and units).

    Attributes
    ----------
    id : int
    position : (3,) float64
        Surface point to press.
    approach : (3,) float64
        Unit direction the sensor moves in: the inward normal of the pad plane.
    quaternion : (4,) float64
        Unit quaternion [w, x, y, z] rotating the world axes onto the sensor's.
    """

    id: int
    position: np.ndarray
    approach: np.ndarray
    quaternion: np.ndarray


@dataclass(frozen=True, eq=False)
class Plan:
    """A probe plan: the sensor's description and the points in pressing order.

    Attributes
    ----------
    points : tuple of ProbePoint
    sensor : dict
        ``rows``, ``cols``, ``pitch_mm``, ``width_mm``, ``height_mm``,
        ``depth_mm`` and the width and height in mesh file units.
    mesh : str
        The mesh file (or toy name) planned on.
    size_mm : float
        Bounding-box diagonal the mesh was scaled to for planning; the
        object's size the imprints are simulated at.
    method : str
        Interest point method.
    frame : meshsal.Similarity
        Maps mesh file coordinates to the planning frame (the mesh scaled
        to ``size_mm`` and centred, millimetres), the frame of simulated
        imprint sets; its ``scale`` is millimetres per file unit.
    """

    points: tuple
    sensor: dict
    mesh: str
    size_mm: float
    method: str
    frame: Similarity

    def positions_mm(self) -> np.ndarray:
        """(k, 3) positions in the planning frame (mm), as ``tactile.ImprintSet`` stores them."""
        return self.frame.apply(np.array([p.position for p in self.points]).reshape(-1, 3))


def sensor_rotations(poses) -> np.ndarray:
    """Rotation matrices whose columns are the sensor's x, y, z axes in world coordinates.

    x is the direction of increasing column (``poses.rights``), y of
    increasing row (``-poses.ups``: row 0 is at the top of the image), z the
    approach direction (``-poses.normals``, into the surface); the frame is
    right-handed because tactile's (right, up, normal) is.

    Parameters
    ----------
    poses : tactile.Poses

    Returns
    -------
    (k, 3, 3) float64

    Examples
    --------
    >>> from tactile.sensor import poses_from_normals
    >>> R = sensor_rotations(poses_from_normals([[0.0, 0, 0]], [[0.0, 0, 1]]))[0]
    >>> (R.round(6) + 0.0).tolist()  # x = world x, y = -world y (image down), z = -normal
    [[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]]
    """
    return np.stack([poses.rights, -poses.ups, -poses.normals], axis=2)


def quaternion_from_matrix(R: np.ndarray) -> np.ndarray:
    """Unit quaternion [w, x, y, z] (w >= 0) of a rotation matrix (``scipy.spatial.transform.Rotation``).

    Examples
    --------
    >>> quaternion_from_matrix(np.eye(3))
    array([1., 0., 0., 0.])
    """
    x, y, z, w = Rotation.from_matrix(np.asarray(R, dtype=np.float64)).as_quat()
    q = np.array([w, x, y, z])
    return -q if w < 0 else q


def matrix_from_quaternion(q) -> np.ndarray:
    """Rotation matrix of a unit quaternion [w, x, y, z]."""
    w, x, y, z = np.asarray(q, dtype=np.float64)
    return Rotation.from_quat([x, y, z, w]).as_matrix()


def make_plan(
    mesh,
    n: int = 15,
    method: str = "attention",
    size_mm: float = 150.0,
    sensor=None,
    seed: int = 0,
    quiet: bool = True,
    source: str = "",
    model=None,
    view_size: int | None = None,
) -> Plan:
    """Plan one press per interest point of ``mesh``.

    Parameters
    ----------
    mesh : meshsal.Mesh
        As loaded (its ``transform`` leads back to the file's frame).
    n, method, seed :
        Passed to ``meshsal.interest_points``.
    size_mm : float
        The mesh is scaled to this principal-frame box diagonal for planning
        (``meshsal.mesh.transform.scale_to_principal``), as the points are chosen and the imprints simulated.
    sensor : tactile.Sensor, optional
        Default ``tactile.Sensor()``.
    source : str
        Mesh file or toy name recorded in the plan.
    model : meshsal.points.learned.TouchModel, optional
        Needed by the learned methods ("learned", "attention_learned").
    view_size : int, optional
        Rendered view size of the methods that look (default ``meshsal.PointOptions``'s; a touch model
        is meant for the size it records).

    Returns
    -------
    Plan
        Positions and directions in the mesh file's frame and units.
    """
    import meshsal
    import tactile
    from meshsal.mesh.transform import scale_to_principal

    sensor = tactile.Sensor() if sensor is None else sensor
    scaled = scale_to_principal(mesh, size_mm)
    sized = {} if view_size is None else {"size": int(view_size)}
    pts = meshsal.interest_points(
        scaled, n=n, method=method, seed=seed, quiet=quiet, pad_width=sensor.width_mm, model=model, **sized
    )
    # The pad settles on the plane tactile fits over its footprint, with tactile's angle-0 image axes.
    poses = tactile.sensor_poses(scaled, pts.positions, pts.normals, sensor)
    positions = scaled.transform.to_source(poses.centers)
    approach = -scaled.transform.direction_to_source(poses.normals)
    rotations = scaled.transform.rotation.T @ sensor_rotations(poses)
    points = tuple(
        ProbePoint(i, positions[i], approach[i], quaternion_from_matrix(rotations[i])) for i in range(len(positions))
    )
    # File -> planning frame: undo the mesh's own transform, then apply the scaled one.
    frame = mesh.transform.inverse().then(scaled.transform)
    width_mm, height_mm = sensor.cols * sensor.pitch_mm, sensor.rows * sensor.pitch_mm
    info = {
        "rows": sensor.rows,
        "cols": sensor.cols,
        "pitch_mm": sensor.pitch_mm,
        "width_mm": width_mm,
        "height_mm": height_mm,
        "depth_mm": sensor.depth_mm,
        "width": width_mm / frame.scale,
        "height": height_mm / frame.scale,
    }
    return Plan(
        points=points, sensor=info, mesh=source or mesh.name, size_mm=float(size_mm), method=method, frame=frame
    )


def _plan_dict(plan: Plan) -> dict:
    return {
        "format": FORMAT,
        "version": VERSION,
        "mesh": plan.mesh,
        "size_mm": plan.size_mm,
        "method": plan.method,
        "units": "positions in the mesh file's frame and units; sensor width and height in mm and in file units",
        "planning_frame": {
            "scale": plan.frame.scale,
            "offset": plan.frame.offset.tolist(),
            "rotation": plan.frame.rotation.tolist(),
            "meaning": "position_mm = scale * rotation @ position + offset: the mesh scaled to size_mm "
            "and centred, where imprints are simulated; scale = mm per file unit",
        },
        "sensor": {
            **plan.sensor,
            "axes": "x = increasing column, y = increasing row (row 0 at the top), z = approach "
            "(into the surface); tactile's pad at in-plane angle 0",
        },
        "points": [
            {
                "id": p.id,
                "position": p.position.tolist(),
                "approach": p.approach.tolist(),
                "quaternion": p.quaternion.tolist(),
            }
            for p in plan.points
        ],
    }


def save_plan(plan: Plan, path) -> tuple[Path, Path]:
    """Write the plan as JSON at ``path`` and as CSV beside it (same stem), atomically.

    Returns the two paths written.
    """
    from meshsal.util.atomic import write_text

    path = Path(path)
    csv_path = path.with_suffix(".csv")
    if csv_path == path:
        raise ValueError(f"{path}: the plan's JSON needs another suffix than .csv")
    write_text(path, json.dumps(_plan_dict(plan), indent=2) + "\n")
    out = io.StringIO()
    writer = csv.writer(out, lineterminator="\n")
    writer.writerow(["id", "x", "y", "z", "approach_x", "approach_y", "approach_z", "qw", "qx", "qy", "qz"])
    for p in plan.points:
        writer.writerow([p.id, *(f"{v:.9g}" for v in (*p.position, *p.approach, *p.quaternion))])
    write_text(csv_path, out.getvalue())
    return path, csv_path


def load_plan(path) -> Plan:
    """Read a plan written by :func:`save_plan`, with clear errors naming the file."""
    path = Path(path)
    data = read_json(path, "probe plan")
    if not isinstance(data, dict) or data.get("format") != FORMAT:
        raise ValueError(f"{path}: not a probe plan (no format {FORMAT!r})")
    if data.get("version") != VERSION:
        raise ValueError(f"{path}: probe plan version {data.get('version')} is not the supported {VERSION}")
    try:
        points = []
        for item in data["points"]:
            position = np.array(item["position"], dtype=np.float64).reshape(3)
            approach = np.array(item["approach"], dtype=np.float64).reshape(3)
            quaternion = np.array(item["quaternion"], dtype=np.float64).reshape(4)
            if not (
                np.isfinite(position).all()
                and abs(np.linalg.norm(approach) - 1) < 1e-6
                and abs(np.linalg.norm(quaternion) - 1) < 1e-6
            ):
                raise ValueError("non-finite position or non-unit approach/quaternion")
            points.append(ProbePoint(int(item["id"]), position, approach, quaternion))
        ids = [p.id for p in points]
        if len(set(ids)) != len(ids):
            raise ValueError("repeated point ids")
        plan = Plan(
            points=tuple(points),
            sensor=dict(data["sensor"]),
            mesh=str(data.get("mesh", "")),
            size_mm=float(data["size_mm"]),
            method=str(data.get("method", "")),
            frame=Similarity(
                float(data["planning_frame"]["scale"]),
                data["planning_frame"]["offset"],
                data["planning_frame"].get("rotation", np.eye(3)),
            ),
        )
    except (KeyError, TypeError, ValueError) as exc:
        raise ValueError(f"{path}: damaged probe plan ({type(exc).__name__}: {exc})") from None
    if not plan.points:
        raise ValueError(f"{path}: the probe plan has no points")
    return plan
