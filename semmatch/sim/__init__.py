"""The simulator: scenes (procedural or from a semantic PLY mesh), trajectories, a renderer on
Open3D's ``RaycastingScene`` and sensor noise."""

from .render import Renderer, RenderResult
from .scene import Scene

__all__ = ["Scene", "Renderer", "RenderResult"]
