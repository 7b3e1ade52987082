"""Fig. 3: segmentation accuracy against camera height on the height-sweep sequences (06)."""

from __future__ import annotations

import re
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from .layout import Layout
from .tables import save_table

__all__ = ["sweep_sequences", "height_study"]

_SWEEP = re.compile(r"^h(\d{3})$")


def sweep_sequences(data_root: str | Path) -> dict[float, list[Path]]:
    """Height-sweep sequences of the evaluation scenes: ``{height_m: [h020 folders ...]}``."""
    sweeps: dict[float, list[Path]] = {}
    for sd in Layout(data_root).scene_dirs("eval"):
        for d in sorted(sd.iterdir()):
            m = _SWEEP.match(d.name)
            if m and d.is_dir():
                sweeps.setdefault(int(m.group(1)) / 100.0, []).append(d)
    if not sweeps:
        raise FileNotFoundError(f"{data_root}: no height-sweep sequences (h020 ..); run 01_simulate with heights_sweep")
    return dict(sorted(sweeps.items()))


def height_study(
    data_root: str | Path, networks: Sequence[str], *, figures_dir: str | Path, progress: bool = True
) -> pd.DataFrame:
    """Score each network on every height-sweep sequence; write ``fig3_height.{png,csv,md}``.

    Returns
    -------
    DataFrame
        model, height, n_frames and the pixel and voxel-style measures over classes 1..10
        (see :func:`semmatch.segment.viewpoint.viewpoint_gap_sequences`), scenes pooled.
    """
    from ..segment.viewpoint import plot_viewpoint_gap, viewpoint_gap_sequences

    layout = Layout(data_root)
    models = {net: layout.load_network(net) for net in networks}
    df = viewpoint_gap_sequences(models, sweep_sequences(data_root), progress=progress)
    save_table(df, figures_dir, "fig3_height")
    import matplotlib.pyplot as plt

    fig = plot_viewpoint_gap(df, path=Path(figures_dir) / "fig3_height.png")
    plt.close(fig)
    return df
