"""The simulator: scenes (procedural or from a semantic PLY mesh), trajectories, two renderers
(ray casting on Open3D's ``RaycastingScene``, the reference; rasterising with OpenGL,
:mod:`semmatch.sim.raster`) and sensor noise. The optional habitat-sim backend lives in
:mod:`semmatch.sim.habitat` (imported on demand).

>>> from semmatch.sim import generate_scene, make_trajectory, simulate_sequence
>>> scene = generate_scene("living_room", seed=0)
>>> poses = make_trajectory(scene, 1.6, 300, kind="upper")       # doctest: +SKIP
>>> simulate_sequence(scene, poses, "data/tmp/upper")             # doctest: +SKIP
"""

from .noise import NoiseConfig
from .plyscene import scene_from_ply
from .procedural import SCENE_KINDS, box_room, generate_scene
from .raster import RasterRenderer, gl_available, make_renderer, render_frames
from .render import Renderer, RenderResult
from .scene import Scene
from .sequence import check_seed_splits, generate_dataset
from .simulate import (
    DEFAULT_SWEEP,
    carrier_poses,
    simulate_pair,
    simulate_sequence,
    simulate_sequences,
    sweep_name,
)
from .trajectory import (
    FreeSpace,
    camera_elevation_deg,
    free_space,
    limit_turn_rate,
    make_sweep_trajectories,
    make_trajectory,
    route_waypoints,
    scene_levels,
    tour_coverage,
)

__all__ = [
    "Scene",
    "Renderer",
    "RasterRenderer",
    "make_renderer",
    "gl_available",
    "RenderResult",
    "render_frames",
    "SCENE_KINDS",
    "generate_scene",
    "box_room",
    "scene_from_ply",
    "FreeSpace",
    "free_space",
    "scene_levels",
    "make_trajectory",
    "route_waypoints",
    "limit_turn_rate",
    "make_sweep_trajectories",
    "camera_elevation_deg",
    "tour_coverage",
    "NoiseConfig",
    "simulate_sequence",
    "simulate_sequences",
    "simulate_pair",
    "carrier_poses",
    "generate_dataset",
    "check_seed_splits",
    "sweep_name",
    "DEFAULT_SWEEP",
]
