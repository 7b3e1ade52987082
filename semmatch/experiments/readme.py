"""Write the results from the tables and figures under ``figures/<profile>/``: every table and
figure into ``docs/results.md`` (generated whole), and a headline (Table 2's figure and the
claims' verdicts) into ``README.md`` between ``<!-- RESULTS:BEGIN -->`` and ``<!-- RESULTS:END -->``.
Once the analysis plan's confirmatory run exists (``figures/confirm/<name>/`` on the plan's
confirmatory seeds, with the shipped networks), the headline comes from it and its tables go to
``docs/results_confirmatory.md``; the development results stay in ``docs/results.md``.
Everything there is generated, so both show exactly what the last run produced.
"""

from __future__ import annotations

import json
import os
from pathlib import Path

from ..io import atomic_write_text

__all__ = ["results_markdown", "headline_markdown", "variance_markdown", "training_seeds_markdown", "update_readme", "confirmatory_run"]

BEGIN, END = "<!-- RESULTS:BEGIN -->", "<!-- RESULTS:END -->"

_SECTIONS = (
    ("frames_upper_lower.png", None, "An upper (1.6 m) and a lower (0.2 m) frame of an evaluation scene: RGB, depth, labels."),
    ("routes.png", None, "The two cameras' own tours through every evaluation scene (the paper's setup; dotted: the route ablation, the robot replaying the person's tour), with the share of the free space each tour passes within 1.5 m of."),
    ("support_per_scene.png", None, "Share of the robot's pixels (with depth) that the person's map supports, per evaluation scene, on the robot's own tour and on the replayed route."),
    ("fig_transferred_frames.png", None, "Robot frames of one evaluation scene: RGB, ground truth and the labels each method transferred from the ground-truth upper map (black: no support in the person's map)."),
    ("table1_speed.png", "table1_speed.md", "**Table 1 (speed).** Transfer methods on 640x480 frames, one process on this 2-core machine, beside the paper's server numbers and the reference closest-point backend measured in the same run."),
    (None, "claims_speed.md", "The paper's speed statements judged on Table 1 by the analysis plan:"),
    ("table2_synthetic.png", "table2_synthetic.md", "**Table 2 (synthetic).** Lower-view semantic reconstructions on the robot's own tour, scored against the lower frames fused with ground-truth labels (5 cm voxels): mean [95% interval] over the evaluation scenes; `fused` = transferred labels where the person's map supports a pixel, the lower-view network elsewhere; `paper_mean_acc`: the paper's value (compact ~ Mask R-CNN, strong ~ Transfiner)."),
    (None, "findings_synthetic.md", None),
    (None, "table2_mesh_reference.md", "**Table 2 against an independent reference**: the ground-truth mesh where the robot's camera observed it (geometry errors of the fusion count)."),
    (None, "table2_route_ablation.md", "**Route ablation**: the robot on its own tour (`own`) and replaying the person's tour there and back (`shared`, the earlier protocol)."),
    ("fig3_height.png", "fig3_height.md", "**Fig. 3 (viewpoint gap).** Accuracy of the networks trained at human height against camera height, camera tilting ±20°: mean [95% interval] over the evaluation scenes."),
    (None, "findings_height.md", None),
    ("table3_real.png", "table3_real.md", "**Table 3 (real-like).** Sensor noise on, each recording's poses estimated by RGB-D odometry from an unknown start, the two reconstructions registered to each other without ground truth: mean [95% interval] over the evaluation scenes."),
    (None, "table3_mesh_reference.md", "**Table 3 against the ground-truth mesh** (observed part; the robot's map brought into the world frame for scoring only)."),
    (None, "trajectory_error_summary.md", "Trajectory and registration errors of the real-like chain (m, deg; mean over scenes):"),
    ("misregistration.png", None, "**Misregistration study.** Mean Acc. of every method when the ground-truth upper map is shifted or rotated against the robot's frames (mean and 95% interval over scenes)."),
    ("depth_noise.png", None, "**Depth-noise study (claim C13-noise).** Mean Acc. of every method when the robot's depth gets the simulator's Kinect-like noise times 0, 1 and 4 (labels transferred from the ground-truth map with the noisy depth, fused at the clean depth; mean and 95% interval over scenes)."),
    (None, "findings_real.md", None),
    ("fig4_qualitative.png", None, "**Fig. 4 (qualitative).** Lower-view semantic maps of one scene per method."),
    ("adapt_height.png", "adapt_gap.md", "**The robot learns (the paper's future work, [adapt.md](adapt.md)).** The compact network fine-tuned on the robot's frames of training scenes with labels from each of the profile's sources (the full profile: `3d-neighborhood` transfer, self-training, ground truth as the ceiling; `large`: every transfer method and `fused` too), scored on the evaluation scenes' height sweep: mIoU at 0.2 m and 1.6 m, the gain at 0.2 m and the change at 1.6 m against the unadapted network (paired, 95% intervals) and the share of its viewpoint gap closed."),
    (None, "table2_adapted.md", "The adapted networks' own lower-view maps as Table 2 rows, beside the unadapted network (`lower`), transfer from the person's map and `fused`:"),
    (None, "table2_adapted_vs_transfer.md", "Does the adapted robot beat transfer on its own? Each adapted network's own map against the unadapted network, transfer (`3d-neighborhood`) and `fused`: paired per-scene differences of Mean Acc. (95% intervals):"),
    (None, "adapt_verdicts.md", "**The adaptation claims**, judged by their plan ([analysis_plan.md](analysis_plan.md#the-adaptation-claims), `semmatch/experiments/adapt_plan.yaml`): paired per scene, 95 % t intervals, the `beats` / `similar` rules with the measure's smallest effect of interest; the share of the gap closed by its one-sided 95 % bounds against 60 %:"),
    ("in_home/in_home.png", "in_home/in_home_comparisons.md", "**In-home adaptation** ([adapt.md](adapt.md#the-in-home-study)): the robot adapts on its first tour of a home, with labels transferred from the person's map of that home, and is scored on a second tour; paired per home, the in-home plan's comparisons (Holm over the four, per measure):"),
    ("table_panoptic.png", "table_panoptic.md", "**Panoptic transfer (the paper's future work, [panoptic.md](panoptic.md)).** Panoptic quality of the robot's map (PQ = SQ x RQ on 5 cm voxels; thing classes, stuff, all) per transfer method and upper-map source (`oracle`: ground-truth classes and instances; `gt+clustering`: ground-truth classes, instances by 3D clustering; a network: its classes, clustered instances): mean [95% interval] over the evaluation scenes. The clustering radius was chosen on the validation scenes."),
    ("fig_panoptic.png", None, "Instances in the robot's map of one evaluation scene (one colour per instance, stuff in its class colour)."),
    ("training_curves.png", "segmentation_validation.md", "Segmentation networks: training curves and validation at human height (validation scenes; the best validation checkpoint is kept)."),
    (None, "validation_flip_summary.md", "Test-time mirror averaging, chosen on the validation scenes' height sweeps (mIoU over all heights; the full profile reads every 2nd sweep frame, `flip_frame_step`):"),
)


#: a run judged by the v2 plan (docs/analysis_plan_v2.md): sections shown instead of v1's (same
#: figure, other table or caption)
_V2_SECTIONS = {
    "claims_speed.md": (None, "claims_speed_bench.md", "The speed claims P1-P3 judged by the analysis plan v2 on "
                        "`semmatch bench transfer --map fused --repeat 5` (each method's median CPU rate and its lowest "
                        "run; the machine, its load and the reference workload's rate in `evidence`); Table 1 above "
                        "is descriptive:"),
    "adapt_verdicts.md": (None, "adapt_verdicts.md", "**The adaptation claims**, judged by the analysis plan v2 "
                          "([analysis_plan_v2.md](analysis_plan_v2.md), statements and comparisons of "
                          "`semmatch/experiments/adapt_plan.yaml`): paired per scene, two-sided 95 % intervals, a "
                          "comparison holds when its lower bound is beyond the smallest effect of interest, the share "
                          "of the gap closed by its one-sided 97.5 % bounds against 60 %:"),
}
#: the claims paragraph of the README's headline, per set of verdict rules
_RULES_TEXT = {
    "v1": "**The paper's claims**, judged by the analysis plan ([docs/analysis_plan.md](docs/analysis_plan.md)): "
          "one verdict per claim under the `fusion` reference, the `mesh` one beside it, and how many "
          "of the paper's own differences lie inside our intervals",
    "v2": "**The paper's claims and the plan's own (F1-F2)**, judged by the analysis plan v2 "
          "([docs/analysis_plan_v2.md](docs/analysis_plan_v2.md)): two-sided 95 % intervals over the scenes and the "
          "training seeds' networks (two-level bootstrap; `provisional` where an architecture has fewer than three); "
          "a comparison holds when its lower bound is beyond the smallest effect of interest (0.02), a claim holds "
          "when every comparison holds (intersection-union) and is refuted when any is significantly against it "
          "(Holm); `min_effect` and the kind-cluster verdict beside it; one verdict per claim under the `fusion` "
          "reference, the `mesh` one beside it, and how many of the paper's own differences lie inside our intervals",
}


#: tables of the ``variance`` profile (the compact network trained from several seeds), shown
#: after the main results when that profile has run
_VARIANCE_SECTIONS = (
    ("table2_training_seeds.md", "Table 2's Mean Acc. over the compact network's training seeds (each seed's mean over the evaluation scenes; `sd` over seeds):"),
    ("fig3_training_seeds.md", "Fig. 3's Mean Acc. over the same training seeds, per camera height:"),
)


#: tables of the training-seed study (:mod:`semmatch.experiments.training_seeds`): both networks
#: of the profile's configuration trained from other seeds, every study run again with them
_SEED_SECTIONS = (
    ("training_seeds_table2.md", "Table 2's Mean Acc. with each training seed's networks (each seed's mean over the "
     "scenes; `sd` and `range` over the seeds; `scene_ci_half`: the half-width of the shipped run's 95 % interval "
     "over scenes, for scale):"),
    ("training_seeds_table3.md", "Table 3's Mean Acc. with each training seed's networks:"),
    ("training_seeds_fig3.md", "Fig. 3's Mean Acc. with each training seed's networks, per camera height:"),
    ("training_seeds_verdicts.md", "Every claim's verdict with each training seed's networks (`agree`: the same "
     "verdict with every seed, fusion reference; `agree_mesh`: mesh reference):"),
)


def training_seeds_markdown(seeds_dir: str | Path, readme_dir: str | Path) -> str:
    """The training-seed study's part of the results (empty when it has not run)."""
    seeds_dir = Path(seeds_dir)
    if not any(_has_rows(seeds_dir / md) for md, _ in _SEED_SECTIONS):
        return ""
    rel = _rel(seeds_dir, Path(readme_dir))
    parts = [f"### Training seeds (from `{_shown(seeds_dir)}/`)\n",
             "Both networks of this configuration trained again from other seeds (seed 0: the shipped networks), "
             "every study of notebooks 03-07 run again with them on the same scenes "
             "([protocol.md](protocol.md#training-variance)).\n"]
    if (seeds_dir / "training_seeds.png").is_file():
        parts.append(f"![training_seeds.png]({rel}/training_seeds.png)\n")
    for md, caption in _SEED_SECTIONS:
        if _has_rows(seeds_dir / md):
            parts += [caption + "\n", (seeds_dir / md).read_text().strip() + "\n"]
    return "\n".join(parts)


def _has_rows(md: Path) -> bool:
    """Whether a markdown table file exists and has at least one data row."""
    return md.is_file() and len([x for x in md.read_text().splitlines() if x.startswith("|")]) > 2


def variance_markdown(variance_dir: str | Path, readme_dir: str | Path) -> str:
    """The training-variance part of the results (empty when the ``variance`` profile has not run)."""
    variance_dir = Path(variance_dir)
    if not any(_has_rows(variance_dir / md) for md, _ in _VARIANCE_SECTIONS):
        return ""
    parts = [f"### Training variance (profile `variance`, from `{_shown(variance_dir)}/`)\n",
             "The protocol run again with the compact network trained from three seeds (`compact`, `compact@1`, "
             "`compact@2`; notebooks 01-06; [protocol.md](protocol.md)).\n"]
    for md, caption in _VARIANCE_SECTIONS:
        if _has_rows(variance_dir / md):
            parts += [caption + "\n", (variance_dir / md).read_text().strip() + "\n"]
    agreement = _verdict_agreement(variance_dir)
    if agreement:
        parts.append(agreement + "\n")
    return "\n".join(parts)


def _verdict_agreement(variance_dir: Path) -> str:
    """One sentence: how many claim comparisons get the same verdict with every training seed."""
    import pandas as pd

    frames = [pd.read_csv(f) for f in sorted(variance_dir.glob("claims_*.csv")) if f.stat().st_size]
    if not frames:
        return ""
    d = pd.concat(frames, ignore_index=True)
    d = d[d["model"].astype(str).str.startswith("compact")]
    key = ["claim", "data", "measure", "comparison"] + (["reference"] if "reference" in d.columns else [])
    if d.empty or not set(key + ["verdict"]) <= set(d.columns):
        return ""
    verdicts = d.groupby(key, sort=False)["verdict"].agg(lambda v: ", ".join(dict.fromkeys(v)))
    differ = verdicts[d.groupby(key, sort=False)["verdict"].nunique() > 1]
    text = (f"Claim verdicts with each training seed (`claims_*.csv` there): {len(verdicts) - len(differ)} of "
            f"{len(verdicts)} comparisons get the same verdict with every seed")
    if len(differ):
        text += "; they differ for " + "; ".join(f"{c} {cmp} ({m}: {v})" for (c, _, m, cmp), v in differ.items())
    return text + "."


def results_markdown(figures_dir: str | Path, readme_dir: str | Path) -> str:
    """The generated results section (links relative to ``readme_dir``), with the training
    variance of ``<figures_dir>/../variance`` when that profile has run."""
    figures_dir, readme_dir = Path(figures_dir), Path(readme_dir)
    rel = _rel(figures_dir, readme_dir)
    run = _confirm_record(figures_dir)
    made_by = "make confirm" if run else "make repro"
    parts = [f"## Results (generated by `{made_by}` from `{_shown(figures_dir)}/`)\n"]
    if run:
        parts.append(_confirm_sentence(run) + "\n")
    missing = []
    v2 = _run_rules(run) == "v2"
    for png, md, caption in (_V2_SECTIONS.get(md, (png, md, caption)) if v2 else (png, md, caption)
                             for png, md, caption in _SECTIONS):
        have_png = png is not None and (figures_dir / png).is_file()
        have_md = md is not None and (figures_dir / md).is_file()
        if not (have_png or have_md):
            missing.append(png or md)
            continue
        if caption:
            parts.append(caption + "\n")
        if have_png:
            parts.append(f"![{png}]({rel}/{png})\n")
        if have_md:
            parts.append((figures_dir / md).read_text().strip() + "\n")
    if len(parts) == 1:
        parts.append(f"_No results yet: run `make repro` to fill `{rel}/`._\n")
    elif missing:
        parts.append(f"_Not generated yet (their pipeline stages have not run): {', '.join(missing)}._\n")
    # the training-seed study of this profile when it has run, else the older variance profile's
    variance = ("" if run or figures_dir.name == "variance"
                else training_seeds_markdown(figures_dir.parent / f"{figures_dir.name}_training_seeds", readme_dir)
                or variance_markdown(figures_dir.parent / "variance", readme_dir))
    if variance:
        parts.append(variance)
    return "\n".join(parts)


def _rel(path: Path, start: Path) -> str:
    """``path`` as a link relative to the folder ``start`` (``../figures/full`` from ``docs/``)."""
    if not path.is_absolute():
        return path.as_posix()
    return Path(os.path.relpath(path.resolve(), start.resolve())).as_posix()


def _shown(figures_dir: Path) -> str:
    """The figures folder as a reader names it (from the repository root when it lies inside one)."""
    parts = figures_dir.resolve().parts
    return "/".join(parts[parts.index("figures"):]) if "figures" in parts else figures_dir.as_posix()


def _confirm_record(figures_dir: Path) -> dict | None:
    """The ``confirm.json`` record of a ``make confirm`` run's figures folder (None for other folders)."""
    path = Path(figures_dir) / "confirm.json"
    if not path.is_file():
        return None
    try:
        return json.loads(path.read_text())
    except json.JSONDecodeError as err:
        raise ValueError(f"{path}: not a confirm record ({err})") from None


def _confirm_sentence(run: dict) -> str:
    """One sentence saying what a confirmatory run scored, with what and how long it took."""
    seeds = [int(s) for s in run.get("seeds", [])]
    kinds = run.get("kinds", [])
    text = (f"Confirmatory run `{run.get('name')}`: scene seeds {', '.join(map(str, seeds))} x {len(kinds)} kinds "
            f"({len(seeds) * len(kinds)} scenes, generated for this run only), networks from "
            f"`{run.get('networks_from')}`, code `{run.get('code_version')}`, started {run.get('started')}, "
            f"{float(run.get('total_seconds', 0)) / 60:.1f} min.")
    for add in run.get("additions", []):  # notebooks added to the run later (make confirm NOTEBOOKS=...)
        what = ", ".join(add.get("notebooks", [])) + (" and the in-home study" if add.get("in_home") else "")
        text += (f" Added later: {what} (adapted networks from `{add.get('adapted_networks_from')}`, code "
                 f"`{add.get('code_version')}`, started {add.get('started')}, "
                 f"{float(add.get('total_seconds', 0)) / 60:.1f} min).")
    return text


def _run_rules(run: dict | None) -> str | None:
    """The verdict rules (``v1`` / ``v2``) of the plan that judged a confirmatory run: its record's
    ``analysis_plan`` entry, else the plan of its seeds
    (:func:`~semmatch.experiments.analysis_plan.plan_for_seeds`); None for other folders."""
    if not run:
        return None
    if (run.get("analysis_plan") or {}).get("rules"):
        return str(run["analysis_plan"]["rules"])
    from .analysis_plan import plan_for_seeds

    try:
        return plan_for_seeds(run.get("seeds") or []).rules
    except ValueError:  # seeds mixing the v2 plan's with others: not a run of either plan's seeds
        return "v1"


def confirmatory_run(figures_root: str | Path, plan=None) -> Path | None:
    """The analysis plan's confirmatory run under ``<figures_root>/confirm/``, if it has been made.

    Parameters
    ----------
    figures_root : path
        The repository's ``figures/`` folder.
    plan : AnalysisPlan or dict, optional
        The analysis plan (a dict is its YAML form); default: the v2 plan's run when it has been
        made, else the v1 plan's (:func:`semmatch.experiments.analysis_plan.load_analysis_plan`).

    Returns
    -------
    Path or None
        The run folder whose ``confirm.json`` lists exactly the plan's confirmatory seeds and
        used the shipped networks; None when there is none.
    """
    if plan is None:
        from .analysis_plan import PLAN_V2_FILE, load_analysis_plan

        return (confirmatory_run(figures_root, load_analysis_plan(PLAN_V2_FILE))
                or confirmatory_run(figures_root, load_analysis_plan()))
    raw = plan if isinstance(plan, dict) else plan.raw
    wanted = sorted(int(s) for s in raw["scenes"]["confirmatory_seeds"])
    for rec in sorted(Path(figures_root, "confirm").glob("*/confirm.json")):
        run = _confirm_record(rec.parent)
        if sorted(int(s) for s in run.get("seeds", [])) == wanted and run.get("networks_from") != "trained here":
            return rec.parent
    return None


def headline_markdown(figures_dir: str | Path, readme_dir: str | Path, results_doc: str | Path, *,
                      development_doc: str | Path | None = None) -> str:
    """The README's headline: Table 2's figure and the claims' verdicts, then a link to all results.

    Parameters
    ----------
    figures_dir : path
        A run's figures folder; ``verdicts.md`` there (:func:`semmatch.experiments.claims.judge_figures`)
        gives the verdict table.
    readme_dir : path
        The folder of the README (links are relative to it).
    results_doc : path
        The generated results document to link to.
    development_doc : path, optional
        The development scenes' results document, linked below a confirmatory headline.

    Returns
    -------
    str
    """
    figures_dir, readme_dir = Path(figures_dir), Path(readme_dir)
    rel = _rel(figures_dir, readme_dir)
    parts = []
    run = _confirm_record(figures_dir)
    if run:
        later = (" The plan of what was added later (the adaptation claims, `adapt_plan.yaml`) was committed before "
                 "that addition ran." if run.get("additions") else "")
        which = ("The analysis plan v2 ([docs/analysis_plan_v2.md](docs/analysis_plan_v2.md))"
                 if _run_rules(run) == "v2" else "The analysis plan")
        parts.append(f"**{_confirm_sentence(run)}** {which} was committed before these scenes "
                     f"existed; nothing was chosen on them.{later}\n")
    if (figures_dir / "table2_synthetic.png").is_file():
        parts.append("**Table 2 (synthetic)**: lower-view semantic reconstructions of the robot's own tour, "
                     "mean and 95 % interval over the evaluation scenes (`fused`: transferred labels where the "
                     "person's map supports a pixel, the robot's network elsewhere).\n")
        parts.append(f"![table2_synthetic.png]({rel}/table2_synthetic.png)\n")
    if (figures_dir / "verdicts.md").is_file():
        parts.append(_RULES_TEXT[_run_rules(run) or "v1"] + f" (from `{_shown(figures_dir)}/`; "
                     "every comparison: `findings_all.md` there).\n")
        parts.append((figures_dir / "verdicts.md").read_text().strip() + "\n")
    if (figures_dir / "adapt_verdicts.md").is_file():
        parts.append("**The adaptation claims** (the robot fine-tuned on labels transferred from the person's map; "
                     "their plan: `semmatch/experiments/adapt_plan.yaml`" +
                     (", judged by the v2 rules" if _run_rules(run) == "v2" else "") + "):\n")
        parts.append((figures_dir / "adapt_verdicts.md").read_text().strip() + "\n")
    if not parts:
        parts.append(f"_No results yet: run `make repro` to fill `{_shown(figures_dir)}/`._\n")
    parts.append(f"All tables and figures: [{_rel(Path(results_doc).resolve(), readme_dir)}]"
                 f"({_rel(Path(results_doc).resolve(), readme_dir)}).\n")
    if development_doc is not None:
        dev = _rel(Path(development_doc).resolve(), readme_dir)
        parts.append(f"The development scenes' results (7001-7003, looked at during development: exploratory): [{dev}]({dev}).\n")
    return "\n".join(parts)


def _replace_between_markers(path: Path, body: str) -> str:
    text = path.read_text()
    if BEGIN not in text or END not in text:
        raise ValueError(f"{path}: no {BEGIN} ... {END} markers")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    return f"{head}{BEGIN}\n{body}{END}{tail}"


def update_readme(readme: str | Path, figures_dir: str | Path, *, results_doc: str | Path | None = None,
                  judge: bool = True, confirmatory_dir: str | Path | None = None) -> bool:
    """Write the results document and the README's headline from ``figures_dir``.

    Parameters
    ----------
    readme : path
        The README (must hold the markers).
    figures_dir : path
        A run's figures folder.
    results_doc : path, optional
        The generated results document (default ``docs/results.md`` beside the README).
    judge : bool, optional
        First judge the plan's claims on the folder's per-scene tables
        (:func:`semmatch.experiments.claims.judge_figures`, writing ``verdicts.md`` there);
        skipped when the folder has none. (Notebook 09 judges the adaptation claims itself.)
    confirmatory_dir : path, optional
        A confirmatory run's figures folder (:func:`confirmatory_run`): the README's headline and
        ``docs/results_confirmatory.md`` come from it as ``make confirm`` left it (its verdicts
        are not judged again); ``figures_dir`` (the development run) still fills ``results_doc``.

    Returns
    -------
    bool
        True when the README or a results document changed.
    """
    readme, figures_dir = Path(readme), Path(figures_dir)
    results_doc = readme.parent / "docs" / "results.md" if results_doc is None else Path(results_doc)
    if judge:  # a confirmatory run was judged once, by make confirm: its record is not rewritten
        from .claims import judge_figures

        try:
            judge_figures(figures_dir)
        except FileNotFoundError:
            pass  # no per-scene tables yet: no verdicts
    note = "<!-- Generated by `python -m semmatch.experiments readme` (run by `make repro`): do not edit. -->\n\n"
    docs = {results_doc: note + results_markdown(figures_dir, results_doc.parent).replace("## Results", "# Results", 1)}
    if confirmatory_dir is not None:  # the v1 plan's run: results_confirmatory.md; v2's: results_confirmatory_v2.md
        v2 = _run_rules(_confirm_record(Path(confirmatory_dir))) == "v2"
        confirm_doc = results_doc.parent / f"results_confirmatory{'_v2' if v2 else ''}.md"
        docs[confirm_doc] = note + results_markdown(confirmatory_dir, confirm_doc.parent).replace(
            "## Results", "# Confirmatory results", 1)
        head = headline_markdown(confirmatory_dir, readme.parent, confirm_doc, development_doc=results_doc)
    else:
        head = headline_markdown(figures_dir, readme.parent, results_doc)
    texts = dict(docs)
    texts[readme] = _replace_between_markers(readme, head)
    changed = False
    for path, text in texts.items():
        if not path.is_file() or path.read_text() != text:
            path.parent.mkdir(parents=True, exist_ok=True)
            atomic_write_text(path, text)
            changed = True
    return changed
