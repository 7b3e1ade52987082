"""Materials of the procedural scenes: albedo and a procedural texture per material.

Materials, not categories, decide colour: a wood table and a wood chair share ``wood_*``, a
white wall and a white ceiling share ``paint_white``, and sofas, beds, curtains and pillows
draw from the same fabrics. Colour alone therefore does not give the label.

The texture is evaluated per pixel by the renderer (:func:`texture_factor`) as a brightness
modulation ``1 + amp * sin(freq * (p . dir) + warp * sin(3.1 * p . (1, 1.3, 0.7)))`` of the
world hit point ``p``: wood grain, plaster unevenness, fabric weave.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Material", "MATERIALS", "TEXTURES", "material_id", "texture_factor", "ROLE_CHOICES"]


@dataclass(frozen=True)
class Material:
    """A named albedo (RGB in [0, 1]) with a procedural texture kind (index into TEXTURES)."""

    name: str
    albedo: tuple[float, float, float]
    texture: int


#: texture kinds: (amplitude, frequency rad/m, direction, warp)
TEXTURES: dict[str, tuple[float, float, tuple[float, float, float], float]] = {
    "plain": (0.0, 0.0, (1.0, 0.0, 0.0), 0.0),
    "plaster": (0.035, 9.0, (0.6, 0.5, 0.62), 2.0),
    "wood": (0.12, 160.0, (0.2, 1.0, 0.15), 6.0),
    "fabric": (0.05, 120.0, (1.0, 0.9, 0.8), 3.0),
    "planks": (0.10, 40.0, (1.0, 0.05, 0.0), 3.0),
    "metal": (0.03, 60.0, (0.3, 0.3, 1.0), 1.0),
}
_TEX_NAMES = tuple(TEXTURES)
_TEX = np.array([[a, f, *d, w] for a, f, d, w in TEXTURES.values()], dtype=np.float32)
_TEX[:, 2:5] /= np.linalg.norm(_TEX[:, 2:5], axis=1, keepdims=True)


def _m(name: str, rgb: tuple[float, float, float], tex: str) -> Material:
    return Material(name, rgb, _TEX_NAMES.index(tex))


MATERIALS: dict[str, Material] = {
    m.name: m
    for m in (
        _m("paint_white", (0.86, 0.85, 0.82), "plaster"),
        _m("paint_beige", (0.80, 0.74, 0.64), "plaster"),
        _m("paint_greyblue", (0.60, 0.66, 0.72), "plaster"),
        _m("paint_sage", (0.62, 0.68, 0.58), "plaster"),
        _m("wood_light", (0.76, 0.60, 0.42), "wood"),
        _m("wood_mid", (0.58, 0.42, 0.28), "wood"),
        _m("wood_dark", (0.36, 0.24, 0.16), "wood"),
        _m("floor_oak", (0.70, 0.55, 0.38), "planks"),
        _m("floor_walnut", (0.46, 0.33, 0.22), "planks"),
        _m("carpet_grey", (0.46, 0.46, 0.47), "fabric"),
        _m("tile_light", (0.80, 0.79, 0.76), "plaster"),
        _m("fabric_grey", (0.50, 0.50, 0.53), "fabric"),
        _m("fabric_blue", (0.28, 0.36, 0.55), "fabric"),
        _m("fabric_beige", (0.76, 0.70, 0.60), "fabric"),
        _m("fabric_red", (0.60, 0.24, 0.22), "fabric"),
        _m("fabric_green", (0.34, 0.48, 0.36), "fabric"),
        _m("fabric_white", (0.88, 0.87, 0.85), "fabric"),
        _m("metal_black", (0.10, 0.10, 0.11), "metal"),
        _m("metal_silver", (0.66, 0.67, 0.70), "metal"),
        _m("plastic_white", (0.90, 0.90, 0.90), "plain"),
        _m("glass", (0.66, 0.78, 0.88), "plain"),
    )
}

#: material choices per role; roles overlap on purpose
ROLE_CHOICES: dict[str, tuple[str, ...]] = {
    "wall": ("paint_white", "paint_white", "paint_beige", "paint_greyblue", "paint_sage"),
    "ceiling": ("paint_white",),
    "floor": ("floor_oak", "floor_walnut", "carpet_grey", "tile_light", "wood_mid"),
    "wood": ("wood_light", "wood_mid", "wood_dark", "paint_white"),
    "fabric": ("fabric_grey", "fabric_blue", "fabric_beige", "fabric_red", "fabric_green", "carpet_grey"),
    "sheet": ("fabric_white", "fabric_beige", "fabric_grey", "paint_white"),
    "metal": ("metal_black", "metal_silver", "plastic_white"),
    "cabinet": ("wood_light", "wood_mid", "wood_dark", "paint_white", "plastic_white", "paint_beige"),
    "frame": ("paint_white", "metal_black", "wood_mid", "plastic_white"),
}


def material_id(name: str) -> int:
    """Texture kind index of material ``name``."""
    try:
        return MATERIALS[name].texture
    except KeyError:
        raise KeyError(f"unknown material {name!r}; valid: {', '.join(MATERIALS)}") from None


def texture_factor(points: np.ndarray, kinds: np.ndarray) -> np.ndarray:
    """Brightness modulation of the procedural textures at world points.

    Parameters
    ----------
    points : float32 (N,3)
        World hit points.
    kinds : uint8 (N,)
        Texture kind of each point (index into :data:`TEXTURES`).

    Returns
    -------
    float32 (N,)
        Factor around 1 to multiply the albedo with.
    """
    p = np.asarray(points, dtype=np.float32)
    k = np.minimum(np.asarray(kinds, dtype=np.intp), len(_TEX) - 1)
    par = _TEX[k]
    phase = par[:, 1] * np.einsum("ij,ij->i", p, par[:, 2:5])
    warp = par[:, 5] * np.sin(p @ np.array([3.1, 4.03, 2.17], dtype=np.float32))
    return 1.0 + par[:, 0] * np.sin(phase + warp)
