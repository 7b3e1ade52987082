"""Timing of the transfer methods and of the published reference, in one process.

Used by ``semmatch bench transfer`` and by the Table 1 experiment (``04_label_transfer``).
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from ..io import Frame
from .index import MapIndex
from .registry import METHODS, available_methods, method_info, transfer_frame

__all__ = ["time_method", "time_methods", "bench_scene"]


def time_method(name: str, frames: Sequence[Frame], index: MapIndex, **params) -> dict:
    """Median wall time of one method over ``frames`` after one warm-up frame.

    Returns
    -------
    dict
        ``ms_median``, ``ms_min``, ``fps`` (1000 / median ms), ``accuracy`` (labelled pixels
        that match the frames' ground truth, when they have labels), ``coverage``, ``labels``
        (the labels of the last frame).
    """
    if not frames:
        raise ValueError("time_method: no frames")
    transfer_frame(name, frames[0], index, **params)  # warm-up (lazy structures, caches)
    ms, acc, cov = [], [], []
    for f in frames:
        r = transfer_frame(name, f, index, **params)
        ms.append(r.seconds * 1000)
        lab = r.labels > 0
        if f.labels is not None:
            acc.append(float((r.labels[lab] == f.labels[lab]).mean()) if lab.any() else 0.0)
        cov.append(r.coverage)
    med = float(np.median(ms))
    return {"ms_median": med, "fps": 1000.0 / med, "ms_min": float(np.min(ms)),
            "accuracy": float(np.mean(acc)) if acc else float("nan"), "coverage": float(np.mean(cov)),
            "labels": r.labels}


def time_methods(
    frames: Sequence[Frame], index: MapIndex, methods: Sequence[str] = METHODS, *, exact_variant: bool = True
) -> dict:
    """Time each method and the reference backend of ``3d-neighborhood`` on the same frames.

    Returns
    -------
    dict
        ``{"methods": {name: {ms_median, ms_min, fps, accuracy, coverage, paper_fps,
        speedup_vs_paper, speedup_vs_reference[, agreement_with_reference]}}, "reference":
        {...}}``; with ``exact_variant`` also ``"3d-neighborhood (exact)"`` (exact closest-point
        refinement near class edges).
    """
    for m in methods:
        if m not in available_methods() or m == "fused":
            valid = [x for x in available_methods() if x != "fused"]
            raise ValueError(f"unknown method {m!r}; valid: {', '.join(valid)}")
    ref = time_method("3d-neighborhood", frames, index, backend="reference")
    ref_labels = ref.pop("labels")
    out: dict = {"methods": {}, "reference": ref}
    variants = [(m, m, {}) for m in methods]
    if exact_variant and "3d-neighborhood" in methods:
        variants.append(("3d-neighborhood (exact)", "3d-neighborhood", {"exact": True}))
    for key, name, params in variants:
        r = time_method(name, frames, index, **params)
        labels = r.pop("labels")
        paper = method_info(name).paper_fps
        r["paper_fps"] = float("nan") if paper is None else paper
        r["speedup_vs_paper"] = float("nan") if paper is None else r["fps"] / paper
        r["speedup_vs_reference"] = r["fps"] / ref["fps"]
        if name == "3d-neighborhood":
            r["agreement_with_reference"] = float((labels == ref_labels).mean())
        out["methods"][key] = r
    return out


def bench_scene(seed: int = 0, n_frames: int = 10, height: float = 0.25):
    """A generated living room and the robot's poses on its own tour, for benchmarks."""
    from ..sim import generate_scene, make_trajectory

    scene = generate_scene("living_room", seed)
    return scene, make_trajectory(scene, height, n_frames, seed=seed, kind="lower")
