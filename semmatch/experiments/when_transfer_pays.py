"""When transfer pays (issue 52): how large the robot's viewpoint and appearance gap, and how
complete the person's map, must be before transfer beats the robot's own network.

Per scene a person tours the home at 1.6 m (the pipeline's tour) and a robot flies one tour,
planned in the free space of the highest grid height, at every camera height of the grid
(``when_transfer_pays.yaml``). Further arms at the reference height (0.2 m): the camera level
(tilt 0 instead of the simulator's +-20 degrees), the held-out look of :mod:`semmatch.sim.appearance`
on the robot's frames only or on both tours, and a person's map fused from only the first part of
the person's tour. In every arm each network labels the person's frames (its map, fused as the
pipeline's upper map) and the robot's frames (``lower``); every transfer method and ``fused``
label the robot's frames from that map; the robot's frames are fused with each labelling and
scored as Table 2 (Mean Acc. against the robot's frames fused with ground-truth labels).

The estimand (:func:`crossover_estimate`): per method, the camera height at which the mean of
transfer - ``lower`` over scenes (and networks) changes sign, by linear interpolation on the grid
(:func:`crossing_point`: the first sign change from the lowest height up); its interval is a
percentile bootstrap over scenes within their kinds and, with several networks, over networks
(:func:`resample_means`). No sign change in the grid is a result too: the table then says on which
side transfer pays.

``python -m semmatch.experiments.when_transfer_pays --seeds ... --out DIR`` runs it
(``make confirm`` calls :func:`run_when_transfer_pays` on the run's scenes); docs/when_transfer_pays.md
describes the design and the validation run.

Size: one study in one place, as :mod:`.in_home` is: its grid, the per-scene rendering and scoring,
the crossover estimator and its tables and figure read together, and the estimator is small
(:func:`crossing_point`, :func:`beyond_grid`, :func:`resample_means`, :func:`crossover_estimate`).
"""

from __future__ import annotations

import argparse
import functools
import hashlib
import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

__all__ = ["GRID_PATH", "StudyGrid", "Arm", "load_grid", "study_arms", "arm_methods", "study_scenes", "run_scene",
           "crossing_point", "beyond_grid", "resample_means", "crossover_estimate", "difference_table",
           "crossover_table", "arms_table", "plot_crossover", "when_transfer_pays_study", "run_when_transfer_pays"]

GRID_PATH = Path(__file__).with_name("when_transfer_pays.yaml")
_MEASURES = ("jaccard", "sorensen", "color_acc", "mean_acc")
_LOOKS = ("none", "robot", "both")


@dataclass(frozen=True)
class StudyGrid:
    """The study's arms and estimator settings as the code uses them (``when_transfer_pays.yaml``).

    Attributes
    ----------
    heights : tuple of float
        The robot's camera heights (m), increasing.
    default_tilt_deg, reference_height : float
    tilts_deg : tuple of float
    severity : float
        The held-out look's severity.
    cameras : tuple of str
        ``robot`` and/or ``both``: which tours get the held-out look.
    coverage : tuple of float
        Shares of the person's tour in (0, 1].
    simulation : dict
    networks, methods : tuple of str
        ``methods`` are scored on every height arm.
    secondary_methods : tuple of str
        The methods scored on the tilt, appearance and coverage arms.
    fused_base, measure : str
    voxel_size, eval_voxel_size : float
    n_resamples : int
    confidence : float
    networks_level : bool
    seed : int
    raw : dict
        The whole YAML document.
    """

    heights: tuple[float, ...]
    default_tilt_deg: float
    reference_height: float
    tilts_deg: tuple[float, ...]
    severity: float
    cameras: tuple[str, ...]
    coverage: tuple[float, ...]
    simulation: dict
    networks: tuple[str, ...]
    methods: tuple[str, ...]
    secondary_methods: tuple[str, ...]
    fused_base: str
    measure: str
    voxel_size: float
    eval_voxel_size: float
    n_resamples: int
    confidence: float
    networks_level: bool
    seed: int
    raw: dict = field(default_factory=dict, compare=False, repr=False)


def load_grid(path: str | Path | None = None) -> StudyGrid:
    """Read the study's grid (default: the committed ``when_transfer_pays.yaml``).

    Raises
    ------
    ValueError
        A missing or malformed entry, heights not increasing, a reference height off the grid, an
        unknown camera or method, or a coverage share outside (0, 1] (each named with the file).
    """
    from ..transfer import available_methods

    path = Path(path or GRID_PATH)
    d = yaml.safe_load(path.read_text())
    try:
        boot = d["bootstrap"]
        grid = StudyGrid(
            heights=tuple(float(h) for h in d["heights"]), default_tilt_deg=float(d["default_tilt_deg"]),
            reference_height=float(d["reference_height"]), tilts_deg=tuple(float(t) for t in d["tilts_deg"]),
            severity=float(d["appearance"]["severity"]), cameras=tuple(str(c) for c in d["appearance"]["cameras"]),
            coverage=tuple(float(c) for c in d["coverage"]), simulation=dict(d["simulation"]),
            networks=tuple(str(n) for n in d["networks"]), methods=tuple(str(m) for m in d["methods"]),
            secondary_methods=tuple(str(m) for m in d["secondary_methods"]),
            fused_base=str(d["fused_base"]), measure=str(d["measure"]), voxel_size=float(d["voxel_size"]),
            eval_voxel_size=float(d["eval_voxel_size"]), n_resamples=int(boot["n_resamples"]),
            confidence=float(boot["confidence"]), networks_level=bool(boot["networks_level"]),
            seed=int(boot["seed"]), raw=d)
    except (KeyError, TypeError) as e:
        raise ValueError(f"{path}: missing or malformed entry ({type(e).__name__}: {e})") from None
    h = np.asarray(grid.heights)
    if h.size < 2 or np.any(np.diff(h) <= 0):
        raise ValueError(f"{path}: heights must be at least two increasing values, got {list(grid.heights)}")
    if grid.reference_height not in grid.heights:
        raise ValueError(f"{path}: reference_height {grid.reference_height} is not one of the heights {list(h)}")
    bad = sorted(set(grid.cameras) - {"robot", "both"})
    if bad:
        raise ValueError(f"{path}: appearance cameras {bad} unknown; valid: robot, both")
    if not all(0 < c <= 1 for c in grid.coverage):
        raise ValueError(f"{path}: coverage shares must lie in (0, 1], got {list(grid.coverage)}")
    bad = sorted(set(grid.secondary_methods) - set(grid.methods))
    if bad:
        raise ValueError(f"{path}: secondary_methods {bad} are not among the methods {list(grid.methods)}")
    bad = sorted(set(grid.methods) - set(available_methods()))
    if bad or grid.fused_base not in available_methods():
        raise ValueError(f"{path}: unknown transfer method(s) {bad or [grid.fused_base]}")
    if grid.measure not in _MEASURES:
        raise ValueError(f"{path}: measure {grid.measure!r} unknown; valid: {', '.join(_MEASURES)}")
    return grid


@dataclass(frozen=True)
class Arm:
    """One arm: the robot's camera (height, tilt, look) and the person's map (look, share of tour)."""

    name: str
    factor: str
    height: float
    tilt_deg: float
    look: str
    coverage: float

    @property
    def robot_key(self) -> str:
        """Folder of the robot's frames of this arm (arms with the same camera share them)."""
        look = "_look" if self.look in ("robot", "both") else ""
        return f"robot_h{round(self.height * 100):03d}_t{round(self.tilt_deg):02d}{look}"

    @property
    def person_key(self) -> tuple[bool, float]:
        """(held-out look on the person's tour, share of the tour) of this arm's person map."""
        return self.look == "both", self.coverage


def study_arms(grid: StudyGrid) -> list[Arm]:
    """The arms of ``grid``: every height at the default tilt, then the tilt, appearance and
    coverage arms at the reference height (their comparator is the reference height's arm)."""
    ref, tilt = grid.reference_height, grid.default_tilt_deg
    arms = [Arm(f"height {h:g}", "height", h, tilt, "none", 1.0) for h in grid.heights]
    arms += [Arm(f"tilt {t:g}", "tilt", ref, t, "none", 1.0) for t in grid.tilts_deg if t != tilt]
    arms += [Arm(f"look {c}", "appearance", ref, tilt, c, 1.0) for c in grid.cameras]
    arms += [Arm(f"coverage {c:g}", "coverage", ref, tilt, "none", c) for c in grid.coverage if c != 1.0]
    return arms


def study_scenes(seeds: Sequence[int], split: str = "eval", *, params_file: str | Path | None = None
                 ) -> list[tuple[str, int]]:
    """``(kind, seed)`` of the study's scenes, as the simulator lays out a split of the full profile.

    ``eval``: every kind of every seed (a confirmatory run's scenes); ``val``: the validation scene
    of each seed (seed ``val_seeds[i]`` is of kind ``kinds[i % len(kinds)]``).

    Raises
    ------
    ValueError
        An unknown split, or a ``val`` seed that is not one of the full profile's ``val_seeds``.
    """
    from .pipeline import ROOT, read_params

    common = read_params(params_file or ROOT / "params.yaml")["profiles"]["full"]["common"]
    kinds = list(common["kinds"])
    if split == "eval":
        return [(k, int(s)) for s in seeds for k in kinds]
    if split != "val":
        raise ValueError(f"split must be 'eval' or 'val', got {split!r}")
    val = [int(s) for s in common["val_seeds"]]
    bad = sorted(set(map(int, seeds)) - set(val))
    if bad:
        raise ValueError(f"seeds {bad} are not validation seeds of the full profile ({val})")
    return [(kinds[val.index(int(s)) % len(kinds)], int(s)) for s in seeds]


# ------------------------------------------------------------------------------------------------
# one scene: render the arms, label, fuse, score


def _settings_key(grid: StudyGrid) -> str:
    """8 hex digits over what the rendered frames depend on (a work folder is reused only for them)."""
    from .appearance_severity import look_digest

    key = {"simulation": grid.simulation, "heights": grid.heights, "tilts": grid.tilts_deg,
           "default_tilt": grid.default_tilt_deg, "reference": grid.reference_height, "severity": grid.severity,
           "look": look_digest()}
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:8]


def _render_scene(kind: str, seed: int, sdir: Path, upper_src: Path | None, arms: Sequence[Arm],
                  grid: StudyGrid) -> tuple[dict[str, Path], int]:
    """The tours of one scene (rendered once; complete folders are kept): ``upper`` (the person's,
    ``upper_src`` when given), ``upper_look`` and the robot's frames of every arm; and how many
    folders were rendered now."""
    from ..io import read_tum
    from ..io.geometry import DEFAULT_INTRINSICS
    from ..sim import generate_scene
    from ..sim.appearance import HeldOutRenderer, heldout_appearance
    from ..sim.raster import make_renderer
    from ..sim.simulate import carrier_poses, simulate_sequence
    from ..sim.trajectory import make_sweep_trajectories

    sim = grid.simulation
    scene = generate_scene(kind, seed)
    intr = DEFAULT_INTRINSICS.scaled(int(sim["image_width"]), int(sim["image_height"]))
    renderers: dict[bool, object] = {}
    rendered = []

    def renderer(look: bool):
        if look not in renderers:
            renderers[look] = (HeldOutRenderer(heldout_appearance(scene, seed, grid.severity), intr) if look
                               else make_renderer(scene, intr, backend="raycast"))
        return renderers[look]

    def render(name: str, poses: np.ndarray, look: bool, meta: dict) -> Path:
        out = sdir / name
        if not (out / "poses.txt").is_file():
            rendered.append(name)
            simulate_sequence(scene, poses, out, intrinsics=intr, renderer=renderer(look), overwrite=True,
                              progress=False, meta={**meta, "seed": seed, "look": grid.severity if look else None})
        return out

    tours: dict[str, Path] = {}
    if upper_src is not None:
        tours["upper"] = upper_src
    else:
        up = carrier_poses(scene, float(sim["upper_height"]), int(sim["n_frames_upper"]), carrier="upper",
                           tilt_deg=grid.default_tilt_deg, seed=seed, camera_step=float(sim["camera_step_upper"]))
        tours["upper"] = render("upper", up, False, {"trajectory": "upper"})
    if any(a.look == "both" for a in arms):
        tours["upper_look"] = render("upper_look", read_tum(tours["upper"] / "poses_gt.txt")[1], True,
                                     {"trajectory": "upper"})
    n = int(sim["n_frames_robot"])
    step = float(sim["robot_tour_m"]) / max(n - 1, 1)
    heights = tuple(sorted({*grid.heights, grid.reference_height}))
    paths: dict[float, dict[float, np.ndarray]] = {}
    for arm in arms:
        if arm.robot_key in tours:
            continue
        if arm.tilt_deg not in paths:  # one path for every height, planned at the highest (as Fig. 3's sweep)
            paths[arm.tilt_deg] = make_sweep_trajectories(scene, heights, n, kind="lower", seed=seed, cover=True,
                                                          there_and_back=False, max_step=step, tilt_deg=arm.tilt_deg)
        tours[arm.robot_key] = render(arm.robot_key, paths[arm.tilt_deg][arm.height], arm.look != "none",
                                      {"trajectory": "robot", "height": arm.height, "tilt_deg": arm.tilt_deg})
    return tours, len(rendered)


def arm_methods(grid: StudyGrid, arm: Arm) -> tuple[str, ...]:
    """The methods scored on ``arm``: every method on a height arm, the secondary ones elsewhere."""
    return grid.methods if arm.factor == "height" else grid.secondary_methods


def _scoring_key(grid: StudyGrid, method_settings: Mapping[str, Mapping] | None = None) -> str:
    """8 hex digits over what a network's rows depend on besides the frames (kept rows are reused
    only for them); the methods' settings count where a run gives any."""
    key = {"arms": [a.name for a in study_arms(grid)], "methods": grid.methods, "secondary": grid.secondary_methods,
           "fused_base": grid.fused_base, "voxel": grid.voxel_size, "eval_voxel": grid.eval_voxel_size}
    if any(method_settings.values() if method_settings else ()):
        key["method_settings"] = {m: dict(v) for m, v in method_settings.items() if v}
    return hashlib.sha256(json.dumps(key, sort_keys=True).encode()).hexdigest()[:8]


def _labels(model, frames) -> list[np.ndarray]:
    """A network's labels of every frame (argmax of its probabilities, as :func:`semmatch.segment.predict_sequence`)."""
    return [model.predict_frame(f).argmax(axis=-1).astype(np.uint8) for f in frames]


def _score_network(model, tours: Mapping[str, Path], arms: Sequence[Arm], grid: StudyGrid,
                   method_settings: Mapping[str, Mapping] | None = None) -> list[dict]:
    """Every arm's rows for one network: ``lower`` and each method (with its ``method_settings``),
    Table 2's measures."""
    from ..evaluate.metrics import compare
    from ..fusion import reconstruct, reconstruct_many
    from ..io import read_sequence
    from ..transfer import as_map_index, settings_for, transfer_frame
    from ..transfer.fused import fuse_labels
    from .synthetic import eval_grid_origin, reference_grid

    uppers = {False: read_sequence(tours["upper"]).load()}
    if "upper_look" in tours:
        uppers[True] = read_sequence(tours["upper_look"]).load()
    upper_labels = {look: _labels(model, seq) for look, seq in uppers.items()}
    indexes = {}
    for arm in arms:
        look, share = arm.person_key
        if (look, share) not in indexes:
            k = max(1, int(round(share * len(uppers[look]))))
            indexes[(look, share)] = as_map_index(reconstruct(uppers[look][:k], upper_labels[look][:k],
                                                              grid.voxel_size))
    origin = eval_grid_origin(grid.eval_voxel_size)
    rows = []
    for key in dict.fromkeys(a.robot_key for a in arms):
        frames = read_sequence(tours[key]).load()
        lower = _labels(model, frames)
        valid = np.concatenate([(f.depth > 0).reshape(-1) for f in frames])
        labelings: list[tuple[Arm, str, list[np.ndarray]]] = []
        for arm in (a for a in arms if a.robot_key == key):
            index, methods = indexes[arm.person_key], arm_methods(grid, arm)
            transferred = [m for m in methods if m != "fused"]
            if "fused" in methods and grid.fused_base not in transferred:
                transferred.append(grid.fused_base)
            params = {m: settings_for(m, method_settings) for m in transferred}  # checked once, not per frame
            lab = {m: [transfer_frame(m, f, index, **params[m]).labels for f in frames] for m in transferred}
            if "fused" in methods:
                lab["fused"] = [fuse_labels(t, p) for t, p in zip(lab[grid.fused_base], lower, strict=True)]
            labelings += [(arm, "lower", lower)] + [(arm, m, lab[m]) for m in methods]
        ref, *maps = reconstruct_many(frames, [None, *(lab for _, _, lab in labelings)], grid.voxel_size)
        ref = reference_grid(ref, grid.eval_voxel_size)
        for (arm, method, lab), m in zip(labelings, maps, strict=True):
            s = compare(ref, m, voxel_size=grid.eval_voxel_size, grid_origin=origin)
            labelled = np.concatenate([x.reshape(-1) for x in lab]) > 0
            rows.append(dict(arm=arm.name, factor=arm.factor, height=arm.height, tilt_deg=arm.tilt_deg, look=arm.look,
                             coverage=arm.coverage, method=method, **{k: float(s[k]) for k in _MEASURES},
                             labelled=float((labelled & valid).sum() / max(int(valid.sum()), 1)),
                             frames=len(frames)))
    return rows


def run_scene(data_root: str, work: str, grid_path: str, split: str, scene: tuple[str, int],
              method_settings: Mapping[str, Mapping] | None = None) -> list[dict]:
    """One scene of the study (an engine task): render its arms, then score every network.

    The person's tour is ``data_root/scenes/<split>/<scene>/upper`` where it exists (the
    pipeline's, e.g. a confirmatory run's), else it is rendered as the pipeline does. Rendered
    frames are kept under ``work/<scene>/<settings key>/``; each network's rows are kept there as
    ``rows_<network>_<digest>_<scoring key>.json`` (a rerun scores only what is missing). The
    methods run with ``method_settings`` (``{method: {parameter: value}}``, a run's ``slic_2d``).

    Returns
    -------
    list of dict
        One row per network, arm and method (``lower`` included): ``scene, kind, seed, network``,
        the arm's columns, Table 2's measures, ``labelled`` (share of the robot's pixels with
        depth that the labelling labels), ``frames``, and the timing columns ``render_s`` /
        ``render_cpu_s`` (the scene's rendering, NaN when it was already rendered) and
        ``score_s`` / ``score_cpu_s`` (this network's scoring, NaN when its rows were kept).
    """
    from ..io import atomic_write_text, is_sequence
    from ..segment.adapt.finetune import file_digest
    from .layout import Layout

    grid = load_grid(grid_path)
    arms = study_arms(grid)
    kind, seed = scene
    sid = f"{kind}_{seed:04d}"
    sdir = Path(work) / sid / _settings_key(grid)
    layout = Layout(data_root)
    src = layout.scenes / split / sid / "upper"
    t, c = time.perf_counter(), time.process_time()
    tours, fresh = _render_scene(kind, seed, sdir, src if is_sequence(src) else None, arms, grid)
    render = (time.perf_counter() - t, time.process_time() - c) if fresh else (float("nan"),) * 2
    rows = []
    for net in grid.networks:
        kept = sdir / f"rows_{net}_{file_digest(layout.model(net))[:12]}_{_scoring_key(grid, method_settings)}.json"
        if kept.is_file():
            net_rows, score = json.loads(kept.read_text()), (float("nan"),) * 2
        else:
            t, c = time.perf_counter(), time.process_time()
            net_rows = _score_network(layout.load_network(net), tours, arms, grid, method_settings)
            score = (time.perf_counter() - t, time.process_time() - c)
            atomic_write_text(kept, json.dumps(net_rows))
        rows += [dict(scene=sid, kind=kind, seed=seed, network=net, **r, render_s=render[0], render_cpu_s=render[1],
                      score_s=score[0], score_cpu_s=score[1]) for r in net_rows]
    return rows


# ------------------------------------------------------------------------------------------------
# the estimator


def crossing_point(grid: Sequence[float], values: Sequence[float]) -> float:
    """The grid position where ``values`` first changes sign, scanning from the lowest grid value up.

    Between two neighbouring grid points of opposite sign the crossing is interpolated linearly;
    a value exactly 0 is a crossing at its grid point. With several sign changes (a
    non-monotonic curve) the first one from below is returned.

    Parameters
    ----------
    grid : sequence of float
        Increasing grid positions (e.g. camera heights).
    values : sequence of float
        The curve at each grid position (e.g. mean transfer - ``lower``).

    Returns
    -------
    float
        The crossing, or NaN when the curve keeps one sign over the whole grid.

    Raises
    ------
    ValueError
        Grid and values of different lengths, fewer than two points, a grid that does not
        increase, or a NaN value.
    """
    h, v = _curve(grid, values, "crossing_point")
    for i in range(v.size):
        if v[i] == 0:
            return float(h[i])
        if i + 1 < v.size and v[i] * v[i + 1] < 0:
            return float(h[i] + v[i] * (h[i + 1] - h[i]) / (v[i] - v[i + 1]))
    return float("nan")


def beyond_grid(grid: Sequence[float], values: Sequence[float]) -> float:
    """Where a curve without a sign change on the grid would cross: ``-inf`` (below the grid) or
    ``+inf`` (above it), towards the end whose value is nearer zero (ties: above).

    Raises
    ------
    ValueError
        As :func:`crossing_point`, or a curve that does change sign on the grid.
    """
    h, v = _curve(grid, values, "beyond_grid")
    if not np.isnan(crossing_point(h, v)):
        raise ValueError("beyond_grid: the curve changes sign on the grid")
    return float("-inf") if abs(v[0]) < abs(v[-1]) else float("inf")


def _curve(grid, values, fn: str) -> tuple[np.ndarray, np.ndarray]:
    h, v = np.asarray(grid, np.float64).ravel(), np.asarray(values, np.float64).ravel()
    if h.shape != v.shape or h.size < 2:
        raise ValueError(f"{fn}: need a grid and values of equal length >= 2, got {h.size} and {v.size}")
    if np.any(np.diff(h) <= 0):
        raise ValueError(f"{fn}: the grid must increase, got {h.tolist()}")
    if np.isnan(v).any():
        raise ValueError(f"{fn}: a NaN value in the curve {v.tolist()}")
    return h, v


def resample_means(diffs: np.ndarray, kinds: Sequence[str], *, networks_level: bool = True,
                   n_resamples: int = 2000, seed: int = 0) -> np.ndarray:
    """Bootstrap means of per-network, per-scene curves: scenes within their kind, networks too.

    The scene level is :func:`semmatch.evaluate.stats.interval`'s ``stratified-percentile``
    resampling (the same draws for every network and grid point, so each resample is a whole
    curve; with one network and one grid point its means are exactly that interval's). With
    ``networks_level`` and more than one network, each resample also draws the networks with
    replacement (independently of the scenes: networks and scenes are crossed, every network is
    scored on every scene) and averages the drawn networks.

    Parameters
    ----------
    diffs : ndarray (networks, scenes, points)
        E.g. transfer - ``lower`` per network, scene and camera height; no NaN.
    kinds : sequence of str
        The kind (stratum) of each scene.
    networks_level : bool
        Resample networks as a second level.
    n_resamples : int
    seed : int

    Returns
    -------
    ndarray (n_resamples, points)
        The resampled mean curves.

    Raises
    ------
    ValueError
        ``diffs`` not 3-D, a NaN, or ``kinds`` of another length than the scenes.
    """
    from ..evaluate.stats import _stratified_resample_means

    d = np.asarray(diffs, np.float64)
    if d.ndim != 3 or 0 in d.shape:
        raise ValueError(f"resample_means: diffs must be (networks, scenes, points), got shape {d.shape}")
    if np.isnan(d).any():
        raise ValueError("resample_means: diffs hold NaN (a scene without a score)")
    g = np.asarray(kinds, dtype=object).astype(str)
    if g.size != d.shape[1]:
        raise ValueError(f"resample_means: {d.shape[1]} scenes but {g.size} kinds")
    # the same generator state for every (network, point): the same scene draws, so whole curves
    per_net = np.stack([np.stack([_stratified_resample_means(d[n, :, p], g, n_resamples, np.random.default_rng(seed))
                                  for p in range(d.shape[2])], axis=1) for n in range(d.shape[0])])
    if not networks_level or d.shape[0] == 1:
        return per_net.mean(axis=0)
    draws = np.random.default_rng([seed, 1]).integers(0, d.shape[0], size=(n_resamples, d.shape[0]))
    weights = np.stack([np.bincount(row, minlength=d.shape[0]) for row in draws]) / d.shape[0]
    return np.einsum("bn,nbp->bp", weights, per_net)


def crossover_estimate(grid: Sequence[float], diffs: np.ndarray, kinds: Sequence[str], *,
                       networks_level: bool = True, n_resamples: int = 2000, confidence: float = 0.95,
                       seed: int = 0) -> dict:
    """The crossover of the mean curve over scenes and networks, with a bootstrap interval.

    Parameters
    ----------
    grid : sequence of float
        Increasing grid positions (camera heights).
    diffs : ndarray (networks, scenes, points)
        Per network and scene, transfer - ``lower`` at each grid position.
    kinds : sequence of str
        Kind of each scene (the bootstrap's strata).
    networks_level, n_resamples, seed
        As :func:`resample_means`.
    confidence : float

    Returns
    -------
    dict
        ``crossover`` (:func:`crossing_point` of the mean curve; NaN without a sign change),
        ``direction`` (``pays below``, ``pays above``, ``pays at every height`` or ``pays at no
        height``), ``lo`` / ``hi`` (percentile interval over resamples, a resample without a sign
        change counted at :func:`beyond_grid`, so a bound may be -inf or +inf), ``share_crossing``
        (resamples with a sign change on the grid), ``mean`` (the curve), ``band_lo`` /
        ``band_hi`` (pointwise percentile bands), ``n_networks``, ``n_scenes``.
    """
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"crossover_estimate: confidence must be in (0, 1), got {confidence}")
    d = np.asarray(diffs, np.float64)
    mean = d.mean(axis=(0, 1))
    h = crossing_point(grid, mean)
    curves = resample_means(d, kinds, networks_level=networks_level, n_resamples=n_resamples, seed=seed)
    points = np.array([crossing_point(grid, c) for c in curves])
    crossing = ~np.isnan(points)
    points[~crossing] = [beyond_grid(grid, c) for c in curves[~crossing]]
    a = (1.0 - confidence) / 2
    lo, hi = np.quantile(points, [a, 1.0 - a], method="inverted_cdf")
    band_lo, band_hi = np.quantile(curves, [a, 1.0 - a], axis=0)
    nonzero = mean[mean != 0]
    if np.isnan(h):
        direction = "pays at every height" if mean[0] > 0 else "pays at no height"
    else:
        direction = "pays below" if nonzero.size and nonzero[0] > 0 else "pays above"
    return dict(crossover=h, direction=direction, lo=float(lo), hi=float(hi), share_crossing=float(crossing.mean()),
                mean=mean, band_lo=band_lo, band_hi=band_hi, n_networks=int(d.shape[0]), n_scenes=int(d.shape[1]))


# ------------------------------------------------------------------------------------------------
# tables and figure


def difference_table(per_scene: pd.DataFrame, measure: str = "mean_acc") -> pd.DataFrame:
    """Per scene, network, arm and method: ``measure`` of the method minus that of ``lower``.

    Returns
    -------
    DataFrame
        ``scene, kind, network, arm, factor, height, tilt_deg, look, coverage, method, value,
        lower, diff``.
    """
    keys = ["scene", "network", "arm"]
    low = per_scene[per_scene["method"] == "lower"].set_index(keys)[measure].rename("lower")
    df = per_scene[per_scene["method"] != "lower"].join(low, on=keys)
    cols = ["scene", "kind", "network", "arm", "factor", "height", "tilt_deg", "look", "coverage", "method"]
    out = df[cols].copy()
    out["value"], out["lower"] = df[measure].to_numpy(), df["lower"].to_numpy()
    out["diff"] = out["value"] - out["lower"]
    return out.reset_index(drop=True)


def _cube(diffs: pd.DataFrame, method: str, arms: Sequence[str]) -> tuple[np.ndarray, list[str]]:
    """``(networks, scenes, arms)`` array of one method's differences, and the scenes' kinds."""
    sel = diffs[diffs["method"] == method]
    wide = sel.pivot_table(index=["network", "scene"], columns="arm", values="diff").reindex(columns=list(arms))
    nets = list(dict.fromkeys(sel["network"]))
    scenes = sorted(set(sel["scene"]))
    cube = np.stack([wide.loc[n].reindex(scenes).to_numpy(np.float64) for n in nets])
    from ..evaluate.stats import scene_kind

    return cube, [scene_kind(s) for s in scenes]


def _fmt_point(x: float, grid: Sequence[float]) -> str:
    if np.isneginf(x):
        return f"< {min(grid):g}"
    if np.isposinf(x):
        return f"> {max(grid):g}"
    return "none" if np.isnan(x) else f"{x:.2f}"


def crossover_table(diffs: pd.DataFrame, grid: StudyGrid) -> tuple[pd.DataFrame, dict[str, dict]]:
    """Per method, the crossover height of the mean transfer - ``lower`` curve with its interval.

    Returns
    -------
    table : DataFrame
        ``method, crossover, interval, direction, share_crossing`` (resamples with a sign change
        in the grid), the mean difference at every height (``d@0.1`` ...), ``networks, scenes``.
    estimates : dict
        Per method, :func:`crossover_estimate`'s dict (for the figure).
    """
    arms = [a.name for a in study_arms(grid) if a.factor == "height"]
    rows, est = [], {}
    for m in grid.methods:
        cube, kinds = _cube(diffs, m, arms)
        e = crossover_estimate(grid.heights, cube, kinds, networks_level=grid.networks_level,
                               n_resamples=grid.n_resamples, confidence=grid.confidence, seed=grid.seed)
        est[m] = e
        rows.append(dict(method=m, crossover=_fmt_point(e["crossover"], grid.heights),
                         interval=f"[{_fmt_point(e['lo'], grid.heights)}, {_fmt_point(e['hi'], grid.heights)}]",
                         direction=e["direction"], share_crossing=e["share_crossing"],
                         **{f"d@{h:g}": float(v) for h, v in zip(grid.heights, e["mean"], strict=True)},
                         networks=e["n_networks"], scenes=e["n_scenes"]))
    return pd.DataFrame(rows), est


def arms_table(diffs: pd.DataFrame, grid: StudyGrid) -> pd.DataFrame:
    """Per arm and method (:func:`arm_methods`): mean transfer - ``lower`` with its bootstrap
    interval, and its change from the reference height's arm (the tilt, appearance and coverage
    arms' comparator).

    Returns
    -------
    DataFrame
        ``arm, factor, method, diff, lo, hi, change, change_lo, change_hi`` (``change``: NaN for
        the height arms).
    """
    a = (1.0 - grid.confidence) / 2
    rows = []
    for m in grid.methods:
        arms = [arm for arm in study_arms(grid) if m in arm_methods(grid, arm)]
        names = [arm.name for arm in arms]
        ref = names.index(f"height {grid.reference_height:g}")
        cube, kinds = _cube(diffs, m, names)
        curves = resample_means(cube, kinds, networks_level=grid.networks_level, n_resamples=grid.n_resamples,
                                seed=grid.seed)
        mean = cube.mean(axis=(0, 1))
        lo, hi = np.quantile(curves, [a, 1 - a], axis=0)
        change = curves - curves[:, [ref]]
        clo, chi = np.quantile(change, [a, 1 - a], axis=0)
        for j, arm in enumerate(arms):
            other = arm.factor != "height"
            rows.append(dict(arm=arm.name, factor=arm.factor, method=m, diff=mean[j], lo=lo[j], hi=hi[j],
                             change=mean[j] - mean[ref] if other else np.nan, change_lo=clo[j] if other else np.nan,
                             change_hi=chi[j] if other else np.nan))
    return pd.DataFrame(rows)


def plot_crossover(estimates: Mapping[str, dict], grid: StudyGrid, path: str | Path, *, title: str = "") -> Path:
    """One panel per method: the mean transfer - ``lower`` curve over heights with its pointwise
    bootstrap band, zero, and the crossover (dashed) with its interval (shaded, clipped to the grid)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from ..io import save_figure

    methods = list(estimates)
    cols = min(3, len(methods))
    rows = -(-len(methods) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 2.9 * rows), sharex=True, sharey=True, squeeze=False)
    h = np.asarray(grid.heights)
    for ax, m in zip(axes.ravel(), methods, strict=False):
        e = estimates[m]
        ax.axhline(0.0, color="0.3", lw=0.8)
        ax.fill_between(h, e["band_lo"], e["band_hi"], color="#0072B2", alpha=0.2, lw=0)
        ax.plot(h, e["mean"], color="#0072B2", marker="o", ms=3.5, lw=1.8)
        lo, hi = np.clip([e["lo"], e["hi"]], h[0], h[-1])
        if not np.isnan(e["crossover"]):
            ax.axvspan(lo, hi, color="#D55E00", alpha=0.12, lw=0)
            ax.axvline(e["crossover"], color="#D55E00", ls="--", lw=1.4)
        label = (f"crossover {_fmt_point(e['crossover'], h)} m [{_fmt_point(e['lo'], h)}, {_fmt_point(e['hi'], h)}]"
                 if not np.isnan(e["crossover"]) else f"no crossover: {e['direction']}")
        ax.set_title(f"{m}\n{label}", fontsize=8.5)
        ax.grid(alpha=0.3)
    for ax in axes.ravel()[len(methods):]:
        ax.set_visible(False)
    for ax in axes[-1]:
        ax.set_xlabel("robot camera height (m)")
    for ax in axes[:, 0]:
        ax.set_ylabel(f"{grid.measure}: method - lower")
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


# ------------------------------------------------------------------------------------------------
# the study


def when_transfer_pays_study(data_root: str | Path, work: str | Path, scenes: Sequence[tuple[str, int]], *,
                             split: str = "eval", grid_path: str | Path | None = None, jobs: int = 1,
                             scheduler: str | None = None, progress: bool = True,
                             method_settings: Mapping[str, Mapping] | None = None) -> pd.DataFrame:
    """Every scene's rows (:func:`run_scene`), scenes as tasks of :func:`semmatch.runtime.engine.map_tasks`.

    Raises
    ------
    FileNotFoundError
        A network of the grid that ``data_root/models`` does not hold (before any work).
    """
    from ..runtime.engine import map_tasks
    from .layout import Layout

    grid_path = Path(grid_path or GRID_PATH)
    grid = load_grid(grid_path)
    missing = [str(Layout(data_root).model(n)) for n in grid.networks if not Layout(data_root).model(n).is_file()]
    if missing:
        raise FileNotFoundError(f"{', '.join(missing)}: no such network (the grid's networks: {list(grid.networks)})")
    fn = functools.partial(run_scene, str(Path(data_root).resolve()), str(Path(work).resolve()), str(grid_path), split,
                           method_settings=dict(method_settings or {}))
    per = map_tasks(fn, list(scenes), jobs=jobs, scheduler=scheduler, desc="when transfer pays (scenes)",
                    progress=progress)
    return pd.DataFrame([r for rows in per for r in rows])


def run_when_transfer_pays(data_root: str | Path, figures: str | Path, scenes: Sequence[tuple[str, int]], *,
                           work: str | Path | None = None, split: str = "eval", grid_path: str | Path | None = None,
                           jobs: int = 1, scheduler: str | None = None, progress: bool = True,
                           label: str = "", method_settings: Mapping[str, Mapping] | None = None) -> pd.DataFrame:
    """Run the study and write its results into ``figures`` (each file atomically).

    Writes ``when_transfer_pays_per_scene.{csv,md}`` (tidy: one row per scene, network, arm and
    method), ``when_transfer_pays_crossover.{csv,md}`` (:func:`crossover_table`),
    ``when_transfer_pays_arms.{csv,md}`` (:func:`arms_table`), ``when_transfer_pays.png``
    (:func:`plot_crossover`) and ``run.json`` (scenes, networks, minutes, per-scene seconds).

    Parameters
    ----------
    data_root : path
        A data root with ``models/`` (the grid's networks) and, optionally, the pipeline's scenes.
    figures : path
    scenes : sequence of (kind, seed)
    work : path, optional
        Rendered frames and kept rows (default ``data_root/when_transfer_pays``).
    split : str
        Where the pipeline's scenes are looked for (``data_root/scenes/<split>``).
    grid_path : path, optional
        Default the committed grid.
    jobs, scheduler, progress
        As :func:`semmatch.runtime.engine.map_tasks`.
    label : str
        Added to the figure's title (e.g. ``validation scenes``).
    method_settings : mapping, optional
        The methods' parameters, ``{method: {parameter: value}}`` (a run's ``slic_2d``).

    Returns
    -------
    DataFrame
        The crossover table.
    """
    from ..io import atomic_write_text
    from .tables import save_table

    grid_path = Path(grid_path or GRID_PATH)
    grid = load_grid(grid_path)
    figures = Path(figures)
    t0 = time.perf_counter()
    per_scene = when_transfer_pays_study(data_root, work or Path(data_root) / "when_transfer_pays", scenes,
                                         split=split, grid_path=grid_path, jobs=jobs, scheduler=scheduler,
                                         progress=progress, method_settings=method_settings)
    diffs = difference_table(per_scene, grid.measure)
    table, est = crossover_table(diffs, grid)
    save_table(per_scene, figures, "when_transfer_pays_per_scene", floatfmt=".4f")
    save_table(table, figures, "when_transfer_pays_crossover")
    save_table(arms_table(diffs, grid), figures, "when_transfer_pays_arms")
    n_sc, n_net = per_scene["scene"].nunique(), per_scene["network"].nunique()
    plot_crossover(est, grid, figures / "when_transfer_pays.png",
                   title=f"When transfer pays: {n_sc} scenes x {n_net} network(s)" + (f", {label}" if label else ""))
    timing = per_scene.groupby(["scene", "network"], sort=False)[["render_s", "render_cpu_s", "score_s",
                                                                   "score_cpu_s"]].first().reset_index()
    atomic_write_text(figures / "run.json", json.dumps(
        {"study_version": grid.raw.get("study_version"), "scenes": sorted(per_scene["scene"].unique().tolist()),
         "networks": list(grid.networks), "minutes": round((time.perf_counter() - t0) / 60, 2), "jobs": jobs,
         "seconds_per_scene": json.loads(timing.to_json(orient="records")),
         "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}, indent=1) + "\n")
    return table


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m semmatch.experiments.when_transfer_pays``: run the study, write its tables and figure."""
    from .pipeline import ROOT, read_params
    from .protocol import check_confirm_seeds

    ap = argparse.ArgumentParser(prog="python -m semmatch.experiments.when_transfer_pays",
                                 description=__doc__.splitlines()[0],
                                 formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    ap.add_argument("--seeds", type=int, nargs="+", required=True,
                    help="scene seeds: every kind of each (eval), or the full profile's validation scenes (val)")
    ap.add_argument("--split", choices=("eval", "val"), default="eval",
                    help="eval: fresh seeds or the full profile's development seeds; val: its val_seeds")
    ap.add_argument("--out", type=Path, required=True, help="tables, figure and run.json")
    ap.add_argument("--data", type=Path, default=ROOT / "data" / "full",
                    help="data root: models/<network>.pt and, where present, the pipeline's scenes")
    ap.add_argument("--work", type=Path, default=None, help="rendered frames and kept rows (default DATA/when_transfer_pays)")
    ap.add_argument("--grid", type=Path, default=GRID_PATH, help="the study's grid")
    ap.add_argument("--jobs", type=int, default=1, help="scenes at once")
    ap.add_argument("--label", default="", help="added to the figure's title")
    ap.add_argument("--quiet", action="store_true", help="no progress")
    args = ap.parse_args(argv)
    try:
        scenes = study_scenes(args.seeds, args.split)
        if args.split == "eval":
            profiles = read_params(ROOT / "params.yaml")["profiles"]
            dev = set(map(int, profiles["full"]["common"]["eval_seeds"]))
            fresh = [s for s in args.seeds if s not in dev]
            if fresh:
                check_confirm_seeds(fresh, profiles)
        table = run_when_transfer_pays(args.data, args.out, scenes, work=args.work, split=args.split,
                                       grid_path=args.grid, jobs=args.jobs, progress=not args.quiet, label=args.label)
    except (OSError, ValueError) as e:
        ap.exit(2, f"{ap.prog}: error: {e}\n")
    print(table.to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
