"""The simulator: scenes, renderer, trajectories, noise, sequences and the data set."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from semmatch.io import is_sequence, read_map, read_sequence, read_tum
from semmatch.io.geometry import DEFAULT_INTRINSICS, backproject, check_pose, look_at, project
from semmatch.io.labels import id_of
from semmatch.sim import (
    SCENE_KINDS,
    NoiseConfig,
    Renderer,
    box_room,
    camera_elevation_deg,
    free_space,
    generate_dataset,
    generate_scene,
    limit_turn_rate,
    make_sweep_trajectories,
    make_trajectory,
    route_waypoints,
    simulate_sequence,
    simulate_sequences,
)

SMALL = DEFAULT_INTRINSICS.scaled(160, 120)


@pytest.fixture(scope="module")
def living():
    return generate_scene("living_room", 5)


def analytic_box_depth(T: np.ndarray, size, intr) -> tuple[np.ndarray, np.ndarray]:
    """z-depth and hit plane (0..5: x0, x1, y0, y1, z0, z1) of every pixel in a box room."""
    v, u = np.mgrid[0 : intr.height, 0 : intr.width].astype(np.float64)
    d_cam = np.stack([(u - intr.cx) / intr.fx, (v - intr.cy) / intr.fy, np.ones_like(u)], -1).reshape(-1, 3)
    d = d_cam @ T[:3, :3].T
    o = T[:3, 3]
    ts = []
    for a in range(3):
        for bound in (0.0, size[a]):
            with np.errstate(divide="ignore", invalid="ignore"):
                t = (bound - o[a]) / d[:, a]
            ts.append(np.where(t > 0, t, np.inf))
    ts = np.stack(ts, 1)
    return ts.min(1).reshape(intr.shape), ts.argmin(1).reshape(intr.shape)


@pytest.mark.parametrize("pose_args", [((1.3, 1.1, 1.2), (3.5, 2.0, 0.7)), ((3.0, 0.6, 0.3), (0.5, 2.5, 1.9))])
def test_box_room_depth_is_analytic_within_1mm(pose_args):
    size = (4.0, 3.0, 2.5)
    scene = box_room(size)
    T = look_at(*pose_args)
    r = Renderer(scene, SMALL).render(T)
    want, plane = analytic_box_depth(T, size, SMALL)
    assert (r.depth > 0).all()
    np.testing.assert_allclose(r.depth, want, atol=1e-3)
    # labels: the analytic plane's category (away from the edges where two planes tie)
    ts_sorted = np.sort(np.stack([want]), axis=0)
    del ts_sorted
    lab = np.where(plane == 4, id_of("floor"), np.where(plane == 5, id_of("ceiling"), id_of("wall")))
    agree = (r.labels == lab).mean()
    assert agree > 0.99


def test_backprojected_render_projects_to_its_pixels():
    scene = box_room((4.0, 3.0, 2.5))
    T = look_at((1.0, 1.0, 1.5), (3.0, 2.0, 1.0))
    r = Renderer(scene, SMALL).render(T)
    pts, idx = backproject(r.depth, SMALL, T)
    # every point lies on the box surface
    dist = np.minimum.reduce([np.abs(pts[:, 0]), np.abs(pts[:, 0] - 4), np.abs(pts[:, 1]), np.abs(pts[:, 1] - 3),
                              np.abs(pts[:, 2]), np.abs(pts[:, 2] - 2.5)])
    assert dist.max() < 2e-3
    uv, z = project(pts, SMALL, T)
    np.testing.assert_allclose(uv[:, 0], idx % SMALL.width, atol=1e-3)
    np.testing.assert_allclose(uv[:, 1], idx // SMALL.width, atol=1e-3)


def test_labels_match_the_hit_triangle(living):
    intr = SMALL
    T = make_trajectory(living, 1.6, 12, seed=1)[7]
    r = Renderer(living, intr).render(T)
    hit = r.triangle >= 0
    assert hit.mean() > 0.99
    np.testing.assert_array_equal(r.labels[hit], living.labels[r.triangle[hit]])
    np.testing.assert_array_equal(r.instances[hit], living.instances[r.triangle[hit]])
    assert len(np.unique(r.labels)) >= 3
    # the hit point lies on the plane of the reported triangle
    pts, idx = backproject(r.depth, intr, T)
    tri = r.triangle.reshape(-1)[idx]
    v = living.vertices[living.triangles[tri]].astype(np.float64)
    n = np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    off = np.abs(np.einsum("ij,ij->i", pts - v[:, 0], n))
    assert np.quantile(off, 0.999) < 2e-3


@pytest.mark.parametrize("kind", ["living_room", "bedroom", "office", "apartment"])
def test_scene_kinds_have_the_issue_categories(kind):
    s = generate_scene(kind, 11)
    present = set(np.unique(s.labels).tolist())
    for name in ("wall", "floor", "ceiling", "chair", "table", "window"):
        assert id_of(name) in present, name
    if kind in ("bedroom", "apartment"):
        assert id_of("bed") in present and id_of("pillow") in present
    # colour does not give the label: some material is shared by two categories
    keys = np.round(s.albedo, 4)
    shared = {}
    for k, lab in zip(map(tuple, keys), s.labels):
        shared.setdefault(k, set()).add(int(lab))
    assert any(len(v) > 1 for v in shared.values())
    assert s.texture is not None and s.meta["ceiling_height"] > 2.4


def test_same_seed_same_scene_and_frames(tmp_path, living):
    again = generate_scene("living_room", 5)
    np.testing.assert_array_equal(living.vertices, again.vertices)
    np.testing.assert_array_equal(living.labels, again.labels)
    np.testing.assert_array_equal(living.albedo, again.albedo)
    other = generate_scene("living_room", 6)
    assert other.n_triangles != living.n_triangles or not np.array_equal(other.vertices, living.vertices)
    p1 = make_trajectory(living, 1.6, 6, seed=3)
    p2 = make_trajectory(again, 1.6, 6, seed=3)
    np.testing.assert_array_equal(p1, p2)
    noise = NoiseConfig.kinect(seed=4)
    a = simulate_sequence(living, p1, tmp_path / "a", intrinsics=SMALL, noise=noise, progress=False)
    b = simulate_sequence(again, p2, tmp_path / "b", intrinsics=SMALL, noise=noise, progress=False)
    sa, sb = read_sequence(a), read_sequence(b)
    for i in (0, 5):
        np.testing.assert_array_equal(sa[i].rgb, sb[i].rgb)
        np.testing.assert_array_equal(sa[i].depth, sb[i].depth)
        np.testing.assert_array_equal(sa[i].labels, sb[i].labels)
    np.testing.assert_array_equal(sa.poses, sb.poses)


def _obstacle_distance(scene, points):
    import open3d as o3d

    keep = ~np.isin(scene.labels, [id_of("floor"), id_of("ceiling")])
    rc = o3d.t.geometry.RaycastingScene()
    rc.add_triangles(o3d.core.Tensor(scene.vertices), o3d.core.Tensor(scene.triangles[keep].astype(np.uint32)))
    return rc.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


@pytest.mark.parametrize("kind,height", [("living_room", 1.6), ("office", 0.2), ("apartment", 0.2),
                                         ("bedroom", 1.6)])
def test_trajectory_free_space_height_and_tilt(kind, height):
    scene = generate_scene(kind, 21)
    n = 150
    poses = make_trajectory(scene, height, n, tilt_deg=20.0, seed=2, kind="upper" if height > 1 else "lower")
    assert poses.shape == (n, 4, 4)
    for T in poses[::10]:
        check_pose(T)
    z = poses[:, 2, 3]
    assert np.abs(z - height).max() <= 0.02
    el = camera_elevation_deg(poses)
    assert np.abs(el).max() <= 20.0 + 1e-6 and el.max() > 15 and el.min() < -15  # tilts both ways
    # collision-free: keep (most of) the margin from everything but floor and ceiling
    assert _obstacle_distance(scene, poses[:, :3, 3]).min() > 0.2
    fs = free_space(scene, height)
    assert (fs.clearance_at(poses[:, :2, 3]) > 0).all()
    # inside the rooms and below the ceiling
    lo = np.min([r[:2] for r in scene.meta["rooms"]], axis=0)
    hi = np.max([r[2:] for r in scene.meta["rooms"]], axis=0)
    assert ((poses[:, :2, 3] > lo) & (poses[:, :2, 3] < hi)).all()
    # smooth: small steps, and it moves through the room
    step = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    assert step.max() <= 0.15 + 1e-6 and step.max() < 1.5 * np.median(step)
    span = poses[:, :2, 3].max(0) - poses[:, :2, 3].min(0)
    assert (span > 1.0).all()


def test_upper_and_lower_paths_differ_and_sweep_shares_one_path(living):
    up = make_trajectory(living, 1.6, 50, kind="upper")
    low = make_trajectory(living, 0.2, 50, kind="lower")
    assert np.linalg.norm(up[:, :2, 3] - low[:, :2, 3], axis=1).mean() > 0.3
    sw = make_sweep_trajectories(living, (0.2, 0.8, 1.6), 30)
    assert sorted(sw) == [0.2, 0.8, 1.6]
    np.testing.assert_allclose(sw[0.2][:, :2, 3], sw[1.6][:, :2, 3])
    np.testing.assert_allclose(sw[0.8][:, 2, 3], 0.8)


def test_short_tour_is_walked_there_and_back():
    # bedroom 1001's upper tour is ~3.4 m, far less than 119 steps of 15 cm allow
    scene = generate_scene("bedroom", 1001)
    once = make_trajectory(scene, 1.6, 120, seed=1001, kind="upper", there_and_back=False)
    both = make_trajectory(scene, 1.6, 120, seed=1001, kind="upper")
    length = np.linalg.norm(np.diff(once[:, :2, 3], axis=0), axis=1).sum()
    assert length < 0.15 * 119 / 2
    np.testing.assert_allclose(both[-1, :2, 3], once[0, :2, 3], atol=0.05)  # back where it started
    walked = np.linalg.norm(np.diff(both[:, :2, 3], axis=0), axis=1).sum()
    assert walked == pytest.approx(2 * length, rel=0.05)
    # it faces the other way on the way back: headings at the same spot differ by ~180 deg
    mid = np.argmin(np.linalg.norm(both[60:, :2, 3] - once[60, :2, 3], axis=1)) + 60
    cos = np.dot(both[mid, :2, 2], once[60, :2, 2]) / (
        np.linalg.norm(both[mid, :2, 2]) * np.linalg.norm(once[60, :2, 2]))
    assert cos < 0


def test_lower_path_follows_the_upper_route(living):
    wp = route_waypoints(living, 1.6, seed=2, kind="upper")
    up = make_trajectory(living, 1.6, 400, seed=2, kind="upper", max_step=None)
    low = make_trajectory(living, 0.2, 400, seed=2, kind="lower", waypoints=wp, max_step=None)
    assert wp.shape[1] == 2 and len(wp) >= 5
    for path in (up, low):  # every waypoint of the route is passed (within the smoothing)
        d = np.linalg.norm(path[:, None, :2, 3] - wp[None], axis=2).min(axis=0)
        assert d.max() < 0.5, d
    np.testing.assert_allclose(low[:, 2, 3], 0.2 + free_space(living, 0.2).floor_z)
    with pytest.raises(ValueError, match="waypoints"):
        make_trajectory(living, 0.2, 10, waypoints=np.zeros((3, 3)))


def _headings(poses: np.ndarray) -> np.ndarray:
    fwd = poses[:, :3, 2]
    return np.unwrap(np.arctan2(fwd[:, 1], fwd[:, 0]))


def test_heading_turns_at_most_max_turn_per_frame():
    # bedroom 100's lower path doubles back: unlimited, the camera flips round by > 90 deg in a frame
    scene = generate_scene("bedroom", 100)
    free = make_trajectory(scene, 0.2, 120, seed=100, kind="lower", max_turn_deg=None)
    limited = make_trajectory(scene, 0.2, 120, seed=100, kind="lower")
    assert np.degrees(np.abs(np.diff(_headings(free)))).max() > 45
    assert np.degrees(np.abs(np.diff(_headings(limited)))).max() <= 30 + 1e-6
    np.testing.assert_allclose(limited[:, :3, 3], free[:, :3, 3])  # same path, only the heading lags


def test_limit_turn_rate():
    yaw = np.array([0.0, 0.1, 3.0, 3.0, 3.0, -1.0])
    out = limit_turn_rate(yaw, 1.0)
    np.testing.assert_allclose(out, [0.0, 0.1, 1.1, 2.1, 3.0, 2.0])
    with pytest.raises(ValueError, match="max_turn"):
        limit_turn_rate(yaw, 0.0)


def test_bad_heights_and_intrinsics(living):
    with pytest.raises(ValueError, match="above the ceiling"):
        make_trajectory(living, 3.5, 10)
    with pytest.raises(ValueError, match="height must be > 0"):
        make_trajectory(living, -0.1, 10)
    with pytest.raises(ValueError, match="tilt_deg"):
        make_trajectory(living, 1.6, 10, tilt_deg=120)
    with pytest.raises(ValueError, match="focal length"):
        Renderer(living, DEFAULT_INTRINSICS.__class__(fx=0.0))
    with pytest.raises(ValueError, match="unknown scene kind"):
        generate_scene("castle", 0)


def test_sequence_files_poses_and_refusals(tmp_path, living):
    poses = make_trajectory(living, 1.6, 4, seed=0)
    out = simulate_sequence(living, poses, tmp_path / "seq", intrinsics=SMALL, progress=False)
    seq = read_sequence(out)
    assert len(seq) == 4 and seq.has_labels
    f = seq[2]
    assert f.rgb.shape == (120, 160, 3) and f.labels.dtype == np.uint8
    np.testing.assert_allclose(f.pose, poses[2], atol=1e-6)
    _t, gt = read_tum(out / "poses_gt.txt")
    np.testing.assert_allclose(gt, poses, atol=1e-6)
    assert (out / "instances" / "000002.png").is_file()
    with pytest.raises(FileExistsError, match="already holds another sequence"):
        simulate_sequence(living, poses, out, intrinsics=SMALL, progress=False)
    # overwrite replaces it
    simulate_sequence(living, poses[:2], out, intrinsics=SMALL, progress=False, overwrite=True)
    assert len(read_sequence(out)) == 2


def test_interrupted_simulate_leaves_no_sequence(tmp_path, living):
    poses = make_trajectory(living, 1.6, 6, seed=0)

    class Boom(Renderer):
        calls = 0

        def render(self, pose):
            Boom.calls += 1
            if Boom.calls == 4:
                raise KeyboardInterrupt
            return super().render(pose)

    with pytest.raises(KeyboardInterrupt):
        simulate_sequence(living, poses, tmp_path / "seq", intrinsics=SMALL, progress=False,
                          renderer=Boom(living, SMALL))
    assert not (tmp_path / "seq").exists()
    assert not is_sequence(tmp_path / "seq")
    assert list(tmp_path.iterdir()) == []


def test_noise_is_off_by_default_and_grows_with_distance(tmp_path, living):
    from semmatch.sim.noise import estimated_poses, noisy_depth, noisy_rgb

    rng = np.random.default_rng(0)
    assert not NoiseConfig().enabled
    d = np.full((200, 200), 1.0, np.float32)
    d[:, 100:] = 4.0
    np.testing.assert_array_equal(noisy_depth(d, NoiseConfig(), rng), d)
    cfg = NoiseConfig(depth_a=0.001, depth_b=0.002)
    nd = noisy_depth(d, cfg, rng)
    near, far = (nd - d)[:, 5:95].std(), (nd - d)[:, 105:195].std()
    assert far > 4 * near
    assert abs(far - (0.001 + 0.002 * 16)) < 0.005
    # edge and far dropouts
    drop = noisy_depth(d, NoiseConfig(edge_dropout=1.0), rng)
    assert (drop[:, 99:101] == 0).all() and (drop[:, :98] > 0).all()
    far_drop = noisy_depth(d, NoiseConfig(far_start=2.0, max_range=3.5), rng)
    assert (far_drop[:, 100:] == 0).all() and (far_drop[:, :100] > 0).all()
    rgb = np.full((10, 10, 3), 100, np.uint8)
    assert noisy_rgb(rgb, NoiseConfig(), rng) is rgb
    assert noisy_rgb(rgb, NoiseConfig(rgb_sigma=5), rng).std() > 2
    poses = make_trajectory(living, 1.6, 40, seed=0)
    est = estimated_poses(poses, NoiseConfig(drift_t=0.05, drift_r=1.0), rng)
    err = np.linalg.norm(est[:, :3, 3] - poses[:, :3, 3], axis=1)
    assert err[0] < 1e-9 and err[-1] > 0
    with pytest.raises(ValueError, match="depth_a"):
        NoiseConfig(depth_a=-1)
    # a noisy sequence: poses.txt = estimate, poses_gt.txt = truth, labels from the true pose
    noisy = simulate_sequence(living, poses[:3], tmp_path / "n", intrinsics=SMALL,
                              noise=NoiseConfig.kinect(), progress=False)
    clean = simulate_sequence(living, poses[:3], tmp_path / "c", intrinsics=SMALL, progress=False)
    sn, sc = read_sequence(noisy), read_sequence(clean)
    np.testing.assert_array_equal(sn[2].labels, sc[2].labels)
    assert not np.allclose(sn.poses, sc.poses)
    np.testing.assert_allclose(read_tum(noisy / "poses_gt.txt")[1], sc.poses, atol=1e-6)
    assert not np.array_equal(sn[2].rgb, sc[2].rgb)


def test_one_render_pass_writes_clean_and_noisy_copies(tmp_path, living):
    """simulate_sequences renders once; each folder equals its own simulate_sequence run."""
    import filecmp

    poses = make_trajectory(living, 1.6, 3, seed=1)
    noise = NoiseConfig.kinect(seed=9)
    simulate_sequences(living, poses, [(tmp_path / "both" / "c", None, {"trajectory": "c"}),
                                       (tmp_path / "both" / "n", noise, {"trajectory": "n"})],
                       intrinsics=SMALL, progress=False)
    simulate_sequence(living, poses, tmp_path / "one" / "c", intrinsics=SMALL, progress=False,
                      meta={"trajectory": "c"})
    simulate_sequence(living, poses, tmp_path / "one" / "n", intrinsics=SMALL, noise=noise, progress=False,
                      meta={"trajectory": "n"})
    for name in ("c", "n"):
        cmp = filecmp.dircmp(tmp_path / "both" / name, tmp_path / "one" / name)
        files = [f for sub in ("rgb", "depth", "labels", "instances") for f in
                 (Path(sub) / p.name for p in sorted((tmp_path / "one" / name / sub).iterdir()))]
        files += ["poses.txt", "poses_gt.txt", "meta.json", "intrinsics.json"]
        match, mismatch, errors = filecmp.cmpfiles(tmp_path / "both" / name, tmp_path / "one" / name,
                                                   [str(f) for f in files], shallow=False)
        assert not mismatch and not errors and len(match) == 4 * 3 + 4, (name, mismatch, errors)
        assert not cmp.left_only and not cmp.right_only
    assert not np.array_equal(read_sequence(tmp_path / "both" / "n")[1].rgb,
                              read_sequence(tmp_path / "both" / "c")[1].rgb)
    with pytest.raises(ValueError, match="named twice"):
        simulate_sequences(living, poses, [(tmp_path / "x", None, None), (tmp_path / "x", noise, None)],
                           intrinsics=SMALL, progress=False)

    class Boom(Renderer):
        def render(self, pose):
            if pose is poses[2] or np.array_equal(pose, poses[2]):
                raise KeyboardInterrupt
            return super().render(pose)

    with pytest.raises(KeyboardInterrupt):
        simulate_sequences(living, poses, [(tmp_path / "cut" / "c", None, None), (tmp_path / "cut" / "n", noise, None)],
                           intrinsics=SMALL, progress=False, renderer=Boom(living, SMALL))
    assert list((tmp_path / "cut").iterdir()) == []


def test_generate_dataset_layout_and_resume(tmp_path):
    kw = dict(train_seeds=[1], eval_seeds=[2], kinds=["bedroom"], n_frames_upper=3, n_frames_lower=3,
              heights_sweep=(0.2, 1.6), n_frames_sweep=2, intrinsics=DEFAULT_INTRINSICS.scaled(80, 60),
              progress=False, routes="shared")
    res = generate_dataset(tmp_path, **kw)
    ev = tmp_path / "eval" / "bedroom_0002"
    for sub in ("upper", "lower", "h020", "h160"):
        assert is_sequence(ev / sub), sub
    assert is_sequence(tmp_path / "train" / "bedroom_0001" / "upper")
    assert not (tmp_path / "train" / "bedroom_0001" / "lower").exists()
    m = read_map(ev / "scene.ply")
    assert m.is_mesh and id_of("bed") in m.labels
    np.testing.assert_allclose(read_sequence(ev / "h020").poses[:, 2, 3], 0.2, atol=1e-6)
    # shared routes: the lower camera sets off along the upper route (its first waypoint, snapped)
    scene = generate_scene("bedroom", 2)
    start = route_waypoints(scene, 1.6, seed=2, kind="upper")[0]
    assert np.linalg.norm(read_sequence(ev / "lower").poses[0, :2, 3] - start) < 0.3
    assert len(res["written"]) == 7
    again = generate_dataset(tmp_path, **kw)
    assert again["written"] == [] and len(again["skipped"]) == 7
    with pytest.raises(ValueError, match="disjoint"):
        generate_dataset(tmp_path, train_seeds=[1, 2], eval_seeds=[2], kinds=["bedroom"])


def test_own_routes_differ_and_cover_the_room(tmp_path):
    """The paper's setup: each camera its own tour; the ablation replays the person's tour."""
    from semmatch.sim import free_space, tour_coverage

    kw = dict(train_seeds=[], val_seeds=[3], eval_seeds=[4], kinds=["office"], n_frames_upper=40, n_frames_lower=40,
              heights_sweep=(0.2,), n_frames_sweep=2, intrinsics=DEFAULT_INTRINSICS.scaled(40, 30), progress=False,
              route_ablation=True)
    generate_dataset(tmp_path, **kw)
    ev = tmp_path / "eval" / "office_0004"
    up, low, shared = (read_sequence(ev / n).poses for n in ("upper", "lower", "lower_shared"))
    # own tours: different starts and different paths (mean distance to the other path's nearest point)
    d = np.linalg.norm(low[:, None, :2, 3] - up[None, :, :2, 3], axis=2)
    assert np.linalg.norm(low[0, :2, 3] - up[0, :2, 3]) > 0.5 or d.min(axis=1).mean() > 0.3
    assert d.min(axis=1).mean() > 0.3
    # the replayed route stays near the person's path
    ds = np.linalg.norm(shared[:, None, :2, 3] - up[None, :, :2, 3], axis=2)
    assert ds.min(axis=1).mean() < d.min(axis=1).mean()
    scene = generate_scene("office", 4)
    for poses, h in ((up, 1.6), (low, 0.2)):
        assert tour_coverage(free_space(scene, h), poses) > 0.6
    # validation scenes are laid out like evaluation scenes (no ablation there)
    va = tmp_path / "val" / "office_0003"
    assert is_sequence(va / "upper") and is_sequence(va / "lower") and is_sequence(va / "h020")
    assert not (va / "lower_shared").exists()
    with pytest.raises(ValueError, match="routes"):
        generate_dataset(tmp_path, eval_seeds=[4], kinds=["office"], routes="mine")


def test_seed_splits_are_checked():
    from semmatch.sim import check_seed_splits

    check_seed_splits([1, 2], [3], [4], dev_seeds=[5])
    with pytest.raises(ValueError, match="train and val seeds must be disjoint; both hold \\[2\\]"):
        check_seed_splits([1, 2], [2], [4])
    with pytest.raises(ValueError, match="val and eval"):
        check_seed_splits([1], [4], [4])
    with pytest.raises(ValueError, match="eval_seeds is empty"):
        check_seed_splits([1], [2], [])
    with pytest.raises(ValueError, match="looked at during development"):
        check_seed_splits([1], [2], [3], dev_seeds=[3])
    with pytest.raises(ValueError, match="more than once"):
        check_seed_splits([1, 1], [2], [3])


def test_noisy_recordings_drift_independently(tmp_path):
    """Each noisy recording has its own random stream: the drifts are not in lockstep."""
    from semmatch.sim import NoiseConfig

    generate_dataset(tmp_path, train_seeds=[], eval_seeds=[5], kinds=["bedroom"], n_frames_upper=12,
                     n_frames_lower=12, heights_sweep=None, intrinsics=DEFAULT_INTRINSICS.scaled(40, 30),
                     progress=False, noise=NoiseConfig.kinect(seed=7))
    ev = tmp_path / "eval" / "bedroom_0005"
    seeds = {n: json.loads((ev / n / "meta.json").read_text())["noise"]["seed"] for n in ("upper_noisy", "lower_noisy")}
    assert seeds["upper_noisy"] != seeds["lower_noisy"]
    drift = {}
    for n in ("upper_noisy", "lower_noisy"):
        seq = read_sequence(ev / n)
        _, true = read_tum(ev / n / "poses_gt.txt")
        drift[n] = seq.poses[:, :3, 3] - true[:, :3, 3]
    # the jitter of frame 0 differs between the two recordings
    assert not np.allclose(drift["upper_noisy"][0], drift["lower_noisy"][0])


def test_generate_dataset_in_parallel_writes_the_same_data(tmp_path):
    kw = dict(train_seeds=[1], eval_seeds=[2], kinds=["bedroom", "office"], n_frames_upper=2, n_frames_lower=2,
              heights_sweep=(0.4,), n_frames_sweep=2, intrinsics=DEFAULT_INTRINSICS.scaled(64, 48),
              progress=False)
    one = generate_dataset(tmp_path / "one", **kw)
    two = generate_dataset(tmp_path / "two", jobs=2, **kw)
    rel = [str(Path(p).relative_to(tmp_path / "one")) for p in one["written"]]
    assert rel == [str(Path(p).relative_to(tmp_path / "two")) for p in two["written"]]
    assert len(rel) == 4 * 2 + 2  # eval: mesh, upper, lower, h040 per kind; train: seed 1 -> bedroom
    for r in rel:
        a, b = tmp_path / "one" / r, tmp_path / "two" / r
        if a.is_dir():
            sa, sb = read_sequence(a), read_sequence(b)
            np.testing.assert_array_equal(sa.poses, sb.poses)
            np.testing.assert_array_equal(sa[1].rgb, sb[1].rgb)
            np.testing.assert_array_equal(sa[1].depth, sb[1].depth)
            np.testing.assert_array_equal(sa[1].labels, sb[1].labels)
        else:
            assert a.read_bytes() == b.read_bytes()


def test_scene_generation_all_kinds_and_save(tmp_path):
    for kind in SCENE_KINDS:
        s = generate_scene(kind, 0)
        assert s.n_triangles > 100
    p = s.save(tmp_path / "scene.ply")
    m = read_map(p)
    assert m.is_mesh and len(m.faces) == s.n_triangles


def test_cli_simulate(tmp_path, capsys):
    from semmatch.cli import main

    out = tmp_path / "cli"
    rc = main(["simulate", "--kind", "office", "--seed", "1", "--height", "0.2", "--frames", "3",
               "--size", "80x60", "--out", str(out), "--no-progress", "--noise", "kinect", "--fast"])
    assert rc == 0 and len(read_sequence(out)) == 3
    assert main(["simulate", "--kind", "office", "--frames", "3", "--size", "80x60", "--out", str(out),
                 "--no-progress"]) == 2
    assert "already holds another sequence" in capsys.readouterr().err
    assert main(["simulate", "--kind", "office", "--height", "9", "--frames", "3", "--out",
                 str(tmp_path / "x")]) == 2
    assert "above the ceiling" in capsys.readouterr().err
    with pytest.raises(SystemExit) as e:  # refused by the parser: a focal length must be > 0
        main(["simulate", "--fx", "0", "--frames", "3", "--out", str(tmp_path / "y")])
    assert e.value.code == 2 and "--fx: must be > 0" in capsys.readouterr().err


def test_fast_mode_matches_exact_rendering(living):
    poses = make_trajectory(living, 0.2, 8, seed=4, kind="lower")
    exact, fast = Renderer(living, SMALL), Renderer(living, SMALL, fast=True)
    for T in poses[::3]:
        a, b = exact.render(T), fast.render(T)
        assert (a.labels == b.labels).mean() > 0.995
        close = np.abs(a.depth - b.depth) < 1e-3
        assert close.mean() > 0.99
        assert np.abs(a.rgb.astype(int) - b.rgb).mean() < 3
        assert fast.last_cast_fraction < 0.6


def test_bench_render_json(capsys):
    import json

    from semmatch.cli import main

    assert main(["bench", "render", "--json", "--frames", "2", "--size", "80x60", "--triangles", "5000",
                 "--kind", "bedroom", "--stream", "3"]) == 0
    res = json.loads(capsys.readouterr().out)
    for key in ("fps", "width", "height", "triangles", "fps_fast", "rss_mb_at_end"):
        assert key in res
    assert res["width"] == 80 and res["triangles"] >= 5000 and res["fps"] > 0


def test_generate_dataset_redoes_sequences_of_other_sizes(tmp_path):
    kw = dict(train_seeds=[], eval_seeds=[3], kinds=["bedroom"], n_frames_upper=2, n_frames_lower=2,
              heights_sweep=None, intrinsics=DEFAULT_INTRINSICS.scaled(40, 30), progress=False)
    generate_dataset(tmp_path, **kw)
    ev = tmp_path / "eval" / "bedroom_0003"
    (ev / ".upper.dead.partial").mkdir()  # left by a killed run
    res = generate_dataset(tmp_path, **{**kw, "n_frames_upper": 3})
    assert res["written"] == [str(ev / "upper")]
    assert len(read_sequence(ev / "upper")) == 3 and len(read_sequence(ev / "lower")) == 2
    assert not (ev / ".upper.dead.partial").exists()


def test_short_trajectory_tilts_both_up_and_down():
    from semmatch.sim import camera_elevation_deg, generate_scene, make_trajectory

    poses = make_trajectory(generate_scene("bedroom", 3), 0.2, 24, tilt_deg=20.0, seed=3)
    el = camera_elevation_deg(poses)
    assert el.max() > 15 and el.min() < -15


def test_fewer_frames_at_a_larger_camera_step_fly_the_same_tour(tmp_path):
    """``camera_step``: half the frames at twice the step keep the tour's length and its room coverage."""
    from semmatch.sim import carrier_poses, free_space, tour_coverage

    scene = generate_scene("bedroom", 12)
    dense = carrier_poses(scene, 1.6, 61, carrier="upper", seed=12)
    sparse = carrier_poses(scene, 1.6, 31, carrier="upper", seed=12, camera_step=0.3)
    short = carrier_poses(scene, 1.6, 31, carrier="upper", seed=12)

    def length(p):
        return float(np.linalg.norm(np.diff(p[:, :2, 3], axis=0), axis=1).sum())

    assert length(sparse) == pytest.approx(length(dense), rel=0.1)
    assert length(short) < 0.7 * length(dense)
    steps = np.linalg.norm(np.diff(sparse[:, :2, 3], axis=0), axis=1)
    assert steps.max() <= 0.3 + 1e-6
    fs = free_space(scene, 1.6)
    assert tour_coverage(fs, sparse) >= tour_coverage(fs, short)
    with pytest.raises(ValueError, match="camera_step"):
        generate_dataset(tmp_path, eval_seeds=[4], kinds=["office"], camera_step=0.0)
