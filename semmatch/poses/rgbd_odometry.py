"""Multi-scale RGB-D odometry between two frames that gives the same result on every run.

Open3D's ``t.pipelines.odometry.rgbd_odometry_multi_scale`` is not repeatable on a CPU, for two
reasons measured with Open3D 0.20 (docs/protocol.md, "Repeatability"):

- its intensity pyramid (hybrid and intensity residuals) blurs with IPP's 5x5 Gaussian, which
  reads uninitialised memory at the image's left border: for one input, columns 0-3 of the
  blurred image differed between processes (two of five), so the whole estimate did;
- each iteration's normal equations are summed on Open3D's TBB threads, whose order varies:
  with two threads, eight calls on one frame pair gave eight different transforms (1e-5 m).

Tracking a recording chains hundreds of such calls and picks among candidates by their misfit,
so these differences grew into trajectories that differed by millimetres to centimetres between
runs. This module keeps Open3D's parts that are repeatable, its per-iteration kernels
(``compute_odometry_result_point_to_plane`` / ``_hybrid`` / ``_intensity``) and its depth
processing (unit conversion and clipping, depth pyramid, vertex and normal maps, bilateral
filter), and builds the intensity pyramid and the image gradients with OpenCV: the same 5x5
Gaussian (sigma 1, border replicated) followed by every second pixel, and 3x3 Sobel filters
(equal to Open3D's to 5e-7 away from the border). Calls run with Open3D limited to one thread
(:func:`open3d_threads`). The multi-scale loop and its stopping rule are Open3D's.

A frame's pyramid is built once (:func:`rgbd_pyramid`) and serves as source and target of any
number of calls (:func:`multi_scale_odometry`), which a tracker trying several initial guesses
and residuals per frame pair needs.
"""

from __future__ import annotations

import contextlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

__all__ = ["RGBDPyramid", "rgbd_pyramid", "multi_scale_odometry", "open3d_threads", "METHODS"]

#: residuals of :func:`multi_scale_odometry`
METHODS = ("point-to-plane", "hybrid", "intensity")


@contextlib.contextmanager
def open3d_threads(n: int = 1) -> Iterator[None]:
    """Limit Open3D to ``n`` CPU threads inside the block.

    Process-wide; on leaving, the count Open3D reported on entry is set again (an explicit limit
    equal to its automatic one when none had been set).
    """
    import open3d as o3d

    previous = o3d.utility.get_max_threads()
    o3d.utility.set_max_threads(int(n))
    try:
        yield
    finally:
        o3d.utility.set_max_threads(int(previous))


@dataclass
class RGBDPyramid:
    """One frame's image pyramid for :func:`multi_scale_odometry`, coarsest level first.

    Attributes
    ----------
    depth : list of Tensor (H, W, 1) float32
        Depth in metres, NaN where missing or beyond ``depth_max``.
    intensity : list of Tensor (H, W, 1) float32 or None
        Grey level in [0, 1] (None for a depth-only pyramid).
    vertex : list of Tensor (H, W, 3) float32
        Back-projected depth (NaN where missing).
    intrinsics : list of Tensor (3, 3) float64
        The camera matrix of each level.
    depth_outlier_trunc : float
        Open3D's ``OdometryLossParams.depth_outlier_trunc`` the pyramid was built with (metres).
    """

    depth: list
    intensity: list | None
    vertex: list
    intrinsics: list
    depth_outlier_trunc: float
    _target: dict = field(default_factory=dict, repr=False)

    def _as_target(self, what: str, level: int):
        """The target-side maps of ``level``, computed on first use: ``"normal"`` (normals of the
        bilateral-filtered depth), ``"depth_grad"`` / ``"intensity_grad"`` ((dx, dy) Sobel)."""
        key = (what, level)
        if key not in self._target:
            self._target[key] = _target_maps(self, what, level)
        return self._target[key]


def _tensor(a: np.ndarray, device):
    import open3d.core as o3c

    return o3c.Tensor(np.ascontiguousarray(a[..., None] if a.ndim == 2 else a)).to(device)


def _sobel(img: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import cv2

    return (cv2.Sobel(img, cv2.CV_32F, 1, 0, ksize=3, borderType=cv2.BORDER_REPLICATE),
            cv2.Sobel(img, cv2.CV_32F, 0, 1, ksize=3, borderType=cv2.BORDER_REPLICATE))


#: weights of the 5x5 window of :func:`_pyrdown_depth` by distance from its centre (Open3D's)
_PYR_WEIGHTS = np.array([0.375, 0.25, 0.0625], dtype=np.float32)


def _pyrdown_depth(depth: np.ndarray, diff: float) -> np.ndarray:
    """Half-size depth as Open3D's ``PyrDownDepth`` computes it (its Python binding lacks it).

    Each output pixel is the Gaussian-weighted mean (5x5 window around the even source pixel)
    of the valid depths within ``diff`` of the centre's; NaN where the centre is missing.
    """
    H, W = depth.shape
    h, w = H // 2, W // 2
    pad = np.pad(depth.astype(np.float32), 2, constant_values=np.nan)
    centre = depth[0:2 * h:2, 0:2 * w:2]
    v_sum = np.zeros((h, w), np.float32)
    w_sum = np.zeros((h, w), np.float32)
    for dy in range(-2, 3):
        for dx in range(-2, 3):
            v = pad[2 + dy:2 + dy + 2 * h:2, 2 + dx:2 + dx + 2 * w:2]
            with np.errstate(invalid="ignore"):
                ok = np.abs(v - centre) < np.float32(diff)
            wt = _PYR_WEIGHTS[abs(dx)] * _PYR_WEIGHTS[abs(dy)]
            v_sum += np.where(ok, wt * v, np.float32(0))
            w_sum += np.where(ok, wt, np.float32(0))
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(w_sum > 0, v_sum / w_sum, np.float32(np.nan)).astype(np.float32)


def _target_maps(pyr: RGBDPyramid, what: str, level: int):
    import open3d as o3d

    depth = pyr.depth[level]
    if what == "normal":
        smooth = o3d.t.geometry.Image(depth).filter_bilateral(5, 5.0, 10.0)
        return smooth.create_vertex_map(pyr.intrinsics[level], float("nan")).create_normal_map(float("nan")).as_tensor()
    src = depth if what == "depth_grad" else pyr.intensity[level]
    return tuple(_tensor(g, depth.device) for g in _sobel(src.cpu().numpy()[..., 0]))


def rgbd_pyramid(depth_mm: np.ndarray, rgb: np.ndarray | None, K: np.ndarray, *, levels: int = 3,
                 depth_max: float = 5.0, depth_scale: float = 1000.0, depth_outlier_trunc: float | None = None,
                 device: str | None = None) -> RGBDPyramid:
    """Build a frame's pyramid for :func:`multi_scale_odometry`.

    Parameters
    ----------
    depth_mm : ndarray (H, W) uint16
        Depth in units of 1/``depth_scale`` metres (0 = missing).
    rgb : ndarray (H, W, 3) uint8 or None
        Colour (None: point-to-plane only).
    K : ndarray (3, 3)
        Camera matrix of the full-resolution level.
    levels : int
        Pyramid levels (each halves the size).
    depth_max : float
        Depth beyond this (metres) counts as missing.
    depth_scale : float
    depth_outlier_trunc : float, optional
        Open3D's ``OdometryLossParams.depth_outlier_trunc`` (default: Open3D's default); the depth
        pyramid ignores neighbours differing by more than twice this.
    device : str, optional
        Open3D device (default: CPU).

    Returns
    -------
    RGBDPyramid
    """
    import cv2
    import open3d as o3d
    import open3d.core as o3c

    if depth_outlier_trunc is None:
        depth_outlier_trunc = float(o3d.t.pipelines.odometry.OdometryLossParams().depth_outlier_trunc)
    dev = o3c.Device(device or "CPU:0")
    nan = float("nan")
    depth = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(depth_mm))).to(dev)
    depth = depth.clip_transform(float(depth_scale), 0.0, float(depth_max), nan)
    grey = None
    if rgb is not None:  # Open3D's grey levels (a per-pixel conversion: repeatable)
        colour = o3d.t.geometry.Image(o3c.Tensor(np.ascontiguousarray(rgb, dtype=np.uint8)))
        grey = np.ascontiguousarray(colour.rgb_to_gray().to(o3c.float32).as_tensor().numpy()[..., 0])
    K_level = np.asarray(K, dtype=np.float64).copy()
    out = RGBDPyramid([], None if rgb is None else [], [], [], float(depth_outlier_trunc))
    for i in range(int(levels)):
        k = o3c.Tensor(K_level)
        out.depth.insert(0, depth.as_tensor())
        out.vertex.insert(0, depth.create_vertex_map(k, nan).as_tensor())
        out.intrinsics.insert(0, k)
        if grey is not None:
            out.intensity.insert(0, _tensor(grey, dev))
        if i != levels - 1:
            depth = o3d.t.geometry.Image(_tensor(_pyrdown_depth(depth.as_tensor().cpu().numpy()[..., 0],
                                                                2.0 * depth_outlier_trunc), dev))
            if grey is not None:
                grey = np.ascontiguousarray(cv2.GaussianBlur(grey, (5, 5), 1.0, borderType=cv2.BORDER_REPLICATE)[::2, ::2])
            K_level = K_level / 2.0
            K_level[2, 2] = 1.0
    return out


def multi_scale_odometry(source: RGBDPyramid, target: RGBDPyramid, init: np.ndarray, *,
                         method: str = "point-to-plane", iterations: Sequence = (30, 15, 8)) -> tuple[np.ndarray, float, float]:
    """``T_target_source`` by multi-scale RGB-D odometry (Open3D's kernels and stopping rule).

    Parameters
    ----------
    source, target : RGBDPyramid
        :func:`rgbd_pyramid` of the two frames (same size and levels; with intensity unless
        ``method`` is point-to-plane).
    init : ndarray (4, 4)
        Initial guess of the source-to-target transform.
    method : {"point-to-plane", "hybrid", "intensity"}
    iterations : sequence of int or of ``OdometryConvergenceCriteria``
        Per level, coarsest first: the iteration limit (relative fitness and RMSE change 1e-6, as
        Open3D's default), or Open3D criteria.

    Returns
    -------
    (T, fitness, inlier_rmse)
        ``T`` (4, 4) float64 and the last iteration's fitness and inlier RMSE.

    Raises
    ------
    ValueError
        Unknown method, pyramids of different levels, or without intensity for a photometric method.
    RuntimeError
        An iteration found no correspondences (Open3D's kernels raise it).
    """
    import open3d as o3d
    import open3d.core as o3c

    odo = o3d.t.pipelines.odometry
    if method not in METHODS:
        raise ValueError(f"method must be one of {METHODS}, got {method!r}")
    n = len(source.depth)
    if len(target.depth) != n or len(iterations) != n:
        raise ValueError(f"source, target and iterations must have the same levels, got {n}, {len(target.depth)}, "
                         f"{len(iterations)}")
    if method != "point-to-plane" and (source.intensity is None or target.intensity is None):
        raise ValueError(f"{method} odometry needs pyramids built with colour")
    criteria = [c if isinstance(c, odo.OdometryConvergenceCriteria) else odo.OdometryConvergenceCriteria(int(c))
                for c in iterations]
    loss = odo.OdometryLossParams()
    trunc = source.depth_outlier_trunc
    T = o3c.Tensor(np.asarray(init, dtype=np.float64))
    fitness, rmse = 1.0, 0.0
    with open3d_threads(1):
        for i, crit in enumerate(criteria):
            for _ in range(int(crit.max_iteration)):
                if method == "point-to-plane":
                    delta = odo.compute_odometry_result_point_to_plane(
                        source.vertex[i], target.vertex[i], target._as_target("normal", i), source.intrinsics[i], T,
                        trunc, loss.depth_huber_delta)
                elif method == "hybrid":
                    ddx, ddy = target._as_target("depth_grad", i)
                    idx, idy = target._as_target("intensity_grad", i)
                    delta = odo.compute_odometry_result_hybrid(
                        source.depth[i], target.depth[i], source.intensity[i], target.intensity[i], ddx, ddy, idx, idy,
                        source.vertex[i], source.intrinsics[i], T, trunc, loss.depth_huber_delta,
                        loss.intensity_huber_delta)
                else:
                    idx, idy = target._as_target("intensity_grad", i)
                    delta = odo.compute_odometry_result_intensity(
                        source.depth[i], target.depth[i], source.intensity[i], target.intensity[i], idx, idy,
                        source.vertex[i], source.intrinsics[i], T, trunc, loss.intensity_huber_delta)
                T = delta.transformation.to(o3c.float64) @ T
                converged = (rmse > 0 and fitness > 0 and abs(fitness - delta.fitness) / fitness < crit.relative_fitness
                             and abs(rmse - delta.inlier_rmse) / rmse < crit.relative_rmse)
                if converged:
                    break
                fitness, rmse = float(delta.fitness), float(delta.inlier_rmse)
    return T.cpu().numpy(), fitness, rmse
