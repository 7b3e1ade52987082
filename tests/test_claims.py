"""semmatch.experiments.claims: intervals over scenes and verdicts of the paper's claims."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from semmatch.experiments.claims import (
    CLAIMS,
    Claim,
    check_claims,
    claims_markdown,
    format_with_intervals,
    summarize_over_scenes,
)
from semmatch.stats import bootstrap_ci

SCENES = [f"office_70{i:02d}" for i in range(6)]
ALL_METHODS = ["2d-slic", "3d-projected-sp", "3d-slic", "dbscan", "3d-neighborhood"]
#: a per-scene difficulty shared by every row of a scene: paired differences cancel it
BASE = np.array([0.62, 0.81, 0.70, 0.76, 0.66, 0.73])
#: a difference whose sign changes from scene to scene (mean 0): never resolved
NOISY = np.array([0.05, -0.05, 0.04, -0.04, 0.03, -0.03])
CLEAR = 0.1


def table(spec: dict[tuple[str, str], np.ndarray | float], *, measure: str = "mean_acc") -> pd.DataFrame:
    """Per-scene rows: ``spec[(model, method)]`` is added to :data:`BASE` for ``measure``."""
    rows = []
    for (model, method), off in spec.items():
        vals = BASE + off
        for s, v in zip(SCENES, vals, strict=True):
            rows.append(dict(scene=s, model=model, method=method, jaccard=v - 0.05, sorensen=v - 0.02,
                             color_acc=v + 0.07, mean_acc=v) | {measure: v})
    return pd.DataFrame(rows)


def rows_of(res: pd.DataFrame, claim: str) -> pd.DataFrame:
    return res[res["claim"] == claim].reset_index(drop=True)


def verdict(res: pd.DataFrame, claim: str, model: str, comparison: str | None = None) -> str:
    sel = (res["claim"] == claim) & (res["model"] == model)
    if comparison is not None:
        sel &= res["comparison"].str.startswith(comparison)
    (v,) = res.loc[sel, "verdict"]
    return v


# ------------------------------------------------------------------------------------------------
# beats: the three verdicts


def test_beats_gives_each_verdict():
    t2 = table({
        ("compact", "lower"): 0.0, ("compact", "2d-slic"): CLEAR,
        ("strong", "lower"): 0.0, ("strong", "2d-slic"): -CLEAR, ("strong", "3d-slic"): NOISY,
    })
    res = check_claims(t2, methods=["2d-slic", "3d-slic"])
    c1 = rows_of(res, "C1")
    assert list(zip(c1["model"], c1["comparison"])) == [
        ("compact", "2d-slic - lower"), ("strong", "2d-slic - lower"), ("strong", "3d-slic - lower")]
    assert list(c1["verdict"]) == ["holds", "does not hold", "not resolved"]
    assert c1.loc[0, "diff"] == pytest.approx(CLEAR)
    assert c1.loc[1, "diff"] == pytest.approx(-CLEAR)
    assert c1.loc[2, "diff"] == pytest.approx(0.0, abs=1e-12)
    assert (c1["lo"] <= c1["diff"] + 1e-12).all() and (c1["diff"] <= c1["hi"] + 1e-12).all()
    assert c1.loc[2, "lo"] < 0 < c1.loc[2, "hi"]
    assert (c1["scenes"] == 6).all()
    assert set(res["data"]) == {"synthetic"}


def test_beats_is_judged_on_pairs_not_on_means():
    # 2d-slic is higher on average, but lower in two scenes by a lot: the pairs do not resolve it
    off = np.array([0.2, 0.2, 0.2, 0.2, -0.25, -0.25])
    t2 = table({("compact", "lower"): 0.0, ("compact", "2d-slic"): off})
    (v,) = rows_of(check_claims(t2, methods=["2d-slic"]), "C1")["verdict"]
    assert off.mean() > 0 and v == "not resolved"


def test_one_scene_is_not_resolved():
    t2 = table({("compact", "lower"): 0.0, ("compact", "2d-slic"): CLEAR})
    t2 = t2[t2["scene"] == SCENES[0]]
    res = rows_of(check_claims(t2, methods=["2d-slic"]), "C1")
    assert list(res["verdict"]) == ["not resolved"] and list(res["scenes"]) == [1]
    assert rows_of(check_claims(t2, methods=["2d-slic"], min_scenes=1), "C1")["verdict"][0] == "holds"


# ------------------------------------------------------------------------------------------------
# best / worst among a set


def test_best_of_a_set_reports_the_deciding_competitor():
    t2 = table({
        # holds: 3d-neighborhood above everyone, closest is 3d-slic (+0.05)
        ("ground truth", "2d-slic"): -0.2, ("ground truth", "3d-slic"): -0.05,
        ("ground truth", "dbscan"): -0.1, ("ground truth", "3d-neighborhood"): 0.0,
        # does not hold: dbscan clearly above, 3d-slic unresolved
        ("compact", "3d-slic"): NOISY, ("compact", "dbscan"): CLEAR, ("compact", "3d-neighborhood"): 0.0,
        # not resolved: above 2d-slic, level with 3d-slic
        ("strong", "2d-slic"): -CLEAR, ("strong", "3d-slic"): NOISY, ("strong", "3d-neighborhood"): 0.0,
    })
    res = rows_of(check_claims(t2, methods=ALL_METHODS), "C2")
    assert list(res["model"]) == ["ground truth", "compact", "strong"]
    assert list(res["verdict"]) == ["holds", "does not hold", "not resolved"]
    gt, compact, strong = (res.iloc[i] for i in range(3))
    assert gt["comparison"] == "3d-neighborhood - 3d-slic (closest of 3)"
    assert gt["diff"] == pytest.approx(0.05)
    assert compact["comparison"] == "3d-neighborhood - dbscan (1 of 2 against the claim)"
    assert compact["diff"] == pytest.approx(-CLEAR)
    assert strong["comparison"] == "3d-neighborhood - 3d-slic (closest unresolved of 2)"


def test_worst_of_a_set_and_colour_accuracy():
    # C18 (ground-truth map, Color Acc.): every other method above dbscan
    t2 = table({("ground truth", m): (-CLEAR if m == "dbscan" else 0.01 * i) for i, m in enumerate(ALL_METHODS)},
               measure="color_acc")
    (row,) = rows_of(check_claims(t2, methods=ALL_METHODS), "C18").itertuples()
    assert row.verdict == "holds" and row.measure == "color_acc"
    assert row.comparison == "2d-slic - dbscan (closest of 4)"
    assert row.diff == pytest.approx(CLEAR)


# ------------------------------------------------------------------------------------------------
# equivalence


def test_similar_inside_outside_and_across_the_margin():
    t2 = table({
        ("compact", "3d-projected-sp"): 0.0, ("compact", "3d-slic"): NOISY / 10,  # within +-0.005
        ("strong", "3d-projected-sp"): 0.0, ("strong", "3d-slic"): 0.1 + NOISY / 5,  # 0.1 +- 0.01
    })
    res = rows_of(check_claims(t2, methods=ALL_METHODS), "C6")
    assert list(res["comparison"]) == ["3d-slic - 3d-projected-sp"] * 2
    assert list(res["verdict"]) == ["holds", "does not hold"]
    # a wider margin makes the 0.1 difference "similar"; an interval across the margin is unresolved
    assert verdict(check_claims(t2, methods=ALL_METHODS, margin=0.15), "C6", "strong") == "holds"
    assert verdict(check_claims(t2, methods=ALL_METHODS, margin=0.1), "C6", "strong") == "not resolved"


def test_transfer_similar_to_the_upper_view():
    t2 = table({
        ("compact", "upper"): 0.0, ("compact", "lower"): -0.1, ("compact", "3d-neighborhood"): 0.02 + NOISY / 4,
        ("strong", "upper"): 0.0, ("strong", "lower"): -0.1, ("strong", "3d-neighborhood"): NOISY / 10,
    })
    res = check_claims(t2, methods=["3d-neighborhood"])
    assert verdict(res, "C8", "compact") == "not resolved"  # interval around +0.02: across the margin
    assert verdict(res, "C8", "strong") == "holds"
    assert verdict(res, "C7", "compact") == "holds" and verdict(res, "C7", "strong") == "holds"
    assert rows_of(res, "C7")["comparison"].tolist() == ["upper - lower"] * 2


# ------------------------------------------------------------------------------------------------
# Fig. 3 height sweep

HEIGHTS = [0.2, 0.4, 0.6, 0.8, 1.0, 1.2, 1.4, 1.6]


def height_table(curves: dict[str, list[float]], scenes: int = 4) -> pd.DataFrame:
    bump = np.linspace(-0.01, 0.01, scenes)
    rows = [dict(model=m, scene=f"s{s}", height=h, mean_acc=v + bump[s], miou=v - 0.3)
            for m, curve in curves.items() for s in range(scenes) for h, v in zip(HEIGHTS, curve, strict=True)]
    return pd.DataFrame(rows)


def test_height_claims():
    fig3 = height_table({
        "compact": [0.70, 0.74, 0.76, 0.80, 0.79, 0.78, 0.775, 0.77],  # paper-like: peak at 0.8 m
        "strong": [0.70, 0.72, 0.74, 0.76, 0.78, 0.80, 0.82, 0.84],  # still rising at 1.6 m
        "other": [0.75, 0.70, 0.76, 0.80, 0.80, 0.80, 0.79, 0.78],  # 0.4 m below 0.2 m
    })
    res = check_claims(fig3=fig3, methods=ALL_METHODS)
    assert set(res["claim"]) == {"C9", "C10"} and set(res["data"]) == {"height sweep"}
    c9, c10 = rows_of(res, "C9"), rows_of(res, "C10")
    assert list(c9["verdict"]) == ["holds", "holds", "does not hold"]
    assert c9.loc[0, "comparison"].startswith("0.4 m - 0.2 m (closest of 7)")
    assert c9.loc[0, "diff"] == pytest.approx(0.04)
    assert c9.loc[2, "comparison"].startswith("0.4 m - 0.2 m (1 of 7 against the claim)")
    assert list(c10["verdict"]) == ["holds", "does not hold", "holds"]
    assert c10.loc[0, "comparison"] == "0.8 m - 1.6 m; highest mean at 0.8 m"
    assert c10.loc[0, "diff"] == pytest.approx(0.03)
    assert c10.loc[1, "comparison"] == "0.8 m - 1.6 m; highest mean at 1.6 m"
    assert (c10["scenes"] == 4).all()


# ------------------------------------------------------------------------------------------------
# missing data, references


def full_table(with_upper: bool = True) -> pd.DataFrame:
    spec: dict = {("ground truth", m): 0.1 + 0.01 * i for i, m in enumerate(ALL_METHODS)}
    for net in ("compact", "strong"):
        spec[(net, "lower")] = -0.1
        if with_upper:
            spec[(net, "upper")] = 0.0
        spec |= {(net, m): 0.01 * i for i, m in enumerate(ALL_METHODS)}
    return table(spec)


def test_every_claim_gets_rows_on_complete_data():
    fig3 = height_table({"compact": list(np.linspace(0.7, 0.8, 8)), "strong": list(np.linspace(0.7, 0.8, 8))})
    res = check_claims(full_table(), full_table(), fig3, methods=ALL_METHODS)
    assert [c.id for c in CLAIMS] == list(dict.fromkeys(res["claim"]))
    assert set(res["verdict"]) <= {"holds", "does not hold", "not resolved"}
    assert len(rows_of(res, "C1")) == 2 * 5 and len(rows_of(res, "C2")) == 3 and len(rows_of(res, "C4")) == 2 * 4
    assert set(rows_of(res, "C5")["model"]) == {"ground truth"}
    assert set(rows_of(res, "C11")["model"]) == {"compact", "strong"}


def test_missing_data_and_methods_skip_claims():
    res = check_claims(table3=full_table(with_upper=False), methods=ALL_METHODS)
    assert set(res["data"]) == {"real-like"}
    assert "C16" not in set(res["claim"])  # no upper rows in Table 3
    res = check_claims(full_table(), methods=["2d-slic", "3d-slic"])
    assert set(res["claim"]) == {"C1", "C7"}  # every other claim needs a method not configured
    assert len(rows_of(res, "C1")) == 4
    assert check_claims(methods=ALL_METHODS).empty
    assert claims_markdown(check_claims(methods=ALL_METHODS)).startswith("No claim")


def test_reference_column_selects_the_rows_judged():
    fusion = table({("compact", "lower"): 0.0, ("compact", "2d-slic"): CLEAR}).assign(reference="fusion")
    mesh = table({("compact", "lower"): 0.0, ("compact", "2d-slic"): -CLEAR}).assign(reference="mesh")
    both = pd.concat([fusion, mesh], ignore_index=True)
    assert verdict(check_claims(both, methods=["2d-slic"]), "C1", "compact") == "holds"
    assert verdict(check_claims(both, methods=["2d-slic"], reference="mesh"), "C1", "compact") == "does not hold"
    with pytest.raises(ValueError, match="several rows per"):
        check_claims(both.drop(columns="reference"), methods=["2d-slic"])
    # the route ablation (robot on the person's route) is not judged unless asked for
    routes = pd.concat([fusion.assign(route="own"), mesh.assign(route="shared", reference="fusion")])
    assert verdict(check_claims(routes, methods=["2d-slic"]), "C1", "compact") == "holds"
    assert verdict(check_claims(routes, methods=["2d-slic"], route="shared"), "C1", "compact") == "does not hold"


def test_claims_markdown():
    res = check_claims(full_table(), methods=ALL_METHODS)
    md = claims_markdown(res)
    assert md.splitlines()[0].startswith("| claim")
    assert "difference [95% CI]" in md
    counts = res["verdict"].value_counts()
    line = next(ln for ln in md.splitlines() if ln.startswith("Verdicts"))
    assert f"{counts.get('holds', 0)} holds" in line and f"{len(res)} rows" in line
    for c in set(res["claim"]):
        assert f"**{c}**" in md
    first = res.iloc[0]
    assert f"{first['diff']:+.3f} [{first['lo']:+.3f}, {first['hi']:+.3f}]" in md


def test_claim_definitions():
    ids = [c.id for c in CLAIMS]
    assert ids == [f"C{i}" for i in range(1, 19)]
    with pytest.raises(ValueError, match="kind"):
        Claim("X", "x", "§0", "synthetic", "greater", ("a",), ("b",))


# ------------------------------------------------------------------------------------------------
# summaries


def test_summarize_over_scenes():
    t2 = table({("strong", "lower"): 0.0, ("compact", "lower"): NOISY, ("compact", "2d-slic"): 0.05})
    s = summarize_over_scenes(t2)
    assert list(zip(s["model"], s["method"])) == [("strong", "lower"), ("compact", "lower"), ("compact", "2d-slic")]
    assert (s["scenes"] == 6).all()
    means = t2.groupby(["model", "method"], sort=False)[["jaccard", "mean_acc"]].mean().reset_index()
    merged = s.merge(means, on=["model", "method"], suffixes=("", "_ref"))
    np.testing.assert_allclose(merged["mean_acc"], merged["mean_acc_ref"])
    np.testing.assert_allclose(merged["jaccard"], merged["jaccard_ref"])
    for m in ("jaccard", "sorensen", "color_acc", "mean_acc"):
        assert (s[f"{m}_lo"] <= s[m]).all() and (s[m] <= s[f"{m}_hi"]).all()
        assert (s[f"{m}_lo"] < s[f"{m}_hi"]).all()
    vals = t2[(t2["model"] == "compact") & (t2["method"] == "lower")]["mean_acc"]
    assert tuple(s.loc[1, ["mean_acc", "mean_acc_lo", "mean_acc_hi"]]) == bootstrap_ci(vals)


def test_summarize_keeps_references_apart_and_formats():
    a = table({("compact", "lower"): 0.0}).assign(reference="fusion")
    b = table({("compact", "lower"): 0.1}).assign(reference="mesh")
    s = summarize_over_scenes(pd.concat([a, b]), ("mean_acc",))
    assert list(s["reference"]) == ["fusion", "mesh"]
    assert s["mean_acc"].tolist() == pytest.approx([BASE.mean(), BASE.mean() + 0.1])
    assert "reference" not in summarize_over_scenes(a, ("mean_acc",)).columns  # one reference: no split
    f = format_with_intervals(s, ("mean_acc",))
    assert list(f.columns) == ["model", "method", "reference", "scenes", "mean_acc"]
    r = s.iloc[0]
    assert f.loc[0, "mean_acc"] == f"{r['mean_acc']:.3f} [{r['mean_acc_lo']:.3f}, {r['mean_acc_hi']:.3f}]"


def test_markdown_table_keeps_text_cells_and_formats_floats(tmp_path):
    from semmatch.experiments.tables import markdown_table, save_table

    df = pd.DataFrame({"lr": ["0.0003", "0.001"], "miou": [0.12345, np.nan], "steps": [400, 400],
                       "chosen": [True, False]})
    md = markdown_table(df)
    lines = md.splitlines()
    assert "| 0.0003 |" in lines[2] and "0.123" in lines[2] and "nan" in lines[3]
    # numbers right-aligned, text and flags left-aligned
    assert lines[1].split("|")[1:-1] == [":-------", "-------:", "--------:", ":---------"]
    _, path = save_table(df, tmp_path, "t")
    assert path.read_text() == md + "\n"


def test_interval_table_shows_a_missing_paper_value_blank(tmp_path):
    from semmatch.experiments.tables import save_interval_table

    summary = pd.DataFrame({"model": ["compact", "compact"], "method": ["lower", "fused"], "scenes": [3, 3],
                            "mean_acc": [0.8, 0.9], "mean_acc_lo": [0.7, 0.85], "mean_acc_hi": [0.85, 0.95],
                            "paper_jaccard": [0.5, np.nan], "paper_mean_acc": [0.61, np.nan]})
    _, md = save_interval_table(summary, tmp_path, "t", measures=("mean_acc",), keep=("paper_mean_acc",))
    lines = md.read_text().splitlines()
    assert "nan" not in md.read_text()
    assert "0.500" in lines[2] and "0.610" in lines[2]
    assert [c.strip() for c in lines[3].split("|")[-3:-1]] == ["", ""]
