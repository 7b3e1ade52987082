"""Where the pipeline's generated data lives under ``data/<profile>/``.

::

    scenes/<split>/<scene_id>/scene.ply, upper/, lower/, h020 .. h160/   (01_simulate)
    models/<network>.pt                                                  (02_train_segmentation)
    upper/<scene_id>/<source>.ply, upper/<scene_id>/labels_<network>/    (03_reconstruct_upper)
    lower_labels/<scene_id>/<source>/<method>/                           (04_label_transfer)
    lower_labels/<scene_id>/shared_route/<source>/<method>/              (04, the route ablation)
    lower_maps/<scene_id>/<source>/<method>.ply, lower_maps/<scene_id>/reference.ply  (05)
    lower_maps/<scene_id>/mesh_reference.ply, upper_mesh_reference.ply   (05: the GT mesh, observed part)
    lower_maps/<scene_id>/shared_route/...                               (05, the route ablation)
    real_like/<scene_id>/...                                             (07_real_data)
    panoptic/<scene_id>/upper_<source>.ply, reference.ply, <source>/<method>.ply  (10_panoptic)

``source`` is the upper map a transfer used: ``ground truth`` (written ``gt``) or a network
name; for the network baseline the "method" is ``lower`` (the network applied to the lower
frames), and ``fused`` is the transferred labels where the map supports a pixel, the network's
elsewhere. ``route`` names the robot's sequence: ``own`` (``lower/``, its own tour: the main
protocol) or ``shared`` (``lower_shared/``, the person's route replayed: the ablation).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

__all__ = ["Layout", "GT", "ROUTES", "source_dir", "model_name"]

#: the upper map built from ground-truth labels
GT = "gt"

#: robot sequence folder of each route mode
ROUTES = {"own": "lower", "shared": "lower_shared"}


def _route_part(route: str) -> tuple[str, ...]:
    if route not in ROUTES:
        raise ValueError(f"route must be one of {', '.join(ROUTES)}, got {route!r}")
    return () if route == "own" else ("shared_route",)


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

    def scene_dir(self, index: int, split: str = "eval") -> Path:
        """The ``index``-th scene folder of a split (sorted as :meth:`scene_dirs`).

        Raises
        ------
        ValueError
            ``index`` outside the split's scenes (the message gives their number).
        """
        scenes = self.scene_dirs(split)
        if not 0 <= index < len(scenes):
            raise ValueError(f"scene index {index} out of range: {len(scenes)} {split} scenes")
        return scenes[index]

    def map_scenes(
        self,
        task: Callable[..., Any],
        *args: Any,
        scenes: Iterable[str | Path] | None = None,
        split: str = "eval",
        flatten: bool = True,
        jobs: int | None = 1,
        scheduler: str | None = None,
        desc: str = "scenes",
        progress: bool = True,
    ) -> list:
        """Run ``task(root, *args, scene_id)`` once per scene, as engine tasks: the per-scene fan-out.

        ``root`` is this layout's root, resolved, as text (a task may run in another process or
        on another machine, where it makes its own :class:`Layout`). The scenes run as tasks of
        :func:`semmatch.runtime.engine.map_tasks` (``jobs`` local worker processes, or the cluster at
        ``scheduler``); the results come back in the scenes' order.

        Parameters
        ----------
        task : callable
            A module-level function (it is pickled to the workers), called as
            ``task(root, *args, scene_id)``.
        *args
            The task's arguments between the root and the scene id (picklable).
        scenes : iterable of str or path, optional
            Scene ids or scene folders (their names are the ids); default every scene of
            ``split`` (:meth:`scene_dirs`).
        split : str
            The scenes' split when ``scenes`` is not given.
        flatten : bool
            Each task returns a list of rows: return one list of every scene's rows, in order
            (False: each task's result as it is, one per scene).
        jobs, scheduler, desc, progress
            As :func:`semmatch.runtime.engine.map_tasks`.

        Returns
        -------
        list
            The rows of every scene (``flatten``), else one result per scene.

        Raises
        ------
        FileNotFoundError
            ``scenes`` not given and the split has no scenes folder.
        """
        from functools import partial

        from ..runtime.engine import map_tasks

        ids = [Path(s).name for s in (self.scene_dirs(split) if scenes is None else scenes)]
        per_scene = map_tasks(partial(task, str(self.root.resolve()), *args), ids, jobs=jobs, scheduler=scheduler,
                              desc=desc, progress=progress)
        return [row for rows in per_scene for row in rows] if flatten else per_scene

    def model(self, network: str) -> Path:
        return self.root / "models" / f"{network}.pt"

    @property
    def recipe(self) -> Path:
        """Inference choices made on the validation scenes (``02_train_segmentation``)."""
        return self.root / "models" / "recipe.json"

    def load_network(self, network: str):
        """The trained network ``network`` (:func:`semmatch.segment.load_model`).

        Test-time mirror averaging follows the choice stored in :attr:`recipe` (made on the
        validation scenes); without a recipe file the loader's default applies.
        """
        from ..segment import load_model

        path = self.model(network)
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no trained {network} network; run 02_train_segmentation first")
        flip = self.inference_flip(network)
        return load_model(path) if flip is None else load_model(path, flip=flip)

    def inference_flip(self, network: str) -> bool | None:
        """The mirror-averaging choice for ``network`` in :attr:`recipe` (None: no choice made)."""
        import json

        if not self.recipe.is_file():
            return None
        choice = json.loads(self.recipe.read_text()).get("flip", {})
        return bool(choice[network]) if network in choice else None

    def upper_map(self, scene_id: str, source: str) -> Path:
        return self.root / "upper" / scene_id / f"{source_dir(source)}.ply"

    def upper_labels(self, scene_id: str, network: str) -> Path:
        return self.root / "upper" / scene_id / f"labels_{network}"

    def lower_sequence(self, scene_dir: Path, route: str = "own") -> Path:
        """The robot's sequence folder of a scene for a route mode."""
        _route_part(route)
        return Path(scene_dir) / ROUTES[route]

    def lower_labels(self, scene_id: str, source: str, method: str, route: str = "own") -> Path:
        return self.root.joinpath("lower_labels", scene_id, *_route_part(route), source_dir(source), method)

    def lower_map(self, scene_id: str, source: str, method: str, route: str = "own") -> Path:
        return self.root.joinpath("lower_maps", scene_id, *_route_part(route), source_dir(source), f"{method}.ply")

    def lower_reference(self, scene_id: str, route: str = "own") -> Path:
        """Lower-view reconstruction fused from ground-truth labels: the reference of Table 2."""
        return self.root.joinpath("lower_maps", scene_id, *_route_part(route), "reference.ply")

    def mesh_reference(self, scene_id: str, view: str = "lower", route: str = "own") -> Path:
        """The ground-truth mesh sampled where a view observed it: the independent reference."""
        name = "mesh_reference.ply" if view == "lower" else f"{view}_mesh_reference.ply"
        return self.root.joinpath("lower_maps", scene_id, *_route_part(route), name)

    def upper_reference(self, scene_id: str) -> Path:
        """Upper-view reconstruction fused from ground-truth labels."""
        return self.upper_map(scene_id, GT)

    def panoptic(self, scene_id: str) -> Path:
        """Panoptic maps of one scene (``10_panoptic``): ``upper_<source>.ply``, ``reference.ply``,
        ``<source>/<method>.ply``."""
        return self.root / "panoptic" / scene_id

    @property
    def real_like(self) -> Path:
        return self.root / "real_like"
