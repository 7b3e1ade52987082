"""Files of the data contract: sequence folders, TUM poses, images, PLY semantic maps, safe writes.

Submodules, by what they handle: :mod:`~semmatch.io.files` (atomic writes, output folders that
never replace what semmatch did not write), :mod:`~semmatch.io.images` (RGB, depth and palette
label PNGs, the depth-unit check), :mod:`~semmatch.io.sequences` (intrinsics, TUM poses,
frames, sequence readers and the writer, label folders), :mod:`~semmatch.io.contract` (the
frame contract: the checks of a frame's RGB, depth, labels and intrinsics that segmentation,
transfer and fusion share), :mod:`~semmatch.io.maps` (semantic maps as PLY),
:mod:`~semmatch.io.outputs` (the output policy of every command). Every public name of these
is importable from ``semmatch.io`` itself. Imported from their modules instead: the vocabulary
every file and every package shares, :mod:`~semmatch.io.labels` (the category table and its
palette) and :mod:`~semmatch.io.geometry` (camera intrinsics, pose conventions, projection,
voxel keys, mesh sampling), and the recording readers: :mod:`~semmatch.io.readers` (the reader
registry, one module per recording layout, ``open_recording``) and
:mod:`~semmatch.io.reading_checks` (the checks every reader shares).

Writers never leave a half-written file behind: files are written to a temporary name in the
same folder and renamed; a sequence is written into a hidden temporary folder and renamed to
its final name only when complete.
"""

from .contract import check_depth, check_intrinsics, check_labels, check_rgb
from .files import (
    OUTPUT_MARKER,
    atomic_path,
    atomic_write_text,
    check_output_dir,
    output_kind,
    replace_output_dir,
    save_figure,
    write_json,
)
from .images import (
    DEPTH_UNIT_RANGE,
    check_depth_units,
    depth_to_uint16,
    read_depth,
    read_image,
    read_label_image,
    read_rgb,
    write_depth,
    write_image,
    write_label_image,
)
from .maps import INSTANCE_MAX, SemanticMap, check_ply_header, read_map, require_instances, write_map
from .sequences import (
    Frame,
    InMemorySequence,
    SequenceReader,
    SequenceWriter,
    frame_index,
    is_sequence,
    listed_file,
    read_intrinsics,
    read_labels_folder,
    read_sequence,
    read_tum,
    write_intrinsics,
    write_labels_folder,
    write_tum,
)

__all__ = [
    "Frame",
    "SequenceReader",
    "InMemorySequence",
    "SequenceWriter",
    "SemanticMap",
    "INSTANCE_MAX",
    "atomic_path",
    "atomic_write_text",
    "save_figure",
    "write_json",
    "read_intrinsics",
    "write_intrinsics",
    "read_tum",
    "write_tum",
    "read_image",
    "read_rgb",
    "listed_file",
    "write_image",
    "read_label_image",
    "write_label_image",
    "read_depth",
    "write_depth",
    "depth_to_uint16",
    "check_depth_units",
    "DEPTH_UNIT_RANGE",
    "check_rgb",
    "check_depth",
    "check_labels",
    "check_intrinsics",
    "read_labels_folder",
    "write_labels_folder",
    "OUTPUT_MARKER",
    "output_kind",
    "check_output_dir",
    "replace_output_dir",
    "frame_index",
    "is_sequence",
    "read_sequence",
    "check_ply_header",
    "read_map",
    "require_instances",
    "write_map",
]
