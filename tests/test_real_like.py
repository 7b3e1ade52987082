"""The real-like chain without ground truth (own frames, map registration), the gate choice, misregistration."""

from __future__ import annotations

import shutil

import numpy as np
import pandas as pd
import pytest
from conftest import noisy_scene_root

from semmatch.experiments.layout import GT, Layout
from semmatch.experiments.real import evaluate_real_like, real_like_lower_map
from semmatch.experiments.real_poses import (
    estimate_or_load_poses,
    pose_cache_name,
    registration_errors,
    select_prior_tolerance,
)
from semmatch.io import read_tum, write_map, write_tum

SCENE = "bedroom_0003"
TOL = (0.1, 10.0)


@pytest.fixture(scope="module")
def tiny_root(tmp_path_factory):
    """A data root with one small evaluation scene (clean and Kinect-like noisy recordings)."""
    return noisy_scene_root(tmp_path_factory, "real_like", 24)


def _moved_copy(root, dst, G):
    """A copy of ``root`` whose world is moved by ``G``: true poses (``poses_gt.txt``) and the scene mesh."""
    import dataclasses

    from semmatch.io import read_map, write_map

    shutil.copytree(root / "scenes", dst / "scenes")
    for cache in (root / "real_like").glob("*/*_poses_*.txt"):  # the estimates (their independence: below)
        (dst / "real_like" / cache.parent.name).mkdir(parents=True, exist_ok=True)
        shutil.copy(cache, dst / "real_like" / cache.parent.name / cache.name)
    mesh = dst / "scenes" / "eval" / SCENE / "scene.ply"
    m = read_map(mesh)
    write_map(mesh, dataclasses.replace(m, points=(m.points @ G[:3, :3].T + G[:3, 3]).astype(np.float32)))
    for rec in ("upper_noisy", "lower_noisy"):
        f = dst / "scenes" / "eval" / SCENE / rec / "poses_gt.txt"
        ts, poses = read_tum(f)
        write_tum(f, ts, G @ poses)
    return dst


def test_chain_uses_no_true_pose_and_reports_the_registration(tiny_root, tmp_path, oracle_network):
    kw = dict(voxel_size=0.05, registration_voxel=0.1, registration_restarts=2, prior_tolerance=TOL, progress=False)
    table, traj, reg = evaluate_real_like(tiny_root, ["3d-neighborhood"], ["noisy"], **kw)
    assert set(zip(table["model"], table["method"])) == {
        ("ground truth", "3d-neighborhood"), ("noisy", "lower"), ("noisy", "3d-neighborhood"), ("noisy", "fused"),
        ("noisy", "upper")}  # the network's own upper map (claim C16), no ground-truth upper row
    assert table[["jaccard", "sorensen", "color_acc", "mean_acc"]].apply(lambda c: c.between(0, 1)).all().all()
    work = Layout(tiny_root).real_like / SCENE
    for name in ("upper", "lower"):
        est = read_tum(work / pose_cache_name(name, TOL))[1]
        np.testing.assert_allclose(est[0], np.eye(4), atol=1e-9)  # its own frame, no known start pose
    for source, method in (("gt", "3d-neighborhood"), ("noisy", "lower"), ("noisy", "fused")):
        assert real_like_lower_map(tiny_root, SCENE, source, method).is_file()
    assert set(traj["sequence"]) == {"upper", "lower"} and (traj["ate_rmse"] < 0.1).all(), traj
    assert len(reg) == 1 and reg["truth"].iloc[0] == "mesh"
    row = reg.iloc[0]
    for col in ("reg_trans_err_m", "reg_rot_err_deg", "lower_in_upper_rmse_m", "reg_trans_err_traj_m", "fitness"):
        assert np.isfinite(row[col]), col
    assert row["transform"].shape == row["lower_to_world"].shape == (4, 4)
    assert (work / "registration.json").is_file()
    # fused = the transferred label where supported, the network's elsewhere
    from semmatch.io import read_label_image, read_labels_folder

    lab = work / "lower_labels_noisy"
    for a, b, f in zip(*(read_labels_folder(lab / m) for m in ("3d-neighborhood", "lower", "fused")), strict=True):
        t, n = read_label_image(a), read_label_image(b)
        np.testing.assert_array_equal(read_label_image(f), np.where(t > 0, t, n))

    # the same recordings with every true pose moved: the same estimate, registration and scores
    G = np.eye(4)
    G[:3, :3] = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    G[:3, 3] = [2.0, -1.0, 0.3]
    moved = _moved_copy(tiny_root, tmp_path / "moved", G)
    table2, traj2, reg2 = evaluate_real_like(moved, ["3d-neighborhood"], ["noisy"], **kw)
    for name in ("upper", "lower"):
        np.testing.assert_allclose(read_tum(Layout(moved).real_like / SCENE / pose_cache_name(name, TOL))[1],
                                   read_tum(work / pose_cache_name(name, TOL))[1], atol=1e-12)
    # the same up to the vertex order of Open3D's fusion (labels of a few boundary voxels)
    pd.testing.assert_frame_equal(table2, table, atol=2e-3)
    np.testing.assert_allclose(reg2["transform"].iloc[0], row["transform"], atol=1e-9)
    np.testing.assert_allclose(reg2["lower_to_world"].iloc[0], G @ row["lower_to_world"], atol=2e-3)
    for col in ("reg_trans_err_traj_m", "reg_rot_err_traj_deg"):  # trajectory alignments: exactly invariant
        assert reg2[col].iloc[0] == pytest.approx(row[col], abs=1e-6)
    pd.testing.assert_frame_equal(traj2, traj, atol=1e-6)


def test_estimated_poses_do_not_depend_on_the_true_first_pose(tiny_root, tmp_path):
    seq_dir = tiny_root / "scenes" / "eval" / SCENE / "lower_noisy"
    est, true = estimate_or_load_poses(seq_dir, tmp_path / "a.txt", prior_tolerance=TOL, progress=False)
    copy = tmp_path / "lower_noisy"
    shutil.copytree(seq_dir, copy)
    ts, gt = read_tum(copy / "poses_gt.txt")
    gt[0, :3, 3] += [0.5, -0.3, 0.1]
    write_tum(copy / "poses_gt.txt", ts, gt)
    est2, true2 = estimate_or_load_poses(copy, tmp_path / "b.txt", prior_tolerance=TOL, progress=False)
    np.testing.assert_allclose(est2, est, atol=1e-3)  # Open3D's parallel sums: not bit-identical
    np.testing.assert_allclose(est[0], np.eye(4), atol=1e-12)
    assert not np.allclose(true2[0], true[0])
    assert pose_cache_name("lower", TOL) != pose_cache_name("lower", None)


def test_registration_errors_measure_a_known_error():
    rng = np.random.default_rng(0)
    from semmatch.poses.registration import rigid_perturbation

    true_l = np.stack([rigid_perturbation(1.0, 30.0, center=rng.normal(size=3), seed=i) for i in range(10)])
    Au = rigid_perturbation(2.0, 40.0, center=np.zeros(3), seed=1)
    Al = rigid_perturbation(1.0, 70.0, center=np.zeros(3), seed=2)
    est_l = np.linalg.inv(Al) @ true_l
    exact = np.linalg.inv(Au) @ Al
    e = registration_errors(exact, Au, Al, est_l, true_l)
    assert e["trans_err_m"] < 1e-9 and e["rot_err_deg"] < 1e-5 and e["lower_in_upper_rmse_m"] < 1e-9
    off = np.eye(4)
    off[:3, 3] = [0.03, 0.0, 0.04]  # 5 cm, in the upper frame
    e = registration_errors(off @ exact, Au, Al, est_l, true_l)
    assert e["trans_err_m"] == pytest.approx(0.05) and e["lower_in_upper_rmse_m"] == pytest.approx(0.05)


def test_gate_is_chosen_by_the_lowest_mean_ate(tiny_root):
    chosen, table = select_prior_tolerance([tiny_root / "scenes" / "eval" / SCENE], ((0.1, 10.0), None),
                                           recordings=("lower_noisy",), progress=False)
    assert len(table) == 2 and set(table["prior_tolerance"]) == {"gate0.1m10deg", "ungated"}
    means = table.groupby("prior_tolerance")["ate_rmse"].mean()
    assert means[{None: "ungated"}.get(chosen, "gate0.1m10deg")] == means.min()
    with pytest.raises(ValueError, match="no candidate"):
        select_prior_tolerance([tiny_root / "scenes" / "eval" / SCENE], ())
    with pytest.raises(FileNotFoundError, match="no noisy recording"):
        select_prior_tolerance([tiny_root / "scenes" / "eval"], ((0.1, 10.0),))


def test_misregistration_costs_accuracy(tiny_root, tmp_path):
    from semmatch.experiments.misregistration import misregistration_study
    from semmatch.fusion import reconstruct, reconstruct_many
    from semmatch.io import read_sequence
    from semmatch.plots import plot_misregistration

    layout = Layout(tiny_root)
    sd = layout.scenes / "eval" / SCENE
    with pytest.raises(FileNotFoundError, match="03_reconstruct_upper"):
        misregistration_study(tiny_root, ["3d-neighborhood"], progress=False)
    reconstruct_many(read_sequence(sd / "upper"), [None], 0.05, outs=[layout.upper_map(SCENE, GT)])
    write_map(layout.lower_reference(SCENE), reconstruct(read_sequence(sd / "lower"), None, 0.05))
    df = misregistration_study(tiny_root, ["3d-neighborhood"], translations=(0.0, 0.15), rotations_deg=(5.0,),
                               voxel_size=0.05, progress=False)
    assert list(zip(df["translation_m"], df["rotation_deg"], strict=True)) == [(0.0, 0.0), (0.15, 0.0), (0.0, 5.0)]
    acc = df["mean_acc"].to_numpy()
    assert acc[0] > 0.6 and acc[1] < acc[0] - 0.05 and acc[2] < acc[0], df
    out = plot_misregistration(df, tmp_path / "fig.png")
    assert out.is_file() and out.stat().st_size > 1000


def test_depth_noise_study_isolates_the_labels(tiny_root, tmp_path):
    from semmatch.experiments.claims import check_claims
    from semmatch.experiments.depth_noise import depth_noise_study, noise_drops
    from semmatch.experiments.misregistration import misregistration_study
    from semmatch.fusion import reconstruct, reconstruct_many
    from semmatch.io import read_sequence
    from semmatch.plots import plot_depth_noise

    layout = Layout(tiny_root)
    sd = layout.scenes / "eval" / SCENE
    if not layout.upper_map(SCENE, GT).is_file():
        reconstruct_many(read_sequence(sd / "upper"), [None], 0.05, outs=[layout.upper_map(SCENE, GT)])
    if not layout.lower_reference(SCENE).is_file():
        write_map(layout.lower_reference(SCENE), reconstruct(read_sequence(sd / "lower"), None, 0.05))
    methods = ["3d-neighborhood", "2d-slic"]
    df = depth_noise_study(tiny_root, methods, levels=(0.0, 10.0), voxel_size=0.05, progress=False)
    assert list(zip(df["method"], df["level"])) == [(m, lv) for lv in (0.0, 10.0) for m in methods]
    clean = df[df["level"] == 0].set_index("method")["mean_acc"]
    # level 0 is the unperturbed transfer: the misregistration study's (0, 0) case scores the same
    mis = misregistration_study(tiny_root, methods, translations=(), rotations_deg=(), voxel_size=0.05,
                                progress=False).set_index("method")["mean_acc"]
    assert clean.to_dict() == pytest.approx(mis.to_dict())
    noisy = df[df["level"] == 10].set_index("method")["mean_acc"]
    assert noisy["3d-neighborhood"] < clean["3d-neighborhood"], df  # ~8.8 cm at 2 m hurts the 3D lookup
    drops = noise_drops(df)
    assert set(drops["model"]) == {"ground truth"} and drops.set_index("method")["mean_acc"].to_dict() == \
        pytest.approx((clean - noisy).to_dict())
    res = check_claims(noise=drops, methods=methods)
    assert set(res["claim"]) == set() or set(res["data"]) == {"depth noise"}  # no dbscan here: C13-noise skipped
    with pytest.raises(ValueError, match="levels"):
        depth_noise_study(tiny_root, methods, levels=(-1.0,), progress=False)
    with pytest.raises(ValueError, match="one noise level"):
        noise_drops(df[df["level"] == 0])
    assert plot_depth_noise(df, tmp_path / "noise.png").stat().st_size > 1000
