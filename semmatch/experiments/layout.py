"""Where the pipeline's generated data lives under ``data/<profile>/``.

::

    scenes/<split>/<scene_id>/scene.ply, upper/, lower/, h020 .. h160/   (01_simulate)
    models/<network>.pt                                                  (02_train_segmentation)
    upper/<scene_id>/<source>.ply, upper/<scene_id>/labels_<network>/    (03_reconstruct_upper)
    lower_labels/<scene_id>/<source>/<method>/                           (04_label_transfer)
    lower_maps/<scene_id>/<source>/<method>.ply, lower_maps/<scene_id>/reference.ply  (05)
    real_like/<scene_id>/...                                             (07_real_data)

``source`` is the upper map a transfer used: ``ground truth`` (written ``gt``) or a network
name; for the network baseline the "method" is ``lower`` (the network applied to the lower
frames).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

__all__ = ["Layout", "GT", "source_dir", "model_name"]

#: the upper map built from ground-truth labels
GT = "gt"


def source_dir(source: str) -> str:
    """Folder name of an upper-map source (``ground truth`` -> ``gt``)."""
    return GT if source in (GT, "ground truth") else source


def model_name(source: str) -> str:
    """Table name of an upper-map source (``gt`` -> ``ground truth``)."""
    return "ground truth" if source in (GT, "ground truth") else source


@dataclass(frozen=True)
class Layout:
    """Paths of the generated data of one profile."""

    root: Path

    def __post_init__(self) -> None:
        object.__setattr__(self, "root", Path(self.root))

    @property
    def scenes(self) -> Path:
        return self.root / "scenes"

    def scene_dirs(self, split: str = "eval") -> list[Path]:
        """Scene folders of a split (sorted), each with ``scene.ply``."""
        d = self.scenes / split
        if not d.is_dir():
            raise FileNotFoundError(f"{d}: no {split} scenes; run 01_simulate first")
        return sorted(p for p in d.iterdir() if (p / "scene.ply").is_file())

    def model(self, network: str) -> Path:
        return self.root / "models" / f"{network}.pt"

    def load_network(self, network: str):
        """The trained network ``network`` (:func:`semmatch.segment.load_model`)."""
        from ..segment import load_model

        path = self.model(network)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no trained {network} network; run 02_train_segmentation first")
        return load_model(path)

    def upper_map(self, scene_id: str, source: str) -> Path:
        return self.root / "upper" / scene_id / f"{source_dir(source)}.ply"

    def upper_labels(self, scene_id: str, network: str) -> Path:
        return self.root / "upper" / scene_id / f"labels_{network}"

    def lower_labels(self, scene_id: str, source: str, method: str) -> Path:
        return self.root / "lower_labels" / scene_id / source_dir(source) / method

    def lower_map(self, scene_id: str, source: str, method: str) -> Path:
        return self.root / "lower_maps" / scene_id / source_dir(source) / f"{method}.ply"

    def lower_reference(self, scene_id: str) -> Path:
        """Lower-view reconstruction fused from ground-truth labels: the reference of Table 2."""
        return self.root / "lower_maps" / scene_id / "reference.ply"

    def upper_reference(self, scene_id: str) -> Path:
        """Upper-view reconstruction fused from ground-truth labels."""
        return self.upper_map(scene_id, GT)

    @property
    def real_like(self) -> Path:
        return self.root / "real_like"
