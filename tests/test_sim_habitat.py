"""The optional habitat-sim backend: pose conversion always, rendering only with habitat_sim."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io.geometry import look_at, quat_to_rotation
from semmatch.sim.habitat import WORLD_TO_HABITAT, HabitatRenderer, habitat_available, to_habitat_pose


def test_pose_conversion_to_habitat_frames():
    # a camera looking along +x (semmatch world, z up) looks along +x in Habitat too, with
    # Habitat's up (+y) as the camera's up and the OpenGL camera looking along its -z
    T = look_at((1.0, 2.0, 1.5), (5.0, 2.0, 1.5))
    pos, q = to_habitat_pose(T)
    np.testing.assert_allclose(pos, [1.0, 1.5, -2.0])
    R = quat_to_rotation(q)
    np.testing.assert_allclose(R @ [0, 0, -1], [1, 0, 0], atol=1e-9)  # viewing direction
    np.testing.assert_allclose(R @ [0, 1, 0], [0, 1, 0], atol=1e-9)  # camera up = world up
    assert np.isclose(np.linalg.det(WORLD_TO_HABITAT), 1.0)


@pytest.mark.skipif(habitat_available(), reason="habitat_sim is installed")
def test_missing_habitat_says_how_to_get_it(tmp_path):
    with pytest.raises(ImportError, match="conda"):
        HabitatRenderer(tmp_path / "scene.glb")


@pytest.mark.skipif(not habitat_available(), reason="habitat_sim is not importable")
def test_habitat_renders_a_frame(tmp_path):  # pragma: no cover - needs habitat_sim
    from semmatch.io.geometry import DEFAULT_INTRINSICS
    from semmatch.sim import generate_scene

    scene = generate_scene("box_room", 0)
    mesh = scene.to_semantic_map().to_open3d(label_colors=False)
    import open3d as o3d

    path = tmp_path / "box.ply"
    o3d.io.write_triangle_mesh(str(path), mesh)
    intr = DEFAULT_INTRINSICS.scaled(160, 120)
    r = HabitatRenderer(path, intr).render(look_at((2.0, 1.5, 1.2), (3.5, 2.5, 1.0)))
    assert r.rgb.shape == (120, 160, 3) and r.depth.shape == (120, 160)
    assert (r.depth > 0).mean() > 0.9
