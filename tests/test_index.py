"""The sparse map index: same grid as the dense reference, memory near the surface, budgets, cache."""

from __future__ import annotations

import pickle
import warnings
from pathlib import Path

import numpy as np
import pytest
from scenes import furnished_room

from semmatch.io import SemanticMap, write_map
from semmatch.sim import render_frames
from semmatch.transfer import MapIndex, load_index
from semmatch.transfer.index import BLOCK, index_cache_dir, index_cache_path
from semmatch.transfer.index.label_grid import dense_label_grid


def _dense_grid(idx: MapIndex) -> np.ndarray:
    """The naive reference grid (one EDT over the whole box) of an index's map and grid."""
    return dense_label_grid(idx.map, origin=idx.origin, shape=idx.shape, voxel_size=idx.voxel_size,
                            max_distance=idx.max_distance)


@pytest.fixture(scope="module")
def room():
    return furnished_room()


@pytest.fixture(scope="module")
def mesh_map(room):
    return room.to_semantic_map()


def _points(m: SemanticMap, rng, n=40000) -> np.ndarray:
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    far = rng.uniform(lo - 0.3, hi + 0.3, (n, 3))
    near = m.points[rng.integers(0, len(m.points), n)] + rng.normal(0, 0.05, (n, 3))
    return np.concatenate([far, near]).astype(np.float32)


@pytest.mark.parametrize("voxel,max_distance", [(0.04, 0.10), (0.03, 0.25), (0.05, 0.04)])
def test_sparse_grid_equals_the_dense_reference(mesh_map, voxel, max_distance):
    idx = MapIndex(mesh_map, voxel_size=voxel, max_distance=max_distance)
    assert (idx.grid == _dense_grid(idx)).all()


def test_sparse_grid_of_a_point_map_equals_the_dense_reference(mesh_map):
    rng = np.random.default_rng(3)
    pts = mesh_map.points + rng.normal(0, 0.01, mesh_map.points.shape)
    idx = MapIndex(SemanticMap(pts.astype(np.float32), mesh_map.labels), voxel_size=0.03)
    assert (idx.grid == _dense_grid(idx)).all()


def test_lookups_read_the_dense_grid(mesh_map, room, rng):
    """Every lookup path (points, depth images, labels only or with flags) reads the same voxels
    as a gather from the dense grid, and pickling keeps the answers."""
    idx = MapIndex(mesh_map, voxel_size=0.04)
    dense = _dense_grid(idx)
    pts = _points(mesh_map, rng)
    k = np.clip(np.floor((pts - idx.origin.astype(np.float32)) / np.float32(idx.voxel_size)), 0,
                np.asarray(idx.shape) - 1).astype(np.int64)
    assert (idx.lookup(pts, exact=False) == (dense[tuple(k.T)] & 0x3F)).all()
    again = pickle.loads(pickle.dumps(idx))
    for exact in (False, True):
        assert (again.lookup(pts, exact=exact) == idx.lookup(pts, exact=exact)).all()
    from scenes import orbit_poses

    for f in render_frames(room, orbit_poses(room, 2, 0.3)):
        valid = f.depth > 0
        fast = idx.lookup_depth(f.depth, f.pose, f.intrinsics, exact=False)
        exact = idx.lookup_depth(f.depth, f.pose, f.intrinsics)
        sup = idx.support_depth(f.depth, f.pose, f.intrinsics)
        assert (fast[~valid] == 0).all() and (exact[~valid] == 0).all() and not sup[~valid].any()
        assert (exact[valid] > 0).mean() > 0.5 and ((fast > 0) == (exact > 0)).mean() > 0.95


def test_memory_follows_the_surface_not_the_bounding_box(rng):
    """Two small clusters 50 m apart: a few blocks, not the 50 m box."""
    a = rng.uniform(0, 0.3, (2000, 3))
    pts = np.concatenate([a, a + [40.0, 30.0, 0]]).astype(np.float32)  # 50 m apart
    idx = MapIndex(SemanticMap(pts, np.full(len(pts), 3, np.uint8)))
    box_voxels = int(np.prod(idx.shape))
    assert box_voxels > 40_000_000
    assert 0 < idx.n_blocks <= 2 * 6**3  # each cluster: (0.3 + 2 * reach) / (BLOCK voxels) blocks a side
    assert idx.nbytes < box_voxels / 50
    assert idx.lookup(np.array([[0.1, 0.1, 0.1], [40.1, 30.1, 0.1], [20.0, 15.0, 0.1]]), exact=False).tolist() == [3, 3, 0]
    assert BLOCK == 8


def test_a_point_map_in_millimetres_is_refused_before_allocating(mesh_map):
    mm = SemanticMap(mesh_map.points * 1000.0, mesh_map.labels)
    with pytest.raises(ValueError, match=r"table of [\d,]+ blocks .* millimetres"):
        MapIndex(mm)
    with pytest.raises(ValueError, match=r"max_voxels=1,000.* millimetres"):
        MapIndex(mesh_map, voxel_size=0.04, max_voxels=1000)


def test_the_cache_is_reused_invalidated_and_survives_damage(mesh_map, tmp_path, rng, monkeypatch):
    path = tmp_path / "m" / "upper.ply"
    write_map(path, mesh_map)
    built = load_index(path, voxel_size=0.04, cache_dir="beside")
    (cache,) = path.parent.glob(".upper.ply.index-*.npz")
    pts = _points(mesh_map, rng, 5000)

    def no_build(*a, **k):
        raise AssertionError("built instead of read from the cache")

    with monkeypatch.context() as mp:  # reused: no build
        mp.setattr(MapIndex, "_build_grid", no_build)
        cached = load_index(path, voxel_size=0.04, cache_dir="beside")
    assert (cached.grid == built.grid).all() and cached.n_blocks == built.n_blocks
    for exact in (False, True):
        assert (cached.lookup(pts, exact=exact) == built.lookup(pts, exact=exact)).all()
    # another map content: another key, the old file is not read
    m2 = SemanticMap(mesh_map.points + np.float32(0.5), mesh_map.labels, faces=mesh_map.faces)
    write_map(path, m2)
    moved = load_index(path, voxel_size=0.04, cache_dir="beside")
    assert len(list(path.parent.glob(".upper.ply.index-*.npz"))) == 2
    assert not np.allclose(moved.origin, built.origin)
    # a stale file under the current key (wrong table) or a damaged one: rebuilt with a warning
    newest = max(path.parent.glob(".upper.ply.index-*.npz"), key=lambda p: p.stat().st_mtime)
    with np.load(newest) as z:
        data = {k: z[k] for k in z.files}
    data["table"] = data["table"][:-1]
    np.savez(newest.with_suffix(""), **data)  # np.savez adds .npz
    for damage in (None, b"PK\x03\x04 truncated"):
        if damage is not None:
            newest.write_bytes(damage)
        with pytest.warns(UserWarning, match="unreadable index cache"):
            again = load_index(path, voxel_size=0.04, cache_dir="beside")
        assert (again.grid == moved.grid).all()
    # switched off by the environment: nothing read
    monkeypatch.setenv("SEMMATCH_NO_INDEX_CACHE", "1")
    for c in path.parent.glob(".upper.ply.index-*.npz"):
        c.write_bytes(b"junk")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        load_index(path, voxel_size=0.04, cache_dir="beside")


def test_tests_never_write_to_the_users_cache():
    import os

    import platformdirs

    assert os.environ.get("SEMMATCH_CACHE_DIR")  # set by conftest for the whole session
    assert not index_cache_dir("m.ply").is_relative_to(platformdirs.user_cache_dir("semmatch"))


def _no_build(*a, **k):
    raise AssertionError("built instead of read from the cache")


def test_the_cache_goes_to_the_user_cache_folder_by_default(mesh_map, tmp_path, monkeypatch):
    import platformdirs

    monkeypatch.delenv("SEMMATCH_CACHE_DIR", raising=False)
    monkeypatch.setattr(platformdirs, "user_cache_dir", lambda appname=None, *a, **k: str(tmp_path / "user" / appname))
    path = tmp_path / "maps" / "upper.ply"
    write_map(path, mesh_map)
    folder = tmp_path / "user" / "semmatch" / "index"
    assert index_cache_dir(path) == index_cache_dir(path, "user") == folder
    built = load_index(path, voxel_size=0.04)
    (cf,) = folder.glob("upper.ply.index-*.npz")  # visible there, named after the map
    assert cf == index_cache_path(path, voxel_size=0.04) and cf.parent == folder
    assert [p.name for p in path.parent.iterdir()] == ["upper.ply"]  # nothing left beside the map
    with monkeypatch.context() as mp:
        mp.setattr(MapIndex, "_build_grid", _no_build)
        assert (load_index(path, voxel_size=0.04).grid == built.grid).all()
    # SEMMATCH_CACHE_DIR moves the user cache folder
    monkeypatch.setenv("SEMMATCH_CACHE_DIR", str(tmp_path / "env"))
    load_index(path, voxel_size=0.04)
    assert len(list((tmp_path / "env" / "index").glob("upper.ply.index-*.npz"))) == 1


def test_the_cache_beside_the_map_or_in_a_given_folder(mesh_map, tmp_path, monkeypatch):
    monkeypatch.setenv("SEMMATCH_CACHE_DIR", str(tmp_path / "user"))
    path = tmp_path / "maps" / "upper.ply"
    write_map(path, mesh_map)
    load_index(path, voxel_size=0.04, cache_dir="beside")
    (cf,) = path.parent.glob(".upper.ply.index-*.npz")  # hidden beside the map, as before
    assert cf == index_cache_path(path, voxel_size=0.04, cache_dir="beside")
    for given in (tmp_path / "mine", str(tmp_path / "as-text")):
        load_index(path, voxel_size=0.04, cache_dir=given)
        assert len(list(Path(given).glob("upper.ply.index-*.npz"))) == 1
    assert not index_cache_path(path, voxel_size=0.04).exists()  # the user folder was not written
    with pytest.raises(ValueError, match="empty string"):
        index_cache_dir(path, "")


def test_maps_of_one_name_in_two_folders_keep_their_own_caches(mesh_map, tmp_path, monkeypatch):
    monkeypatch.setenv("SEMMATCH_CACHE_DIR", str(tmp_path / "cache"))
    a, b = tmp_path / "a" / "upper.ply", tmp_path / "b" / "upper.ply"
    write_map(a, mesh_map)
    write_map(b, SemanticMap(mesh_map.points + np.float32(0.5), mesh_map.labels, faces=mesh_map.faces))
    built = {p: load_index(p, voxel_size=0.04) for p in (a, b)}
    assert len(list((tmp_path / "cache" / "index").glob("upper.ply.index-*.npz"))) == 2
    assert index_cache_path(a, voxel_size=0.04) != index_cache_path(b, voxel_size=0.04)
    with warnings.catch_warnings(), monkeypatch.context() as mp:
        warnings.simplefilter("error")  # neither reads the other's file (that would warn and rebuild)
        mp.setattr(MapIndex, "_build_grid", _no_build)
        for p in (b, a, b):
            again = load_index(p, voxel_size=0.04)
            assert (again.grid == built[p].grid).all() and np.allclose(again.origin, built[p].origin)
    assert not np.allclose(built[a].origin, built[b].origin)


def test_block_lookups_equal_dense_lookups(mesh_map, room, rng, monkeypatch):
    """A large box looks up through the block table (two gathers); a small one through its dense
    copy: same answers."""
    from scenes import orbit_poses

    import semmatch.transfer.index.queries as index_module

    dense = MapIndex(mesh_map, voxel_size=0.04)
    monkeypatch.setattr(index_module, "DENSE_LOOKUP_VOXELS", 0)
    blocks = MapIndex(mesh_map, voxel_size=0.04)
    assert dense._dense is not None and blocks._dense is None
    pts = _points(mesh_map, rng)
    for exact in (False, True):
        assert (blocks.lookup(pts, exact=exact) == dense.lookup(pts, exact=exact)).all()
    for f in render_frames(room, orbit_poses(room, 2, 0.3)):
        for exact in (False, True):
            assert (blocks.lookup_depth(f.depth, f.pose, f.intrinsics, exact=exact)
                    == dense.lookup_depth(f.depth, f.pose, f.intrinsics, exact=exact)).all()
        assert (blocks.support_depth(f.depth, f.pose, f.intrinsics)
                == dense.support_depth(f.depth, f.pose, f.intrinsics)).all()


def test_the_vertex_cover_radius_bounds_every_point_of_every_triangle(rng):
    """The bound behind the vertex shortcut of the support test: no point of a triangle is farther
    than it from that triangle's nearest vertex; tight for an equilateral triangle (L / sqrt 3)."""
    from semmatch.transfer.index.reach import vertex_cover_radius as _vertex_cover_radius

    eq = np.array([[0, 0, 0], [1, 0, 0], [0.5, np.sqrt(3) / 2, 0]], np.float32)
    assert _vertex_cover_radius(eq, np.array([[0, 1, 2]])) == pytest.approx(1 / np.sqrt(3), rel=1e-6)
    pts = rng.normal(size=(300, 3)).astype(np.float32)
    pts[:30, 2] = 0  # flat, obtuse and near-degenerate triangles among them
    faces = rng.integers(0, len(pts), size=(200, 3))
    faces = faces[(faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])]
    radius = _vertex_cover_radius(pts, faces)
    w = rng.dirichlet(np.ones(3), size=(len(faces), 50))  # points inside every triangle
    v = pts[faces].astype(np.float64)
    x = np.einsum("fsk,fkd->fsd", w, v)
    worst = np.linalg.norm(x[:, :, None, :] - v[:, None, :, :], axis=3).min(axis=2).max()
    assert worst <= radius + 1e-9


def test_support_with_the_vertex_shortcut_equals_exact_queries(room, rng):
    """``support_depth`` answers shell pixels from the memoised voxel-centre distances and the
    nearest vertex where those settle them; the answer must equal the exact closest-point test
    on every pixel, with the memo empty (first pass) and filled (second pass), here for a fused
    reconstruction (many small triangles) and frames whose depth is stretched by up to 8 %, so
    that many points lie about ``max_distance`` from the surface."""
    from scenes import orbit_poses

    from semmatch.fusion import reconstruct
    from semmatch.transfer.index.queries import LABEL_BITS, SHELL

    frames = render_frames(room, orbit_poses(room, 4, 0.3))
    fused = reconstruct(frames, [f.labels for f in frames], 0.04)
    index = MapIndex(fused, max_distance=0.1)
    shell_pixels = 0
    depths = [(f.depth * (1 + 0.08 * rng.random(f.depth.shape))).astype(np.float32) for f in frames]
    for f, depth in [*zip(frames, depths), *zip(frames, depths)]:
        got = index.support_depth(depth, f.pose, f.intrinsics)
        out, world = index._gather_depth(depth, f.pose, f.intrinsics)
        want = (out & np.uint8(LABEL_BITS)) > 0
        shell = (out & np.uint8(SHELL)) > 0
        if shell.any():
            sel = np.nonzero(shell)
            want[sel] = np.isfinite(index.nearest(world(sel), index.max_distance)[1])
            shell_pixels += int(shell.sum())
        np.testing.assert_array_equal(got, want)
    assert shell_pixels > 100  # the shortcut and the exact queries both ran
    assert (index._reach.codes != -128).sum() > 10  # centre distances were memoised


@pytest.mark.parametrize("kind", ["mesh", "points"])
def test_centre_distance_bounds_settle_only_what_the_exact_distance_confirms(room, rng, kind):
    """Points settled from their voxel's centre distance (``ReachTest.centre_bounds``) agree with the exact
    distance; points on both sides of ``max_distance`` are settled, and a pickled index drops the
    memo (rebuilt on use)."""

    m = room.to_semantic_map()
    if kind == "points":
        m = SemanticMap(m.points, m.labels)
    index = MapIndex(m, max_distance=0.1, voxel_size=0.05)
    surf = m.points[rng.integers(0, len(m.points), 4000)]
    p = (surf + rng.normal(size=surf.shape) * 0.08).astype(np.float32)
    d = index.nearest(p, 1.0)[1]
    index._within_reach(p[:1])  # makes the reach test
    index._reach.codes[:] = -128  # an empty memo
    near, unsure = index._reach.centre_bounds(p)
    settled = np.ones(len(p), bool)
    settled[unsure] = False
    assert near[settled].sum() > 100 and (~near[settled]).sum() > 100
    np.testing.assert_array_equal(near[settled], d[settled] <= 0.1)
    assert not near[unsure].any()
    again, unsure2 = index._reach.centre_bounds(p)  # from the memo
    np.testing.assert_array_equal(again, near)
    np.testing.assert_array_equal(unsure2, unsure)
    assert pickle.loads(pickle.dumps(index))._reach is None
