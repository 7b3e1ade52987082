"""Write dvc.yaml: one stage per notebook (run `python scripts/dvc_stages.py dvc.yaml`).

Edit the stage table here, not dvc.yaml by hand: every stage depends on its notebook, on the
semmatch modules it can run (found from the imports: semmatch.experiments.stagedeps), and on the
data folders of the stages before it.
"""

import sys

import yaml

from semmatch.experiments.pipeline import OVERRIDABLE, PROFILES_FILE, ROOT, read_params
from semmatch.experiments.stagedeps import LEAVE_OUT, stage_modules

PROFILES = read_params(ROOT / "params.yaml")["profiles"]

P = "${profile}"


def fig(*names):
    return [{f"figures/{P}/{n}": {"cache": False}} for n in names]


def tbl(*names):
    out = []
    for n in names:
        out += [f"{n}.csv", f"{n}.md"]
    return out


# execution settings: how a stage runs, not what it computes (results do not depend on them), so
# they are never tracked and changing them reruns nothing
EXECUTION = ("jobs", "scheduler")


def common(*keys):
    assert not set(keys) & set(EXECUTION), f"execution settings {EXECUTION} are not tracked params"
    return [f"profiles.{P}.common.{k}" for k in keys]


def modules(nb, figs):
    """The stage's semmatch modules: never those no stage computes with (stagedeps.LEAVE_OUT),
    the figure-drawing ones (semmatch.plots) only when the stage writes a figure file."""
    draws = any(str(f).endswith(".png") for f in figs)
    return stage_modules(nb, leave_out=LEAVE_OUT + (() if draws else ("semmatch.plots",)))


stages = {
 "simulate": dict(
    nb="01_simulate", deps=[],
    params=["profile", *common("kinds", "eval_seeds", "train_seeds", "val_seeds", "dev_seeds", "min_val_per_kind", "seed"), f"profiles.{P}.simulate"],
    outs=[f"data/{P}/scenes"], figs=["frames_upper_lower.png", "routes.png"]),
 "train_segmentation": dict(
    nb="02_train_segmentation", deps=[f"data/{P}/scenes", "models"],  # the shipped networks (every profile)
    params=["profile", *common("kinds", "train_seeds", "val_seeds", "eval_seeds", "networks", "seed"), f"profiles.{P}.train_segmentation"],
    outs=[{f"data/{P}/models": {"persist": True}}],
    figs=["training_curves.png", *tbl("segmentation_validation", "validation_flip", "validation_flip_summary")]),
 "reconstruct_upper": dict(
    nb="03_reconstruct_upper", deps=[f"data/{P}/scenes", f"data/{P}/models"],
    params=["profile", *common("networks", "voxel_size", "eval_voxel_size"), f"profiles.{P}.reconstruct_upper"],
    outs=[f"data/{P}/upper"], figs=[*tbl("upper_maps"), "upper_maps.png"]),
 "label_transfer": dict(
    nb="04_label_transfer", deps=[f"data/{P}/scenes", f"data/{P}/models", f"data/{P}/upper"],
    params=["profile", *common("methods", "networks", "fused_base", "slic_2d"), f"profiles.{P}.label_transfer"],
    outs=[f"data/{P}/lower_labels"],
    figs=[*tbl("table1_speed", "support_per_scene", "claims_speed"), "table1_speed.png", "support_per_scene.png",
          "fig_transferred_frames.png"]),
 "evaluate_synthetic": dict(
    nb="05_evaluate_synthetic", deps=[f"data/{P}/scenes", f"data/{P}/upper", f"data/{P}/lower_labels"],
    params=["profile", *common("methods", "networks", "voxel_size", "eval_voxel_size", "fused_base"), f"profiles.{P}.evaluate_synthetic"],
    outs=[f"data/{P}/lower_maps"],
    figs=[*tbl("table2_per_scene", "table2_synthetic", "table2_mesh_reference", "table2_route_ablation", "claims_synthetic", "verdicts_synthetic", "table2_training_seeds"),
          "table2_synthetic.png", "table2_mesh_reference.png", "findings_synthetic.md"]),
 "height_study": dict(
    nb="06_height_study", deps=[f"data/{P}/scenes", f"data/{P}/models"],
    params=["profile", *common("networks"), f"profiles.{P}.height_study"],
    outs=[], figs=[*tbl("fig3_height", "fig3_height_per_scene", "claims_height", "verdicts_height", "fig3_training_seeds"), "fig3_height.png", "findings_height.md"]),
 "real_data": dict(
    nb="07_real_data", deps=[f"data/{P}/scenes", f"data/{P}/models", f"data/{P}/upper", f"data/{P}/lower_maps"],
    params=["profile", *common("methods", "networks", "voxel_size", "eval_voxel_size", "fused_base", "slic_2d"), f"profiles.{P}.real_data"],
    outs=[f"data/{P}/real_like"],
    figs=[*tbl("table3_per_scene", "table3_real", "table3_mesh_reference", "trajectory_error", "validation_odometry_gate",
               "misregistration", "claims_real", "verdicts_real", "depth_noise", "claims_depth_noise", "trajectory_error_summary", "registration_error"),
          "table3_real.png", "misregistration.png", "depth_noise.png", "findings_real.md"]),
 "qualitative": dict(
    nb="08_qualitative", deps=[f"data/{P}/scenes", f"data/{P}/lower_maps"],
    params=["profile", *common("methods"), f"profiles.{P}.qualitative"],
    outs=[], figs=["fig4_qualitative.png"]),
 "adapt_robot_view": dict(
    # models: the shipped adapted networks (models/<profile>/adapted, every profile; notebook 09 uses them when they
    # answer its request)
    nb="09_adapt_robot_view", deps=[f"data/{P}/scenes", f"data/{P}/models", f"data/{P}/lower_maps", "models"],
    params=["profile", *common("kinds", "train_seeds", "eval_seeds", "voxel_size", "eval_voxel_size", "fused_base",
                               "seed"), f"profiles.{P}.adapt_robot_view"],
    outs=[f"data/{P}/adapted"],
    figs=[*tbl("adapt_label_quality", "validation_adapt_recipe", "adapt_height_per_scene", "adapt_height", "adapt_gap",
               "adapt_gap_bounds", "table2_adapted_per_scene", "table2_adapted", "table2_adapted_vs_transfer",
               "adapt_claims"),
          "adapt_verdicts.md", "adapt_height.png", "adapt_change_high.png"]),
 "panoptic": dict(
    nb="10_panoptic", deps=[f"data/{P}/scenes", f"data/{P}/upper", f"data/{P}/lower_maps"],
    params=["profile", *common("methods", "voxel_size", "eval_voxel_size"), f"profiles.{P}.panoptic"],
    outs=[f"data/{P}/panoptic"],
    figs=[*tbl("validation_panoptic_clustering", "table_panoptic_per_scene", "table_panoptic"),
          "table_panoptic.png", "fig_panoptic.png"]),
}
# stages whose headline numbers go to figures/<profile>/metrics/<stage>.json (semmatch.experiments.headline),
# gathered into the one metrics file figures/<profile>/metrics.json that `dvc metrics show` reads
METRICS = ("train_segmentation", "reconstruct_upper", "label_transfer", "evaluate_synthetic", "height_study",
           "real_data", "adapt_robot_view", "panoptic")
# curves and tables for `dvc plots show`: file -> (stage, x, y, template, title). Templates are the
# vega-lite specs in .dvc/plots/ (each draws one mark per series: per model, method or route);
# the page loads vega from .dvc/plots/offline.html (configured in .dvc/config), so it works offline.
PLOTS = {
    "fig3_height.csv": ("height_study", "height", "miou", "lines_by_model",
                        "Fig. 3: mIoU against camera height, one line per network (95 % band)"),
    "table1_speed.csv": ("label_transfer", "method", "fps", "bar_log",
                         "Table 1: label-transfer speed per method (FPS, this machine)"),
    "support_per_scene.csv": ("label_transfer", "scene", "support", "grouped_bar_route",
                              "Support of the robot's frames in the person's map, per scene and route"),
    "misregistration.csv": ("real_data", "translation_m", "mean_acc", "misregistration",
                            "Mean Acc. against misregistration of the person's map, one line per method"),
}


def with_overrides(params):
    """The stage's params plus the top-level overrides (``-S key=value``) that reach them."""
    extra = []
    for p in params:
        parts = p.split(".")
        if len(parts) == 4 and parts[2] == "common" and parts[3] in OVERRIDABLE:
            extra.append(parts[3])
        elif len(parts) == 3 and parts[0] == "profiles":
            extra += [k for k in OVERRIDABLE if any(k in (prof.get(parts[2]) or {}) for prof in PROFILES.values())]
    return [*params, *dict.fromkeys(extra)]


#: data files a module reads at run time: a stage that runs the module depends on them too
MODULE_DATA = {"semmatch/experiments/analysis_plan.py": ["semmatch/experiments/analysis_plan.yaml",
                                                          "semmatch/experiments/analysis_plan_v2.yaml"],
               "semmatch/experiments/adapt_claims.py": ["semmatch/experiments/adapt_plan.yaml"]}

out = {"stages": {}}
for name, st in stages.items():
    plots = {f: v for f, v in PLOTS.items() if v[0] == name}
    figs = [f for f in st["figs"] if f not in plots]
    params = with_overrides(st["params"])
    stage = {
        "cmd": f"python -m semmatch.experiments run {st['nb']}",
        "deps": [f"notebooks/{st['nb']}.ipynb", *(mods := modules(st["nb"], st["figs"])),
                 *(f for m in mods for f in MODULE_DATA.get(m, ())), *st["deps"]],
        # params.yaml: the profile's name and the overrides; profiles.yaml: this stage's keys of the active
        # profile only (DVC shows all of params.yaml but only the tracked keys of other files)
        "params": [*(p for p in params if not p.startswith("profiles.")),
                   {PROFILES_FILE: [p for p in params if p.startswith("profiles.")]}],
        "outs": [*st["outs"], f"reports/{P}/{st['nb']}.ipynb", *fig(*figs),
                 *([{f"figures/{P}/metrics/{name}.json": {"cache": False}}] if name in METRICS else [])],
    }
    if plots:
        stage["plots"] = [{f"figures/{P}/{f}": {"cache": False, "x": x, "y": y, "template": tpl, "title": title}}
                          for f, (_, x, y, tpl, title) in plots.items()]
    out["stages"][name] = stage
out["metrics"] = [f"figures/{P}/metrics.json"]  # every stage's headline numbers in one row (headline.gather_metrics)
head = """# The paper's results, one stage per notebook, run through papermill by
# `python -m semmatch.experiments run NN_name` with the parameters of the active profile
# (params.yaml: `profile`). Data goes to data/<profile>/, executed notebooks to
# reports/<profile>/, figures and tables to figures/<profile>/ (small: kept in git).
# Every stage depends on the semmatch modules it can run, found from the imports of its
# notebook and of the stage command (semmatch.experiments.stagedeps; generated by
# scripts/dvc_stages.py, checked at run time by the smoke test): editing a module reruns
# exactly the stages that use it. Presentation-only modules (semmatch.plots.views: views inside the
# executed reports; the README and snapshot writers), the command's other subcommands
# (confirm, ship) and execution settings (jobs, scheduler) are not tracked.
"""
if __name__ == "__main__":
    open(sys.argv[1], "w").write(head + yaml.safe_dump(out, sort_keys=False, width=120))
