"""semmatch.poses.odometry: trajectory errors, RGB-D pose estimation on a rendered sequence."""

from __future__ import annotations

import numpy as np
import pytest

from semmatch.io import Frame
from semmatch.io.geometry import DEFAULT_INTRINSICS, look_at
from semmatch.poses.odometry import estimate_poses, shrink_frame
from semmatch.poses.pose_graph import refine_pose_graph
from semmatch.poses.trajectory_metrics import align_trajectory, ate, rpe, trajectory_errors
from semmatch.sim import Renderer, generate_scene


def circle_poses(n: int = 20) -> np.ndarray:
    a = np.linspace(0, 1.0, n)
    return np.stack([look_at([2 + 0.5 * np.cos(t), 1.5 + 0.5 * np.sin(t), 1.2], [2.5, 3.5, 0.8]) for t in a])


def slide_poses(scene, n: int) -> np.ndarray:
    """A camera sliding sideways through ``scene`` while looking at the far wall."""
    lo, hi = scene.bounds
    c = (lo + hi) / 2
    return np.stack([
        look_at([c[0] - 0.6 + 0.03 * i, c[1] - 0.3, 1.0], [c[0] + 1.0, hi[1], 0.6 + 0.01 * i]) for i in range(n)
    ])


def rendered_slide(width: int, height: int, n: int = 12) -> tuple[list[Frame], np.ndarray]:
    """Frames (RGB, depth, labels; no pose) of :func:`slide_poses` in living_room 0, and the true poses."""
    scene = generate_scene("living_room", 0)
    intr = DEFAULT_INTRINSICS.scaled(width, height)
    r = Renderer(scene, intr)
    gt = slide_poses(scene, n)
    return [Frame(x.rgb, x.depth, x.labels, None, intr, index=i) for i, p in enumerate(gt) for x in [r.render(p)]], gt


def test_ate_is_zero_after_alignment_of_a_moved_trajectory():
    gt = circle_poses()
    S = np.eye(4)
    S[:3, :3] = look_at([0, 0, 0], [1, 1, 0.2])[:3, :3]
    S[:3, 3] = [3.0, -1.0, 0.5]
    est = S @ gt
    assert ate(est, gt) == pytest.approx(0.0, abs=1e-9)
    assert ate(est, gt, align=False) > 1.0
    assert np.allclose(align_trajectory(est, gt), np.linalg.inv(S), atol=1e-9)
    t, r = rpe(est, gt)
    assert t == pytest.approx(0.0, abs=1e-9) and r == pytest.approx(0.0, abs=1e-5)


def test_trajectory_errors_count_a_known_offset():
    gt = circle_poses()
    est = gt.copy()
    est[:, 0, 3] += np.where(np.arange(len(gt)) % 2, 0.01, -0.01)  # +-1 cm zigzag in x
    e = trajectory_errors(est, gt)
    assert e["ate_rmse_unaligned"] == pytest.approx(0.01)
    assert e["rpe_trans"] == pytest.approx(0.02)  # every step is off by 2 cm
    assert e["n_frames"] == len(gt)
    gt_nan = gt.copy()
    gt_nan[3] = np.nan  # frames without ground truth are skipped
    assert trajectory_errors(est, gt_nan)["n_frames"] == len(gt) - 1
    with pytest.raises(ValueError, match="must both be"):
        ate(est[:5], gt)


def test_estimate_poses_tracks_a_rendered_camera():
    frames, gt = rendered_slide(160, 120)
    intr = frames[0].intrinsics
    est = estimate_poses(frames, init_pose=gt[0])
    assert np.allclose(est[0], gt[0])
    e = trajectory_errors(est, gt)
    assert e["ate_rmse_unaligned"] < 0.02 and e["rpe_rot_deg"] < 0.5, e
    with pytest.raises(ValueError, match="residual must be one of"):
        estimate_poses(frames, residual="magic")
    bad = [Frame(f.rgb, f.depth * 1000, None, None, intr, index=f.index) for f in frames[:2]]
    with pytest.raises(ValueError, match="frame 0: median depth .* wrong unit"):
        estimate_poses(bad)


def test_prior_tolerance_rejects_motions_far_from_the_prior():
    frames, gt = rendered_slide(160, 120, n=6)
    prior = gt.copy()
    prior[4:, 0, 3] += 0.5  # the prior claims a 50 cm jump between frames 3 and 4 (truth: 3 cm)
    free = estimate_poses(frames, init_pose=gt[0], prior=prior, prior_tolerance=None, pose_graph=False)
    with pytest.warns(UserWarning, match=r"1 frame\(s\) \(first: \[4\]\); their motion was taken from the prior"):
        gated = estimate_poses(frames, init_pose=gt[0], prior=prior, pose_graph=False)
    step = lambda P: np.linalg.inv(P[3]) @ P[4]  # noqa: E731
    # ungated, the tracker started at the prior's jump settles > 10 cm away from it and is kept;
    # gated, that motion is rejected and the prior's is used
    assert np.linalg.norm(step(free)[:3, 3] - step(prior)[:3, 3]) > 0.1
    np.testing.assert_allclose(step(gated), step(prior), atol=1e-9)
    # where the prior agrees with the images, no motion is rejected and both track the truth
    for est in (free, gated):
        assert np.abs(est[:4, :3, 3] - gt[:4, :3, 3]).max() < 0.01


def test_tracking_on_shrunk_frames():
    frames, gt = rendered_slide(320, 240)
    intr = frames[0].intrinsics
    small = shrink_frame(frames[3], 2)
    assert small.depth.shape == (120, 160) and small.rgb.shape == (120, 160, 3) and small.index == 3
    assert small.intrinsics == intr.scaled(160, 120)
    assert set(np.unique(small.depth)) <= set(np.unique(frames[3].depth))  # no depth invented at edges
    est = estimate_poses(frames, init_pose=gt[0], downsample=2)
    e = trajectory_errors(est, gt)
    assert e["ate_rmse_unaligned"] < 0.02 and e["rpe_rot_deg"] < 0.5, e
    with pytest.raises(ValueError, match="downsample must be"):
        estimate_poses(frames, downsample=0)


def test_pose_graph_removes_drift_from_chained_poses():
    from scipy.spatial.transform import Rotation

    from semmatch.poses.odometry import _depth_mm

    frames, gt = rendered_slide(160, 120, 10)
    intr = frames[0].intrinsics
    depths = [_depth_mm(f.depth, f"frame {f.index}") for f in frames]
    # chained estimate with a growing drift: every step off by 1 cm and 0.5 degrees of yaw
    step = np.eye(4)
    step[:3, :3] = Rotation.from_euler("y", 0.5, degrees=True).as_matrix()
    step[:3, 3] = [0.01, 0.0, 0.0]
    drifted = [gt[0]]
    for i in range(1, len(gt)):
        drifted.append(drifted[-1] @ np.linalg.inv(gt[i - 1]) @ gt[i] @ step)
    drifted = np.stack(drifted)
    before = trajectory_errors(drifted, gt)["ate_rmse_unaligned"]
    out = refine_pose_graph(depths, intr, drifted)
    after = trajectory_errors(out, gt)["ate_rmse_unaligned"]
    assert np.allclose(out[0], gt[0]) and before > 0.02
    assert after < 0.3 * before and after < 0.01, (before, after)
    with pytest.raises(ValueError, match="one depth image per pose"):
        refine_pose_graph(depths[:3], intr, drifted)


def test_reconstruct_estimates_the_poses_of_a_noisy_simulated_sequence(tmp_path, capsys):
    """``semmatch reconstruct --estimate-poses --prior``: poses tracked from the noisy frames,
    seeded by the recorded drifting ones, scored against poses_gt.txt."""
    import json

    from semmatch.cli import main
    from semmatch.sim import NoiseConfig, make_trajectory, simulate_sequence

    scene = generate_scene("living_room", 0)
    intr = DEFAULT_INTRINSICS.scaled(160, 120)
    poses = make_trajectory(scene, 0.2, 300, kind="lower", seed=0)[:10]
    simulate_sequence(scene, poses, tmp_path / "lower", intrinsics=intr, noise=NoiseConfig.kinect(0),
                      progress=False)
    rc = main(["reconstruct", str(tmp_path / "lower"), "--out", str(tmp_path / "m.ply"), "--estimate-poses",
               "--prior", "--quiet", "--poses-out", str(tmp_path / "est.txt"), "--json"])
    assert rc == 0
    info = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert info["ate_rmse"] < 0.05 and info["n_frames"] == 10 and (tmp_path / "est.txt").is_file()


def test_sensor_dropouts_are_bridged_not_tracked(recwarn):
    from dataclasses import replace

    frames, gt = rendered_slide(160, 120, n=12)
    clean = estimate_poses(frames, init_pose=gt[0], pose_graph=False, progress=False)
    dropped = [replace(f, depth=np.zeros_like(f.depth)) if f.index in (4, 5) else f for f in frames]
    with pytest.warns(UserWarning, match=r"2 of 12 frame\(s\) had \(almost\) no valid depth.*first: \[4, 5\]"):
        est = estimate_poses(dropped, init_pose=gt[0], pose_graph=False, progress=False)
    # frames after the gap are tracked against the last good frame: the trajectory stays on course
    assert ate(est[6:], gt[6:], align=False) < 0.03 + ate(clean[6:], gt[6:], align=False)
    with pytest.raises(ValueError, match="none of its 12 frame"):
        estimate_poses([replace(f, depth=np.zeros_like(f.depth)) for f in frames], pose_graph=False, progress=False)


def test_rpe_pairs_never_span_a_gap_in_the_ground_truth():
    from semmatch.poses.trajectory_metrics import rpe_pairs

    gt = circle_poses(10)
    est = gt.copy()
    est[6:, 0, 3] += 0.5  # a 50 cm jump between frames 4 and 6, across frame 5 that has no ground truth
    gt_gap = gt.copy()
    gt_gap[5] = np.nan
    assert list(rpe_pairs(est, gt_gap)) == [0, 1, 2, 3, 6, 7, 8]
    t, _ = rpe(est, gt_gap)
    assert t == pytest.approx(0.0, abs=1e-9)  # pair (4, 6) would have counted the jump
    assert rpe(est, gt)[0] > 0.1  # with frame 5 known, the jump is a real error
    gt_gap[1::2] = np.nan
    with pytest.raises(ValueError, match="two frames 1 apart with ground truth"):
        rpe(est, gt_gap)


def test_chain_is_anchored_where_the_ground_truth_starts():
    from semmatch.poses.odometry import anchor_to_ground_truth

    gt = circle_poses(8)
    S = look_at([1.0, 2.0, 0.5], [3.0, 1.0, 0.0])
    est = S @ gt  # a perfect estimate in another frame (e.g. started at the identity)
    late = gt.copy()
    late[:3] = np.nan  # ground truth starts at frame 3
    with pytest.warns(UserWarning, match="ground truth starts at frame 3, not 0; .* anchored at frame 3"):
        out, first = anchor_to_ground_truth(est, late)
    assert first == 3 and np.allclose(out, gt, atol=1e-9)
    assert trajectory_errors(out, late)["ate_rmse_unaligned"] == pytest.approx(0.0, abs=1e-9)
    same, first = anchor_to_ground_truth(est, gt)  # ground truth from frame 0: the start pose was known
    assert first == 0 and same is est
    assert anchor_to_ground_truth(est, None) == (est, None)


def test_pose_graph_memory_is_bounded_and_does_not_change_the_poses():
    from semmatch.poses.odometry import _depth_mm
    from semmatch.poses.pose_graph import CompressedDepths

    frames, gt = rendered_slide(160, 120, 13)
    intr = frames[0].intrinsics
    depths = [_depth_mm(f.depth, f"frame {f.index}") for f in frames]
    packed = CompressedDepths()
    for d in depths:
        packed.append(d)
    assert all(np.array_equal(a, b) for a, b in zip(packed, depths)) and packed.nbytes < sum(d.nbytes for d in depths)
    step = np.eye(4)
    step[:3, 3] = [0.01, 0.0, 0.0]
    drifted = np.stack([gt[0]] + [gt[i] @ np.linalg.matrix_power(step, i) for i in range(1, len(gt))])
    # every pyramid kept (as before the cache) vs one kept: frames 9 and 12 close loops to keyframes 0 and 3
    everything = refine_pose_graph(depths, intr, drifted, cache=len(gt))
    one = refine_pose_graph(packed, intr, drifted, cache=1)
    np.testing.assert_array_equal(everything, one)
    assert not np.allclose(everything, drifted)
    # a long recording is optimised in fragments (bounded optimiser memory): the drift still goes
    before = trajectory_errors(drifted, gt)["ate_rmse_unaligned"]
    fragments = refine_pose_graph(packed, intr, drifted, max_nodes=5)
    assert np.allclose(fragments[0], gt[0]) and not np.allclose(fragments, everything)
    assert trajectory_errors(fragments, gt)["ate_rmse_unaligned"] < 0.5 * before
