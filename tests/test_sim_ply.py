"""Scenes from semantic PLY meshes: palette labels, bad files, the up axis, Replica meshes."""

from __future__ import annotations

import numpy as np
import pytest
from plyfile import PlyData, PlyElement

from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.io.labels import id_of, labels_to_colors
from semmatch.sim import Renderer, box_room, make_trajectory
from semmatch.sim.plyscene import scene_from_ply

SMALL = DEFAULT_INTRINSICS.scaled(160, 120)


def write_ply(path, vertices, colors=None, faces=None):
    fields = [("x", "f4"), ("y", "f4"), ("z", "f4")]
    if colors is not None:
        fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")]
    v = np.empty(len(vertices), dtype=fields)
    v["x"], v["y"], v["z"] = np.asarray(vertices, np.float32).T
    if colors is not None:
        v["red"], v["green"], v["blue"] = np.asarray(colors, np.uint8).T
    els = [PlyElement.describe(v, "vertex")]
    if faces is not None:
        f = np.empty(len(faces), dtype=[("vertex_indices", "i4", (3,))])
        f["vertex_indices"] = faces
        els.append(PlyElement.describe(f, "face"))
    PlyData(els, text=True).write(str(path))
    return path


def box_ply(path, rotate=None, bad_every=0):
    m = box_room((4.0, 3.0, 2.5)).to_semantic_map()
    pts = m.points @ (rotate.T if rotate is not None else np.eye(3))
    col = labels_to_colors(m.labels).copy()
    if bad_every:
        col[::bad_every] = (1, 2, 3)
    return write_ply(path, pts, col, m.faces)


def test_palette_labels_and_off_palette_colours(tmp_path):
    p = box_ply(tmp_path / "room.ply", bad_every=50)
    with pytest.warns(UserWarning, match=r"colours in .*room.ply are not in the category palette"):
        s = scene_from_ply(p)
    assert {id_of("wall"), id_of("floor"), id_of("ceiling")} <= set(np.unique(s.labels).tolist())
    assert s.meta["up_axis"] == "+z"
    assert abs(s.meta["floor_z"]) < 1e-3 and abs(s.meta["ceiling_height"] - 2.5) < 1e-3
    # colour comes from shading of materials, not from the label palette
    assert not np.allclose(s.albedo * 255, labels_to_colors(s.labels), atol=3)
    poses = make_trajectory(s, 1.5, 5, margin=0.3)
    r = Renderer(s, SMALL).render(poses[2])
    assert (r.depth > 0).all() and r.rgb.std() > 5


def test_up_axis_is_checked_against_the_floor(tmp_path):
    # a y-up file: world z -> y
    R = np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    p = box_ply(tmp_path / "yup.ply", rotate=R)
    with pytest.warns(UserWarning, match=r"up axis is \+y"):
        s = scene_from_ply(p)
    floor = s.labels == id_of("floor")
    assert s.triangle_normals()[floor][:, 2].mean() > 0.99
    assert abs(s.meta["ceiling_height"] - 2.5) < 1e-3


def test_bad_ply_files_name_the_file(tmp_path):
    empty = write_ply(tmp_path / "empty.ply", np.zeros((0, 3)), np.zeros((0, 3)), np.zeros((0, 3), int))
    with pytest.raises(ValueError, match=r"empty.ply.*empty"):
        scene_from_ply(empty)
    cloud = write_ply(tmp_path / "cloud.ply", np.random.default_rng(0).random((10, 3)),
                      labels_to_colors(np.full(10, 1)))
    with pytest.raises(ValueError, match=r"cloud.ply.*no faces"):
        scene_from_ply(cloud)
    junk = tmp_path / "junk.ply"
    junk.write_text("not a ply\n")
    with pytest.raises(ValueError, match="junk.ply"):
        scene_from_ply(junk)
    with pytest.raises(FileNotFoundError, match="nope.ply"):
        scene_from_ply(tmp_path / "nope.ply")


def test_replica_mesh_becomes_a_scene(shared_dir):
    path = shared_dir / "scenes" / "replica" / "frl_apartment_4" / "high_3d_nb_model_final_0_noise.ply"
    s = scene_from_ply(path)
    assert s.n_triangles > 10_000
    assert len(set(np.unique(s.labels).tolist()) & set(range(1, 11))) >= 3
    assert s.instances.max() > 0 and s.texture is not None
    lo, hi = s.bounds
    pose = np.eye(4)
    pose[:3, :3] = np.array([[0, 0, 1], [-1, 0, 0], [0, -1, 0]], float)  # looking along +x
    pose[:3, 3] = (lo + hi) / 2
    r = Renderer(s, SMALL).render(pose)
    hit = r.triangle >= 0
    np.testing.assert_array_equal(r.labels[hit], s.labels[r.triangle[hit]])


def test_stray_ceiling_labels_do_not_lower_the_ceiling(tmp_path):
    # a 2.8 m room (two big ceiling triangles) whose scan labelled three small triangles of a
    # table (0.9 m) as ceiling: more stray triangles than real ones, a fraction of their area
    m = box_room((4.0, 3.0, 2.8), cell=5.0).to_semantic_map()
    pts, faces = m.points, m.faces
    assert (m.labels[faces].min(axis=1) == id_of("ceiling")).sum() == 2
    stray = np.array([[x + dx, 1.0 + dy, 0.9] for x in (1.0, 2.0, 3.0) for dx, dy in ((0, 0), (0.1, 0), (0, 0.1))])
    labels = np.concatenate([m.labels, np.full(len(stray), id_of("ceiling"), np.uint8)])
    faces = np.concatenate([faces, len(pts) + np.arange(len(stray)).reshape(-1, 3)])
    p = write_ply(tmp_path / "scan.ply", np.concatenate([pts, stray]), labels_to_colors(labels), faces)
    s = scene_from_ply(p)
    assert abs(s.meta["ceiling_height"] - 2.8) < 1e-3
    assert len(make_trajectory(s, 1.6, 4, margin=0.3)) == 4  # 1.6 m fits under a 2.8 m ceiling


def test_no_free_space_says_why(tmp_path):
    from semmatch.sim.trajectory import free_space

    m = box_room((4.0, 3.0, 2.5)).to_semantic_map()
    walls = np.isin(m.labels[m.faces], [id_of("floor"), id_of("ceiling")]).sum(axis=1) == 0  # walls only
    p = write_ply(tmp_path / "walls.ply", m.points, labels_to_colors(m.labels), m.faces[walls])
    with pytest.raises(ValueError, match="no free space.*no cell lies inside the mesh, and the mesh has no floor"):
        free_space(scene_from_ply(p), 1.0, margin=0.3)
    s2 = scene_from_ply(box_ply(tmp_path / "room.ply"))
    with pytest.raises(ValueError, match=r"largest distance to an obstacle or wall is 1\.\d\d m \(< margin\)"):
        free_space(s2, 1.0, margin=1.6)
