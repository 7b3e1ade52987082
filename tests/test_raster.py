"""The rasterising renderer agrees with the ray caster (the reference); backends and fallback."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.sim import Renderer, generate_scene, make_trajectory, raster
from semmatch.sim.raster import RasterRenderer, gl_available, make_renderer

GL, WHY = gl_available()
needs_gl = pytest.mark.skipif(not GL, reason=f"no OpenGL context here: {WHY}")
INTR = DEFAULT_INTRINSICS.scaled(320, 240)


def agreement(scene, poses, intr=INTR) -> dict:
    rc, rr = Renderer(scene, intr), RasterRenderer(scene, intr)
    out = {"depth": [], "labels": [], "instances": [], "hit": [], "rgb": []}
    for p in poses:
        a, b = rc.render(p), rr.render(p)
        out["depth"].append(np.abs(a.depth - b.depth) < 1e-3)
        out["labels"].append(a.labels == b.labels)
        out["instances"].append(a.instances == b.instances)
        out["hit"].append((a.depth > 0) == (b.depth > 0))
        out["rgb"].append(np.abs(a.rgb.astype(np.int16) - b.rgb.astype(np.int16)).mean(axis=-1))
        assert b.rgb.dtype == np.uint8 and b.depth.dtype == np.float32 and b.labels.dtype == np.uint8
        assert b.instances.dtype == np.int32 and b.triangle.dtype == np.int64
        assert ((b.triangle < 0) == (b.depth == 0)).all() and (b.labels[b.triangle < 0] == 0).all()
    return {k: float(np.mean(v)) for k, v in out.items()}


@needs_gl
@pytest.mark.parametrize("kind,seed", [("living_room", 3), ("apartment", 1)])
def test_raster_agrees_with_the_ray_caster_on_procedural_scenes(kind, seed):
    scene = generate_scene(kind, seed)
    poses = np.concatenate([make_trajectory(scene, 1.6, 4, seed=seed), make_trajectory(scene, 0.2, 4, seed=seed,
                                                                                        kind="lower")])
    a = agreement(scene, poses)
    assert a["depth"] >= 0.99 and a["hit"] >= 0.999
    assert a["labels"] >= 0.995 and a["instances"] >= 0.995
    assert a["rgb"] < 1.0, a  # the same shading, texture and display curve (differences at edges)


@needs_gl
def test_raster_agrees_on_a_ply_scene_with_another_camera(tmp_path):
    from test_sim_ply import box_ply

    from semmatch.sim.plyscene import scene_from_ply

    scene = scene_from_ply(box_ply(tmp_path / "room.ply"))
    intr = DEFAULT_INTRINSICS.scaled(160, 100)  # another aspect ratio: the principal point matters
    poses = make_trajectory(scene, 1.2, 5, margin=0.3)
    a = agreement(scene, poses, intr)
    assert a["depth"] >= 0.99 and a["labels"] >= 0.995 and a["instances"] >= 0.995


@needs_gl
def test_simulated_sequences_from_both_backends_agree(tmp_path):
    from semmatch.io import read_sequence
    from semmatch.sim import simulate_sequence

    scene = generate_scene("bedroom", 2)
    poses = make_trajectory(scene, 0.3, 3, seed=2, kind="lower")
    small = DEFAULT_INTRINSICS.scaled(96, 72)
    for backend in ("raycast", "raster"):
        simulate_sequence(scene, poses, tmp_path / backend, intrinsics=small, progress=False, backend=backend)
    a, b = read_sequence(tmp_path / "raycast"), read_sequence(tmp_path / "raster")
    for fa, fb in zip(a, b, strict=True):
        assert (fa.labels == fb.labels).mean() >= 0.995
        assert (np.abs(fa.depth - fb.depth) <= 1e-3).mean() >= 0.99


def test_auto_falls_back_to_ray_casting_with_one_warning(monkeypatch):
    monkeypatch.setattr(raster, "gl_available", lambda: (False, "no EGL display (test)"))
    monkeypatch.setattr(raster, "_WARNED", [])
    scene = generate_scene("living_room", 0)
    with pytest.warns(UserWarning, match=r"rasteriser unavailable \(no EGL display \(test\)\); rendering by ray"):
        r = make_renderer(scene, INTR, backend="auto")
    assert type(r) is Renderer
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("error")  # a second fallback stays silent
        assert type(make_renderer(scene, INTR, backend="auto")) is Renderer
    with pytest.raises(RuntimeError, match="cannot rasterise: no EGL display"):
        make_renderer(scene, INTR, backend="raster")
    with pytest.raises(ValueError, match="unknown renderer backend 'vulkan'"):
        make_renderer(scene, INTR, backend="vulkan")


def test_pair_of_sequences_and_mostly_empty_frames_warn(tmp_path, capsys):
    from semmatch.cli import main
    from semmatch.io import read_sequence
    from semmatch.sim import box_room, simulate_sequence

    assert main(["simulate", "--kind", "bedroom", "--pair", "--routes", "shared", "--frames", "4",
                 "--size", "64x48", "--out", str(tmp_path / "pair"), "--quiet"]) == 0
    up, low = read_sequence(tmp_path / "pair" / "upper"), read_sequence(tmp_path / "pair" / "lower")
    assert len(up) == len(low) == 4
    assert 1.5 < up[0].pose[2, 3] < 1.7 and 0.1 < low[0].pose[2, 3] < 0.3
    # a scan of the lower half of a room only, seen from 1.6 m looking up: mostly empty frames
    room = box_room((4.0, 3.0, 2.5), cell=0.25)
    keep = room.vertices[room.triangles][:, :, 2].mean(axis=1) < 1.0
    from semmatch.sim import Scene

    low_scan = Scene(room.vertices, room.triangles[keep], room.labels[keep], room.instances[keep],
                     room.albedo[keep], name="low_scan", meta=room.meta)
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, 1], [-1, 0, 0], [0, -1, 0]]  # camera z along world x, y down = world -z
    pose[:3, 3] = [0.5, 1.5, 1.6]
    tilt = np.eye(4)
    c, s = np.cos(0.6), np.sin(0.6)
    tilt[1:3, 1:3] = [[c, -s], [s, c]]  # pitch up (forward towards -y, the camera's up)
    poses = np.stack([pose @ tilt] * 4)
    with pytest.warns(UserWarning, match="4 of 4 frames are mostly empty"):
        simulate_sequence(low_scan, poses, tmp_path / "empty", intrinsics=DEFAULT_INTRINSICS.scaled(64, 48),
                          progress=False)
