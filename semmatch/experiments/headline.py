"""Headline numbers of each pipeline stage as DVC metrics.

Each stage writes one flat JSON object (``figures/<profile>/metrics/<stage>.json``, a stage
output), keys ``<table>.<row>.<measure>`` (e.g. ``table2.compact.3d-neighborhood.mean_acc``),
taken from the stage's CSV tables after its notebook ran (:func:`write_stage_metrics`, called by
:func:`semmatch.experiments.pipeline.run_notebook`); stages without headline numbers write none.
The stages' files are then gathered into ``figures/<profile>/metrics.json``
(:func:`gather_metrics`), the one metrics file of dvc.yaml that ``dvc metrics show`` / ``diff``
and ``dvc exp show`` read.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import pandas as pd

from ..io import atomic_write_text

__all__ = ["STAGE_METRICS", "stage_metrics", "write_stage_metrics", "gather_metrics", "metrics_path"]


def _rows(csv: Path, keys: tuple[str, ...], values: tuple[str, ...], prefix: str,
          where: dict[str, tuple] | None = None) -> dict:
    """``prefix.<key values>.<value>`` of every row (only rows whose ``where`` columns hold one of
    the listed values)."""
    if not csv.is_file():
        return {}
    df = pd.read_csv(csv)
    for col, allowed in (where or {}).items():
        if col in df.columns:
            df = df[df[col].isin(allowed)]
    out = {}
    for _, r in df.iterrows():
        name = ".".join(str(r[k]).replace(" ", "_") for k in keys if k in df.columns)
        for v in values:
            if v in df.columns and pd.notna(r[v]):
                out[f"{prefix}.{name}.{v}" if name else f"{prefix}.{v}"] = round(float(r[v]), 4)
    return out


def _train(d: Path) -> dict:
    return _rows(d / "segmentation_validation.csv", ("network",), ("val_miou",), "validation")


def _upper(d: Path) -> dict:
    return _rows(d / "upper_maps.csv", ("model",), ("mean_acc",), "upper_maps")


def _transfer(d: Path) -> dict:
    out = _rows(d / "table1_speed.csv", ("method",), ("fps",), "table1")
    sup = d / "support_per_scene.csv"
    if sup.is_file():
        df = pd.read_csv(sup)
        own = df[df["route"] == "own"] if "route" in df.columns else df
        out["support.own.mean"] = round(float(own["support"].mean()), 4)
    return out


def _synthetic(d: Path) -> dict:
    return _rows(d / "table2_synthetic.csv", ("model", "method"), ("mean_acc",), "table2", _HEADLINE_ROWS)


def _height(d: Path) -> dict:
    csv = d / "fig3_height.csv"
    if not csv.is_file():
        return {}
    df = pd.read_csv(csv)
    out = {}
    for _, r in df[df["height"].round(2).isin((0.2, 1.6))].iterrows():
        out[f"fig3.{r['model']}.h{r['height']:.1f}.miou"] = round(float(r["miou"]), 4)
    return out


def _real(d: Path) -> dict:
    out = _rows(d / "table3_real.csv", ("model", "method"), ("mean_acc",), "table3", _HEADLINE_ROWS)
    reg = d / "registration_error.csv"
    if reg.is_file():
        df = pd.read_csv(reg)
        out["registration.trans_err_m.mean"] = round(float(df["reg_trans_err_m"].mean()), 4)
    return out


def _adapt(d: Path) -> dict:
    return _rows(d / "adapt_gap.csv", ("source",), ("miou@0.2", "miou@1.6", "gap_closed"), "adapt")


def _panoptic(d: Path) -> dict:
    return _rows(d / "table_panoptic.csv", ("source", "method"), ("pq_things",), "panoptic",
                 {"method": ("3d-neighborhood",)})


#: the rows of Tables 2/3 shown as metrics: the paper's best method, the lower-view network, fused
_HEADLINE_ROWS = {"method": ("3d-neighborhood", "lower", "fused")}


#: headline numbers per notebook section (``pipeline.section_of``)
STAGE_METRICS: dict[str, Callable[[Path], dict]] = {
    "train_segmentation": _train,
    "reconstruct_upper": _upper,
    "label_transfer": _transfer,
    "evaluate_synthetic": _synthetic,
    "height_study": _height,
    "real_data": _real,
    "adapt_robot_view": _adapt,
    "panoptic": _panoptic,
}


def metrics_path(figures_dir: str | Path, section: str) -> Path:
    """Where the metrics of a stage go: ``<figures_dir>/metrics/<section>.json``."""
    return Path(figures_dir) / "metrics" / f"{section}.json"


def stage_metrics(figures_dir: str | Path, section: str) -> dict:
    """The headline numbers of one stage from its tables in ``figures_dir`` (empty if none)."""
    fn = STAGE_METRICS.get(section)
    return fn(Path(figures_dir)) if fn else {}


def write_stage_metrics(figures_dir: str | Path, section: str) -> Path | None:
    """Write a stage's headline numbers as JSON (atomically); None for stages without any."""
    if section not in STAGE_METRICS:
        return None
    path = metrics_path(figures_dir, section)
    path.parent.mkdir(parents=True, exist_ok=True)
    atomic_write_text(path, json.dumps(stage_metrics(figures_dir, section), indent=1, sort_keys=True) + "\n")
    gather_metrics(figures_dir)
    return path


def gather_metrics(figures_dir: str | Path) -> Path | None:
    """Write ``<figures_dir>/metrics.json``: every stage's headline numbers (the ``metrics/*.json``
    files present) in one flat object, the file ``dvc metrics show`` reads (one row, no column of
    another stage's dashes). None when no stage has written any.

    Raises
    ------
    ValueError
        If two stages' files hold the same key with different values.
    """
    out: dict = {}
    for f in sorted((Path(figures_dir) / "metrics").glob("*.json")):
        for k, v in json.loads(f.read_text()).items():
            if out.setdefault(k, v) != v:
                raise ValueError(f"{f}: headline number {k} = {v} differs from another stage's {out[k]}")
    if not out:
        return None
    path = Path(figures_dir) / "metrics.json"
    atomic_write_text(path, json.dumps(out, indent=1, sort_keys=True) + "\n")
    return path
