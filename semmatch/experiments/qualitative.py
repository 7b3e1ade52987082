"""Fig. 4: renders of the lower-view semantic maps per method beside the reference (08)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..io import SemanticMap, read_map
from ..io.geometry import Intrinsics, look_at
from ..io.labels import PALETTE
from .layout import GT, Layout

__all__ = ["overview_pose", "render_map", "qualitative_figure", "transferred_frames_figure"]


def overview_pose(m: SemanticMap, *, elevation_deg: float = 55.0, azimuth_deg: float = -60.0) -> np.ndarray:
    """A camera above and outside the map looking down at its centre (``T_world_camera``)."""
    lo, hi = m.points.min(axis=0), m.points.max(axis=0)
    centre = (lo + hi) / 2
    centre[2] = lo[2]
    radius = float(np.linalg.norm(hi[:2] - lo[:2])) * 0.85 + 1.0
    el, az = np.radians(elevation_deg), np.radians(azimuth_deg)
    eye = centre + radius * np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    return look_at(eye, centre)


def render_map(
    m: SemanticMap,
    pose: np.ndarray,
    intrinsics: Intrinsics,
    *,
    cut_ceiling: float = 0.5,
    background: int = 255,
    colors: np.ndarray | None = None,
) -> np.ndarray:
    """Shaded label-colour render of a semantic mesh, with the ceiling cut away.

    Triangles whose vertices all lie within ``cut_ceiling`` metres of the map's top are
    dropped so that the room can be seen from above. ``colors`` (uint8 (N,3), one per vertex,
    e.g. :func:`semmatch.io.labels.instance_colors`) replaces the label colours; a triangle
    takes its first vertex's colour.
    """
    from ..sim import Renderer, Scene
    from ..sim.plyscene import triangle_labels

    if not m.is_mesh:
        raise ValueError(f"{m.source}: rendering needs a mesh (faces)")
    top = float(m.points[:, 2].max())
    keep = (m.points[m.faces][:, :, 2] < top - cut_ceiling).any(axis=1)
    faces = m.faces[keep]
    if len(faces) == 0:
        raise ValueError(f"{m.source}: nothing left below the ceiling cut")
    labels = triangle_labels(faces, m.labels)
    albedo = PALETTE[labels] if colors is None else np.asarray(colors, dtype=np.uint8)[faces[:, 0]]
    scene = Scene(m.points, faces, labels, np.zeros(len(faces)), albedo / 255.0, name="map")
    r = Renderer(scene, intrinsics, ambient=0.55, shadows=False, texture=False).render(pose)
    rgb = r.rgb.copy()
    rgb[r.depth <= 0] = background
    return rgb


def qualitative_figure(
    data_root: str | Path,
    methods: Sequence[str],
    path: str | Path,
    *,
    scene: int = 0,
    sources: Sequence[str] = (GT,),
    size: tuple[int, int] = (480, 360),
) -> Path:
    """Render the reference and each method's lower map of one scene into a PNG grid.

    One row per upper-map source (default: ground truth, as the paper's Fig. 4), one column per
    method, the reference (lower frames fused with ground-truth labels) first.
    """
    from ..plots import image_grid

    layout = Layout(data_root)
    sid = layout.scene_dir(scene).name
    ref = read_map(layout.lower_reference(sid))
    pose = overview_pose(ref)
    w, h = size
    intr = Intrinsics(w, h, 0.9 * w, 0.9 * w, w / 2, h / 2)
    cols = ["reference", *methods]
    images, seen = [], set()
    for source in sources:
        row = []
        for name in cols:
            m = ref if name == "reference" else read_map(layout.lower_map(sid, source, name))
            seen |= set(np.unique(m.labels).tolist())
            row.append(render_map(m, pose, intr))
        images.append(row)
    return image_grid(images, path, col_titles=cols,
                      row_titles=["GT upper map" if s == GT else f"{s} upper map" for s in sources],
                      legend=seen - {0}, suptitle=f"Lower-view semantic maps of {sid}")


def transferred_frames_figure(
    data_root: str | Path,
    methods: Sequence[str],
    path: str | Path,
    *,
    scene: int = 0,
    frames: int = 3,
    source: str = GT,
) -> Path:
    """A few robot frames of one scene: RGB | ground truth | each method's transferred labels.

    Labels are shown in the palette colours (void black); the frames are spread evenly over the
    robot's sequence; ``source`` names the upper map the transfers used (04's label folders).
    """
    from ..io import read_label_image, read_sequence
    from ..plots import image_grid

    layout = Layout(data_root)
    sd = layout.scene_dir(scene)
    seq = read_sequence(layout.lower_sequence(sd))
    idx = np.linspace(0, len(seq) - 1, max(1, int(frames))).round().astype(int)
    images, seen = [], set()
    for i in idx:
        f = seq[int(i)]
        row = [f.rgb, PALETTE[f.labels]]
        seen |= set(np.unique(f.labels).tolist())
        for m in methods:
            lab = read_label_image(layout.lower_labels(sd.name, source, m) / f"{int(i):06d}.png")
            seen |= set(np.unique(lab).tolist())
            row.append(PALETTE[lab])
        images.append(row)
    src = "the ground-truth upper map" if source == GT else f"the {source} upper map"
    return image_grid(images, path, col_titles=["RGB", "ground truth", *methods],
                      row_titles=[f"frame {int(i)}" for i in idx], legend=seen, cell=(2.1, 1.7), fontsize=8,
                      suptitle=f"Robot frames of {sd.name}: labels transferred from {src} (black: no support)",
                      suptitle_fontsize=9)
