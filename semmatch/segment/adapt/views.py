"""The robot's training frames for adaptation, each labelled by every label source.

:func:`robot_training_views` renders the person's and the robot's tours of training scenes and
labels the robot's frames from the network's map of each (:func:`label_robot_frame`);
:func:`home_views` labels a robot's recorded tour of a home from the person's map of it. The
label sources are :data:`LABEL_SOURCES`; :mod:`semmatch.segment.adapt.finetune` learns from them.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ...io import Frame

if TYPE_CHECKING:
    from ...transfer import MapIndex
    from ..predict import Segmenter

__all__ = ["BASELINES", "LABEL_SOURCES", "HOME_SOURCES", "MIN_COVERAGE", "RobotViews", "adapted_name",
           "label_robot_frame", "robot_training_views", "home_views"]

#: label sources besides the transfer methods
BASELINES = ("self-training", "ground-truth")


def _label_sources() -> tuple[str, ...]:
    from ...transfer import METHODS

    return (*METHODS, "fused", *BASELINES)


#: every label source: the paper's transfer methods, ``fused``, self-training, ground truth
LABEL_SOURCES: tuple[str, ...] = _label_sources()

#: label sources of in-home adaptation (:func:`~semmatch.segment.adapt.finetune.adapt_in_home`): labels from the person's map only
HOME_SOURCES: tuple[str, ...] = tuple(s for s in LABEL_SOURCES if s not in BASELINES)

#: smallest share of the robot's pixels with depth that the labels must cover (:func:`~semmatch.segment.adapt.finetune.fine_tune`)
MIN_COVERAGE = 0.005


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
    """Label one robot frame with each label source (the pseudo-labels :func:`~semmatch.segment.adapt.finetune.fine_tune` learns from).

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
    from ...transfer import transfer_frame

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
    from ...fusion import reconstruct
    from ...io.geometry import DEFAULT_INTRINSICS
    from ...runtime.progress import tqdm
    from ...sim import Renderer
    from ...sim.trajectory import make_trajectory
    from ...transfer import MapIndex
    from .. import load_model
    from ..data import Views, make_scenes

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


def check_home_depth(sequence: str | Path) -> None:
    """Refuse a robot's sequence folder without a ``depth/`` folder (before it is read).

    Parameters
    ----------
    sequence : path
        The robot's recording; only a semmatch sequence folder (``intrinsics.json`` and
        ``poses.txt``) is checked here, other layouts keep depth elsewhere.

    Raises
    ------
    ValueError
        The folder has no ``depth/``: adapting in a home needs the robot's depth.
    """
    from ...io import is_sequence

    sequence = Path(sequence)
    if is_sequence(sequence) and not (sequence / "depth").is_dir():
        raise ValueError(f"{sequence}: the sequence has no depth/ folder; adapting in a home needs the robot's "
                         "depth to place its pixels in the person's map")


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
    recording=None,
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
    recording : sequence of Frame, optional
        ``sequence`` already opened (any layout of :mod:`semmatch.io.readers`, e.g. with
        estimated poses); default: ``sequence`` read as a sequence folder.

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

    from ...io import read_map, read_sequence
    from ...io.maps import map_scene
    from ...io.sequences import sequence_scene
    from ...runtime.progress import tqdm
    from ...transfer import load_index
    from .. import load_model
    from ..data import Views

    if source not in HOME_SOURCES:
        raise ValueError(f"in-home adaptation takes labels from the person's map: source must be one of "
                         f"{', '.join(HOME_SOURCES)}, got {source!r}")
    if int(frame_step) < 1 or (frames is not None and int(frames) < 1):
        raise ValueError(f"need frames >= 1 and frame_step >= 1, got {frames}, {frame_step}")
    sequence, person_map = Path(sequence), Path(person_map)
    check_home_depth(sequence)
    seq = read_sequence(sequence) if recording is None else recording
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
        from ...io.readers import frame_files

        files = frame_files(seq, picks[0])
        where = (f"{files[-1].parent}: no depth in any of the {len(picks)} frames used (frame {picks[0]}: {files[-1]})"
                 if files else f"{sequence}: no depth in any of the {len(picks)} frames used")
        raise ValueError(f"{where}; adapting in a home needs the robot's depth")
    coverage = labelled / valid_px
    if coverage < min_coverage:
        raise ValueError(f"{person_map}: the map's labels cover {coverage:.2%} of the robot's pixels with depth in "
                         f"{sequence} (fewer than {min_coverage:.2%}): the map does not cover this robot's view "
                         "(a map of another home, or in another frame?)")
    views = Views(np.stack(rgb), np.stack(depth).astype(np.float32), np.stack(gt), np.zeros(len(rgb), np.int64),
                  np.asarray(cam_z, np.float32))
    return RobotViews(views, {source: np.stack(lab)}, {source: coverage}, [home or sequence.resolve().name],
                      picks)
