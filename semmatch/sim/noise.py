"""Sensor noise for "real-like" sequences: depth, RGB and pose errors.

Every part has its own parameters and is off by default (``NoiseConfig()`` changes nothing);
``NoiseConfig.kinect()`` is a preset resembling a structured-light RGB-D camera with a
visual-odometry pose estimate.

- depth: Gaussian noise with ``sigma = depth_a + depth_b * z**2`` (Kinect-like axial noise,
  Khoshelham & Elberink 2012), dropouts at depth edges (``edge_dropout`` of the pixels
  next to a jump larger than ``edge_jump`` x depth) and at far range (dropout probability
  rising linearly from ``far_start`` to 1 at ``max_range``), quantisation to ``depth_step``.
- RGB: per-frame exposure gain (a log-normal random walk, ``exposure_sigma`` per frame),
  additive Gaussian noise ``rgb_sigma`` (8-bit units).
- pose: the *estimated* pose a real recording would give. A drift that grows with the
  distance travelled (random walk, ``drift_t`` m and ``drift_r`` degrees per metre) and
  independent per-frame jitter (``pose_sigma_t`` m, ``pose_sigma_r`` degrees).

Ground truth (labels, depth before noise) stays aligned with the *true* pose; see
:func:`semmatch.sim.simulate_sequence` for which pose goes to which file.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, fields

import numpy as np

__all__ = ["NoiseConfig", "noisy_depth", "noisy_rgb", "exposure_gains", "estimated_poses"]


@dataclass(frozen=True)
class NoiseConfig:
    """Parameters of the sensor noise; all zero (off) by default.

    Parameters
    ----------
    depth_a, depth_b : float
        Depth noise ``sigma = depth_a + depth_b * z**2`` (m, 1/m).
    depth_step : float
        Quantisation step of the depth (m); 0 = none.
    edge_dropout : float
        Probability of dropping a pixel next to a depth edge.
    edge_jump : float
        Relative depth jump that makes an edge.
    far_start, max_range : float
        Far-range dropout: probability 0 at ``far_start`` rising to 1 at ``max_range`` (m);
        ``max_range = 0`` disables it.
    rgb_sigma : float
        Additive Gaussian RGB noise (8-bit units).
    exposure_sigma : float
        Per-frame step of the log exposure gain random walk.
    pose_sigma_t, pose_sigma_r : float
        Per-frame pose jitter (m, degrees).
    drift_t, drift_r : float
        Pose drift per metre travelled (m, degrees), accumulated as a random walk.
    seed : int
        Seed of all noise draws.
    """

    depth_a: float = 0.0
    depth_b: float = 0.0
    depth_step: float = 0.0
    edge_dropout: float = 0.0
    edge_jump: float = 0.05
    far_start: float = 0.0
    max_range: float = 0.0
    rgb_sigma: float = 0.0
    exposure_sigma: float = 0.0
    pose_sigma_t: float = 0.0
    pose_sigma_r: float = 0.0
    drift_t: float = 0.0
    drift_r: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name != "seed" and (not np.isfinite(v) or v < 0):
                raise ValueError(f"NoiseConfig.{f.name} must be a finite number >= 0, got {v}")
        if not self.edge_dropout <= 1:
            raise ValueError(f"NoiseConfig.edge_dropout is a probability, got {self.edge_dropout}")
        if self.max_range and self.far_start >= self.max_range:
            raise ValueError(
                f"NoiseConfig.far_start ({self.far_start}) must be below max_range ({self.max_range})"
            )

    @property
    def enabled(self) -> bool:
        """True when any part is switched on."""
        return any(getattr(self, f.name) for f in fields(self) if f.name not in ("seed", "edge_jump"))

    @property
    def pose_noise(self) -> bool:
        """True when the estimated poses differ from the true ones."""
        return bool(self.pose_sigma_t or self.pose_sigma_r or self.drift_t or self.drift_r)

    def to_dict(self) -> dict:
        """Plain dictionary (for ``meta.json``)."""
        return asdict(self)

    @classmethod
    def from_dict(cls, d: dict | None) -> NoiseConfig:
        """Build from a dictionary; unknown keys are an error naming them."""
        d = dict(d or {})
        known = {f.name for f in fields(cls)}
        bad = sorted(set(d) - known)
        if bad:
            raise ValueError(f"unknown noise parameter(s) {', '.join(bad)}; valid: {', '.join(sorted(known))}")
        return cls(**d)

    @classmethod
    def kinect(cls, seed: int = 0) -> NoiseConfig:
        """A Kinect-like preset: depth noise, edge/far dropouts, RGB noise, exposure, pose drift."""
        return cls(
            depth_a=0.0012, depth_b=0.0019, depth_step=0.001, edge_dropout=0.5, edge_jump=0.05,
            far_start=3.5, max_range=5.0, rgb_sigma=3.0, exposure_sigma=0.03,
            pose_sigma_t=0.005, pose_sigma_r=0.2, drift_t=0.01, drift_r=0.3, seed=seed,
        )


def noisy_depth(depth: np.ndarray, cfg: NoiseConfig, rng: np.random.Generator) -> np.ndarray:
    """Apply depth noise and dropouts (0 = no measurement) to a float32 depth image."""
    d = np.asarray(depth, dtype=np.float32)
    valid = d > 0
    out = d.copy()
    if cfg.depth_a or cfg.depth_b:
        sigma = cfg.depth_a + cfg.depth_b * d * d
        out = out + rng.standard_normal(d.shape).astype(np.float32) * sigma.astype(np.float32)
    drop = np.zeros(d.shape, dtype=bool)
    if cfg.edge_dropout:
        pad = np.pad(d, 1, mode="edge")
        jump = np.zeros(d.shape, dtype=np.float32)
        for dy, dx in ((0, 1), (2, 1), (1, 0), (1, 2)):
            jump = np.maximum(jump, np.abs(pad[dy : dy + d.shape[0], dx : dx + d.shape[1]] - d))
        edge = jump > cfg.edge_jump * np.maximum(d, 1e-3)
        drop |= edge & (rng.random(d.shape) < cfg.edge_dropout)
    if cfg.max_range:
        p = np.clip((d - cfg.far_start) / (cfg.max_range - cfg.far_start), 0.0, 1.0)
        drop |= rng.random(d.shape) < p
    if cfg.depth_step:
        out = np.round(out / cfg.depth_step) * cfg.depth_step
    out = np.where(valid & ~drop & (out > 0), out, 0.0)
    return out.astype(np.float32)


def exposure_gains(n: int, cfg: NoiseConfig, rng: np.random.Generator) -> np.ndarray:
    """Per-frame exposure gains (a mean-reverting log-normal random walk), shape (n,)."""
    if not cfg.exposure_sigma:
        return np.ones(n)
    g = np.zeros(n)
    for i in range(1, n):
        g[i] = 0.95 * g[i - 1] + cfg.exposure_sigma * rng.standard_normal()
    return np.exp(g)


def noisy_rgb(rgb: np.ndarray, cfg: NoiseConfig, rng: np.random.Generator, gain: float = 1.0) -> np.ndarray:
    """Apply an exposure gain and additive Gaussian noise to a uint8 RGB image."""
    if gain == 1.0 and not cfg.rgb_sigma:
        return rgb
    x = rgb.astype(np.float32) * np.float32(gain)
    if cfg.rgb_sigma:
        x += rng.standard_normal(rgb.shape).astype(np.float32) * np.float32(cfg.rgb_sigma)
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


def _small_rotation(rotvec: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_rotvec(rotvec).as_matrix()


def estimated_poses(poses: np.ndarray, cfg: NoiseConfig, rng: np.random.Generator) -> np.ndarray:
    """The pose estimate of a real recording: true poses with drift and jitter.

    The drift is a world-frame transform ``D_k`` (random walk whose steps scale with the
    distance travelled since the previous frame, starting at identity); the estimate is
    ``D_k @ T_k @ J_k`` with per-frame jitter ``J_k``.

    Parameters
    ----------
    poses : ndarray (N,4,4)
        True ``T_world_camera``.
    cfg : NoiseConfig
    rng : numpy Generator

    Returns
    -------
    ndarray (N,4,4)
    """
    poses = np.asarray(poses, dtype=np.float64)
    if not cfg.pose_noise:
        return poses.copy()
    n = len(poses)
    out = np.empty_like(poses)
    D = np.eye(4)
    for k in range(n):
        if k:
            step = float(np.linalg.norm(poses[k, :3, 3] - poses[k - 1, :3, 3]))
            dD = np.eye(4)
            s = np.sqrt(max(step, 1e-9))
            dD[:3, :3] = _small_rotation(np.radians(cfg.drift_r) * s * rng.standard_normal(3) * [0.3, 0.3, 1.0])
            dD[:3, 3] = cfg.drift_t * s * rng.standard_normal(3)
            D = dD @ D
        J = np.eye(4)
        J[:3, :3] = _small_rotation(np.radians(cfg.pose_sigma_r) * rng.standard_normal(3))
        J[:3, 3] = cfg.pose_sigma_t * rng.standard_normal(3)
        out[k] = D @ poses[k] @ J
    return out
