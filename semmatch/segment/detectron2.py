"""Optional detectron2 backend: instance predictions -> semantic label image via the category table.

detectron2 is not installable from the package registries here (it needs a source build; see
``environment.yml``), so it is imported lazily, only when a :class:`Detectron2Segmenter` is
made. The conversion itself (:func:`instances_to_semantic`) is plain NumPy and always available.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from ..io.labels import NAMES, NUM_CLASSES, VOID, id_of
from .oracle import one_hot

__all__ = ["ALIASES", "class_map", "instances_to_semantic", "Detectron2Segmenter"]

#: dataset class names (COCO, SUN RGB-D, ADE20K spellings) -> semmatch category name
ALIASES: dict[str, str] = {
    "couch": "sofa", "dining table": "table", "desk": "table", "tv": "monitor", "tvmonitor": "monitor",
    "laptop": "monitor", "painting": "picture", "poster": "picture", "fridge": "refrigerator",
    "microwave": "object", "potted plant": "object", "vase": "object", "book": "object", "bottle": "object",
    "cup": "object", "clock": "object", "lamp": "object", "bookshelf": "cabinet", "shelves": "cabinet",
    "dresser": "cabinet", "night stand": "cabinet", "nightstand": "cabinet", "counter": "cabinet",
    "blinds": "curtain", "trash can": "trashcan", "garbage bin": "trashcan", "bathtub": "bathtub",
    "bath": "bathtub", "toilet": "toilet", "sink": "sink", "oven": "oven", "bed": "bed", "chair": "chair",
    "armchair": "chair", "pillow": "pillow", "cushion": "pillow", "window": "window", "curtain": "curtain",
    "picture": "picture", "wall": "wall", "floor": "floor", "ceiling": "ceiling", "table": "table",
    "sofa": "sofa", "cabinet": "cabinet", "monitor": "monitor", "refrigerator": "refrigerator",
}


def class_map(class_names: Sequence[str], mapping: Mapping[str, str | int] | None = None) -> np.ndarray:
    """Category id of each detector class (0 = void for classes with no counterpart).

    Parameters
    ----------
    class_names : sequence of str
        The detector's class names, index = class id.
    mapping : mapping name -> category name or id, optional
        Overrides :data:`ALIASES` (and exact category names).

    Raises
    ------
    ValueError
        A mapping target that is not a category.
    """
    out = np.zeros(len(class_names), np.uint8)
    for i, name in enumerate(class_names):
        key = str(name).strip().lower()
        target = (mapping or {}).get(name, (mapping or {}).get(key))
        if target is None:
            target = ALIASES.get(key, key if key in NAMES else None)
        if target is None:
            continue
        if isinstance(target, int | np.integer):
            if not 0 <= int(target) < NUM_CLASSES:
                raise ValueError(f"mapping for {name!r}: category id {target} outside 0..{NUM_CLASSES - 1}")
            out[i] = int(target)
        else:
            out[i] = id_of(str(target))
    return out


def instances_to_semantic(
    masks: np.ndarray,
    classes: np.ndarray,
    scores: np.ndarray,
    cmap: np.ndarray,
    *,
    shape: tuple[int, int] | None = None,
    score_thresh: float = 0.5,
) -> np.ndarray:
    """Paint instance masks into a semantic label image; overlaps go to the higher score.

    Parameters
    ----------
    masks : bool (N,H,W)
    classes : int (N,)
        Detector class ids.
    scores : float (N,)
    cmap : uint8 (n_detector_classes,)
        Detector class -> category id (:func:`class_map`).
    shape : (H, W), optional
        Image size; needed when there are no instances.
    score_thresh : float
        Instances below it are dropped.

    Returns
    -------
    uint8 (H,W)
        Category ids, 0 (void) where no kept instance covers the pixel.
    """
    masks = np.asarray(masks, dtype=bool)
    classes = np.asarray(classes, dtype=np.int64).reshape(-1)
    scores = np.asarray(scores, dtype=np.float64).reshape(-1)
    if masks.ndim != 3 or not len(masks) == len(classes) == len(scores):
        raise ValueError(f"instances: masks {masks.shape}, {len(classes)} classes, {len(scores)} scores do not agree")
    if shape is None:
        if not len(masks):
            raise ValueError("instances_to_semantic: no instances and no shape given")
        shape = masks.shape[1:]
    if len(masks) and tuple(masks.shape[1:]) != tuple(shape):
        raise ValueError(f"instance masks are {masks.shape[1:]}, the image {tuple(shape)}")
    if classes.size and (classes.min() < 0 or classes.max() >= len(cmap)):
        raise ValueError(f"instance class id outside 0..{len(cmap) - 1}")
    out = np.full(shape, VOID, np.uint8)
    for i in np.argsort(scores, kind="stable"):  # ascending: the best instance is painted last
        if scores[i] >= score_thresh and cmap[classes[i]] != VOID:
            out[masks[i]] = cmap[classes[i]]
    return out


class Detectron2Segmenter:
    """A detectron2 instance-segmentation model behind the segmenter interface.

    Parameters
    ----------
    predictor : callable, optional
        A ready ``detectron2.engine.DefaultPredictor`` (or anything returning
        ``{"instances": Instances}`` for a BGR image).
    config_file, weights : str, optional
        Build a ``DefaultPredictor`` from a detectron2 config and a weights file instead.
    class_names : sequence of str
        The model's class names (index = class id), mapped through :func:`class_map`.
    mapping : mapping, optional
        Extra class-name -> category mapping.
    score_thresh : float
    device : str
        ``"cpu"`` or ``"cuda"`` (when building from a config).

    Raises
    ------
    ImportError
        detectron2 is not installed (it needs a source build; see ``environment.yml``).
    """

    def __init__(self, predictor=None, *, config_file: str | None = None, weights: str | None = None,
                 class_names: Sequence[str] = (), mapping: Mapping[str, str | int] | None = None,
                 score_thresh: float = 0.5, device: str = "cpu") -> None:
        if not class_names:
            raise ValueError("Detectron2Segmenter: give the model's class_names")
        if predictor is None:
            try:
                from detectron2.config import get_cfg
                from detectron2.engine import DefaultPredictor
            except ImportError as e:
                raise ImportError(
                    "detectron2 is not installed; it needs a source build (see environment.yml)"
                ) from e
            if config_file is None or weights is None:
                raise ValueError("Detectron2Segmenter: give a predictor, or config_file and weights")
            cfg = get_cfg()
            cfg.merge_from_file(config_file)
            cfg.MODEL.WEIGHTS = weights
            cfg.MODEL.DEVICE = device
            predictor = DefaultPredictor(cfg)
        self.predictor = predictor
        self.cmap = class_map(class_names, mapping)
        self.score_thresh = float(score_thresh)
        self.name = "detectron2"
        self._bgr = str(getattr(predictor, "input_format", "BGR")).upper() != "RGB"

    def predict_labels(self, rgb: np.ndarray, depth: np.ndarray | None = None) -> np.ndarray:
        """Semantic label image ``(H,W)`` uint8 of one RGB image (depth is ignored)."""
        from .predict import check_rgb

        check_rgb(rgb)
        if np.asarray(rgb).dtype != np.uint8:
            rgb = np.clip(np.rint(np.asarray(rgb) * 255), 0, 255).astype(np.uint8)
        img = np.ascontiguousarray(rgb[..., ::-1] if self._bgr else rgb)
        inst = self.predictor(img)["instances"].to("cpu")
        return instances_to_semantic(
            inst.pred_masks.numpy(), inst.pred_classes.numpy(), inst.scores.numpy(), self.cmap,
            shape=rgb.shape[:2], score_thresh=self.score_thresh,
        )

    def predict(self, rgb: np.ndarray, depth: np.ndarray | None = None) -> np.ndarray:
        """One-hot ``(H,W,21)`` float32 probabilities of :meth:`predict_labels`."""
        return one_hot(self.predict_labels(rgb))

    def predict_frame(self, frame) -> np.ndarray:
        """Probabilities of a :class:`semmatch.io.Frame`."""
        return self.predict(frame.rgb)
