"""Real Kinect frames (7-Scenes red kitchen, scripts/fetch_7scenes_kitchen.sh); skipped when they are absent.

Set ``SEMMATCH_7SCENES`` to the data folder, or fetch it to the script's default place.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

DATA = Path(os.environ.get("SEMMATCH_7SCENES", Path.home() / ".cache/semmatch/tsdf-fusion-python/data"))

pytestmark = pytest.mark.skipif(not (DATA / "frame-000000.depth.png").is_file(),
                                reason=f"no 7-Scenes frames in {DATA} (scripts/fetch_7scenes_kitchen.sh)")


def test_red_kitchen_reads_as_a_7scenes_recording():
    from semmatch.io.recordings import SevenScenesSequence, check_depth_scale, read_recording

    seq = read_recording(DATA, frames=slice(0, 500))  # the development frames only: 500-999 are held out
    assert isinstance(seq, SevenScenesSequence) and len(seq) >= 10
    assert (seq.intrinsics.fx, seq.intrinsics.shape, seq.intrinsics.depth_scale) == (585.0, (480, 640), 1000.0)
    f = seq[0]
    assert 1.0 < np.median(f.depth[f.depth > 0]) < 3.0 and f.pose is not None
    with pytest.raises(ValueError, match="most likely in millimetres"):  # read as a TUM folder would read it
        check_depth_scale(seq._depth, 5000.0, where=str(DATA))


def test_red_kitchen_first_frames_track_within_a_centimetre():
    from semmatch.io.recordings import SevenScenesSequence
    from semmatch.poses.odometry import estimate_poses
    from semmatch.poses.trajectory_metrics import trajectory_errors

    seq = SevenScenesSequence(DATA, frames=slice(0, 6))
    est = estimate_poses(seq, init_pose=seq.poses[0], downsample=2, pose_graph=False)
    e = trajectory_errors(est, seq.poses)
    assert e["ate_rmse_unaligned"] < 0.01, e
