"""semmatch.poses.alignment and ``semmatch align`` / ``transfer --align``: the robot placed in the person's map."""

from __future__ import annotations

import json

import numpy as np
import pytest

from semmatch.io import SemanticMap
from semmatch.poses.alignment import AlignmentResult, align_to_map, camera_up, check_alignment, fit_floor
from semmatch.poses.registration import transform_error

#: coarse settings that keep each alignment to a few seconds
FAST = dict(voxel_size=0.15, icp_voxels=(0.05,), restarts=2, hypotheses=4000, check_voxel=0.04)
CLI_FAST = ["--align-voxel", "0.15", "--restarts", "2", "--map-voxel", "0.06"]


def _mesh_points(kind: str, seed: int, n: int = 25_000) -> tuple[np.ndarray, np.ndarray]:
    """Points and normals sampled on a procedural scene's mesh (z up, floor at 0)."""
    import open3d as o3d

    from semmatch.sim import generate_scene

    scene = generate_scene(kind, seed)
    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(scene.vertices.astype(np.float64)),
                                     o3d.utility.Vector3iVector(scene.triangles))
    mesh.compute_triangle_normals()
    o3d.utility.random.seed(0)
    pc = mesh.sample_points_uniformly(n, use_triangle_normal=True)
    return np.asarray(pc.points), np.asarray(pc.normals)


def _map(P: np.ndarray, N: np.ndarray, T: np.ndarray | None = None) -> SemanticMap:
    if T is not None:
        P, N = P @ T[:3, :3].T + T[:3, 3], N @ T[:3, :3].T
    return SemanticMap(points=P.astype(np.float32), labels=np.zeros(len(P), np.uint8), normals=N.astype(np.float32))


@pytest.fixture(scope="module")
def bedroom():
    return _mesh_points("bedroom", 0)


def _crops(P, N):
    """The person's part (left 75 %, below 2 m) and the robot's (right 70 %, below 1 m) of one room."""
    x0, w = P[:, 0].min(), np.ptp(P[:, 0])
    person = (P[:, 0] <= x0 + 0.75 * w) & (P[:, 2] <= 2.0)
    robot = (P[:, 0] >= x0 + 0.3 * w) & (P[:, 2] <= 1.0)
    return (P[person], N[person]), (P[robot], N[robot])


def _robot_frame() -> np.ndarray:
    """World -> robot frame: a camera-like rotation (roll and pitch too) and a shift."""
    import open3d as o3d

    T = np.eye(4)
    T[:3, :3] = o3d.geometry.get_rotation_matrix_from_xyz(np.radians([100.0, 30.0, 5.0]))
    T[:3, 3] = [0.5, -1.2, 0.3]
    return T


def test_floor_constrained_alignment_recovers_a_known_transform(bedroom):
    (Pp, Np), (Pr, Nr) = _crops(*bedroom)
    T = _robot_frame()
    r = align_to_map(_map(Pr, Nr, T), _map(Pp, Np), source_up=T[:3, :3] @ [0, 0, 1], target_up=[0, 0, 1], **FAST)
    assert isinstance(r, AlignmentResult) and r.constrained and r.floors is not None
    dt, dr = transform_error(r.transform, np.linalg.inv(T))
    assert dt < 0.02 and dr < 0.5, (dt, dr)
    assert r.accepted, r.failures()
    assert r.floor_angle_deg < 0.5 and abs(r.floor_offset_m) < 0.01
    # the floors: the robot's normal is its frame's up, the person's +z
    assert np.degrees(np.arccos(r.floors[1].normal @ [0, 0, 1])) < 1.0
    report = r.as_dict()
    assert set(report["floor"]) == {"source", "target", "angle_deg", "offset_m"}
    json.dumps(report)  # JSON-ready


def test_a_wrong_pair_is_refused(bedroom):
    (_, _), (Pr, Nr) = _crops(*bedroom)
    P2, N2 = _mesh_points("office", 3)
    keep = P2[:, 2] <= 2.0
    T = _robot_frame()
    r = align_to_map(_map(Pr, Nr, T), _map(P2[keep], N2[keep]), source_up=T[:3, :3] @ [0, 0, 1],
                     target_up=[0, 0, 1], **FAST)
    assert not r.accepted
    assert any("structure_fitness" in f for f in r.failures()), r.failures()


def test_fit_floor_and_camera_up():
    import open3d as o3d

    rng = np.random.default_rng(0)
    floor = np.c_[rng.uniform(0, 4, (3000, 2)), rng.normal(0, 0.003, 3000)]
    table = np.c_[rng.uniform(1, 2, (800, 2)), np.full(800, 0.7)]
    pc = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.r_[floor, table]))
    pc.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=0.2, max_nn=30))
    f = fit_floor(pc, np.array([0.2, 0.1, 1.0]), 0.05)  # a rough hint is enough
    assert f is not None and f.normal[2] > 0.999 and abs(f.offset) < 0.01  # the table top is not the floor
    cams = np.tile(np.eye(4), (3, 1, 1))
    cams[:, :3, :3] = [[1, 0, 0], [0, 0, 1], [0, -1, 0]]  # camera y (down) = world -z
    assert np.allclose(camera_up(cams), [0, 0, 1])
    with pytest.raises(ValueError, match="unknown alignment checks"):
        check_alignment({}, {"min_fitnes": 0.5})


# --------------------------------------------------------------------------- the command line
@pytest.fixture(scope="module")
def robot_and_wrong_map(tmp_path_factory):
    """A tiny robot recording of a bedroom and an office's map (a wrong pair)."""
    from semmatch.cli import main
    from semmatch.io import write_map

    root = tmp_path_factory.mktemp("align")
    assert main(["simulate", "--scene-kind", "bedroom", "--seed", "0", "--camera-height", "0.2", "--frames", "6",
                 "--image-size", "96x72", "--camera-step", "0.3", "--out", str(root / "robot"), "--quiet"]) == 0
    P, N = _mesh_points("office", 3, 15_000)
    write_map(root / "office.ply", _map(P, N))
    return root


@pytest.mark.slow
def test_align_refuses_a_wrong_pair_and_writes_nothing(robot_and_wrong_map, capsys):
    from semmatch.cli import main

    root = robot_and_wrong_map
    out = root / "poses.txt"
    assert main(["align", str(root / "robot"), "--to", str(root / "office.ply"), "--out", str(out),
                 "--person-up", "0,0,1", *CLI_FAST, "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "refused" in err and "below the minimum" in err and "--accept-weak-alignment" in err
    assert not out.exists() and not (root / "poses.txt.json").exists()


@pytest.mark.slow
def test_forced_alignment_says_so_in_every_output(robot_and_wrong_map):
    from semmatch.cli import main
    from semmatch.io import read_tum

    root = robot_and_wrong_map
    out = root / "forced.txt"
    assert main(["align", str(root / "robot"), "--to", str(root / "office.ply"), "--out", str(out),
                 "--person-up", "0,0,1", *CLI_FAST, "--accept-weak-alignment", "--quiet", "--json"]) == 0
    report = json.loads((root / "forced.txt.json").read_text())
    assert report["forced"] is True and report["accepted"] is False
    assert "FORCED" in out.read_text().splitlines()[1]
    _, poses = read_tum(out)
    assert poses.shape == (6, 4, 4)
    # transfer through the forced poses: its labels folder says so too
    labels = root / "labels"
    assert main(["transfer", str(root / "robot"), "--map", str(root / "office.ply"), "--method", "3d-neighborhood",
                 "--align", str(out), "--out", str(labels), "--quiet", "--no-index-cache"]) == 0
    assert json.loads((labels / "alignment.json").read_text())["forced"] is True


@pytest.mark.slow
def test_transfer_align_refuses_and_transfers_nothing(robot_and_wrong_map, capsys):
    from semmatch.cli import main

    root = robot_and_wrong_map
    labels = root / "refused_labels"
    assert main(["transfer", str(root / "robot"), "--map", str(root / "office.ply"), "--method", "3d-neighborhood",
                 "--align", str(root / "office.ply"), "--out", str(labels), "--quiet", "--no-index-cache"]) == 2
    assert "refused" in capsys.readouterr().err
    assert not labels.exists()


# --------------------------------------------------------------------------- trajectories through evo
def test_trajectory_errors_equal_evo():
    from semmatch.poses.registration import rigid_perturbation
    from semmatch.poses.trajectory_metrics import evo_trajectory_errors, trajectory_errors

    n = 40
    gt = np.tile(np.eye(4), (n, 1, 1))
    for i in range(1, n):
        gt[i] = gt[i - 1] @ rigid_perturbation(0.05, 3.0, center=np.zeros(3), seed=i)
    est = gt.copy()
    for i in range(n):  # a drift, then a frame of the world moved away
        est[i] = est[i] @ rigid_perturbation(0.002 * i, 0.1 * i, center=np.zeros(3), seed=100 + i)
    est = rigid_perturbation(1.0, 30.0, center=np.zeros(3), seed=7) @ est
    ours, evo = trajectory_errors(est, gt), evo_trajectory_errors(est, gt)
    for k in ("ate_rmse", "ate_rmse_unaligned", "rpe_trans", "rpe_rot_deg"):
        assert ours[k] == pytest.approx(evo[k], rel=1e-6, abs=1e-9), k
