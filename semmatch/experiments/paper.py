"""The paper's published numbers, used as reference columns beside ours.

Source: Szeier et al., "3D Semantic Label Transfer and Matching in Human-Robot Collaboration"
(``shared/paper``), Tables 1-3 and §4.2. Method names are semmatch's API names.
"""

from __future__ import annotations

import pandas as pd

from ..evaluate.metrics import MEASURES
from ..transfer.registry import PAPER_FPS

__all__ = ["TABLE1_FPS", "TABLE2", "TABLE3", "FIG3_MEAN_ACC", "table2_frame", "table3_frame"]

#: Table 1: frames per second on an AMD EPYC 7401P server with 3 RTX 2080 Ti (registered with
#: the methods: :func:`semmatch.transfer.register_method`).
TABLE1_FPS: dict[str, float] = PAPER_FPS


# Table 2 (synthetic, Replica in Habitat). Keys: (upper-map model, row), row "upper" = the
# upper-view network reconstruction, "lower" = lower-view network baseline, else a method.
TABLE2: dict[tuple[str, str], tuple[float, float, float, float]] = {
    ("ground truth", "2d-slic"): (0.813, 0.868, 0.955, 0.879),
    ("ground truth", "3d-slic"): (0.892, 0.922, 0.975, 0.930),
    ("ground truth", "3d-projected-sp"): (0.894, 0.921, 0.969, 0.928),
    ("ground truth", "dbscan"): (0.859, 0.865, 0.953, 0.892),
    ("ground truth", "3d-neighborhood"): (0.917, 0.944, 0.985, 0.949),
    ("mask r-cnn", "upper"): (0.778, 0.754, 0.867, 0.800),
    ("mask r-cnn", "lower"): (0.737, 0.720, 0.841, 0.766),
    ("mask r-cnn", "2d-slic"): (0.728, 0.717, 0.852, 0.766),
    ("mask r-cnn", "3d-slic"): (0.781, 0.746, 0.861, 0.796),
    ("mask r-cnn", "3d-projected-sp"): (0.794, 0.752, 0.860, 0.802),
    ("mask r-cnn", "dbscan"): (0.793, 0.757, 0.871, 0.807),
    ("mask r-cnn", "3d-neighborhood"): (0.800, 0.757, 0.865, 0.808),
    ("transfiner", "upper"): (0.794, 0.758, 0.867, 0.806),
    ("transfiner", "lower"): (0.734, 0.708, 0.832, 0.758),
    ("transfiner", "2d-slic"): (0.718, 0.707, 0.851, 0.759),
    ("transfiner", "3d-slic"): (0.790, 0.746, 0.862, 0.799),
    ("transfiner", "3d-projected-sp"): (0.798, 0.749, 0.860, 0.802),
    ("transfiner", "dbscan"): (0.796, 0.753, 0.871, 0.807),
    ("transfiner", "3d-neighborhood"): (0.804, 0.754, 0.866, 0.808),
}

# Table 3 (real recordings, Azure Kinect): lower-view rows only.
TABLE3: dict[tuple[str, str], tuple[float, float, float, float]] = {
    ("mask r-cnn", "lower"): (0.379, 0.522, 0.868, 0.590),
    ("mask r-cnn", "2d-slic"): (0.460, 0.604, 0.898, 0.654),
    ("mask r-cnn", "3d-slic"): (0.513, 0.644, 0.892, 0.683),
    ("mask r-cnn", "3d-projected-sp"): (0.635, 0.727, 0.878, 0.747),
    ("mask r-cnn", "dbscan"): (0.547, 0.680, 0.919, 0.715),
    ("mask r-cnn", "3d-neighborhood"): (0.665, 0.749, 0.891, 0.768),
    ("transfiner", "lower"): (0.384, 0.527, 0.864, 0.592),
    ("transfiner", "2d-slic"): (0.509, 0.648, 0.912, 0.690),
    ("transfiner", "3d-slic"): (0.565, 0.682, 0.891, 0.713),
    ("transfiner", "3d-projected-sp"): (0.697, 0.767, 0.882, 0.782),
    ("transfiner", "dbscan"): (0.540, 0.677, 0.927, 0.715),
    ("transfiner", "3d-neighborhood"): (0.718, 0.777, 0.881, 0.792),
}

#: §4.2 / Fig. 3: segmentation mean accuracy at 0.2 m and at the best height 0.8 m.
FIG3_MEAN_ACC: dict[str, dict[float, float]] = {
    "mask r-cnn": {0.2: 0.737, 0.8: 0.770},
    "transfiner": {0.2: 0.767, 0.8: 0.802},
}

#: our networks stand in for the paper's: compact ~ Mask R-CNN, strong ~ Transfiner
PAPER_MODEL_OF = {"ground truth": "ground truth", "compact": "mask r-cnn", "strong": "transfiner"}


def _frame(table: dict) -> pd.DataFrame:
    rows = [dict(model=m, method=r, **dict(zip(MEASURES, v, strict=True))) for (m, r), v in table.items()]
    return pd.DataFrame(rows)


def table2_frame() -> pd.DataFrame:
    """Table 2 as a DataFrame (columns model, method, jaccard, sorensen, color_acc, mean_acc)."""
    return _frame(TABLE2)


def table3_frame() -> pd.DataFrame:
    """Table 3 as a DataFrame (same columns as :func:`table2_frame`)."""
    return _frame(TABLE3)
