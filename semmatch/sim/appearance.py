"""A held-out appearance: materials, textures and lighting that no training view shows.

The networks learn from renderings whose colours come from :data:`semmatch.sim.materials.MATERIALS`
(their albedos, six texture kinds of amplitude <= 0.12) under ceiling point lights with ambient
0.3, augmented by colour jitter (+-25 % brightness, contrast and saturation, +-8 % per channel).
Real images differ from such renderings in ways the networks never saw. :func:`heldout_appearance`
gives a scene a look from families held out of all of that, so that a network meets an
appearance shift the way the paper's networks met real images (issue 36 item 5):

* **materials**: every material of the scene (each distinct albedo and texture) is replaced by
  one of :data:`HELDOUT_ALBEDOS` (terracotta, mustard, teal, ...: hues and saturations the
  training pool lacks), drawn per scene, so colour still does not give the category;
* **textures**: each new material gets one of :data:`HELDOUT_TEXTURES`, patterns the training
  textures lack (hard-edged tiles and stripes, strongly warped marble; amplitude 0.15-0.25);
* **lighting**: one light instead of the ceiling grid, lowered towards eye height, ambient 0.15
  instead of 0.3, and a coloured illuminant (tungsten, green-tinged fluorescent or overcast
  daylight) that tints every surface.

Geometry and labels are untouched, so the depth and ground truth of a recording stay valid; only
its RGB changes (:class:`HeldOutRenderer`). A ``severity`` below 1 blends the training look and the
held-out one (albedos, textures, illuminant tint and irradiance), so that the size of the shift can
be set on validation scenes, e.g. to the paper's synthetic-to-real drop. The families were fixed
before any network was scored on them; docs/protocol.md ("An appearance gap") describes them.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..io.geometry import DEFAULT_INTRINSICS, Intrinsics
from .materials import texture_factor
from .render import Renderer
from .scene import Scene

__all__ = ["HELDOUT_ALBEDOS", "HELDOUT_TEXTURES", "ILLUMINANTS", "Appearance", "heldout_appearance",
           "heldout_texture_factor", "HeldOutRenderer", "write_heldout_recording"]

#: albedos of the held-out materials (RGB in [0, 1]); none is in the training pool
HELDOUT_ALBEDOS: dict[str, tuple[float, float, float]] = {
    "terracotta": (0.70, 0.33, 0.20), "mustard": (0.78, 0.62, 0.18), "teal": (0.10, 0.44, 0.46),
    "lilac": (0.60, 0.50, 0.72), "navy": (0.12, 0.15, 0.34), "olive": (0.40, 0.42, 0.16),
    "blush": (0.86, 0.62, 0.62), "charcoal": (0.16, 0.16, 0.18), "mint": (0.62, 0.84, 0.72),
    "burgundy": (0.42, 0.10, 0.16), "sand": (0.84, 0.76, 0.56), "cobalt": (0.18, 0.30, 0.70),
}

#: held-out texture kinds: (pattern, amplitude, period in m, direction, warp); ``sine`` is a
#: smooth modulation, ``square`` a hard-edged one along ``direction``, ``checker`` hard-edged tiles
#: in two directions (``direction`` and the one across it)
HELDOUT_TEXTURES: dict[str, tuple[str, float, float, tuple[float, float, float], float]] = {
    "matte": ("sine", 0.0, 1.0, (1.0, 0.0, 0.0), 0.0),
    "tiles": ("checker", 0.15, 0.30, (1.0, 0.0, 0.0), 0.0),
    "stripes": ("square", 0.20, 0.12, (0.7, 0.7, 0.0), 0.0),
    "marble": ("sine", 0.25, 0.40, (0.5, 0.3, 0.8), 9.0),
}

#: coloured illuminants (RGB gains, normalised to mean 1 when applied)
ILLUMINANTS: dict[str, tuple[float, float, float]] = {
    "tungsten": (1.00, 0.78, 0.52), "fluorescent": (0.86, 1.00, 0.88), "overcast": (0.82, 0.90, 1.12),
}

#: the held-out lighting's ambient term (training: 0.3) and how far its one light is lowered (m)
HELDOUT_AMBIENT = 0.15
LIGHT_DROP = 0.8


@dataclass(frozen=True)
class Appearance:
    """A scene with a held-out look, and how to light it.

    Attributes
    ----------
    scene : Scene
        Same geometry, labels and instances; new albedos (tinted by the illuminant); no training
        texture kinds.
    texture : int array (T,)
        Held-out texture kind of each triangle (index into :data:`HELDOUT_TEXTURES`).
    lights : float array (L, 3)
        Point-light positions.
    ambient : float
    illuminant : str
        Key of :data:`ILLUMINANTS`.
    severity : float
        How far the look goes from the training look to the held-out one, in (0, 1]: albedos,
        textures, illuminant tint and irradiance are blended ``(1 - severity) * training +
        severity * held-out``. ``scene.texture`` keeps the training texture kinds for the blend.
    """

    scene: Scene
    texture: np.ndarray
    lights: np.ndarray
    ambient: float
    illuminant: str
    severity: float = 1.0


def heldout_appearance(scene: Scene, seed: int, severity: float = 1.0) -> Appearance:
    """Give ``scene`` a held-out look (module documentation), drawn with ``seed``.

    Parameters
    ----------
    scene : Scene
        A rendered scene (its ``meta["lights"]`` or the renderer's default lights are used).
    seed : int
        Same scene and seed, same look (the draws do not depend on ``severity``).
    severity : float
        In (0, 1]: 1 is the held-out look, smaller values blend it with the training look
        (:class:`Appearance`).

    Returns
    -------
    Appearance

    Raises
    ------
    ValueError
        ``severity`` outside (0, 1].
    """
    severity = float(severity)
    if not 0.0 < severity <= 1.0:
        raise ValueError(f"appearance severity must be in (0, 1], got {severity}")
    rng = np.random.default_rng([int(seed), 36005])
    tex_in = scene.texture if scene.texture is not None else np.zeros(len(scene.labels), np.uint8)
    keys = np.concatenate([np.round(scene.albedo, 4), tex_in[:, None].astype(np.float32)], axis=1)
    _, group = np.unique(keys, axis=0, return_inverse=True)
    group = group.reshape(-1)
    n = int(group.max()) + 1 if len(group) else 0
    names = list(HELDOUT_ALBEDOS)
    albedo_of = np.array([HELDOUT_ALBEDOS[names[i]] for i in rng.integers(0, len(names), n)], np.float32)
    albedo_of *= rng.uniform(0.9, 1.1, (n, 1)).astype(np.float32)
    kinds = rng.integers(0, len(HELDOUT_TEXTURES), n)
    illuminant = list(ILLUMINANTS)[int(rng.integers(0, len(ILLUMINANTS)))]
    tint = np.asarray(ILLUMINANTS[illuminant], np.float32)
    tint /= tint.mean()
    if severity == 1.0:
        albedo = np.clip(albedo_of[group] * tint, 0.0, 1.0)
    else:
        mixed = (1.0 - severity) * scene.albedo + severity * albedo_of[group]
        albedo = np.clip(mixed * (1.0 + severity * (tint - 1.0)), 0.0, 1.0).astype(np.float32)
    lights = scene.meta.get("lights")
    if lights is None or len(lights) == 0:
        lo, hi = scene.bounds
        lights = [[(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, hi[2] - 0.3]]
    lights = np.asarray(lights, np.float32).reshape(-1, 3)
    light = lights[int(rng.integers(0, len(lights)))].copy()
    light[2] -= LIGHT_DROP
    return Appearance(replace(scene, albedo=albedo, texture=None if severity == 1.0 else scene.texture),
                      kinds[group].astype(np.uint8), light[None, :], HELDOUT_AMBIENT, illuminant, severity)


_TABLE = np.array([[("sine", "square", "checker").index(p), a, 2 * np.pi / per, *d, w]
                   for p, a, per, d, w in HELDOUT_TEXTURES.values()], np.float32)
_TABLE[:, 3:6] /= np.linalg.norm(_TABLE[:, 3:6], axis=1, keepdims=True)


def heldout_texture_factor(points: np.ndarray, kinds: np.ndarray) -> np.ndarray:
    """Brightness modulation of the held-out textures at world points (around 1).

    Parameters
    ----------
    points : float (N, 3)
        World points.
    kinds : int (N,)
        Held-out texture kind of each point (index into :data:`HELDOUT_TEXTURES`).

    Returns
    -------
    float32 (N,)
    """
    p = np.asarray(points, np.float32)
    par = _TABLE[np.clip(np.asarray(kinds, np.intp), 0, len(_TABLE) - 1)]
    d = par[:, 3:6]
    warp = par[:, 6] * np.sin(p @ np.array([1.7, 2.3, 1.1], np.float32))
    wave = np.sin(par[:, 2] * np.einsum("ij,ij->i", p, d) + warp)
    across = np.cross(d, np.array([0.0, 0.0, 1.0], np.float32))  # the tiles' second direction
    across = np.where(np.linalg.norm(across, axis=1, keepdims=True) > 1e-6, across, [0.0, 1.0, 0.0])
    wave2 = np.sin(par[:, 2] * (np.einsum("ij,ij->i", p, across) + p[:, 2]))
    pattern = np.where(par[:, 0] == 0, wave, np.where(par[:, 0] == 1, np.sign(wave), np.sign(wave * wave2)))
    return (1.0 + par[:, 1] * pattern).astype(np.float32)


class HeldOutRenderer(Renderer):
    """:class:`semmatch.sim.render.Renderer` of an :class:`Appearance`: its lights and ambient,
    and the held-out textures in place of the training ones (the shading is the parent's:
    albedo x interpolated irradiance x texture, through the same display curve). Below severity
    1 the irradiance of the training lighting (the scene's lights, ambient 0.3) and the training
    textures are blended in."""

    def __init__(self, appearance: Appearance, intrinsics: Intrinsics = DEFAULT_INTRINSICS, **kwargs) -> None:
        s = float(appearance.severity)
        super().__init__(appearance.scene, intrinsics, lights=appearance.lights, ambient=appearance.ambient,
                         texture=s < 1.0, **kwargs)
        self._heldout_texture = np.asarray(appearance.texture, np.uint8)
        self._severity = s
        if s < 1.0:
            training = Renderer(appearance.scene, intrinsics, texture=False, **kwargs)
            self._irradiance = s * self._irradiance + (1.0 - s) * training._irradiance

    def _shade(self, rays, t, prim, uv) -> np.ndarray:
        """RGB of hit points: the parent's shading times the held-out texture (misses: black)."""
        tri = np.maximum(prim, 0)
        corners = self._irradiance[tri + self._side[tri]]
        u, v = uv[:, 0], uv[:, 1]
        shade = corners[:, 0] + (corners[:, 1] - corners[:, 0]) * u + (corners[:, 2] - corners[:, 0]) * v
        p = rays[:, :3] + rays[:, 3:] * t[:, None]
        held = heldout_texture_factor(p, self._heldout_texture[tri])
        if self._severity < 1.0:
            train = texture_factor(p, self.scene.texture[tri]) if self.use_texture else np.ones_like(held)
            held = 1.0 + (1.0 - self._severity) * (train - 1.0) + self._severity * (held - 1.0)
        shade *= held
        col = self._albedo_ext[prim] * shade[:, None]
        np.minimum(col, 4095.0, out=col)
        return self._lut[col.astype(np.int16)]


def write_heldout_recording(noisy: str | Path, out: str | Path, *, severity: float = 1.0, progress: bool = False) -> Path:
    """A noisy recording again, its RGB rendered with the scene's held-out appearance.

    The scene is regenerated from the recording's ``meta.json`` (procedural ``kind`` and
    ``seed``); its look is :func:`heldout_appearance` with the scene's seed, so every recording of
    one scene shares it. Each frame is rendered at its true pose (``poses_gt.txt``) and passes
    through the recording's own RGB noise (its ``noise`` settings: exposure drift and pixel noise,
    a random stream of its own). Depth, labels, instances, poses and intrinsics are the noisy
    recording's, copied. Written to a temporary folder and renamed to ``out`` (the temporary
    folders of killed writers are removed first).

    Parameters
    ----------
    noisy : path
        A noisy recording of a procedural scene (the simulator's ``upper_noisy``/``lower_noisy``).
    out : path
        The new recording's folder; it must not exist.
    severity : float
        :func:`heldout_appearance`'s blend of the training and held-out looks, in (0, 1].
    progress : bool

    Returns
    -------
    Path
        ``out``.

    Raises
    ------
    ValueError
        ``meta.json`` without the scene's kind and seed or without noise settings; a scene that
        regenerates under another name; frames and true poses of different counts.
    FileExistsError
        ``out`` exists.
    """
    import json
    import os
    import shutil
    from dataclasses import fields

    from ..io import read_intrinsics, read_sequence, read_tum, write_image
    from ..io.outputs import sweep_stale, temp_dir
    from ..runtime.progress import tqdm
    from .noise import NoiseConfig, exposure_gains, noisy_rgb
    from .procedural import generate_scene

    noisy, out = Path(noisy), Path(out)
    if out.exists():
        raise FileExistsError(f"{out}: exists; remove it to write the held-out recording again")
    meta = json.loads((noisy / "meta.json").read_text())
    sm, noise = meta.get("scene_meta") or {}, meta.get("noise")
    if "kind" not in sm or "seed" not in sm:
        raise ValueError(f"{noisy / 'meta.json'}: no scene_meta kind and seed to regenerate the scene from")
    if not isinstance(noise, dict):
        raise ValueError(f"{noisy / 'meta.json'}: no 'noise' settings")
    scene = generate_scene(sm["kind"], int(sm["seed"]))
    if meta.get("scene") not in (None, scene.name):
        raise ValueError(f"{noisy}: recorded in scene {meta['scene']!r}, but {sm['kind']} seed {sm['seed']} "
                         f"regenerates {scene.name!r}")
    true = read_tum(noisy / "poses_gt.txt")[1]
    seq = read_sequence(noisy)
    if len(seq) != len(true):
        raise ValueError(f"{noisy}: {len(seq)} frames against {len(true)} true poses")
    cfg = NoiseConfig(**{k: v for k, v in noise.items() if k in {f.name for f in fields(NoiseConfig)}})
    rng = np.random.default_rng([int(cfg.seed), 36005])
    gains = exposure_gains(len(true), cfg, rng)
    appearance = heldout_appearance(scene, int(sm["seed"]), severity)
    renderer = HeldOutRenderer(appearance, read_intrinsics(noisy / "intrinsics.json"))
    names = sorted(p.name for p in (noisy / "rgb").iterdir())
    if len(names) != len(true):
        raise ValueError(f"{noisy / 'rgb'}: {len(names)} images against {len(true)} true poses")
    sweep_stale(out)  # a killed writer's temporary folder
    tmp = temp_dir(out)
    try:
        shutil.copytree(noisy, tmp, dirs_exist_ok=True)
        for i, name in enumerate(tqdm(names, desc=f"held-out look {noisy.name}", disable=not progress)):
            rgb = renderer.render(true[i]).rgb
            write_image(tmp / "rgb" / name, noisy_rgb(rgb, cfg, rng, float(gains[i])))
        meta["appearance"] = {"family": "held-out (semmatch.sim.appearance)", "seed": int(sm["seed"]),
                              "illuminant": appearance.illuminant, "severity": appearance.severity,
                              "from": noisy.name}
        (tmp / "meta.json").write_text(json.dumps(meta, indent=2) + "\n")
        os.replace(tmp, out)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return out
