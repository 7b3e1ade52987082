"""Timing of the transfer methods and of the published reference, in one process.

Used by ``semmatch bench transfer`` and by the Table 1 experiment (``04_label_transfer``).
"""

from __future__ import annotations

import os
import time
from collections.abc import Iterator, Mapping, Sequence
from contextlib import contextmanager

import numpy as np

from ..io import Frame
from ..io.labels import NUM_CLASSES
from .index import MapIndex
from .registry import METHODS, available_methods, method_info, settings_for, transfer_frame

__all__ = ["time_method", "time_methods", "bench_scene", "bench_upper_map", "bench_probs", "one_core"]


@contextmanager
def one_core() -> Iterator[None]:
    """Run the block on one thread: torch, Open3D, numba and the OpenMP / BLAS runtimes
    (:func:`semmatch.runtime.threads.limit_threads`) and OpenCV, whose two-thread SLIC costs a fifth more
    CPU time on a busy machine. The previous settings are restored on exit."""
    import cv2

    from ..runtime.threads import limit_threads

    cv_threads = cv2.getNumThreads()
    cv2.setNumThreads(1)
    try:
        with limit_threads(1):
            yield
    finally:
        cv2.setNumThreads(cv_threads)


def bench_probs(frame: Frame, seed: int = 0) -> np.ndarray:
    """Class probabilities of a stand-in network for timing ``fused``: float32 (H,W,21), right
    (its most probable class is the ground truth) on about 80 % of the pixels, seeded."""
    rng = np.random.default_rng(seed + int(frame.index))
    H, W = np.asarray(frame.depth).shape
    probs = rng.random((H, W, NUM_CLASSES), dtype=np.float32)
    if frame.labels is not None:
        right = rng.random((H, W)) < 0.8
        probs[right, np.asarray(frame.labels)[right]] += 1.0
    probs /= probs.sum(axis=2, keepdims=True)
    return probs


def time_method(name: str, frames: Sequence[Frame], index: MapIndex, **params) -> dict:
    """CPU time and wall time of one method per frame, after one warm-up frame.

    The rate that counts is the one from the CPU time of the method (``time.process_time``
    around each frame): what one core delivers whatever else runs on the machine. The wall
    rate and the machine's 1-minute load average are reported beside it: on a busy machine the
    wall rate falls and the CPU rate does not (much). Run it inside :func:`one_core`.
    ``fused`` takes the probabilities of :func:`bench_probs` unless ``probs`` is given.

    Returns
    -------
    dict
        ``ms_median`` and ``ms_min`` (CPU milliseconds per frame), ``fps`` and ``cpu_fps`` (both
        1000 / median CPU ms), ``wall_ms_median``, ``wall_fps``, ``load_average`` (the higher
        1-minute load average, before or after), ``cpu_share`` (CPU time / wall time: the part
        of a core the method got), ``accuracy`` (labelled pixels that match the frames' ground
        truth, when they have labels), ``coverage``, ``labels`` (the labels of the last frame).
    """
    if not frames:
        raise ValueError("time_method: no frames")

    def extra(f: Frame) -> dict:
        return {"probs": bench_probs(f)} if name == "fused" and "probs" not in params else {}

    transfer_frame(name, frames[0], index, **extra(frames[0]), **params)  # warm-up (caches, kernels)
    cpu, wall, acc, cov = [], [], [], []
    load = os.getloadavg()[0]
    for f in frames:
        more = extra(f)  # made outside the timed span
        c, t = time.process_time(), time.perf_counter()
        r = transfer_frame(name, f, index, **more, **params)
        cpu.append((time.process_time() - c) * 1000)
        wall.append((time.perf_counter() - t) * 1000)
        lab = r.labels > 0
        if f.labels is not None:
            acc.append(float((r.labels[lab] == f.labels[lab]).mean()) if lab.any() else 0.0)
        cov.append(r.coverage)
    load = max(load, os.getloadavg()[0])
    med, wmed = float(np.median(cpu)), float(np.median(wall))
    return {"ms_median": med, "fps": 1000.0 / max(med, 1e-9), "ms_min": float(np.min(cpu)),
            "cpu_fps": 1000.0 / max(med, 1e-9), "wall_ms_median": wmed, "wall_fps": 1000.0 / max(wmed, 1e-9),
            "load_average": float(load),
            "cpu_share": float(np.sum(cpu) / max(np.sum(wall), 1e-9)),
            "accuracy": float(np.mean(acc)) if acc else float("nan"), "coverage": float(np.mean(cov)),
            "labels": r.labels}


def time_methods(
    frames: Sequence[Frame], index: MapIndex, methods: Sequence[str] = METHODS, *, exact_variant: bool = True,
    variants: Sequence[tuple[str, str, dict]] = (), settings: Mapping[str, Mapping] | None = None,
) -> dict:
    """Time each method and the reference backend of ``3d-neighborhood`` on the same frames, on
    one core (:func:`one_core`, :func:`time_method`).

    ``fused`` runs on its default base (``3d-projected-sp``) with :func:`bench_probs`.

    Returns
    -------
    dict
        ``{"methods": {name: {ms_median, ms_min, fps, cpu_fps, wall_ms_median, wall_fps,
        load_average, cpu_share, accuracy, coverage, paper_fps, speedup_vs_paper,
        speedup_vs_reference[, agreement_with_reference]}}, "reference": {...}, "threads":
        {...}}``; with ``exact_variant`` also ``"3d-neighborhood (exact)"`` (exact closest-point
        refinement near class edges). Speed-ups compare CPU rates. ``variants``: more rows
        ``(key, method, parameters)``, each method timed again with those parameters (e.g.
        ``("2d-slic [iterations=3]", "2d-slic", {"iterations": 3})``), after the methods.
        ``settings``: the methods' own parameters (``{method: {parameter: value}}``,
        :func:`~semmatch.transfer.registry.settings_for`), e.g. a run's ``2d-slic`` lever: the
        method's main row runs with them.
    """
    for m in [*methods, *(name for _, name, _ in variants)]:
        if m not in available_methods():
            raise ValueError(f"unknown method {m!r}; valid: {', '.join(available_methods())}")
    with one_core():
        from ..runtime.threads import current

        ref = time_method("3d-neighborhood", frames, index, backend="reference")
        ref_labels = ref.pop("labels")
        out: dict = {"methods": {}, "reference": ref, "threads": current()}
        rows = [(m, m, settings_for(m, settings)) for m in methods]
        if exact_variant and "3d-neighborhood" in methods:
            rows.append(("3d-neighborhood (exact)", "3d-neighborhood", {"exact": True}))
        rows += [(key, name, dict(params)) for key, name, params in variants]
        for key, name, params in rows:
            r = time_method(name, frames, index, **params)
            labels = r.pop("labels")
            paper = None if name == "fused" else method_info(name).paper_fps
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


def bench_upper_map(scene, seed: int = 0, n_frames: int = 60, height: float = 1.6, voxel_size: float = 0.04,
                    size: tuple[int, int] = (320, 240)):
    """The person's fused ground-truth map of ``scene``: what Table 1 indexes.

    The upper (human-height) tour of ``n_frames`` is rendered at ``size`` with its ground-truth
    labels and fused into a semantic TSDF mesh at ``voxel_size``, as the pipeline's stage
    ``03_reconstruct_upper`` makes ``upper/<scene>/gt.ply`` (the full profile's sizes are the
    defaults). Such a reconstruction has about ten times the vertices of the scene's own mesh and
    a surface that only approximately meets the robot's depth, so more of the robot's points lie
    near the support distance and need an exact query: the transfer rate against it is the one
    that matters for the pipeline (docs/speed.md, "Map density").

    Returns
    -------
    SemanticMap
        Labelled triangle mesh.
    """
    from ..fusion import reconstruct
    from ..io.geometry import DEFAULT_INTRINSICS
    from ..sim import make_trajectory, render_frames

    poses = make_trajectory(scene, height, n_frames, seed=seed, kind="upper")
    frames = render_frames(scene, poses, DEFAULT_INTRINSICS.scaled(*size))
    return reconstruct(frames, [f.labels for f in frames], voxel_size)
