"""Fig. 4: renders of the lower-view semantic maps per method beside the reference (08)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import numpy as np

from ..geometry import Intrinsics, look_at
from ..io import SemanticMap, read_map, save_figure
from ..labels import NAMES, PALETTE
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
    e.g. :func:`semmatch.panoptic.instance_colors`) replaces the label colours; a triangle
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
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    layout = Layout(data_root)
    scenes = layout.scene_dirs("eval")
    if not 0 <= scene < len(scenes):
        raise ValueError(f"scene index {scene} out of range: {len(scenes)} evaluation scenes")
    sid = scenes[scene].name
    ref = read_map(layout.lower_reference(sid))
    pose = overview_pose(ref)
    w, h = size
    intr = Intrinsics(w, h, 0.9 * w, 0.9 * w, w / 2, h / 2)
    cols = ["reference", *methods]
    fig, axes = plt.subplots(len(sources), len(cols), figsize=(2.6 * len(cols), 2.2 * len(sources) + 0.6),
                             squeeze=False)
    seen: set[int] = set()
    for r, source in enumerate(sources):
        for c, name in enumerate(cols):
            m = ref if name == "reference" else read_map(layout.lower_map(sid, source, name))
            seen |= set(np.unique(m.labels).tolist())
            axes[r][c].imshow(render_map(m, pose, intr))
            axes[r][c].set_xticks([])
            axes[r][c].set_yticks([])
            if r == 0:
                axes[r][c].set_title(name, fontsize=9)
        axes[r][0].set_ylabel("GT upper map" if source == GT else f"{source} upper map", fontsize=9)
    handles = [Patch(color=PALETTE[i] / 255.0, label=NAMES[i]) for i in sorted(seen) if i > 0]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 8), fontsize=7, frameon=False)
    fig.suptitle(f"Lower-view semantic maps of {sid}")
    fig.tight_layout(rect=(0, 0.08, 1, 1))
    return save_figure(fig, path, dpi=110)


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
    import matplotlib.pyplot as plt
    from matplotlib.patches import Patch

    from ..io import read_label_image, read_sequence

    layout = Layout(data_root)
    scenes = layout.scene_dirs("eval")
    if not 0 <= scene < len(scenes):
        raise ValueError(f"scene index {scene} out of range: {len(scenes)} evaluation scenes")
    sd = scenes[scene]
    seq = read_sequence(layout.lower_sequence(sd))
    idx = np.linspace(0, len(seq) - 1, max(1, int(frames))).round().astype(int)
    cols = ["RGB", "ground truth", *methods]
    fig, axes = plt.subplots(len(idx), len(cols), figsize=(2.1 * len(cols), 1.7 * len(idx) + 0.6), squeeze=False)
    seen: set[int] = set()
    for r, i in enumerate(idx):
        f = seq[int(i)]
        images = [f.rgb, PALETTE[f.labels]]
        seen |= set(np.unique(f.labels).tolist())
        for m in methods:
            lab = read_label_image(layout.lower_labels(sd.name, source, m) / f"{int(i):06d}.png")
            seen |= set(np.unique(lab).tolist())
            images.append(PALETTE[lab])
        for c, img in enumerate(images):
            axes[r][c].imshow(img)
            axes[r][c].set_xticks([])
            axes[r][c].set_yticks([])
            if r == 0:
                axes[r][c].set_title(cols[c], fontsize=8)
        axes[r][0].set_ylabel(f"frame {int(i)}", fontsize=8)
    handles = [Patch(color=PALETTE[k] / 255.0, label=NAMES[k]) for k in sorted(seen)]
    fig.legend(handles=handles, loc="lower center", ncol=min(len(handles), 8), fontsize=7, frameon=False)
    src = "the ground-truth upper map" if source == GT else f"the {source} upper map"
    fig.suptitle(f"Robot frames of {sd.name}: labels transferred from {src} (black: no support)", fontsize=9)
    fig.tight_layout(rect=(0, 0.07, 1, 1))
    return save_figure(fig, path, dpi=110)
