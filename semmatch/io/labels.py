"""The category table: ids, names, palette colours and the evaluation classes.

The table is the one of ``shared/palette/categories20.csv`` (void + 20 categories), embedded
here so that semmatch runs without the shared folder. Colours are unique: the authors'
palette gave ``sink`` and ``oven`` one colour; ``oven`` is moved by one unit of blue, and
the authors' shared colour reads as ``sink``.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

__all__ = [
    "Category",
    "CATEGORIES",
    "NAMES",
    "PALETTE",
    "NUM_CLASSES",
    "VOID",
    "EVAL_CLASSES",
    "STUFF_CLASSES",
    "THING_CLASSES",
    "id_of",
    "name_of",
    "labels_to_colors",
    "instance_colors",
    "colors_to_labels",
    "table_fingerprint",
]


@dataclass(frozen=True)
class Category:
    """One row of the category table."""

    id: int
    name: str
    color: tuple[int, int, int]


_TABLE = [
    (0, "void", (0, 0, 0)),
    (1, "wall", (119, 119, 119)),
    (2, "floor", (244, 243, 131)),
    (3, "ceiling", (255, 190, 190)),
    (4, "chair", (54, 114, 113)),
    (5, "table", (255, 150, 255)),
    (6, "window", (0, 163, 33)),
    (7, "curtain", (150, 255, 0)),
    (8, "picture", (255, 180, 10)),
    (9, "bed", (150, 255, 255)),
    (10, "sofa", (0, 0, 176)),
    (11, "pillow", (24, 209, 255)),
    (12, "monitor", (152, 163, 55)),
    (13, "sink", (70, 72, 115)),
    (14, "trashcan", (87, 64, 34)),
    (15, "toilet", (193, 195, 234)),
    (16, "refrigerator", (192, 79, 212)),
    (17, "oven", (70, 72, 116)),
    (18, "bathtub", (52, 57, 131)),
    (19, "cabinet", (137, 28, 157)),
    (20, "object", (255, 69, 0)),
]

CATEGORIES: tuple[Category, ...] = tuple(Category(i, n, c) for i, n, c in _TABLE)
NAMES: tuple[str, ...] = tuple(c.name for c in CATEGORIES)
PALETTE: np.ndarray = np.array([c.color for c in CATEGORIES], dtype=np.uint8)
PALETTE.setflags(write=False)
NUM_CLASSES: int = len(CATEGORIES)
VOID: int = 0
EVAL_CLASSES: tuple[int, ...] = tuple(range(1, 11))
#: amorphous classes without instances (panoptic "stuff"): wall, floor, ceiling
STUFF_CLASSES: tuple[int, ...] = (1, 2, 3)
#: countable classes (panoptic "things"): every other category
THING_CLASSES: tuple[int, ...] = tuple(range(4, NUM_CLASSES))

_NAME_TO_ID = {c.name: c.id for c in CATEGORIES}
_COLOR_KEYS = (
    PALETTE[:, 0].astype(np.int64) << 16 | PALETTE[:, 1].astype(np.int64) << 8 | PALETTE[:, 2]
)
_KEY_ORDER = np.argsort(_COLOR_KEYS)
_SORTED_KEYS = _COLOR_KEYS[_KEY_ORDER]


def id_of(name: str) -> int:
    """Return the category id of ``name``.

    Raises
    ------
    KeyError
        If ``name`` is not a category; the message lists the valid names.
    """
    try:
        return _NAME_TO_ID[name]
    except KeyError:
        raise KeyError(f"unknown category {name!r}; valid: {', '.join(NAMES)}") from None


def name_of(label: int) -> str:
    """Return the name of category id ``label``."""
    if not 0 <= int(label) < NUM_CLASSES:
        raise ValueError(f"category id {label} outside 0..{NUM_CLASSES - 1}")
    return NAMES[int(label)]


def labels_to_colors(labels: np.ndarray) -> np.ndarray:
    """Map category ids to palette colours.

    Parameters
    ----------
    labels : ndarray of int, any shape
        Category ids in ``0..NUM_CLASSES-1``.

    Returns
    -------
    ndarray of uint8, shape ``labels.shape + (3,)``
    """
    labels = np.asarray(labels)
    if labels.size and (labels.min() < 0 or labels.max() >= NUM_CLASSES):
        raise ValueError(f"category ids must lie in 0..{NUM_CLASSES - 1}")
    return PALETTE[labels.astype(np.intp)]


def instance_colors(instances: np.ndarray, labels: np.ndarray | None = None) -> np.ndarray:
    """Distinct, repeatable colours per instance id (uint8 (N,3)); instance 0 grey, or the
    label's palette colour when ``labels`` is given (stuff shows in its class colour)."""
    inst = np.asarray(instances).reshape(-1).astype(np.int64)
    rng = np.random.default_rng(12345)
    n = int(inst.max(initial=0)) + 1
    table = rng.integers(40, 256, size=(n, 3)).astype(np.uint8)
    out = table[inst]
    none = inst == 0
    if labels is None:
        out[none] = 128
    else:
        out[none] = PALETTE[np.asarray(labels).reshape(-1)[none]]
    return out


def colors_to_labels(
    colors: np.ndarray, *, source: str | None = None, warn: bool = True
) -> tuple[np.ndarray, int]:
    """Map palette colours to category ids; colours outside the palette read as void.

    Parameters
    ----------
    colors : ndarray, shape (..., 3)
        RGB colours, uint8 or floats in [0, 1] (Open3D style).
    source : str, optional
        Name of the file the colours came from, used in the warning.
    warn : bool
        Emit a ``UserWarning`` counting the colours that are not in the palette.

    Returns
    -------
    labels : ndarray of uint8, shape ``colors.shape[:-1]``
    n_unknown : int
        How many entries had a colour outside the palette (read as void).
    """
    colors = np.asarray(colors)
    if colors.shape[-1] != 3:
        raise ValueError(f"colours must have shape (..., 3), got {colors.shape}")
    if np.issubdtype(colors.dtype, np.floating):
        colors = np.clip(np.rint(colors * 255.0), 0, 255)
    c = colors.astype(np.int64)
    keys = c[..., 0] << 16 | c[..., 1] << 8 | c[..., 2]
    pos = np.searchsorted(_SORTED_KEYS, keys)
    pos = np.clip(pos, 0, len(_SORTED_KEYS) - 1)
    hit = _SORTED_KEYS[pos] == keys
    labels = np.where(hit, _KEY_ORDER[pos], 0).astype(np.uint8)
    n_unknown = int((~hit).sum())
    if n_unknown and warn:
        where = f" in {source}" if source else ""
        warnings.warn(
            f"{n_unknown} of {keys.size} colours{where} are not in the category palette; "
            "they read as void (0)",
            UserWarning,
            stacklevel=2,
        )
    return labels, n_unknown


def table_fingerprint() -> list[list]:
    """Return the category table as plain lists (stored in checkpoints to detect mismatches)."""
    return [[c.id, c.name, list(c.color)] for c in CATEGORIES]
