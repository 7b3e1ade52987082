"""Table 1: the transfer methods timed on one core (CPU time) on 640x480 lower frames of an
evaluation scene (04)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from ..io import read_sequence
from .layout import GT, Layout
from .tables import speed_table

__all__ = ["measure_speed"]


def _frames_at(sd: Path, n_frames: int, width: int, height: int) -> list:
    """``n_frames`` evenly spaced lower frames of scene folder ``sd`` at ``width`` x ``height``.

    The recorded frames when the sequence has that size; otherwise the scene (regenerated from
    ``scene.json``: kind and seed) is rendered at the true poses of those frames.
    """
    import json

    from ..io import Frame
    from ..io.geometry import DEFAULT_INTRINSICS

    seq = read_sequence(sd / "lower")
    idx = np.unique(np.linspace(0, len(seq) - 1, min(n_frames, len(seq))).round().astype(int))
    if (seq.intrinsics.width, seq.intrinsics.height) == (width, height):
        return [seq[int(i)] for i in idx]
    from ..io import read_tum
    from ..sim import Renderer, generate_scene

    meta = json.loads((sd / "scene.json").read_text())
    if "kind" not in meta or "seed" not in meta:
        raise ValueError(f"{sd / 'scene.json'}: no kind/seed to regenerate the scene at {width}x{height}")
    intr = DEFAULT_INTRINSICS.scaled(width, height)
    renderer = Renderer(generate_scene(meta["kind"], int(meta["seed"])), intr)
    _, poses = read_tum(sd / "lower" / "poses_gt.txt")
    frames = []
    for k, i in enumerate(idx):
        r = renderer.render(poses[int(i)])
        frames.append(Frame(rgb=r.rgb, depth=r.depth, labels=r.labels, pose=poses[int(i)], intrinsics=intr, index=k))
    return frames


def measure_speed(data_root: str | Path, methods: Sequence[str], *, n_frames: int = 30, scene: int = 0,
                  width: int = 640, height: int = 480,
                  method_settings: Mapping[str, Mapping] | None = None) -> pd.DataFrame:
    """Table 1: the rate of each method on one core, from its CPU time, in one process.

    The ground-truth upper map of one evaluation scene is indexed once; ``n_frames`` lower
    frames (evenly spaced; rendered at ``width`` x ``height``, the paper's 640x480, when the
    profile records smaller frames) are labelled by each method after one warm-up frame, on one
    thread (:func:`semmatch.transfer.benchmark.time_methods`, as ``semmatch bench transfer``).
    The rate is 1 / the median CPU time of the method per frame: what one free core delivers,
    whatever else the machine runs. The wall rate and the machine's load stand beside it. Each
    method runs with its ``method_settings`` (``{method: {parameter: value}}``).

    Returns
    -------
    DataFrame
        Table 1: method, fps (= cpu_fps), cpu_fps, ms_per_frame (CPU), wall_fps, load_average
        (1-minute load average while the method ran), cpu_share (CPU time / wall time), paper_fps,
        speedup_vs_paper, speedup_vs_reference (CPU rates; the reference is ``3d-neighborhood``
        with Open3D closest-point queries on the mesh, as the authors' code). ``attrs``:
        ``reference_fps``, ``frames``, ``cpus``.
    """
    import os

    from ..transfer import load_index
    from ..transfer.benchmark import time_methods

    layout = Layout(data_root)
    sd = layout.scene_dirs("eval")[scene]
    frames = _frames_at(sd, n_frames, width, height)
    index = load_index(layout.upper_map(sd.name, GT))  # cached beside the map

    timing = time_methods(frames, index, methods, exact_variant=False, settings=method_settings)
    ref_fps = timing["reference"]["fps"]
    rows = timing["methods"]
    df = speed_table({m: rows[m]["fps"] for m in methods}, ref_fps)
    df.insert(2, "cpu_fps", df["fps"])
    for col in ("wall_fps", "load_average", "cpu_share"):
        df[col] = [rows[m][col] for m in methods]
    df.attrs["reference_fps"] = ref_fps
    df.attrs["frames"] = len(frames)
    df.attrs["cpus"] = os.cpu_count()
    return df
