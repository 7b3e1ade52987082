"""The in-home adaptation study: a robot adapts inside the home it serves (issue 38 item 5).

A person has mapped a home with a human-height camera and a segmentation network. A robot
arrives; its first tour of the home, labelled from the person's map
(:func:`semmatch.segment.adapt.adapt_in_home`), is its adaptation data. Every arm then labels the robot's
*second* tour of the same home, which no arm adapted on, and is scored there as in Table 2: the
tour's frames fused with the arm's labels, against the tour fused with ground-truth labels, on
the evaluation grid. Arms: the unadapted network, the shipped network adapted across homes (on
training scenes), the network adapted in this home, transfer (``3d-neighborhood`` from the
person's map) and ``fused``. Comparisons are paired per home, with the analysis plan's inference
and verdict rule; the study's own plan (homes, sizes, recipe, arms, measures, comparisons) is
``in_home_plan.yaml``, committed before any of its homes was generated.

``python -m semmatch.experiments.in_home [--data DIR] [--figures DIR] [--jobs N]`` (``make in-home``)
runs it; docs/adapt.md ("The in-home study") describes the method and the result.
"""

from __future__ import annotations

import argparse
import functools
import json
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from ..segment.adapt import AdaptRecipe

__all__ = ["InHomePlan", "load_in_home_plan", "simulate_home", "person_map", "score_home", "run_home",
           "in_home_study", "run_in_home_study", "in_home_comparisons", "plot_in_home", "write_in_home_results",
           "ARMS", "PLAN_PATH"]

PLAN_PATH = Path(__file__).with_name("in_home_plan.yaml")
#: the arms, in table order
ARMS = ("unadapted", "across homes", "in home", "transfer", "fused")
_MAP_MEASURES = ("jaccard", "sorensen", "color_acc", "mean_acc")


@dataclass(frozen=True)
class InHomePlan:
    """The in-home study's plan as the code uses it (see ``in_home_plan.yaml``).

    Attributes
    ----------
    kinds, seeds : tuple
        The homes: every kind for every seed.
    simulation : dict
        ``n_frames_upper``, ``n_frames_lower``, ``upper_height``, ``lower_height``,
        ``image_width``, ``image_height``, ``camera_step``, ``scoring_tour_seed_offset``.
    profile, network, across_homes : str
        ``models/<profile>/<network>.pt`` and ``models/<profile>/adapted/<across_homes>.pt``.
    voxel_size, eval_voxel_size : float
    fused_base, source : str
    recipe : AdaptRecipe
    primary : str
    secondary : tuple of str
    comparisons : tuple of (str, str)
    raw : dict
        The whole YAML document.
    """

    kinds: tuple[str, ...]
    seeds: tuple[int, ...]
    simulation: dict
    profile: str
    network: str
    across_homes: str
    voxel_size: float
    eval_voxel_size: float
    fused_base: str
    source: str
    recipe: AdaptRecipe
    primary: str
    secondary: tuple[str, ...]
    comparisons: tuple[tuple[str, str], ...]
    raw: dict = field(default_factory=dict, compare=False, repr=False)

    @property
    def homes(self) -> list[tuple[str, int]]:
        """``(kind, seed)`` of every home, seed by seed."""
        return [(k, s) for s in self.seeds for k in self.kinds]


def load_in_home_plan(path: str | Path | None = None) -> InHomePlan:
    """Read the in-home study's plan (default: the committed ``in_home_plan.yaml``).

    Raises
    ------
    ValueError
        An arm of a comparison that is not one of :data:`ARMS`, a seed that is not an integer, or
        a missing entry (named).
    """
    path = Path(path or PLAN_PATH)
    d = yaml.safe_load(path.read_text())
    try:
        sim = dict(d["simulation"])
        comps = tuple((str(a), str(b)) for a, b in d["comparisons"])
        plan = InHomePlan(
            kinds=tuple(d["homes"]["kinds"]), seeds=tuple(int(s) for s in d["homes"]["seeds"]), simulation=sim,
            profile=str(d["networks"]["profile"]), network=str(d["networks"]["network"]),
            across_homes=str(d["networks"]["across_homes"]), voxel_size=float(d["voxel_size"]),
            eval_voxel_size=float(d["eval_voxel_size"]), fused_base=str(d["fused_base"]),
            source=str(d["adaptation"]["source"]), recipe=AdaptRecipe(**d["adaptation"]["recipe"]),
            primary=str(d["measures"]["primary"]), secondary=tuple(d["measures"]["secondary"]),
            comparisons=comps, raw=d)
    except (KeyError, TypeError) as e:
        raise ValueError(f"{path}: missing or malformed entry ({type(e).__name__}: {e})") from None
    bad = sorted({a for c in comps for a in c} - set(ARMS))
    if bad:
        raise ValueError(f"{path}: comparisons name unknown arms {bad}; arms: {', '.join(ARMS)}")
    return plan


def simulate_home(kind: str, seed: int, folder: str | Path, sim: Mapping) -> dict[str, Path]:
    """The home's scene and three tours: the person's (``upper``), the robot's first (``first``:
    adaptation) and second (``second``: scoring, the planner's seed + ``scoring_tour_seed_offset``).

    Returns
    -------
    dict
        ``{"upper", "first", "second"}``: sequence folders (rendered once; complete ones are kept).
    """
    from ..io.geometry import DEFAULT_INTRINSICS
    from ..sim import generate_scene
    from ..sim.raster import make_renderer
    from ..sim.simulate import carrier_poses, simulate_sequence

    folder = Path(folder)
    scene = generate_scene(kind, int(seed))
    intr = DEFAULT_INTRINSICS.scaled(int(sim["image_width"]), int(sim["image_height"]))
    step = float(sim["camera_step"])
    tours = {"upper": (float(sim["upper_height"]), int(sim["n_frames_upper"]), "upper", int(seed)),
             "first": (float(sim["lower_height"]), int(sim["n_frames_lower"]), "lower", int(seed)),
             "second": (float(sim["lower_height"]), int(sim["n_frames_lower"]), "lower",
                        int(seed) + int(sim["scoring_tour_seed_offset"]))}
    out, renderer = {}, None
    for name, (height, n, carrier, tour_seed) in tours.items():
        out[name] = folder / name
        if (out[name] / "poses.txt").is_file():
            continue
        renderer = renderer or make_renderer(scene, intr, backend="raycast")
        poses = carrier_poses(scene, height, n, carrier=carrier, seed=tour_seed, camera_step=step)
        simulate_sequence(scene, poses, out[name], intrinsics=intr, renderer=renderer, overwrite=True, progress=False,
                          meta={"trajectory": name, "seed": tour_seed, "height": height, "home": scene.name})
    return out


def person_map(upper: str | Path, network, out: str | Path, voxel_size: float) -> Path:
    """The person's semantic map: ``network``'s labels of the person's tour, fused at ``voxel_size``
    (as the pipeline's ``upper/<scene>/<network>.ply``), written with the tour's scene name."""
    from ..fusion import reconstruct
    from ..io import read_sequence, write_map
    from ..io.sequences import sequence_scene

    out = Path(out)
    if not out.is_file():
        frames = read_sequence(upper).load()
        m = reconstruct(frames, [network.predict_labels(f.rgb) for f in frames], voxel_size)
        write_map(out, m, scene=sequence_scene(upper))
    return out


def _arm_labels(frames, nets: Mapping, index, fused_base: str) -> dict[str, list[np.ndarray]]:
    """Every arm's labels of the scoring tour's frames."""
    from ..transfer import transfer_frame

    labels: dict[str, list[np.ndarray]] = {a: [] for a in ARMS}
    for f in frames:
        probs = nets["unadapted"].predict(f.rgb)
        labels["unadapted"].append(probs.argmax(axis=2).astype(np.uint8))
        for arm in ("across homes", "in home"):
            labels[arm].append(nets[arm].predict_labels(f.rgb))
        labels["transfer"].append(transfer_frame("3d-neighborhood", f, index).labels)
        labels["fused"].append(transfer_frame("fused", f, index, probs=probs, base=fused_base).labels)
    return labels


def score_home(second: str | Path, person: str | Path, nets: Mapping, *, voxel_size: float, eval_voxel_size: float,
               fused_base: str) -> list[dict]:
    """Score every arm on the robot's scoring tour (one row per arm).

    Each arm's labels of the tour's frames are fused with the tour (one TSDF, every labelling:
    :func:`semmatch.fusion.reconstruct_many`) and compared with the tour fused with its
    ground-truth labels on the ``eval_voxel_size`` grid (Table 2's measures); ``miou`` and
    ``pixel_acc`` score the labels of the frames themselves (10 evaluation classes), and
    ``labelled`` is the share of the frames' pixels with depth that the arm labels.
    """
    from ..evaluate.metrics import compare, pixel_metrics
    from ..fusion import reconstruct_many
    from ..io import read_map, read_sequence
    from ..transfer import as_map_index
    from .synthetic import eval_grid_origin

    frames = read_sequence(second).load()
    labels = _arm_labels(frames, nets, as_map_index(read_map(person)), fused_base)
    ref, *maps = reconstruct_many(frames, [None, *labels.values()], voxel_size)
    gt = [f.labels for f in frames]
    valid = np.concatenate([(f.depth > 0).reshape(-1) for f in frames])
    rows = []
    for arm, m in zip(labels, maps, strict=True):
        px = pixel_metrics(gt, labels[arm])
        lab = np.concatenate([x.reshape(-1) for x in labels[arm]]) > 0
        s = compare(ref, m, voxel_size=eval_voxel_size, grid_origin=eval_grid_origin(eval_voxel_size))
        rows.append({"arm": arm, **{k: float(s[k]) for k in _MAP_MEASURES}, "miou": float(px["miou"]),
                     "pixel_acc": float(px["pixel_acc"]), "labelled": float((lab & valid).sum() / max(valid.sum(), 1))})
    return rows


def _check_settings(hdir: Path, plan: InHomePlan, models: Path) -> None:
    """A home folder is reused (tours, map, adapted checkpoint) only for the settings it was made
    with: recorded in ``settings.json`` when the folder is made, compared on every later run.

    Raises
    ------
    ValueError
        The folder holds files but no settings record, or a record of other settings (named).
    """
    from ..io import atomic_write_text
    from ..segment.adapt.finetune import file_digest

    want = {"simulation": plan.simulation, "voxel_size": plan.voxel_size, "network": plan.network,
            "network_sha256": file_digest(models / f"{plan.network}.pt"), "source": plan.source,
            "recipe": plan.recipe.as_dict()}
    want = json.loads(json.dumps(want))  # the JSON form, as read back
    record = hdir / "settings.json"
    if record.is_file():
        got = json.loads(record.read_text())
        diff = sorted(k for k in set(want) | set(got) if want.get(k) != got.get(k))
        if diff:
            raise ValueError(f"{hdir}: made with other settings ({', '.join(diff)} differ); remove it or use "
                             "another --data folder")
        return
    if hdir.is_dir() and any(hdir.iterdir()):
        raise ValueError(f"{hdir}: holds files but no settings.json; remove it or use another --data folder")
    hdir.mkdir(parents=True, exist_ok=True)
    atomic_write_text(record, json.dumps(want, indent=1))


def run_home(data: str, plan_path: str, models: str, views_cache: str | None, home: tuple[str, int]) -> list[dict]:
    """One home of the study (an engine task): simulate, map, adapt in the home, score every arm.

    Returns
    -------
    list of dict
        One row per arm: ``home``, ``kind``, ``seed``, ``arm``, the map measures, ``miou``,
        ``pixel_acc``, ``labelled``; the ``in home`` row also ``label_coverage`` (the adaptation
        labels' share of the first tour's pixels with depth), ``finetune_s`` (the fine-tuning's
        wall seconds, from the checkpoint's record) and ``adapt_s`` / ``adapt_cpu_s`` (wall and CPU
        seconds of the whole adaptation, labelling included; NaN for a checkpoint of an earlier run).
    """
    from ..segment import load_model
    from ..segment.adapt import adapt_in_home

    plan = load_in_home_plan(plan_path)
    kind, seed = home
    hdir = Path(data) / "homes" / f"{kind}_{seed:04d}"
    _check_settings(hdir, plan, Path(models))
    tours = simulate_home(kind, seed, hdir, plan.simulation)
    net_path = Path(models) / f"{plan.network}.pt"
    net = load_model(net_path, device="cpu")
    person = person_map(tours["upper"], net, hdir / "person.ply", plan.voxel_size)
    adapted = hdir / "in_home.pt"
    seconds = cpu = float("nan")  # a checkpoint of an earlier run: not timed here
    if not adapted.is_file():
        t, c = time.perf_counter(), time.process_time()
        adapt_in_home(net_path, tours["first"], person, adapted, plan.recipe, source=plan.source,
                      cache_dir=views_cache or "checkpoint-if-present", progress=False)
        seconds, cpu = time.perf_counter() - t, time.process_time() - c
    nets = {"unadapted": net, "across homes": load_model(Path(models) / "adapted" / f"{plan.across_homes}.pt",
                                                         device="cpu"),
            "in home": load_model(adapted, device="cpu")}
    rows = score_home(tours["second"], person, nets, voxel_size=plan.voxel_size,
                      eval_voxel_size=plan.eval_voxel_size, fused_base=plan.fused_base)
    record = nets["in home"].info.get("adapted", {})
    for r in rows:
        r.update(home=f"{kind}_{seed:04d}", kind=kind, seed=seed)
        if r["arm"] == "in home":
            r.update(label_coverage=float(record.get("label_coverage", float("nan"))),
                     finetune_s=float(record.get("seconds", float("nan"))), adapt_s=seconds, adapt_cpu_s=cpu)
    return rows


def in_home_study(data: str | Path, *, plan_path: str | Path | None = None, models: str | Path | None = None,
                  views_cache: str | Path | None = None, homes: Sequence[tuple[str, int]] | None = None,
                  jobs: int = 1, scheduler: str | None = None, progress: bool = True) -> pd.DataFrame:
    """Run the study on every home of the plan (or ``homes``); per-home rows, one per arm.

    The first home runs alone (it renders the network's human-height views into ``views_cache``
    when they are not cached yet), the others as tasks of :func:`semmatch.runtime.engine.map_tasks`.
    A home whose adapted checkpoint exists is not adapted again.
    """
    from ..runtime.engine import map_tasks
    from .pipeline import ROOT

    plan_path = Path(plan_path or PLAN_PATH)
    plan = load_in_home_plan(plan_path)
    models = Path(models or ROOT / "models" / plan.profile)
    todo = list(homes or plan.homes)
    fn = functools.partial(run_home, str(data), str(plan_path), str(models),
                           None if views_cache is None else str(views_cache))
    rows = fn(todo[0]) + [r for rs in map_tasks(fn, todo[1:], jobs=jobs, scheduler=scheduler, desc="homes",
                                                progress=progress) for r in rs] if todo else []
    cols = ["home", "kind", "seed", "arm", *_MAP_MEASURES, "miou", "pixel_acc", "labelled", "label_coverage",
            "finetune_s", "adapt_s", "adapt_cpu_s"]
    return pd.DataFrame(rows).reindex(columns=cols)


def in_home_comparisons(per_home: pd.DataFrame, plan: InHomePlan, *, analysis_plan=None) -> pd.DataFrame:
    """The plan's comparisons, paired per home, for the primary and every secondary measure.

    The analysis plan's inference (interval method, confidence, Holm over the comparisons of one
    measure, ``sesoi`` of the measure, the ``beats`` verdict rule: holds / does not hold /
    equivalent / inconclusive). Under a v2 plan (``rules: v2``) its comparison rules instead
    (:func:`~semmatch.experiments.rules_v2.comparison_verdict_v2`: holds / against / equivalent /
    inconclusive, a family per measure), with all of their columns.

    Returns
    -------
    DataFrame
        ``measure``, ``role`` (primary / secondary), ``comparison``, ``diff``, ``lo``, ``hi``,
        ``homes``, ``p_holds``, ``p_against``, ``p_equivalent``, ``verdict``.
    """
    from ..evaluate.stats import holm
    from .analysis_plan import load_analysis_plan
    from .claims import _compare, _comparison_verdict

    ap = analysis_plan or load_analysis_plan()
    if ap.rules == "v2":
        return _comparisons_v2(per_home, plan, ap)
    wide_all = {m: per_home.pivot(index="home", columns="arm", values=m) for m in (plan.primary, *plan.secondary)}
    rows = []
    for measure, wide in wide_all.items():
        kinds = [h.rsplit("_", 1)[0] for h in wide.index]
        fam = []
        for a, b in plan.comparisons:
            c = _compare(wide[a].to_numpy(np.float64), wide[b].to_numpy(np.float64), kinds,
                         sesoi=float(ap.sesoi.get(measure, 0.02)), plan=ap, seed=0)
            if c is not None:
                fam.append({"measure": measure, "role": "primary" if measure == plan.primary else "secondary",
                            "comparison": f"{a} - {b}", **c})
        if not fam:
            continue
        f = pd.DataFrame(fam)
        f["p_holds"], f["p_against"], f["p_equivalent"] = holm(f["p_pos"]), holm(f["p_neg"]), holm(f["p_eq"])
        f["verdict"] = [_comparison_verdict("beats", h, g, e, ap.alpha)
                        for h, g, e in zip(f["p_holds"], f["p_against"], f["p_equivalent"])]
        rows.append(f.rename(columns={"scenes": "homes"}))
    cols = ["measure", "role", "comparison", "diff", "lo", "hi", "homes", "p_holds", "p_against", "p_equivalent",
            "verdict"]
    return pd.concat(rows, ignore_index=True)[cols] if rows else pd.DataFrame(columns=cols)


def _comparisons_v2(per_home: pd.DataFrame, plan: InHomePlan, ap) -> pd.DataFrame:
    """:func:`in_home_comparisons` under a v2 analysis plan (``ap``)."""
    from .claims import _compare
    from .rules_v2 import _judge_family_v2

    rows = []
    for measure in (plan.primary, *plan.secondary):
        wide = per_home.pivot(index="home", columns="arm", values=measure)
        kinds = [h.rsplit("_", 1)[0] for h in wide.index]
        sesoi = float(ap.sesoi.get(measure, 0.02))
        fam = [{"measure": measure, "role": "primary" if measure == plan.primary else "secondary",
                "comparison": f"{a} - {b}",
                **_compare(wide[a].to_numpy(np.float64), wide[b].to_numpy(np.float64), kinds, sesoi=sesoi,
                           plan=ap, seed=0)} for a, b in plan.comparisons]
        rows.append(_judge_family_v2(pd.DataFrame(fam), "beats", sesoi, ap.alpha))
    return pd.concat(rows, ignore_index=True).rename(columns={"scenes": "homes"})


def plot_in_home(per_home: pd.DataFrame, path: str | Path, *, measure: str = "mean_acc") -> Path:
    """One line per home across the arms (``measure``), the arms' means on top: the paired view."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wide = per_home.pivot(index="home", columns="arm", values=measure).reindex(columns=list(ARMS))
    x = np.arange(len(ARMS))
    fig, ax = plt.subplots(figsize=(7, 4))
    for _, row in wide.iterrows():
        ax.plot(x, row.to_numpy(np.float64), color="0.75", lw=0.8, marker="o", ms=3)
    ax.plot(x, wide.mean().to_numpy(np.float64), color="#0072B2", lw=2.2, marker="o", ms=6, label="mean over homes")
    ax.set_xticks(x, ARMS)
    ax.set_ylabel(measure.replace("_", " "))
    ax.set_title(f"In-home adaptation: {len(wide)} homes, scored on the robot's second tour")
    ax.legend(loc="lower right", frameon=False)
    ax.grid(axis="y", alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _views_cache(models: Path, network: str, data: Path) -> Path:
    """The network's recorded views cache where it exists on this machine, else ``data/views_cache``."""
    import torch

    rec = torch.load(models / f"{network}.pt", map_location="cpu", weights_only=True).get("train_config") or {}
    cached = rec.get("cache_dir")
    return Path(cached) if cached and Path(cached).is_dir() else data / "views_cache"


def write_in_home_results(per_home: pd.DataFrame, comparisons: pd.DataFrame, plan: InHomePlan,
                          figures: str | Path, *, minutes: float) -> list[Path]:
    """Write the study's tables (CSV and Markdown), its figure and ``run.json`` into ``figures``
    (each file atomically); return the paths."""
    from ..io import atomic_write_text
    from .tables import save_table

    figures = Path(figures)
    out = []
    for name, df in (("in_home_per_home", per_home), ("in_home_comparisons", comparisons)):
        out += list(save_table(df, figures, name))
    out.append(plot_in_home(per_home, figures / "in_home.png", measure=plan.primary))
    atomic_write_text(figures / "run.json", json.dumps(
        {"plan_version": plan.raw.get("plan_version"), "homes": int(per_home["home"].nunique()),
         "seeds": sorted(int(v) for v in per_home["seed"].unique()),
         "minutes": round(minutes, 1), "finished": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())}, indent=1))
    out.append(figures / "run.json")
    return out


def run_in_home_study(data: str | Path, figures: str | Path, *, plan_path: str | Path | None = None,
                      models: str | Path | None = None, homes: Sequence[tuple[str, int]] | None = None,
                      jobs: int = 1, scheduler: str | None = None, progress: bool = True,
                      analysis_plan=None) -> pd.DataFrame:
    """Run the study (:func:`in_home_study`), judge its comparisons and write its results into ``figures``.

    Parameters
    ----------
    data, figures : path
        Homes and adapted checkpoints; tables, figure and ``run.json``.
    plan_path : path, optional
        Default the committed plan.
    models : path, optional
        Shipped networks (default ``models/<the plan's profile>``).
    homes : sequence of (kind, seed), optional
        Other homes than the plan's (e.g. a confirmatory run's scenes); the rest of the plan holds.
    jobs, scheduler, progress
        As :func:`in_home_study`.
    analysis_plan : AnalysisPlan, optional
        The rules of the comparisons (:func:`in_home_comparisons`; default the v1 plan; a
        confirmatory run passes the plan of its seeds).

    Returns
    -------
    DataFrame
        The comparisons (:func:`in_home_comparisons`).
    """
    from .pipeline import ROOT

    plan = load_in_home_plan(plan_path)
    models = Path(models or ROOT / "models" / plan.profile)
    t0 = time.perf_counter()
    per_home = in_home_study(data, plan_path=plan_path, models=models, homes=homes, jobs=jobs, scheduler=scheduler,
                             views_cache=_views_cache(models, plan.network, Path(data)), progress=progress)
    comps = in_home_comparisons(per_home, plan, analysis_plan=analysis_plan)
    for p in write_in_home_results(per_home, comps, plan, figures, minutes=(time.perf_counter() - t0) / 60):
        if progress:
            print(p)
    return comps


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m semmatch.experiments.in_home``: run the study, write its tables and figure."""
    from .pipeline import ROOT, read_params
    from .protocol import check_confirm_seeds

    ap = argparse.ArgumentParser(prog="python -m semmatch.experiments.in_home", description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=ROOT / "data" / "in_home",
                    help="homes and adapted checkpoints (default %(default)s)")
    ap.add_argument("--figures", type=Path, default=ROOT / "figures" / "in_home",
                    help="tables and figure (default %(default)s)")
    ap.add_argument("--plan", type=Path, default=PLAN_PATH, help="the study's plan (default: the committed one)")
    ap.add_argument("--models", type=Path, default=None, help="shipped networks (default models/<the plan's profile>)")
    ap.add_argument("--jobs", type=int, default=1, help="homes run at once after the first (default %(default)s)")
    args = ap.parse_args(argv)
    try:
        plan = load_in_home_plan(args.plan)
        check_confirm_seeds(list(plan.seeds), read_params(ROOT / "params.yaml")["profiles"],
                            where=str(args.plan))
    except (OSError, ValueError) as e:
        ap.error(str(e))
    comps = run_in_home_study(args.data, args.figures, plan_path=args.plan, models=args.models, jobs=args.jobs)
    print(comps[comps["role"] == "primary"].to_string(index=False))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
