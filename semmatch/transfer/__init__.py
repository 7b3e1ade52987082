"""Label transfer: the upper (human-view) semantic map -> lower (robot-view) frame labels.

The paper's five projection methods (§3.2) behind one call::

    from semmatch.transfer import transfer, transfer_frame, as_map_index, METHODS
    index = as_map_index(semantic_map)             # index the map once
    lab = transfer("3d-neighborhood", frame, index)   # (H,W) uint8, 0 = no support
    r = transfer_frame("2d-slic", frame, index)       # r.labels, r.coverage, r.seconds, r.purity

plus ``fused`` (transferred labels + a network's probabilities) and
:func:`transfer_sequence` (a whole sequence into a labels folder). :func:`register_method` adds
a method (the CLI, the benchmark and the notebooks pick it up). Instances travel the same way:
:mod:`~semmatch.transfer.panoptic` (instance layers of maps, panoptic transfer and fusion, PQ;
imported from there).
"""

from .fused import fuse_labels, fuse_with_probabilities, write_fused_labels
from .index import DEFAULT_MAX_DISTANCE, MapIndex, as_map_index, index_cache_dir, load_index
from .registry import (
    ALL_METHODS,
    METHODS,
    PAPER_FPS,
    TransferResult,
    available_methods,
    method_params,
    register_method,
    settings_for,
    transfer,
    transfer_frame,
)
from .sequence import transfer_sequence
from .superpixels import BACKENDS as SUPERPIXEL_BACKENDS
from .superpixels import superpixels
from .voting import paint, vote

__all__ = [
    "transfer",
    "transfer_frame",
    "transfer_sequence",
    "TransferResult",
    "METHODS",
    "ALL_METHODS",
    "PAPER_FPS",
    "register_method",
    "available_methods",
    "MapIndex",
    "load_index",
    "index_cache_dir",
    "as_map_index",
    "DEFAULT_MAX_DISTANCE",
    "method_params",
    "settings_for",
    "fuse_with_probabilities",
    "fuse_labels",
    "write_fused_labels",
    "superpixels",
    "SUPERPIXEL_BACKENDS",
    "vote",
    "paint",
]
