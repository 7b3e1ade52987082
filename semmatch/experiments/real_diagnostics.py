"""Diagnostics of the real-like chain (Table 3): what each of its parts costs the robot's labels.

Table 3's chain (:mod:`semmatch.experiments.real`) turns noisy frames, drifting pose priors,
RGB-D odometry and map registration into one score per scene. This study runs the same chain
(:func:`semmatch.experiments.real.chain_from_poses`) in arms that switch its parts off one at a
time, on the same scenes, paired per scene:

* ``clean, true poses``: the clean renderings at their true poses, the two recordings placed by
  the true relative transform: what is left is the transfer itself;
* ``noisy, true poses``: Kinect-like frames (depth noise, dropouts, RGB noise, exposure) at the
  true poses: the cost of the sensor;
* ``clean, estimated poses``: clean frames, poses by the chain's odometry and registration: the
  cost of the poses alone;
* ``chain``: noisy frames at estimated poses, both cameras' odometry seeded by a drifting prior
  (wheel odometry or an IMU would give it): Table 3's chain;
* ``person visual-only``: as ``chain``, but the person's camera is tracked from its frames
  alone (no prior: the paper's person used visual SLAM); the robot keeps its wheel-odometry-like
  prior;
* ``held-out appearance, true poses`` and ``chain, held-out appearance``: the noisy recordings
  with their RGB rendered in a look no training view shows (:mod:`semmatch.sim.appearance`:
  held-out materials, textures and lighting; depth, labels and priors unchanged), at the true
  poses and through the whole chain: the appearance gap the paper's networks met on real images
  (issue 36 item 5). The same two arms run with that look blended into the training look at
  :data:`APPEARANCE_SEVERITY` (``x0.35``), the severity at which the robot's network loses what
  the paper's lost on real images, chosen on the validation scenes
  (:func:`semmatch.experiments.appearance_severity.appearance_severity_on_validation`). The
  recordings are written once per scene under ``<data_root>/real_diagnostics/appearance/``
  (:func:`heldout_recording`); they and every cache made from them (labels, poses, the arms'
  results) are keyed by the look's code (:func:`semmatch.experiments.appearance_severity.look_digest`).

Arms with estimated poses run in ``draws`` draws: draw ``d`` regenerates each recording's prior
with :func:`semmatch.sim.noise.estimated_poses` from the recording's own noise settings and the
random stream ``d`` (draw 0 is the recorded ``poses.txt``, bit for bit: Table 3's prior), and
registers the maps with RANSAC seeds ``d * restarts ...``. A per-scene value is the mean over
draws, so the draws' spread is inside the intervals over scenes; the spread of the mean over
scenes from draw to draw is reported beside them. ``chain`` also runs at other drift levels:
the priors' drift (``drift_t``, ``drift_r``) scaled by each level, the same random stream
(level 0: the true motions plus the per-frame jitter).

Sources: the ground-truth upper map (the ``ground truth`` rows) and each network's; methods
as given, with ``lower`` (the network on the robot's frames), ``fused`` and ``upper`` (the
network's own upper map against the person's reference: claim C16). Every score uses the
chain's own reference (the robot's frames of the arm, fused at the arm's poses with
ground-truth labels), as Table 3 does.

``python -m semmatch.experiments.real_diagnostics --profile full`` (``make real-diagnostics``)
runs it on the profile's evaluation scenes (the development scenes: it decides nothing) and
writes ``figures/<profile>_real_diagnostics/`` (tables and figure:
:mod:`semmatch.experiments.real_diagnostics_tables`); docs/protocol.md ("Diagnosing the real-like
chain") reports the result.
"""

from __future__ import annotations

import argparse
import functools
import json
import time
import zlib
from collections.abc import Sequence
from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import pandas as pd

from .appearance_severity import (
    APPEARANCE_SEVERITY,
    PAPER_KEPT,
    appearance_severity_on_validation,
    look_digest,
)
from .layout import GT, Layout

__all__ = ["Arm", "ARMS", "FRAMES", "APPEARANCE_SEVERITY", "frames_kind", "heldout_recording", "PAPER_KEPT",
           "appearance_severity_on_validation", "diagnostic_arms", "drifted_prior", "predict_scene", "run_arm",
           "real_like_diagnostics", "main"]


@dataclass(frozen=True)
class Arm:
    """One arm of the study: which frames, which poses, which priors.

    Attributes
    ----------
    name : str
    frames : str
        The recordings' renderings: ``clean`` (``upper``/``lower``), ``noisy``
        (``upper_noisy``/``lower_noisy``), ``heldout`` (the noisy ones with the held-out
        appearance, :func:`heldout_recording`) or ``heldout@S`` (that look at severity ``S``).
    poses : {"true", "estimated"}
        True poses and relative transform, or odometry plus registration.
    person_prior : bool
        The person's odometry is seeded by its drifting prior (else visual only).
    drift : float
        Scale of the priors' drift (1: the simulator's Kinect-like setting).
    """

    name: str
    frames: str
    poses: str
    person_prior: bool = True
    drift: float = 1.0

    @property
    def random(self) -> bool:
        """Whether its result depends on the draw (estimated poses)."""
        return self.poses == "estimated"

    @property
    def slug(self) -> str:
        """Folder name of the arm's work."""
        return f"{self.name.replace(' ', '_').replace(',', '')}_drift{self.drift:g}"


#: the arms at the simulator's drift (module documentation)
ARMS = (
    Arm("clean, true poses", "clean", "true"),
    Arm("noisy, true poses", "noisy", "true"),
    Arm("clean, estimated poses", "clean", "estimated"),
    Arm("chain", "noisy", "estimated"),
    Arm("person visual-only", "noisy", "estimated", person_prior=False),
    Arm("held-out appearance, true poses", "heldout", "true"),
    Arm("chain, held-out appearance", "heldout", "estimated"),
    Arm(f"held-out appearance x{APPEARANCE_SEVERITY:g}, true poses", f"heldout@{APPEARANCE_SEVERITY:g}", "true"),
    Arm(f"chain, held-out appearance x{APPEARANCE_SEVERITY:g}", f"heldout@{APPEARANCE_SEVERITY:g}", "estimated"),
)

#: the kinds of frames an arm can use
FRAMES = ("clean", "noisy", "heldout")


def diagnostic_arms(drift_levels: Sequence[float] = (0.0, 1.0, 2.0, 4.0)) -> list[Arm]:
    """:data:`ARMS` and ``chain`` at every other drift level of ``drift_levels``.

    Raises
    ------
    ValueError
        A negative or non-finite level.
    """
    levels = [float(v) for v in drift_levels]
    if any(not np.isfinite(v) or v < 0 for v in levels):
        raise ValueError(f"drift levels must be finite and >= 0, got {list(drift_levels)}")
    return [*ARMS, *(Arm("chain", "noisy", "estimated", drift=v) for v in sorted(set(levels)) if v != 1.0)]


def drifted_prior(seq_dir: str | Path, true: np.ndarray, *, drift: float = 1.0, draw: int = 0) -> np.ndarray:
    """A recording's drifting pose prior, regenerated: draw ``draw``, its drift scaled by ``drift``.

    The simulator's :func:`semmatch.sim.noise.estimated_poses` with the noise settings in the
    recording's ``meta.json``; draw 0 uses the recording's own random stream, draw ``d`` the
    stream ``[seed, d]``. Draw 0 at ``drift=1`` is the recorded ``poses.txt`` itself (the
    regenerated poses agree with it to the file's rounding, but the odometry starts from the
    prior, and the file is what Table 3's chain reads).

    Parameters
    ----------
    seq_dir : path
        The noisy recording (its ``meta.json`` holds ``noise``).
    true : ndarray (N, 4, 4)
        Its true poses.
    drift : float
        Factor on ``drift_t`` and ``drift_r`` (the jitter is kept).
    draw : int

    Returns
    -------
    ndarray (N, 4, 4)

    Raises
    ------
    ValueError
        ``meta.json`` without noise settings.
    """
    from dataclasses import replace

    from ..io import read_tum
    from ..sim import NoiseConfig
    from ..sim.noise import estimated_poses

    if draw == 0 and drift == 1.0 and (Path(seq_dir) / "poses.txt").is_file():
        recorded = read_tum(Path(seq_dir) / "poses.txt")[1]
        if len(recorded) == len(true):
            return recorded
    meta_file = Path(seq_dir) / "meta.json"
    noise = json.loads(meta_file.read_text()).get("noise")
    if not isinstance(noise, dict):
        raise ValueError(f"{meta_file}: no 'noise' settings to regenerate the recording's prior from")
    names = {f.name for f in fields(NoiseConfig)}
    cfg = NoiseConfig(**{k: v for k, v in noise.items() if k in names})
    cfg = replace(cfg, drift_t=cfg.drift_t * drift, drift_r=cfg.drift_r * drift)
    rng = np.random.default_rng(cfg.seed if draw == 0 else [int(cfg.seed), int(draw)])
    return estimated_poses(np.asarray(true, dtype=np.float64), cfg, rng)


def _inputs_digest(data_root: str | Path, sid: str, networks: Sequence[str]) -> str:
    """What the cached labels, poses and results of a scene were made from: its noisy recordings'
    settings and true poses and each network's checkpoint (12 hex digits; ``-`` for a network
    without a checkpoint file, e.g. a test's oracle)."""
    import hashlib

    from ..segment.adapt.finetune import file_digest

    layout = Layout(data_root)
    sd = layout.scenes / "eval" / sid
    parts = [file_digest(sd / f"{r}_noisy" / f) for r in ("upper", "lower") for f in ("meta.json", "poses_gt.txt")]
    parts += [file_digest(layout.model(n)) if layout.model(n).is_file() else "-" for n in networks]
    return hashlib.sha256("/".join(parts).encode()).hexdigest()[:12]


def _look_tag(frames: str) -> str:
    """What a held-out-look cache is keyed on besides its inputs: ``-look<digest>`` over the code
    that renders the look (:func:`semmatch.experiments.appearance_severity.look_digest`), so that
    a change to the look renders, predicts and scores again; empty for clean and noisy frames."""
    return "-look" + look_digest() if frames_kind(frames)[0] == "heldout" else ""


def _labels_folder(data_root: str | Path, sid: str, frames: str, recording: str, network: str, digest: str) -> Path:
    """Where a network's labels of a scene's recording (clean, noisy or held-out-look frames) are
    kept for every arm."""
    return (Path(data_root) / "real_diagnostics" / "labels" / f"{sid}-{digest}" / f"{frames}{_look_tag(frames)}"
            / f"{recording}_{network}")


def heldout_recording(data_root: str | Path, sid: str, recording: str, severity: float = 1.0) -> Path:
    """The scene's noisy ``recording`` (``upper`` or ``lower``) with the held-out appearance at
    ``severity`` (:func:`semmatch.sim.appearance.write_heldout_recording`), written on first use
    under ``<data_root>/real_diagnostics/appearance/<scene>-<inputs>/`` (``<recording>`` at
    severity 1, else ``<recording>@<severity>``, then the look's code digest, :func:`_look_tag`).
    The labels predicted on it, the poses estimated from it and the arms' cached results carry the
    same digest, so a change to the look's code makes them again."""
    from ..sim.appearance import write_heldout_recording

    layout = Layout(data_root)
    name = recording if float(severity) == 1.0 else f"{recording}@{float(severity):g}"
    name += _look_tag("heldout")
    out = Path(data_root) / "real_diagnostics" / "appearance" / f"{sid}-{_inputs_digest(data_root, sid, ())}" / name
    if not out.is_dir():
        try:
            write_heldout_recording(layout.scenes / "eval" / sid / f"{recording}_noisy", out, severity=severity)
        except FileExistsError:  # another worker wrote it meanwhile
            pass
    return out


def frames_kind(frames: str) -> tuple[str, float]:
    """An arm's ``frames`` as (kind, appearance severity): ``heldout@0.4`` is ``("heldout", 0.4)``,
    ``heldout`` severity 1, the others severity 0.

    Raises
    ------
    ValueError
        An unknown kind or a severity outside (0, 1].
    """
    kind, _, level = str(frames).partition("@")
    if kind not in FRAMES or (level and kind != "heldout"):
        raise ValueError(f"unknown frames {frames!r}; valid: clean, noisy, heldout or heldout@SEVERITY")
    severity = (float(level) if level else 1.0) if kind == "heldout" else 0.0
    if kind == "heldout" and not 0.0 < severity <= 1.0:
        raise ValueError(f"frames {frames!r}: the appearance severity must be in (0, 1]")
    return kind, severity


def _recording(data_root: str | Path, sd: Path, recording: str, frames: str) -> Path:
    kind, severity = frames_kind(frames)
    if kind == "heldout":
        return heldout_recording(data_root, sd.name, recording, severity)
    return sd / (f"{recording}_noisy" if kind == "noisy" else recording)


def predict_scene(data_root: str, networks: tuple[str, ...], task: tuple[str, str]) -> list[Path]:
    """Each network's labels of a scene's two recordings, clean or noisy (``task``: scene, frames),
    predicted once for every arm (labels do not depend on poses); existing folders are kept
    (a labels folder is swapped in whole)."""
    from ..io import read_sequence
    from ..segment import predict_sequence

    sid, frames = task
    layout = Layout(data_root)
    sd = layout.scenes / "eval" / sid
    out = []
    for net in networks:
        model, digest = None, _inputs_digest(data_root, sid, [net])
        for recording in ("upper", "lower"):
            folder = _labels_folder(data_root, sid, frames, recording, net, digest)
            if not folder.is_dir():
                model = model or layout.load_network(net)
                predict_sequence(model, read_sequence(_recording(data_root, sd, recording, frames)), folder,
                                 progress=False)
            out.append(folder)
    return out


def run_arm(data_root: str, networks: tuple[str, ...], methods: tuple[str, ...], o: dict,
            task: tuple[Arm, int, str]) -> dict:
    """One arm, one draw, one scene (a task of :func:`real_like_diagnostics`).

    Writes under ``<data_root>/real_diagnostics/<arm>/d<draw>/<scene>/`` (the chain's maps and
    labels, ``result.json``) and ``real_diagnostics/poses/<scene>-<inputs>/`` (the estimated poses, one
    file per frames, recording and prior: arms with the same prior share them); a
    ``result.json`` made with the same settings and inputs (:func:`_inputs_digest`) is reused.
    The networks' labels are those of
    :func:`predict_scene` where it has run. The registration error is measured against the
    trajectories' alignment to the truth (uncertain by about their ATE).

    Returns
    -------
    dict
        ``rows`` (scores), ``trajectories`` and ``registration`` (errors), each a list of dicts
        carrying ``arm``, ``drift``, ``draw`` and ``scene``; ``reused``: whether it was read from
        an earlier run's ``result.json``.
    """
    from ..io import atomic_write_text, read_sequence, read_tum
    from ..poses.rgbd_odometry import open3d_threads
    from .real import chain_from_poses, trajectory_row
    from .real_poses import PosedSequence, cached_odometry, gate_name

    arm, draw, sid = task
    layout = Layout(data_root)
    sd = layout.scenes / "eval" / sid
    work = Path(data_root) / "real_diagnostics" / arm.slug / f"d{draw}" / sid
    poses_dir = Path(data_root) / "real_diagnostics" / "poses" / f"{sid}-{_inputs_digest(data_root, sid, ())}"
    settings = dict(arm=arm.name, frames=arm.frames, poses=arm.poses, person_prior=arm.person_prior,
                    drift=arm.drift, draw=draw, networks=list(networks), methods=list(methods),
                    inputs=_inputs_digest(data_root, sid, networks) + _look_tag(arm.frames),
                    **{k: (list(v) if isinstance(v, tuple) else v) for k, v in o.items()})
    done = work / "result.json"
    if done.is_file():
        prev = json.loads(done.read_text())
        if prev.get("settings") == settings:
            return dict(prev["result"], reused=True)
    work.mkdir(parents=True, exist_ok=True)
    tag = dict(arm=arm.name, drift=arm.drift, draw=draw, scene=sid)
    models = {net: layout.load_network(net) for net in networks}
    seqs, est, true, traj = {}, {}, {}, []
    with open3d_threads(1):  # Open3D's sums and RANSAC repeat run to run on one thread
        for name in ("upper", "lower"):
            folder = sd / f"{name}_noisy"
            if not folder.is_dir():
                raise FileNotFoundError(f"{folder}: no noisy recording; run 01_simulate with noise on")
            true[name] = read_tum(folder / "poses_gt.txt")[1]
            frames = read_sequence(_recording(data_root, sd, name, arm.frames)).load()
            if len(frames) != len(true[name]):
                raise ValueError(f"{sd / name}: {len(frames)} frames against {len(true[name])} true poses")
            if arm.poses == "true":
                est[name] = true[name]
            else:
                use_prior = name == "lower" or arm.person_prior
                prior = drifted_prior(folder, true[name], drift=arm.drift, draw=draw) if use_prior else None
                if prior is not None:
                    traj.append(tag | trajectory_row(sid, name, "prior", prior, true[name]))
                spec = f"drift{arm.drift:g}_d{draw}" if prior is not None else "visual"
                cache = poses_dir / f"{arm.frames}{_look_tag(arm.frames)}_{name}_{spec}_{gate_name(o['tol'])}.txt"
                cache.parent.mkdir(parents=True, exist_ok=True)
                est[name] = cached_odometry(frames, cache, prior=prior, prior_tolerance=o["tol"], progress=False)
                traj.append(tag | trajectory_row(sid, name, "estimated", est[name], true[name]))
            seqs[name] = PosedSequence(frames, est[name])
        sources = (*networks, GT)  # the first network's map is registered onto, as in Table 3
        oo = dict(o, registration_seed=int(draw) * int(o["registration_restarts"]))
        predicted = {(r, n): _labels_folder(data_root, sid, arm.frames, r, n, _inputs_digest(data_root, sid, [n]))
                     for r in ("upper", "lower") for n in networks}
        rows, reg = chain_from_poses(sd, work, seqs, est, true, models, methods, sources, oo,
                                     transform=np.eye(4) if arm.poses == "true" else None,
                                     predicted={k: v for k, v in predicted.items() if v.is_dir()})
    keep = ("reg_trans_err_m", "reg_rot_err_deg", "fitness", "agreement")
    result = dict(rows=[tag | r for r in rows], trajectories=traj,
                  registration=[tag | {k: float(reg[k]) for k in keep}])
    atomic_write_text(done, json.dumps(dict(settings=settings, result=result), indent=1))
    return dict(result, reused=False)


def _task_order(task: tuple[Arm, int, str]) -> int:
    """A stable spread of tasks over workers (scene-major order would pair the slow scenes)."""
    arm, draw, sid = task
    return zlib.crc32(f"{arm.slug}/{draw}/{sid}".encode())


def real_like_diagnostics(data_root: str | Path, *, networks: Sequence[str] = ("compact",),
                          methods: Sequence[str] = ("3d-neighborhood",), arms: Sequence[Arm] | None = None,
                          draws: int = 3, sweep_draws: int = 1, scenes: Sequence[str] | None = None, voxel_size: float = 0.04,
                          eval_voxel_size: float = 0.05, prior_tolerance=(0.1, 10.0), fused_base: str = "3d-neighborhood",
                          registration_voxel: float = 0.1, registration_restarts: int = 3, jobs: int = 1,
                          scheduler: str | None = None, progress: bool = True) -> dict[str, pd.DataFrame]:
    """Run every arm (module documentation) on the evaluation scenes of ``data_root``.

    Parameters
    ----------
    data_root : path
        A profile's data folder (``scenes/eval`` with noisy recordings, ``models``).
    networks, methods : sequences of str
        Networks (upper-map sources beside the ground truth) and transfer methods.
    arms : sequence of Arm, optional
        Default :func:`diagnostic_arms`.
    draws : int
        Draws of each arm with estimated poses (>= 1); arms at true poses run once.
    sweep_draws : int
        Draws of the arms at another drift than the simulator's (at most ``draws``).
    scenes : sequence of str, optional
        Scene ids (default every evaluation scene).
    voxel_size, eval_voxel_size, prior_tolerance, fused_base, registration_voxel, registration_restarts
        As :func:`semmatch.experiments.real.evaluate_real_like` (Table 3's values by default).
    jobs, scheduler, progress
        Tasks (arm, draw, scene) on :func:`semmatch.runtime.engine.map_tasks`.

    Returns
    -------
    dict of DataFrame
        ``scores`` (arm, drift, draw, scene, model, method, the four measures),
        ``trajectories`` (arm, drift, draw, scene, sequence, poses, ate_rmse, ...) and
        ``registration`` (arm, drift, draw, scene, reg_trans_err_m, reg_rot_err_deg, fitness,
        agreement) and ``tasks`` (arm, drift, draw, scene, reused: computed by an earlier run).

    Raises
    ------
    ValueError
        ``draws < 1``, ``fused_base`` not among the methods, an unknown scene.
    """
    from ..runtime.engine import map_tasks
    from .real_poses import check_tolerance

    if int(draws) < 1:
        raise ValueError(f"draws must be >= 1, got {draws}")
    if fused_base not in methods:
        raise ValueError(f"fused_base {fused_base!r} is not among the methods {list(methods)}")
    layout = Layout(data_root)
    known = [sd.name for sd in layout.scene_dirs("eval")]
    scenes = list(known if scenes is None else scenes)
    unknown = sorted(set(scenes) - set(known))
    if unknown:
        raise ValueError(f"{layout.scenes / 'eval'}: no evaluation scene {unknown}")
    arms = list(diagnostic_arms() if arms is None else arms)
    o = dict(voxel_size=float(voxel_size), eval_voxel_size=float(eval_voxel_size),
             tol=check_tolerance(prior_tolerance), fused_base=fused_base, registration_voxel=float(registration_voxel),
             registration_seed=0, registration_restarts=int(registration_restarts), frame_jobs=1,
             world_truth="traj")

    def n_draws(a: Arm) -> int:
        return 1 if not a.random else int(draws) if a.drift == 1.0 else max(1, min(int(draws), int(sweep_draws)))

    pred = [(s, f) for s in scenes for f in dict.fromkeys(a.frames for a in arms)]
    map_tasks(functools.partial(predict_scene, str(data_root), tuple(networks)), pred, jobs=jobs, scheduler=scheduler,
              desc="network labels", progress=progress)
    tasks = sorted([(a, d, s) for a in arms for d in range(n_draws(a)) for s in scenes], key=_task_order)
    fn = functools.partial(run_arm, str(data_root), tuple(networks), tuple(methods), o)
    results = map_tasks(fn, tasks, jobs=jobs, scheduler=scheduler, desc="diagnostic arms", progress=progress)
    parts = {"scores": "rows", "trajectories": "trajectories", "registration": "registration"}
    out = {name: pd.DataFrame([r for res in results for r in res[key]]) for name, key in parts.items()}
    out["tasks"] = pd.DataFrame([dict(arm=a.name, drift=a.drift, draw=d, scene=s, reused=bool(res["reused"]))
                                 for (a, d, s), res in zip(tasks, results, strict=True)])
    return out


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m semmatch.experiments.real_diagnostics``: run the arms, write the tables and figure."""
    from .pipeline import ROOT
    from .real_diagnostics_tables import write_diagnostics

    ap = argparse.ArgumentParser(prog="python -m semmatch.experiments.real_diagnostics",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--profile", default="full", help="data/<profile> holds the scenes and networks (%(default)s)")
    ap.add_argument("--data", type=Path, default=None, help="data folder instead of data/<profile>")
    ap.add_argument("--figures", type=Path, default=None,
                    help="tables and figure (default figures/<profile>_real_diagnostics)")
    ap.add_argument("--networks", nargs="+", default=["compact"], help="networks (default %(default)s)")
    ap.add_argument("--methods", nargs="+", default=["3d-neighborhood"], help="transfer methods (default %(default)s)")
    ap.add_argument("--draws", type=int, default=3, help="draws of each arm with estimated poses (%(default)s)")
    ap.add_argument("--sweep-draws", type=int, default=1,
                    help="draws of the chain at the other drift levels (%(default)s)")
    ap.add_argument("--drift-levels", type=float, nargs="+", default=[0.0, 1.0, 2.0, 4.0],
                    help="prior drift levels of the chain arm, x the simulator's (default %(default)s)")
    ap.add_argument("--scenes", nargs="+", default=None, help="scene ids (default every evaluation scene)")
    ap.add_argument("--jobs", type=int, default=1, help="local worker processes (%(default)s)")
    ap.add_argument("--choose-severity", action="store_true",
                    help="only choose the appearance severity on the validation scenes (writes "
                         "appearance_severity_validation.md beside the tables; APPEARANCE_SEVERITY holds the choice)")
    ap.add_argument("--scheduler", default=None, help="Dask scheduler address (default SEMMATCH_SCHEDULER)")
    args = ap.parse_args(argv)
    data = args.data or ROOT / "data" / args.profile
    figures = args.figures or ROOT / "figures" / f"{args.profile}_real_diagnostics"
    if not (data / "scenes" / "eval").is_dir():
        ap.error(f"{data / 'scenes' / 'eval'}: no evaluation scenes; run the profile's pipeline first "
                 f"(make repro PROFILE={args.profile})")
    if args.choose_severity:
        from .tables import save_table

        table, chosen = appearance_severity_on_validation(data, args.networks[0], jobs=args.jobs)
        save_table(table, figures, "appearance_severity_validation")
        print(table.round(3).to_string(), f"\nchosen severity {chosen:g} (APPEARANCE_SEVERITY = {APPEARANCE_SEVERITY:g})")
        return 0
    try:
        arms = diagnostic_arms(args.drift_levels)
    except ValueError as e:
        ap.error(str(e))
    t0 = time.time()
    if args.methods and "3d-neighborhood" not in args.methods:
        ap.error(f"--methods {' '.join(args.methods)}: the fused rows need 3d-neighborhood among them")
    try:
        result = real_like_diagnostics(data, networks=args.networks, methods=args.methods, arms=arms,
                                       draws=args.draws, sweep_draws=args.sweep_draws, scenes=args.scenes,
                                       jobs=args.jobs, scheduler=args.scheduler)
    except (ValueError, FileNotFoundError) as e:  # a bad scene, draw count or missing network, named
        ap.error(str(e))
    settings = dict(profile=args.profile, networks=args.networks, methods=args.methods, draws=args.draws,
                    sweep_draws=args.sweep_draws, drift_levels=args.drift_levels)
    for p in write_diagnostics(result, figures, minutes=(time.time() - t0) / 60, settings=settings,
                               arms=[a.name for a in ARMS]):
        print(p)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
