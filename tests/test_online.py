"""The robot online (semmatch.online, semmatch replay): streamed = batch for the same poses,
frame-to-model tracking in the person's map and in the robot's own map, lost frames void, the
live frame schedule, and the replay verb's outputs."""

from __future__ import annotations

import json

import numpy as np
import pytest

from semmatch.fusion import reconstruct
from semmatch.io import Frame, SequenceWriter, read_label_image, read_labels_folder
from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.online import Initialisation, ModelTracker, RobotSession
from semmatch.online.replay import frame_schedule, replay
from semmatch.poses.registration import transform_error
from semmatch.sim import Renderer, generate_scene, make_trajectory
from semmatch.transfer import MapIndex, transfer_sequence

INTR = DEFAULT_INTRINSICS.scaled(160, 120)


def _frames(renderer, poses):
    out = []
    for i, p in enumerate(poses):
        r = renderer.render(p)
        out.append(Frame(r.rgb, r.depth, r.labels, p, renderer.intrinsics, index=i, timestamp=i / 30.0))
    return out


@pytest.fixture(scope="module")
def room():
    """A living room: the person's map (1.6 m, ground-truth labels, mesh) and 16 consecutive robot
    frames (0.2 m, up to 4 cm and 4 degrees apart, as a video stream) at 160x120."""
    scene = generate_scene("living_room", 0)
    r = Renderer(scene, INTR)
    upper = _frames(r, make_trajectory(scene, 1.6, 40, kind="upper", seed=0))
    person = reconstruct(upper, voxel_size=0.04)
    lower = _frames(r, make_trajectory(scene, 0.2, 16, kind="lower", seed=0, max_step=0.04, max_turn_deg=4.0))
    return person, lower


@pytest.mark.parametrize("method", ["3d-neighborhood", "2d-slic", "fused"])
def test_streamed_labels_and_map_equal_the_batch_functions(room, tmp_path, method):
    person, lower = room
    rng = np.random.default_rng(0)
    probs = [rng.dirichlet(np.ones(21), size=INTR.shape).astype(np.float32) for _ in lower]
    params = {"probs": tmp_path / "probs"} if method == "fused" else {}
    if method == "fused":
        (tmp_path / "probs").mkdir()
        for i, p in enumerate(probs):
            np.save(tmp_path / "probs" / f"{i:06d}.npy", p)
    index = MapIndex(person)
    transfer_sequence(method, lower, index, tmp_path / "batch", progress=False, **params)
    batch_labels = [read_label_image(p) for p in read_labels_folder(tmp_path / "batch")]
    batch_map = reconstruct(lower, labels=tmp_path / "batch", voxel_size=0.04)

    session = RobotSession(person, method=method, index=index)
    for i, f in enumerate(lower):
        r = session.step(f, pose=f.pose, probs=probs[i] if method == "fused" else None)
        assert r.status == "given" and r.fused
        np.testing.assert_array_equal(r.labels, batch_labels[i])  # byte for byte
    streamed = session.semantic_map()
    for key in ("points", "labels", "colors", "faces"):
        np.testing.assert_array_equal(getattr(streamed, key), getattr(batch_map, key), err_msg=key)


def test_batch_and_session_take_the_same_per_frame_steps(room, monkeypatch):
    """transfer_sequence / fuse_sequence and the session call one shared transfer step and one shared
    fusion step, with the same frames, poses and labels in the same order: the two cannot drift."""
    import semmatch.fusion.reconstruction as fusion_mod
    import semmatch.transfer.sequence as transfer_mod
    from semmatch.fusion import fuse_sequence

    person, lower = room
    frames, calls = lower[:4], []
    shared_transfer, shared_fuse = transfer_mod.transfer_posed_frame, fusion_mod.fuse_frame

    def transfer_step(method, frame, index, *, pose=None, **kw):
        r = shared_transfer(method, frame, index, pose=pose, **kw)
        calls.append(("transfer", frame.index, np.asarray(frame.pose if pose is None else pose).tobytes(),
                      r.labels.tobytes()))
        return r

    def fuse_step(vol, frame, pose, labels=None, **kw):
        calls.append(("fuse", frame.index, np.asarray(pose).tobytes(), np.asarray(labels).tobytes()))
        return shared_fuse(vol, frame, pose, labels, **kw)

    monkeypatch.setattr(transfer_mod, "transfer_posed_frame", transfer_step)
    monkeypatch.setattr(fusion_mod, "fuse_frame", fuse_step)
    index = MapIndex(person)
    labels = [transfer_mod._transfer_one(frames, None, index, "3d-neighborhood", {}, i)[1] for i in range(4)]
    fuse_sequence(frames, labels=labels)
    batch, calls[:] = list(calls), []
    session = RobotSession(person, index=index)
    for f in frames:
        session.step(f, pose=f.pose)
    # the batch transfers every frame, then fuses; the session alternates: compare each kind in order
    for kind in ("transfer", "fuse"):
        assert [c for c in calls if c[0] == kind] == [c for c in batch if c[0] == kind], kind
    assert len(calls) == 8


@pytest.mark.slow
def test_streamed_outputs_equal_the_batch_verbs(room, tmp_path):
    """semmatch transfer + semmatch reconstruct and semmatch replay --true-poses write the same labels and map."""
    from semmatch.cli import main
    from semmatch.io import read_map, write_map

    person, lower = room
    write_map(tmp_path / "person.ply", person)
    w = SequenceWriter(tmp_path / "lower", INTR)
    for f in lower[:6]:
        w.add(f.rgb, f.depth, f.pose, timestamp=f.timestamp)
    w.close()
    seq, pmap, q = str(tmp_path / "lower"), str(tmp_path / "person.ply"), ["--quiet", "--no-index-cache"]
    assert main(["transfer", seq, "--map", pmap, "--method", "3d-neighborhood", "--out", str(tmp_path / "batch"), *q]) == 0
    assert main(["reconstruct", seq, "--labels", str(tmp_path / "batch"), "--depth-max", "4",
                 "--out", str(tmp_path / "batch.ply"), "--quiet"]) == 0
    assert main(["replay", seq, "--map", pmap, "--method", "3d-neighborhood", "--true-poses", "--rate", "0",
                 "--labels-out", str(tmp_path / "stream"), "--map-out", str(tmp_path / "stream.ply"), *q]) == 0
    batch, stream = read_labels_folder(tmp_path / "batch"), read_labels_folder(tmp_path / "stream")
    assert len(batch) == len(stream) == 6
    for a, b in zip(batch, stream, strict=True):
        np.testing.assert_array_equal(read_label_image(a), read_label_image(b), err_msg=a.name)
    a, b = read_map(tmp_path / "batch.ply"), read_map(tmp_path / "stream.ply")
    assert a.labels.any()
    for key in ("points", "labels", "colors", "faces"):
        np.testing.assert_array_equal(getattr(a, key), getattr(b, key), err_msg=key)


def test_tracking_in_the_person_map_with_an_odometry_prior(room):
    person, lower = room
    session = RobotSession(person, init_pose=lower[0].pose)
    # the true poses as a perfect wheel-odometry prior: the tracker corrects the prediction against the
    # person's 4 cm mesh, which lies 3-4 cm behind the robot's depth at 0.2 m (docs/online.md), so the
    # poses stay within a few centimetres, not millimetres
    results = [session.step(f, prior=f.pose) for f in lower]
    assert results[0].status == "initialised"
    assert [(r.status, r.reason) for r in results[1:]] == [("tracked", "")] * (len(lower) - 1)
    for f, r in zip(lower, results, strict=True):
        dt, dr = transform_error(r.pose, f.pose)
        assert dt < 0.1 and dr < 2.0, (f.index, dt, dr)
        assert r.labels.shape == INTR.shape and r.labels.any()
    t = results[-1].tracking
    assert t.model == "person" and 0 < t.fitness <= 1 and np.isfinite(t.rmse)


def test_self_tracking_without_a_person_map(room):
    _, lower = room
    session = RobotSession(None, init_pose=lower[0].pose, tracker=ModelTracker(None))
    results = [session.step(f, prior=f.pose) for f in lower]  # a perfect odometry prior, corrected by tracking
    assert all(r.labels is None for r in results)
    assert [(r.status, r.tracking.model) for r in results[1:]] == [("tracked", "robot")] * (len(lower) - 1)
    errs = [transform_error(r.pose, f.pose)[0] for f, r in zip(lower, results, strict=True)]
    assert max(errs) < 0.05, errs


def test_lost_frames_get_void_labels_and_are_not_fused(room):
    person, lower = room
    session = RobotSession(person, init_pose=lower[0].pose, relocalise_every=2)
    session.step(lower[0])
    blocks = session.tsdf.n_blocks
    dark = Frame(lower[1].rgb, np.zeros_like(lower[1].depth), None, None, INTR, index=1)  # a sensor dropout
    r = session.step(dark)
    assert r.status == "lost" and r.pose is None and not r.fused and r.reason
    assert r.labels.shape == INTR.shape and not r.labels.any()
    assert session.tsdf.n_blocks == blocks
    r = session.step(lower[2])  # tracked again from the last good pose
    assert r.status == "relocalised" and r.labels.any()


def test_initialiser_is_pluggable_and_retried_until_it_answers(room):
    person, lower = room
    calls = []

    def init(frame, person_map):
        calls.append(frame.index)
        return Initialisation(lower[frame.index].pose if len(calls) > 1 else None, 1.0, "test")

    session = RobotSession(person, initialiser=init)
    r0, r1 = session.step(lower[0]), session.step(lower[1])
    assert (r0.status, r1.status) == ("initialising", "initialised") and calls == [0, 1]
    assert not r0.labels.any() and r0.reason


def test_align_frame_places_a_frame_or_answers_not_found(room):
    """``replay --init align``: semmatch align's checked alignment of one frame into the person's map;
    a pose only when the alignment passes its checks, and then near the truth."""
    from semmatch.online import align_frame

    person, lower = room
    assert align_frame(lower[0], None).pose is None
    answers = [align_frame(f, person) for f in lower[:4]]
    assert all(a.method == "align" for a in answers) and any(a.pose is not None for a in answers)
    for a, f in zip(answers, lower[:4]):
        if a.pose is not None:  # measured: 3 of 4 accepted, 5-6 cm / 0.3 degrees (the 4 cm map's offset)
            err = transform_error(a.pose, f.pose)
            assert err[0] < 0.08 and err[1] < 2.0, err


def test_frame_schedule_drops_what_arrives_while_busy():
    took = {0: 0.05, 3: 0.01}
    processed, dropped = frame_schedule(8, 30.0, lambda i: took.get(i, 0.1))
    # frame 0 ends at 0.05 s: frame 1 (0.033 s) is the newest; frame 1 ends at 0.15: frame 4 ...
    assert processed == [0, 1, 4, 7] and dropped == [2, 3, 5, 6]
    assert frame_schedule(5, 0.0, lambda i: 1.0) == ([0, 1, 2, 3, 4], [])


def test_replay_drops_frames_by_the_chosen_clock(room):
    person, lower = room
    truth = [f.pose for f in lower[:6]]
    report = replay(RobotSession(person), lower[:6], rate=1e6, poses=truth, clock="cpu")
    assert len(report.results) + len(report.dropped) == 6 and report.dropped  # a million frames per second
    with pytest.raises(ValueError, match="clock"):
        replay(RobotSession(person), lower[:2], clock="gpu")


def test_replay_reports_latency_drops_and_trajectory_error(room):
    person, lower = room
    session = RobotSession(person, init_pose=lower[0].pose)
    truth = np.stack([f.pose for f in lower[:8]])
    report = replay(session, lower[:8], rate=0, priors=truth)
    s = report.summary(truth)
    assert s["processed"] == 8 and s["dropped"] == 0 and s["lost_frames"] == 0
    assert s["ate_m"] < 0.1 and s["latency_ms_p95"] >= s["latency_ms_median"] > 0


def test_replay_verb_writes_poses_labels_and_map(room, tmp_path):
    from semmatch.cli import main
    from semmatch.io import read_map, read_tum, write_map

    person, lower = room
    write_map(tmp_path / "person.ply", person)
    w = SequenceWriter(tmp_path / "lower", INTR)
    for f in lower[:6]:
        w.add(f.rgb, f.depth, f.pose, timestamp=f.timestamp)
    w.close()
    out = tmp_path / "out"
    code = main(["replay", str(tmp_path / "lower"), "--map", str(tmp_path / "person.ply"), "--rate", "0",
                 "--true-poses", "--json", "--poses-out", str(out / "poses.txt"),
                 "--labels-out", str(out / "labels"), "--map-out", str(out / "robot.ply"), "--quiet"])
    assert code == 0
    _, poses = read_tum(out / "poses.txt")
    assert len(poses) == 6 and len(read_labels_folder(out / "labels")) == 6
    assert len(read_map(out / "robot.ply").points) > 0
    assert main(["replay", str(tmp_path / "lower"), "--map", str(tmp_path / "nope.ply"), "--quiet"]) == 2


def test_replay_writes_a_rerun_log_that_reads_back(room, tmp_path):
    from rerun.chunk import RrdReader

    from semmatch.online.outputs import ReplayOutputs

    person, lower = room
    session = RobotSession(person, init_pose=lower[0].pose)
    out = tmp_path / "replay.rrd"
    with ReplayOutputs(rerun=out, frames=lower[:4], session=session) as outputs:
        outputs.log.map_every = 2
        report = replay(session, lower[:4], rate=0, poses=[f.pose for f in lower[:4]], on_frame=outputs.on_frame)
        outputs.finish(report, session)
    assert out.is_file() and not list(tmp_path.glob(".*partial"))
    paths = {str(c.entity_path) for c in RrdReader(out).stream().to_chunks()}
    for entity in ("/world/camera/image/rgb", "/world/camera/image/labels", "/world/camera/image/depth",
                   "/tracking/status", "/world/trajectory", "/world/map"):
        assert entity in paths, (entity, sorted(paths))


def test_bench_online_prints_the_chain_beside_plain_open3d(room, tmp_path, capsys):
    from semmatch.cli import main
    from semmatch.cli.bench.online import _played

    assert _played(list(range(10)), slice(2, 5), 3) == [2, 3, 4, 3, 2, 3, 4]
    _, lower = room
    w = SequenceWriter(tmp_path / "lower", INTR)
    for f in lower[:6]:
        w.add(f.rgb, f.depth, f.pose, timestamp=f.timestamp)
    w.close()
    capsys.readouterr()
    assert main(["bench", "online", str(tmp_path / "lower"), "--frames", "0:6", "--no-offline", "--json",
                 "--methods", "3d-neighborhood", "3d-projected-sp"]) == 0
    s = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert set(s["chain_frames_per_cpu_second"]) == {"3d-neighborhood", "3d-projected-sp"}
    assert s["chain_frames_per_cpu_second"]["3d-projected-sp"] > 0 and len(s["rss_gb_by_frame"]) == 2
    assert s["played"] == 6 and s["processed"] == 6 and s["frames_per_cpu_second"] > 0
    assert s["plain_open3d"]["ate_m"] >= 0 and "online_ate_m" in s and s["peak_rss_gb"] > 0


@pytest.mark.slow
def test_online_study_scores_the_online_map_against_the_true_pose_chain(room, tmp_path):
    """semmatch.experiments.online_study on a small scene folder: both maps scored, the trajectories
    measured, the recording's odometry (here a drifting copy of the truth) as prior."""
    from semmatch.experiments.online_study import main, online_scene
    from semmatch.io import write_tum

    _, lower = room
    scene = generate_scene("living_room", 0)
    r = Renderer(scene, INTR)
    upper = _frames(r, make_trajectory(scene, 1.6, 12, kind="upper", seed=0))
    sd = tmp_path / "living_room_0"
    drift = np.eye(4)
    for name, frames in (("upper_noisy", upper), ("lower_noisy", lower[:8])):
        with SequenceWriter(sd / name, INTR) as w:
            for k, f in enumerate(frames):
                drift[0, 3] = 0.002 * k  # the recording's odometry drifts 2 mm a frame
                w.add(f.rgb, f.depth, drift @ f.pose, labels=f.labels, timestamp=f.timestamp)
        write_tum(sd / name / "poses_gt.txt", np.arange(len(frames), dtype=float), np.stack([f.pose for f in frames]))
    row = online_scene(sd, tmp_path / "study" / sd.name, init="first-pose")  # global alignment: test above
    assert row["frames"] == 8 and 0.5 < row["mean_acc_true"] <= 1
    assert row["posed_frames"] + row["initialising"] + row["lost_frames"] == 8
    assert row["posed_frames"] == 8 and abs(row["mean_acc_diff"]) < 0.1 and row["ate_online_abs_m"] < 0.1
    assert row["ate_prior_m"] >= 0 and row["ate_offline_m"] >= 0
    assert (tmp_path / "study" / sd.name / "row.json").is_file()
    with pytest.raises(FileNotFoundError, match="poses_gt"):
        online_scene(tmp_path / "nope", tmp_path / "w2")
    assert main([str(sd), "--out", str(tmp_path / "study"), "--init", "first-pose"]) == 0  # the row reused
    assert (tmp_path / "study" / "rows.csv").is_file()
