"""The robot learns: adapt a segmentation network to the robot's viewpoint with transferred labels.

The paper ends where this begins ("label transfer and the fine-tuning of semantic segmentation
networks to these perspectives becomes possible"). On **training scenes only**, the person
(1.6 m) and the robot (0.2 m) each tour the room; the network builds the person's semantic map,
its labels are transferred into the robot's frames, and the network is fine-tuned on those
frames (:func:`fine_tune`). Label sources (:data:`LABEL_SOURCES`):

* a transfer method (the paper's five): its labels where the map supports a pixel and the
  pixel's group agreed (vote purity >= ``min_purity``); everything else is ignored by the loss;
* ``fused``: the transferred label where the map supports a pixel, the network's elsewhere;
* ``self-training`` (the standard domain-adaptation baseline): the network's own predictions on
  the robot's frames where its confidence is >= ``self_threshold``;
* ``ground-truth`` (the ceiling): the simulator's labels of the robot's frames.

Forgetting the human view is guarded against by mixing each batch: ``upper_share`` of it comes
from the network's own human-height training views with their ground truth.
The adapted checkpoint records what it was adapted from and with (``adapted``); it loads with
:func:`semmatch.segment.load_model` like any other.
"""

from __future__ import annotations

import copy
import hashlib
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .io import Frame, atomic_path

if TYPE_CHECKING:
    from .segment.predict import Segmenter
    from .transfer import MapIndex

__all__ = ["LABEL_SOURCES", "HOME_SOURCES", "MIN_COVERAGE", "AdaptRecipe", "RobotViews", "label_robot_frame",
           "robot_training_views", "home_views", "adapt_in_home", "fine_tune", "adapted_name"]

#: label sources besides the transfer methods
BASELINES = ("self-training", "ground-truth")


def _label_sources() -> tuple[str, ...]:
    from .transfer import METHODS

    return (*METHODS, "fused", *BASELINES)


#: every label source: the paper's transfer methods, ``fused``, self-training, ground truth
LABEL_SOURCES: tuple[str, ...] = _label_sources()

#: label sources of in-home adaptation (:func:`adapt_in_home`): labels from the person's map only
HOME_SOURCES: tuple[str, ...] = tuple(s for s in LABEL_SOURCES if s not in BASELINES)

#: smallest share of the robot's pixels with depth that the labels must cover (:func:`fine_tune`)
MIN_COVERAGE = 0.005


@dataclass(frozen=True)
class AdaptRecipe:
    """The fine-tuning recipe of :func:`fine_tune`: the one place its defaults live.

    Every function that fine-tunes (:func:`fine_tune`, :func:`adapt_in_home`,
    :func:`semmatch.experiments.adapt.adapt_networks`, ``semmatch adapt``) takes its recipe from
    here; a profile of params.yaml sets its own (``adapt_robot_view``: ``steps``, ``batch_size``;
    the learning rate, ``upper_share`` and ``distill`` are chosen on validation scenes) and
    :meth:`from_mapping` reads it. Values are stored as ``int`` / ``float``.

    Attributes
    ----------
    steps : int
        Optimisation steps (AdamW, one-cycle schedule peaking at ``lr``).
    batch_size : int
        Images per step (at least 2).
    lr : float
        Peak learning rate.
    upper_share : float
        Share of each batch from the network's own human-height training views, in [0, 1).
    distill : float
        Weight of the distillation term (0: none; > 0 needs human-height views in the batch).
    seed : int
        Seed of the batch draws, the augmentation and the weights' updates.

    Raises
    ------
    ValueError
        ``steps`` < 1, ``batch_size`` < 2, ``upper_share`` outside [0, 1), ``distill`` < 0, or
        ``distill`` > 0 without a human-height view in the batch.
    """

    steps: int = 400
    batch_size: int = 16
    lr: float = 1e-3
    upper_share: float = 0.5
    distill: float = 0.0
    seed: int = 0

    def __post_init__(self) -> None:
        for f in fields(self):  # 400 or 400.0 or "400" from a table: the field's type
            object.__setattr__(self, f.name, type(f.default)(getattr(self, f.name)))
        steps, batch_size, upper_share, distill = self.steps, self.batch_size, self.upper_share, self.distill
        if steps < 1 or batch_size < 2 or not 0.0 <= upper_share < 1.0:
            raise ValueError(f"need steps >= 1, batch_size >= 2 and 0 <= upper_share < 1, got {steps}, {batch_size}, "
                             f"{upper_share}")
        if not distill >= 0 or (distill > 0 and int(round(batch_size * upper_share)) == 0):
            raise ValueError(f"distill must be >= 0 and needs human-height views in the batch (upper_share > 0), "
                             f"got distill={distill}, upper_share={upper_share}")

    @classmethod
    def names(cls) -> tuple[str, ...]:
        """The recipe's field names, in order."""
        return tuple(f.name for f in fields(cls))

    @classmethod
    def from_mapping(cls, values: Mapping[str, Any], **changes: Any) -> AdaptRecipe:
        """The recipe whose fields are found in ``values``, the defaults elsewhere.

        Parameters
        ----------
        values : mapping
            A params.yaml section or a notebook's parameters
            (:func:`semmatch.experiments.pipeline.notebook_parameters`), a row of a recipe table;
            keys that are not fields of the recipe are ignored.
        **changes
            Fields set over ``values``.

        Returns
        -------
        AdaptRecipe
        """
        return cls(**{k: values[k] for k in cls.names() if k in values}, **changes)

    @classmethod
    def of(cls, recipe: AdaptRecipe | None = None, **changes: Any) -> AdaptRecipe:
        """``recipe`` (default: the default recipe) with ``changes`` to its fields.

        Raises
        ------
        TypeError
            A change that is not a field of the recipe.
        """
        return replace(recipe if recipe is not None else cls(), **changes)

    def as_dict(self) -> dict[str, int | float]:
        """The fields as a dict, in order (the checkpoint's ``adapted`` record holds them)."""
        return {k: getattr(self, k) for k in self.names()}


def adapted_name(network: str, source: str) -> str:
    """Name of ``network`` adapted with ``source`` labels (``compact~3d-neighborhood``)."""
    return f"{network}~{source}"


@dataclass
class RobotViews:
    """The robot's frames of the adaptation scenes with one pseudo-label image per source.

    Attributes
    ----------
    views : Views
        RGB, depth, ground-truth labels, scene index, camera height.
    pseudo : dict
        ``{source: uint8 (N,H,W)}``; 0 = ignored by the loss.
    coverage : dict
        ``{source: share of the pixels with depth that carry a label}``.
    scenes : list of str
        Scene names, in the order of ``views.scene``.
    frames : list of int
        The views' frame indices in their recorded sequence (:func:`home_views`); empty for
        rendered tours.
    """

    views: object
    pseudo: dict[str, np.ndarray]
    coverage: dict[str, float] = field(default_factory=dict)
    scenes: list[str] = field(default_factory=list)
    frames: list[int] = field(default_factory=list)


def _check_sources(sources: Sequence[str]) -> None:
    bad = [s for s in sources if s not in LABEL_SOURCES]
    if bad:
        raise ValueError(f"unknown label source(s) {', '.join(bad)}; valid: {', '.join(LABEL_SOURCES)}")


def label_robot_frame(
    frame: Frame,
    index: MapIndex,
    sources: Sequence[str],
    seg: Segmenter | None = None,
    *,
    min_purity: float = 0.5,
    self_threshold: float = 0.9,
    fused_base: str = "3d-neighborhood",
) -> dict[str, np.ndarray]:
    """Label one robot frame with each label source (the pseudo-labels :func:`fine_tune` learns from).

    Parameters
    ----------
    frame : Frame
        The robot's posed RGB-D frame (``labels``: its ground truth, needed by ``ground-truth``).
    index : MapIndex
        The person's semantic map, indexed (:class:`semmatch.transfer.MapIndex`).
    sources : sequence of str
        Label sources (:data:`LABEL_SOURCES`).
    seg : Segmenter, optional
        The network (its class probabilities on ``frame.rgb``); needed by ``fused`` and
        ``self-training``.
    min_purity : float
        A transfer method's labels of pixels whose group vote was less pure are ignored (0).
    self_threshold : float
        Self-training keeps predictions at least this confident.
    fused_base : str
        The transfer method ``fused`` completes with the network's labels.

    Returns
    -------
    dict
        ``{source: uint8 (H,W)}``, 0 = ignored by the loss; a transfer method labels only
        pixels with depth.
    """
    from .transfer import transfer_frame

    probs = None
    if {"fused", "self-training"} & set(sources):
        if seg is None:
            raise ValueError("the fused and self-training sources need the network's predictions (seg)")
        probs = seg.predict(frame.rgb)
    valid = frame.depth > 0
    out = {}
    for s in sources:
        if s == "ground-truth":
            if frame.labels is None:
                raise ValueError(f"frame {frame.index}: the ground-truth source needs the frame's labels")
            lab = frame.labels
        elif s == "self-training":
            lab = np.where(probs.max(axis=2) >= self_threshold, probs.argmax(axis=2), 0)
        elif s == "fused":
            lab = transfer_frame("fused", frame, index, probs=probs, base=fused_base).labels
        else:
            res = transfer_frame(s, frame, index)
            lab = np.where(valid & (res.purity >= min_purity), res.labels, 0)
        out[s] = np.asarray(lab).astype(np.uint8)
    return out


def robot_training_views(
    checkpoint: str | Path,
    *,
    kinds: Sequence[str],
    seeds: Sequence[int],
    sources: Sequence[str] = LABEL_SOURCES,
    n_frames: int = 40,
    upper_height: float = 1.6,
    lower_height: float = 0.2,
    voxel_size: float = 0.04,
    min_purity: float = 0.5,
    self_threshold: float = 0.9,
    fused_base: str = "3d-neighborhood",
    seed: int = 0,
    progress: bool = True,
) -> RobotViews:
    """Render the person's and the robot's tours of training scenes and label the robot's frames.

    Frames are rendered at the resolution the network was trained on (its checkpoint's
    ``train_config``). Each camera plans its own coverage-matched tour (the evaluation protocol);
    the person's map is the network's predictions fused (TSDF, ``voxel_size``).

    Parameters
    ----------
    checkpoint : path
        The network to adapt.
    kinds, seeds : sequences
        The training scenes (``make_scenes(kinds, seeds)``): must be scenes the network was
        trained on, never validation or evaluation scenes.
    sources : sequence of str
        Label sources to prepare (:data:`LABEL_SOURCES`).
    n_frames : int
        Frames per tour.
    min_purity : float
        Transferred labels of pixels whose group vote was less pure are ignored.
    self_threshold : float
        Self-training keeps predictions at least this confident.

    Raises
    ------
    ValueError
        Unknown source, or seeds that are validation/evaluation seeds of the network.
    """
    from .fusion import reconstruct
    from .geometry import DEFAULT_INTRINSICS
    from .progress import tqdm
    from .segment import load_model
    from .segment.data import Views, make_scenes
    from .sim import Renderer
    from .sim.trajectory import make_trajectory
    from .transfer import MapIndex

    _check_sources(sources)
    seg = load_model(checkpoint)
    cfg = seg.info.get("train_config") or {}
    held_out = set(cfg.get("val_seeds", ())) | set(cfg.get("eval_seeds", ()))
    if held_out & set(seeds):
        raise ValueError(f"adaptation seeds {sorted(held_out & set(seeds))} are validation/evaluation seeds of "
                         f"{checkpoint}; adapt on training scenes only")
    intr = DEFAULT_INTRINSICS.scaled(int(cfg.get("width", 320)), int(cfg.get("height", 240)))
    scenes = make_scenes(kinds, seeds)
    rgb, depth, gt, scene_of, pseudo = [], [], [], [], {s: [] for s in sources}
    valid_px, labelled = 0, dict.fromkeys(sources, 0)
    names = []
    for k, scene in enumerate(tqdm(scenes, desc="adaptation scenes", disable=not progress)):
        names.append(scene.name)
        r = Renderer(scene, intr)
        up_poses = make_trajectory(scene, upper_height, n_frames, seed=seed + k, kind="upper", cover=True)
        lo_poses = make_trajectory(scene, lower_height, n_frames, seed=seed + k, kind="lower", cover=True)
        up = [r.render(T) for T in up_poses]
        lo = [r.render(T) for T in lo_poses]
        up_frames = [Frame(v.rgb, v.depth, None, np.asarray(T), intr, index=i)
                     for i, (v, T) in enumerate(zip(up, up_poses))]
        probs_up = [seg.predict(v.rgb) for v in up]
        index = MapIndex(reconstruct(up_frames, labels=probs_up, voxel_size=voxel_size))
        for i, (v, T) in enumerate(zip(lo, lo_poses)):
            frame = Frame(v.rgb, v.depth, v.labels, np.asarray(T), intr, index=i)
            labs = label_robot_frame(frame, index, sources, seg, min_purity=min_purity,
                                     self_threshold=self_threshold, fused_base=fused_base)
            valid = v.depth > 0
            valid_px += int(valid.sum())
            for s, lab in labs.items():
                pseudo[s].append(lab)
                labelled[s] += int(np.count_nonzero(lab[valid]))
            rgb.append(v.rgb)
            depth.append(v.depth)
            gt.append(v.labels)
            scene_of.append(k)
    views = Views(np.stack(rgb), np.stack(depth).astype(np.float32), np.stack(gt), np.asarray(scene_of, np.int64),
                  np.full(len(rgb), lower_height, np.float32))
    return RobotViews(views, {s: np.stack(v) for s, v in pseudo.items()},
                      {s: labelled[s] / max(valid_px, 1) for s in sources}, names)


def home_views(
    checkpoint: str | Path,
    sequence: str | Path,
    person_map: str | Path,
    *,
    source: str = "3d-neighborhood",
    frames: int | None = None,
    frame_step: int = 1,
    min_purity: float = 0.5,
    fused_base: str = "3d-neighborhood",
    min_coverage: float = MIN_COVERAGE,
    progress: bool = True,
) -> RobotViews:
    """Label a robot's recorded tour of a home with the person's map of that home.

    The frames' labels come from :func:`label_robot_frame` (the same rules as
    :func:`robot_training_views`); frames of another size than the network was trained at are
    resized to it after the transfer (labels and depth nearest-neighbour).

    Parameters
    ----------
    checkpoint : path
        The network to adapt (its training size; its predictions for ``fused``).
    sequence : path
        The robot's sequence folder (:func:`semmatch.io.read_sequence`): RGB, metric depth,
        poses in the map's frame.
    person_map : path
        The person's semantic map of the same home (PLY).
    source : str
        A transfer method or ``fused`` (:data:`HOME_SOURCES`).
    frames : int, optional
        Use at most this many frames (after ``frame_step``); default all.
    frame_step : int
        Use every ``frame_step``-th frame.
    min_purity, fused_base
        As :func:`label_robot_frame`.
    min_coverage : float
        Smallest share of the robot's pixels with depth the labels must cover.
    progress : bool

    Returns
    -------
    RobotViews
        One scene: the home (its name from the sequence's ``meta.json``, else the folder's name).

    Raises
    ------
    ValueError
        A source outside :data:`HOME_SOURCES`; a sequence without depth; a map without labels;
        a map and a sequence naming different scenes; labels covering less than
        ``min_coverage`` of the robot's pixels (the map does not cover this view).
    FileNotFoundError
        A missing sequence or map.
    """
    import cv2

    from .io import read_map, read_sequence
    from .io.maps import map_scene
    from .io.sequences import sequence_scene
    from .progress import tqdm
    from .segment import load_model
    from .segment.data import Views
    from .transfer import load_index

    if source not in HOME_SOURCES:
        raise ValueError(f"in-home adaptation takes labels from the person's map: source must be one of "
                         f"{', '.join(HOME_SOURCES)}, got {source!r}")
    if int(frame_step) < 1 or (frames is not None and int(frames) < 1):
        raise ValueError(f"need frames >= 1 and frame_step >= 1, got {frames}, {frame_step}")
    sequence, person_map = Path(sequence), Path(person_map)
    if sequence.is_dir() and not (sequence / "depth").is_dir():
        raise ValueError(f"{sequence}: the sequence has no depth/ folder; adapting in a home needs the robot's "
                         "depth to place its pixels in the person's map")
    seq = read_sequence(sequence)
    m = read_map(person_map)
    if not np.any(m.labels > 0):
        raise ValueError(f"{person_map}: the map carries no labels (every vertex is void); a person's semantic map "
                         "is needed")
    home, map_home = sequence_scene(sequence), map_scene(person_map)
    if home is not None and map_home is not None and home != map_home:
        raise ValueError(f"{person_map}: the map is of scene {map_home!r} but the robot's sequence {sequence} is of "
                         f"{home!r}: a map of another home")
    picks = list(range(0, len(seq), int(frame_step)))[: None if frames is None else int(frames)]
    seg = load_model(checkpoint)
    cfg = seg.info.get("train_config") or {}
    size = (int(cfg.get("width", seq.intrinsics.width)), int(cfg.get("height", seq.intrinsics.height)))
    index = load_index(person_map, semantic_map=m, cache=False)
    rgb, depth, gt, cam_z, lab = [], [], [], [], []
    valid_px = labelled = 0
    for i in tqdm(picks, desc=f"labelling {sequence.name}", disable=not progress):
        frame = seq[i]
        if frame.pose is None or not np.isfinite(frame.pose).all():
            raise ValueError(f"{sequence}: frame {i} has no pose; the robot's frames must be posed in the map's frame")
        valid = frame.depth > 0
        valid_px += int(valid.sum())
        y = label_robot_frame(frame, index, [source], seg, min_purity=min_purity, fused_base=fused_base)[source]
        labelled += int(np.count_nonzero(y[valid]))
        truth = frame.labels if frame.labels is not None else np.zeros(frame.depth.shape, np.uint8)
        if (frame.rgb.shape[1], frame.rgb.shape[0]) != size:
            near = cv2.INTER_NEAREST
            frame_rgb = cv2.resize(np.ascontiguousarray(frame.rgb), size, interpolation=cv2.INTER_AREA)
            d, y, truth = (cv2.resize(np.ascontiguousarray(a), size, interpolation=near)
                           for a in (frame.depth, y, truth))
        else:
            frame_rgb, d = frame.rgb, frame.depth
        rgb.append(frame_rgb)
        depth.append(d)
        lab.append(y)
        gt.append(truth)
        cam_z.append(frame.pose[2, 3])
    if valid_px == 0:
        raise ValueError(f"{sequence / 'depth'}: no depth in any of the {len(picks)} frames used (frame {picks[0]}: "
                         f"{sequence / 'depth' / f'{picks[0]:06d}.png'}); adapting in a home needs the robot's depth")
    coverage = labelled / valid_px
    if coverage < min_coverage:
        raise ValueError(f"{person_map}: the map's labels cover {coverage:.2%} of the robot's pixels with depth in "
                         f"{sequence} (fewer than {min_coverage:.2%}): the map does not cover this robot's view "
                         "(a map of another home, or in another frame?)")
    views = Views(np.stack(rgb), np.stack(depth).astype(np.float32), np.stack(gt), np.zeros(len(rgb), np.int64),
                  np.asarray(cam_z, np.float32))
    return RobotViews(views, {source: np.stack(lab)}, {source: coverage}, [home or sequence.resolve().name],
                      picks)


def adapt_in_home(
    checkpoint: str | Path,
    sequence: str | Path,
    person_map: str | Path,
    out: str | Path,
    recipe: AdaptRecipe | None = None,
    *,
    source: str = "3d-neighborhood",
    frames: int | None = None,
    frame_step: int = 1,
    min_purity: float = 0.5,
    min_coverage: float = MIN_COVERAGE,
    cache_dir: str | Path | None = "checkpoint-if-present",
    progress: bool = True,
    **changes: Any,
) -> Path:
    """Adapt a network in a home: the robot's tour labelled from the person's map of it.

    :func:`home_views` labels the robot's frames, :func:`fine_tune` fine-tunes on them (half of
    each batch, by default, the network's own human-height training views).

    Parameters
    ----------
    checkpoint : path
        The network to adapt.
    sequence, person_map : paths
        The robot's tour of the home and the person's semantic map of it (:func:`home_views`).
    out : path
        The adapted checkpoint (never ``checkpoint`` nor an input).
    recipe : AdaptRecipe, optional
        The fine-tuning recipe (default :class:`AdaptRecipe`'s).
    source, frames, frame_step, min_purity, min_coverage
        As :func:`home_views`.
    cache_dir : path, "checkpoint", "checkpoint-if-present" or None
        The cache of the network's human-height training views (:func:`fine_tune`); by default
        the checkpoint's recorded folder where it exists, else the views are rendered each run.
    progress : bool
    **changes
        Fields of the recipe set over ``recipe`` (``steps=800``).

    Returns
    -------
    Path
        The checkpoint; its ``adapted`` record holds, besides :func:`fine_tune`'s fields (the
        recipe: ``steps``, ``lr``, ``batch_size``, ``upper_share``, ``seed``, ``label_source``;
        ``label_coverage``; ``scenes``: the home), ``home`` (``sequence``, ``scene`` or None,
        ``frames``: the frame indices used) and ``map`` (``path``, ``sha256``: the first 16 hex
        digits).

    Raises
    ------
    ValueError
        ``out`` is the network or an input; the errors of :func:`home_views` and
        :func:`fine_tune`.
    TypeError
        A change that is not a field of the recipe.
    """
    from .io.sequences import sequence_scene

    recipe = AdaptRecipe.of(recipe, **changes)
    out = Path(out)
    for flag, p in (("--model", checkpoint), ("--home", sequence), ("--map", person_map)):
        if out.resolve() == Path(p).resolve() or Path(p).resolve() in out.resolve().parents:
            raise ValueError(f"--out {out}: it is the input {flag} {p} (or inside it); refusing to overwrite an input")
    robot = home_views(checkpoint, sequence, person_map, source=source, frames=frames, frame_step=frame_step,
                       min_purity=min_purity, min_coverage=min_coverage, progress=progress)
    extra = {
        "mode": "home",
        "home": {"sequence": str(sequence), "scene": sequence_scene(sequence), "frames": list(robot.frames)},
        "map": {"path": str(person_map), "sha256": _file_digest(Path(person_map))},
        "min_purity": float(min_purity),
    }
    return fine_tune(checkpoint, robot, source, out, recipe, min_coverage=min_coverage, extra=extra,
                     cache_dir=cache_dir, progress=progress)


def _file_digest(path: Path) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for chunk in iter(lambda: fh.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()[:16]


def fine_tune(
    checkpoint: str | Path,
    robot: RobotViews,
    source: str,
    out: str | Path,
    recipe: AdaptRecipe | None = None,
    *,
    min_coverage: float = MIN_COVERAGE,
    extra: dict | None = None,
    cache_dir: str | Path | None = "checkpoint",
    progress: bool = True,
    **changes: Any,
) -> Path:
    """Fine-tune a network on the robot's frames labelled by ``source``; write the checkpoint.

    The recipe (:class:`AdaptRecipe`): each step takes ``round(batch_size * upper_share)`` of the
    network's own human-height training views (ground truth) and the rest from the robot's frames
    (``source`` labels, 0 ignored), with the network's training augmentation and class weights;
    AdamW with a one-cycle schedule peaking at ``lr``. With ``distill`` > 0 the loss also has ``distill`` times the
    per-pixel KL divergence from the unadapted network's class distribution to the adapted one's
    on the human-height part of each batch (distillation, a guard against forgetting the human
    view besides the mix itself). The final weights are kept (no selection on any scene).

    Parameters
    ----------
    checkpoint : path
        The network to adapt (:func:`semmatch.segment.load_model`: a checkpoint of another
        category table is refused).
    robot : RobotViews
        :func:`robot_training_views`, prepared with ``source``.
    source : str
        Label source (:data:`LABEL_SOURCES`).
    out : path
        Where the adapted checkpoint goes (written to a temporary file, then renamed).
    recipe : AdaptRecipe, optional
        The schedule (AdamW, one-cycle peaking at ``lr``), the share of each batch from the
        network's human-height training views and the distillation weight (default
        :class:`AdaptRecipe`'s).
    min_coverage : float
        Smallest share of the robot's pixels with depth that ``source`` must label: below it the
        person's map barely overlaps the robot's view and there is nothing to learn from.
    extra : dict, optional
        More entries for the checkpoint's ``adapted`` record (:func:`adapt_in_home`: the home
        and the map).
    cache_dir : path, "checkpoint", "checkpoint-if-present" or None
        Where the network's human-height training views are cached: the folder recorded in the
        checkpoint (``"checkpoint"``, the default), that folder only when it exists on this
        machine (``"checkpoint-if-present"``: a shipped network's training folder is never
        created elsewhere), another folder, or None (rendered, not cached).
    progress : bool
    **changes
        Fields of the recipe set over ``recipe`` (``steps=2, batch_size=4``).

    Returns
    -------
    Path
        The checkpoint: the source network's format and fields, the new ``state_dict``, and
        ``adapted``: the source checkpoint (path and SHA-256 prefix), the label source, the
        adaptation scenes, the coverage of the labels and the schedule.

    Raises
    ------
    ValueError
        Unknown source (or one ``robot`` was not prepared with), bad schedule, labels covering
        less than ``min_coverage`` of the robot's pixels, a checkpoint of another category table.
    TypeError
        A change that is not a field of the recipe.
    """
    import torch

    from .progress import tqdm
    from .segment import load_model
    from .segment.training import TrainConfig, augment, build_views, make_optimiser, optimisation_step

    _check_sources([source])
    if source not in robot.pseudo:
        raise ValueError(f"the robot views carry no {source!r} labels (prepared: {', '.join(robot.pseudo)})")
    recipe = AdaptRecipe.of(recipe, **changes)
    steps, batch_size, lr, upper_share, distill, seed = (getattr(recipe, k) for k in AdaptRecipe.names())
    coverage = robot.coverage.get(source)
    if coverage is not None and coverage < min_coverage:
        raise ValueError(f"{source}: its labels cover {coverage:.2%} of the robot's pixels with depth (fewer than "
                         f"{min_coverage:.2%}): the person's map barely overlaps the robot's view of the adaptation "
                         f"scenes ({', '.join(robot.scenes)}); use longer tours, more scenes or another source")
    checkpoint = Path(checkpoint)
    seg = load_model(checkpoint, device="cpu", flip=False)
    info = seg.info
    rec = dict(info.get("train_config") or {})
    known = {f for f in TrainConfig.__dataclass_fields__}
    cfg = TrainConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in rec.items() if k in known})
    cfg.progress = False
    if cache_dir == "checkpoint-if-present":
        cfg.cache_dir = cfg.cache_dir if cfg.cache_dir and Path(cfg.cache_dir).is_dir() else None
    elif cache_dir != "checkpoint":
        cfg.cache_dir = None if cache_dir is None else str(cache_dir)
    upper_views, _ = build_views(cfg)
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True)
    net = seg.net
    opt, sched = make_optimiser(net, lr, cfg.weight_decay, steps)
    w_t = torch.tensor(info["class_weights"], dtype=torch.float32)
    rng = np.random.default_rng(seed)
    n_up = int(round(batch_size * upper_share))
    n_lo = batch_size - n_up
    aux = _distillation(copy.deepcopy(net), n_up, distill) if distill > 0 else None
    lab_lo = robot.pseudo[source]
    usable = np.flatnonzero((lab_lo > 0).reshape(len(lab_lo), -1).any(axis=1))
    if len(usable) == 0:
        raise ValueError(f"{source}: no robot frame carries a label")
    aug = dict(crop=cfg.crop_size, zoom=cfg.zoom, jitter=cfg.jitter, base_zoom=cfg.width / cfg.net_size[0],
               use_depth=cfg.use_depth)
    t0 = time.perf_counter()
    losses = []
    net.train()
    for _ in tqdm(range(steps), desc=f"adapt {source}", disable=not progress):
        xs, ys = [], []
        if n_up:
            i = np.sort(rng.choice(len(upper_views), n_up, replace=len(upper_views) < n_up))
            x, y = augment(upper_views.rgb[i], upper_views.depth[i], upper_views.labels[i], rng, **aug)
            xs.append(x)
            ys.append(y)
        j = np.sort(rng.choice(usable, n_lo, replace=len(usable) < n_lo))
        x, y = augment(robot.views.rgb[j], robot.views.depth[j], lab_lo[j], rng, **aug)
        xs.append(x)
        ys.append(y)
        x = torch.cat(xs).contiguous(memory_format=torch.channels_last)
        losses.append(optimisation_step(net, x, torch.cat(ys), w_t, opt, sched, what=f"adaptation loss ({source})",
                                        aux_loss=aux))
    net.eval()
    ckpt = {k: copy.deepcopy(v) for k, v in info.items()}
    ckpt["state_dict"] = {k: v.detach().cpu() for k, v in net.state_dict().items()}
    ckpt["adapted"] = {
        "from": str(checkpoint), "from_sha256": _file_digest(checkpoint), "label_source": source,
        "scenes": list(robot.scenes), "frames": int(len(robot.views)), "label_coverage": robot.coverage.get(source),
        **recipe.as_dict(), "final_loss": float(np.mean(losses[-20:])), "seconds": time.perf_counter() - t0,
        **(extra or {}),
    }
    out = Path(out)
    with atomic_path(out) as tmp:
        torch.save(ckpt, tmp)
    return out


def _distillation(teacher, n_upper: int, weight: float):
    """``loss(x, logits)`` for :func:`fine_tune`: ``weight`` times the per-pixel KL divergence
    from the frozen ``teacher`` (the unadapted network) to the adapted network's ``logits`` on
    the first ``n_upper`` images of batch ``x``."""
    import torch
    import torch.nn.functional as F

    teacher.eval()
    for p in teacher.parameters():
        p.requires_grad_(False)

    def loss(x, logits):
        with torch.no_grad():
            t = F.log_softmax(teacher(x[:n_upper]), 1)
        return weight * (t.exp() * (t - F.log_softmax(logits[:n_upper], 1))).sum(1).mean()
    return loss
