"""semmatch.plots: every figure function writes a readable image and refuses empty input."""

import numpy as np
import pandas as pd
import pytest

from semmatch.io import Frame
from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.io.labels import PALETTE, id_of
from semmatch.plots import (
    confusion_figure,
    floor_plans_figure,
    frame_figure,
    image_grid,
    plot_height_study,
    plot_support,
    plot_table,
    plot_training_curves,
)


def _png_size(path) -> tuple[int, int]:
    import cv2

    img = cv2.imread(str(path))
    assert img is not None, f"{path} is not a readable image"
    return img.shape[1], img.shape[0]


def _frame(label: int) -> Frame:
    lab = np.zeros((24, 32), np.uint8)
    lab[6:, :] = label
    depth = np.where(lab > 0, 2.0, 0.0).astype(np.float32)
    return Frame(rgb=PALETTE[lab], depth=depth, labels=lab, pose=np.eye(4), intrinsics=DEFAULT_INTRINSICS.scaled(32, 24))


def test_image_grid_draws_rows_of_any_length_with_a_legend(tmp_path):
    a = PALETTE[np.full((12, 16), id_of("floor"), np.uint8)]
    out = image_grid([[a, a, a], [a]], tmp_path / "grid.png", col_titles=["x", "y", "z"], row_titles=["r0", "r1"],
                     legend={id_of("floor"), id_of("wall")}, suptitle="grid")
    w, h = _png_size(out)
    assert w > h > 100
    with pytest.raises(ValueError, match="no images"):
        image_grid([], tmp_path / "empty.png")
    with pytest.raises(ValueError, match="column titles"):
        image_grid([[a]], tmp_path / "bad.png", col_titles=["a", "b"])
    assert not (tmp_path / "empty.png").exists() and not (tmp_path / "bad.png").exists()


def test_frame_figure_needs_labelled_frames(tmp_path):
    out = frame_figure([_frame(id_of("floor")), _frame(id_of("chair"))], tmp_path / "frames.png",
                       titles=["upper", "lower"])
    assert _png_size(out)[1] > 200
    with pytest.raises(ValueError, match="titles"):
        frame_figure([_frame(1)], tmp_path / "x.png", titles=["a", "b"])
    unlabelled = Frame(rgb=np.zeros((4, 4, 3), np.uint8), depth=np.ones((4, 4), np.float32), labels=None,
                       pose=np.eye(4), intrinsics=DEFAULT_INTRINSICS.scaled(4, 4))
    with pytest.raises(ValueError, match="no labels"):
        frame_figure([unlabelled], tmp_path / "x.png")


def test_floor_plans_and_charts(tmp_path):
    t = np.linspace(0, 2 * np.pi, 20)
    plans = [{"title": f"scene {k}", "obstacles": np.random.default_rng(k).uniform(-2, 2, (200, 2)),
              "paths": {"upper": np.c_[np.cos(t), np.sin(t)], "lower": 0.5 * np.c_[np.cos(t), np.sin(t)]}}
             for k in range(3)]
    assert _png_size(floor_plans_figure(plans, tmp_path / "plans.png", suptitle="tours"))[0] > 300
    with pytest.raises(ValueError, match="no plans"):
        floor_plans_figure([], tmp_path / "none.png")
    summary = pd.DataFrame({"model": ["a"] * 2 + ["b"] * 2, "height": [0.2, 1.6] * 2,
                            "mean_acc": [0.5, 0.8, 0.6, 0.7], "miou": [0.3, 0.6, 0.4, 0.5]})
    summary["mean_acc_lo"], summary["mean_acc_hi"] = summary["mean_acc"] - 0.05, summary["mean_acc"] + 0.05
    plot_height_study(summary, tmp_path / "fig3.png")
    table = pd.DataFrame({"model": ["net"] * 3, "method": ["upper", "lower", "3d-neighborhood"],
                          "mean_acc": [0.9, 0.6, 0.8]})
    plot_table(table, tmp_path / "t2.png", title="t", methods=["3d-neighborhood"])
    plot_support(pd.DataFrame({"scene": ["s1", "s1", "s2", "s2"], "route": ["own", "shared"] * 2,
                               "support": [0.4, 0.9, 0.5, 0.8]}), tmp_path / "support.png")
    plot_training_curves({"n": [{"step": 10, "train_loss": 1.0, "val_miou": 0.2},
                                {"step": 20, "train_loss": 0.5, "val_miou": 0.4}]}, tmp_path / "curves.png")
    with pytest.raises(ValueError, match="no training history"):
        plot_training_curves({"n": []}, tmp_path / "none.png")
    conf = np.array([[5, 1], [0, 4]])
    confusion_figure({"pred": {"confusion": conf, "classes": [id_of("floor"), id_of("wall")], "mean_acc": 0.9}},
                     tmp_path / "conf.png")
    for name in ("fig3", "t2", "support", "curves", "conf"):
        assert _png_size(tmp_path / f"{name}.png")[0] > 200
