"""Table 3 on "real-like" sequences: sensor noise on, poses withheld and estimated (07).

The simulator writes, for every evaluation scene, ``upper_noisy`` and ``lower_noisy``: the
same trajectories as ``upper``/``lower`` seen through a Kinect-like sensor model (depth noise
growing with distance, dropouts, RGB noise and exposure changes) with drifting, jittered
recorded poses (what wheel odometry or an IMU would give). The true poses are withheld: poses
are estimated by RGB-D odometry (:func:`semmatch.odometry.estimate_poses`: frame-to-frame
tracking refined by a pose graph with loop closures) seeded by the recorded drifting poses as a
motion prior, from the known first pose (both agents start at a
known anchor, as when a robot is docked). The upper map and the lower frames therefore drift
independently, as in a real recording.

As in the paper's real-data protocol (the reconstruction itself annotated by hand), the
reference of a scene is the noisy lower sequence fused at the *estimated* poses with
ground-truth labels: the measures score the labels, while registration errors between the
upper map and the lower frames still degrade the transferred labels.
"""

from __future__ import annotations

from collections.abc import Sequence
from collections.abc import Sequence as _SequenceABC
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm.auto import tqdm

from ..io import Frame, InMemorySequence, SequenceReader, read_sequence, read_tum, write_tum
from .layout import GT, Layout, model_name
from .synthetic import MEASURE_COLUMNS

__all__ = ["PosedSequence", "estimate_or_load_poses", "evaluate_real_like"]


class PosedSequence(_SequenceABC):
    """A sequence whose frames carry other poses (e.g. estimated ones) than the recorded ones."""

    def __init__(self, seq: SequenceReader | InMemorySequence, poses: np.ndarray) -> None:
        if len(poses) != len(seq):
            raise ValueError(f"{seq.path}: {len(poses)} poses for {len(seq)} frames")
        self.seq, self.poses, self.intrinsics, self.path = seq, np.asarray(poses), seq.intrinsics, seq.path

    def __len__(self) -> int:
        return len(self.seq)

    def __getitem__(self, i: int) -> Frame:  # type: ignore[override]
        return replace(self.seq[i], pose=self.poses[i].copy())

    def read_labels(self, i: int):
        return self.seq.read_labels(i)


#: the pipeline tracks on frames shrunk by this factor (:func:`semmatch.odometry.estimate_poses`):
#: on a 640x480 real-like lower sequence 0.17 s instead of 0.75 s a frame, ATE 0.2 cm instead of 0.04 cm
ODOMETRY_DOWNSAMPLE = 2


def estimate_or_load_poses(seq_dir: Path, out: Path, *, seq: _SequenceABC | None = None,
                           progress: bool = True) -> tuple[np.ndarray, np.ndarray]:
    """Estimated poses of a noisy sequence (cached in ``out``) and its true poses.

    The poses are :func:`semmatch.odometry.estimate_poses` with the pose graph on, tracked on
    frames shrunk by :data:`ODOMETRY_DOWNSAMPLE`, frame-to-frame motions gated by the recorded
    (prior) motions; the cache file name of :func:`evaluate_real_like`
    (``*_estimated_posegraph_ds2_gated.txt``) names these, so that caches of other settings
    are not reused.

    Parameters
    ----------
    seq_dir : path
        The noisy sequence folder (with ``poses_gt.txt``).
    out : path
        Cache file (TUM format).
    seq : sequence, optional
        The frames of ``seq_dir`` when already read (e.g. an :class:`~semmatch.io.InMemorySequence`).
    progress : bool

    Returns
    -------
    estimated, true : ndarray (N,4,4)
    """
    from ..odometry import estimate_poses

    seq = read_sequence(seq_dir) if seq is None else seq
    _, true = read_tum(seq_dir / "poses_gt.txt")
    if out.is_file():
        _, est = read_tum(out)
        if len(est) == len(seq):
            return est, true
    est = estimate_poses(seq, init_pose=true[0], prior=seq.poses, downsample=ODOMETRY_DOWNSAMPLE, progress=progress)
    write_tum(out, np.arange(len(est), dtype=np.float64), est)
    return est, true


def evaluate_real_like(
    data_root: str | Path,
    methods: Sequence[str],
    networks: Sequence[str],
    *,
    voxel_size: float = 0.04,
    eval_voxel_size: float = 0.05,
    include_ground_truth: bool = True,
    jobs: int = 1,
    progress: bool = True,
) -> tuple[pd.DataFrame, pd.DataFrame]:
    """Run the whole real-like chain for every evaluation scene and score it.

    Per scene: estimate poses of ``upper_noisy`` and ``lower_noisy``; build the upper map of
    each network (its predictions on the noisy upper frames, fused with estimated poses); label
    the noisy lower frames by each method from each upper map, and by each network directly;
    fuse each with the estimated lower poses; compare with the reference (the noisy lower
    frames fused with ground-truth labels at the estimated poses).

    Parameters
    ----------
    data_root : path
    methods, networks : sequences of str
    voxel_size, eval_voxel_size : float
        Fusion and evaluation voxel sizes (m).
    include_ground_truth : bool
        Also transfer from a ground-truth upper map (fused from the noisy upper frames).
    jobs : int
        Worker processes for the label transfer.
    progress : bool

    Returns
    -------
    table : DataFrame
        scene, model, method, jaccard, sorensen, color_acc, mean_acc.
    trajectories : DataFrame
        scene, sequence, poses (recorded prior or estimated), ate_rmse (m, aligned),
        ate_rmse_unaligned, rpe_trans (m/frame), rpe_rot_deg (deg/frame), n_frames.
    """
    from ..fusion import reconstruct_many
    from ..metrics import compare
    from ..odometry import trajectory_errors
    from ..segment import predict_sequence
    from ..transfer import prepare, transfer_sequence

    layout = Layout(data_root)
    models = {net: layout.load_network(net) for net in networks}
    rows, traj_rows = [], []
    for sd in tqdm(layout.scene_dirs("eval"), desc="real-like scenes", disable=not progress):
        sid = sd.name
        for need in ("upper_noisy", "lower_noisy"):
            if not (sd / need).is_dir():
                raise FileNotFoundError(f"{sd / need}: no noisy sequence; run 01_simulate with noise on")
        work = layout.real_like / sid
        work.mkdir(parents=True, exist_ok=True)
        seqs = {}
        for name in ("upper", "lower"):
            cache = work / f"{name}_estimated_posegraph_ds{ODOMETRY_DOWNSAMPLE}_gated.txt"
            # read once: predicted, transferred and fused from memory
            noisy = read_sequence(sd / f"{name}_noisy").load()
            est, true = estimate_or_load_poses(sd / f"{name}_noisy", cache, seq=noisy, progress=progress)
            for what, poses in (("recorded (drifting prior)", noisy.poses), ("estimated (RGB-D odometry)", est)):
                err = trajectory_errors(poses, true)
                traj_rows.append(dict(scene=sid, sequence=name, poses=what, **{
                    k: float(v) for k, v in err.items() if np.isscalar(v)}))
            seqs[name] = PosedSequence(noisy, est)
        sources = ([GT] if include_ground_truth else []) + list(networks)
        # upper maps: one fusion of the upper frames, labelled by ground truth and each network
        upper_labels = {GT: None}
        for net in networks:
            upper_labels[net] = work / f"upper_labels_{net}"
            predict_sequence(models[net], seqs["upper"], upper_labels[net], progress=False)
        upper_maps = reconstruct_many(seqs["upper"], [upper_labels[s] for s in sources], voxel_size,
                                      outs=[work / f"upper_{s}.ply" for s in sources])
        # lower labels: each network on the lower frames, each method from each upper map
        lower = []  # (model, method, labels folder)
        for source, upper_map in zip(sources, upper_maps, strict=True):
            if source != GT:
                low_dir = work / f"lower_labels_{source}" / "lower"
                predict_sequence(models[source], seqs["lower"], low_dir, progress=False)
                lower.append((model_name(source), "lower", low_dir))
            index = prepare(upper_map)
            for method in methods:
                lab_dir = work / f"lower_labels_{source}" / method
                transfer_sequence(method, seqs["lower"].seq, index, lab_dir, poses=seqs["lower"].poses,
                                  jobs=jobs, progress=False)
                lower.append((model_name(source), method, lab_dir))
        # one fusion of the lower frames: the reference (ground-truth labels) and every labeling
        reference, *maps = reconstruct_many(seqs["lower"], [None, *(d for *_, d in lower)], voxel_size,
                                            outs=[work / "reference.ply"] + [None] * len(lower))
        for (model, method, _), pred in zip(lower, maps, strict=True):
            s = compare(reference, pred, voxel_size=eval_voxel_size)
            rows.append(dict(scene=sid, model=model, method=method, **{k: float(s[k]) for k in MEASURE_COLUMNS}))
    return pd.DataFrame(rows), pd.DataFrame(traj_rows)
