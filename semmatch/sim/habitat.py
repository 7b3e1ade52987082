"""Optional habitat-sim backend behind the renderer interface (``render(pose) -> RenderResult``).

``habitat_sim`` is imported lazily, only when a :class:`HabitatRenderer` is built; it is not
installable from PyPI (conda: ``conda install habitat-sim -c conda-forge -c aihabitat``, see
``environment.yml``). Trajectories still come from :func:`semmatch.sim.make_trajectory` on a
:class:`~semmatch.sim.Scene` of the same mesh (e.g. :func:`semmatch.sim.plyscene.scene_from_ply`),
and :func:`semmatch.sim.simulate_sequence` accepts the renderer through its ``renderer``
argument.

Frames: semmatch's world is z-up with OpenCV cameras; Habitat's is y-up with OpenGL cameras
(looking along -z). :func:`to_habitat_pose` converts.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics, check_pose, rotation_to_quat
from ..io.labels import NAMES
from .render import RenderResult

__all__ = ["HabitatRenderer", "to_habitat_pose", "habitat_available", "WORLD_TO_HABITAT"]

#: rotation of semmatch world coordinates (z up) into Habitat's (y up): (x, y, z) -> (x, z, -y)
WORLD_TO_HABITAT = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
_CV_TO_GL = np.diag([1.0, -1.0, -1.0])


def habitat_available() -> bool:
    """True when ``habitat_sim`` can be imported."""
    import importlib.util

    return importlib.util.find_spec("habitat_sim") is not None


def to_habitat_pose(pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Habitat agent position and rotation (quaternion ``x, y, z, w``) of a semmatch pose.

    Parameters
    ----------
    pose : ndarray (4,4)
        ``T_world_camera`` (z-up world, OpenCV camera).

    Returns
    -------
    position : ndarray (3,)
        In Habitat's y-up world.
    rotation : ndarray (4,)
        Quaternion ``(x, y, z, w)`` of the OpenGL camera in Habitat's world.
    """
    T = check_pose(pose)
    R = WORLD_TO_HABITAT @ T[:3, :3] @ _CV_TO_GL
    return WORLD_TO_HABITAT @ T[:3, 3], rotation_to_quat(R)


class HabitatRenderer:
    """Render a Habitat scene (e.g. Replica ``mesh.ply`` + semantics) from semmatch poses.

    Parameters
    ----------
    scene_path : path
        Scene file habitat-sim can load (``.glb``, ``.ply``, or a scene dataset config).
    intrinsics : Intrinsics
        Square pixels and a centred principal point (Habitat's pinhole model).
    category_map : dict, optional
        Habitat category name -> semmatch category id; default: names equal to semmatch's
        category names map to them, others to void.
    gpu_device_id : int
        habitat-sim GPU (it needs an EGL-capable GPU for rendering).

    Raises
    ------
    ImportError
        ``habitat_sim`` is not installed (the message says how to get it).
    FileNotFoundError
        No such scene file.
    ValueError
        Intrinsics Habitat cannot represent.
    """

    def __init__(
        self,
        scene_path: str | os.PathLike,
        intrinsics: Intrinsics = DEFAULT_INTRINSICS,
        *,
        category_map: dict[str, int] | None = None,
        gpu_device_id: int = 0,
    ) -> None:
        try:
            import habitat_sim
        except ImportError:
            raise ImportError(
                "the habitat backend needs habitat_sim, which is not installable from PyPI; "
                "use conda (conda install habitat-sim -c conda-forge -c aihabitat, see "
                "environment.yml) or the built-in semmatch.sim.Renderer"
            ) from None
        path = Path(scene_path)
        if not path.exists():
            raise FileNotFoundError(f"{path}: no such habitat scene")
        W, H = intrinsics.width, intrinsics.height
        if abs(intrinsics.fx - intrinsics.fy) > 1e-6 * intrinsics.fx:
            raise ValueError(f"{path}: habitat cameras need fx == fy, got {intrinsics.fx} and {intrinsics.fy}")
        if abs(intrinsics.cx - (W - 1) / 2) > 0.51 or abs(intrinsics.cy - (H - 1) / 2) > 0.51:
            raise ValueError(f"{path}: habitat cameras need a centred principal point")
        hfov = float(np.degrees(2 * np.arctan(W / (2 * intrinsics.fx))))
        self.intrinsics = intrinsics
        sim_cfg = habitat_sim.SimulatorConfiguration()
        sim_cfg.scene_id = str(path)
        sim_cfg.gpu_device_id = int(gpu_device_id)
        specs = []
        for uuid, kind in (("rgb", habitat_sim.SensorType.COLOR), ("depth", habitat_sim.SensorType.DEPTH),
                           ("semantic", habitat_sim.SensorType.SEMANTIC)):
            s = habitat_sim.CameraSensorSpec()
            s.uuid, s.sensor_type, s.resolution = uuid, kind, [H, W]
            s.position, s.hfov = [0.0, 0.0, 0.0], hfov
            specs.append(s)
        agent = habitat_sim.agent.AgentConfiguration(sensor_specifications=specs)
        from habitat_sim.utils.common import quat_from_coeffs

        self._habitat = habitat_sim
        self._quat_from_coeffs = quat_from_coeffs
        self._sim = habitat_sim.Simulator(habitat_sim.Configuration(sim_cfg, [agent]))
        names = {n: i for i, n in enumerate(NAMES)}
        cmap = category_map or {}
        ids = [0]
        for obj in getattr(self._sim.semantic_scene, "objects", []) or []:
            if obj is None:
                continue
            idx = int(obj.id.split("_")[-1]) if isinstance(obj.id, str) else int(obj.id)
            name = obj.category.name() if obj.category is not None else ""
            while len(ids) <= idx:
                ids.append(0)
            ids[idx] = int(cmap.get(name, names.get(name, 0)))
        self._instance_to_category = np.asarray(ids, dtype=np.uint8)

    def render(self, pose: np.ndarray) -> RenderResult:
        """Render ``pose`` (``T_world_camera``): rgb, depth (z, metres), labels, instances.

        ``triangle`` is -1 everywhere (Habitat does not report hit triangles).
        """
        pos, q = to_habitat_pose(pose)
        agent = self._sim.get_agent(0)
        state = self._habitat.AgentState()
        state.position = pos.astype(np.float32)
        state.rotation = self._quat_from_coeffs(q)  # coefficients x, y, z, w
        agent.set_state(state, reset_sensors=True)
        obs = self._sim.get_sensor_observations()
        inst = np.asarray(obs["semantic"]).astype(np.int64)
        table = self._instance_to_category
        labels = np.where(inst < len(table), table[np.clip(inst, 0, len(table) - 1)], 0).astype(np.uint8)
        H, W = self.intrinsics.shape
        return RenderResult(
            rgb=np.ascontiguousarray(np.asarray(obs["rgb"])[..., :3], dtype=np.uint8),
            depth=np.asarray(obs["depth"], dtype=np.float32),
            labels=labels,
            instances=inst.astype(np.int32),
            triangle=np.full((H, W), -1, dtype=np.int64),
        )

    def close(self) -> None:
        """Release the simulator."""
        self._sim.close()
