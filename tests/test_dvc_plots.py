"""`dvc plots show` draws every figure's series, offline, in a real (headless) browser.

The page is rendered from the committed full-profile CSVs (figures/full/) with the templates in
.dvc/plots/ and the vega-inlined page template .dvc/plots/offline.html named in .dvc/config.
"""

from __future__ import annotations

import re
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest
import yaml

ROOT = Path(__file__).resolve().parents[1]
DVC = Path(sys.executable).with_name("dvc")
FIGURES = ROOT / "figures" / "full"


def _plot_defs() -> dict[str, dict]:
    """file name -> plot definition (x, y, template) of every stage in dvc.yaml."""
    stages = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
    out = {}
    for st in stages.values():
        for entry in st.get("plots", []):
            for path, props in entry.items():
                out[Path(path).name] = props
    return out


def test_every_plot_has_a_template_that_uses_its_fields():
    defs = _plot_defs()
    assert set(defs) == {"fig3_height.csv", "table1_speed.csv", "support_per_scene.csv", "misregistration.csv"}
    for name, props in defs.items():
        tpl = ROOT / ".dvc" / "plots" / f"{props['template']}.json"
        assert tpl.is_file(), f"{name}: template {tpl} missing"
        assert "<DVC_METRIC_DATA>" in tpl.read_text()
        cols = set(pd.read_csv(FIGURES / name, nrows=1).columns)
        assert {props["x"], props["y"]} <= cols, f"{name}: x/y not columns of the CSV"


def test_page_template_is_offline_and_configured():
    config = (ROOT / ".dvc" / "config").read_text()
    assert re.search(r"html_template\s*=\s*plots/offline.html", config)
    page = (ROOT / ".dvc" / "plots" / "offline.html").read_text()
    assert "{plot_divs}" in page and "{scripts}" not in page  # dvc's CDN <script> tags are never inserted
    assert "src=\"http" not in page and "vegaEmbed" in page
    assert (ROOT / ".dvc" / "plots" / "LICENSE-vega").is_file()


def _marks(dom: str, div: str, role: str) -> list[tuple[str, str]]:
    """(path data, colour) of every ``role`` mark (aria-roledescription) inside the plot ``div``."""
    start = dom.index(f'id="{div}"')
    end = dom.find('<div id="', start + 10)
    part = dom[start:end if end > 0 else len(dom)]
    out = []
    for tag in re.findall(rf'<path[^>]*aria-roledescription="{role}"[^>]*>', part):
        d = re.search(r' d="([^"]*)"', tag)
        colour = re.search(r' (?:stroke|fill)="(#[0-9a-f]{6})"', tag)
        out.append((d.group(1) if d else "", colour.group(1) if colour else ""))
    return out


def _numeric_labels(dom: str, div: str) -> list[float]:
    """The numbers among the text labels drawn inside the plot ``div`` (axis ticks)."""
    start = dom.index(f'id="{div}"')
    end = dom.find('<div id="', start + 10)
    texts = re.findall(r"<text[^>]*>([^<]*)</text>", dom[start:end if end > 0 else len(dom)])
    return [float(t.replace(",", "")) for t in texts if re.fullmatch(r"-?[\d,]*\.?\d+", t.strip())]


def _xs_increase(path: str) -> bool:
    """True when the x coordinates of an SVG polyline (M/L commands) never go back."""
    xs = [float(x) for x in re.findall(r"[ML](-?[\d.]+),", path)]
    return len(xs) >= 2 and all(b >= a - 1e-6 for a, b in zip(xs, xs[1:]))


@pytest.mark.skipif(shutil.which("chromium") is None, reason="chromium not installed (scripts/setup.sh installs it)")
@pytest.mark.skipif(not DVC.is_file(), reason="dvc not installed in this environment")
def test_dvc_plots_page_draws_one_mark_per_series(tmp_path):
    if yaml.safe_load((ROOT / "params.yaml").read_text())["profile"] != "full":
        pytest.skip("the committed CSVs are the full profile's; params.yaml selects another profile")
    run = subprocess.run([str(DVC), "plots", "show", "-o", str(tmp_path / "plots")], cwd=ROOT,
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 0, run.stderr[-2000:]
    page = tmp_path / "plots" / "index.html"
    assert "jsdelivr" not in page.read_text()
    shot = subprocess.run(
        ["chromium", "--headless=new", "--no-sandbox", "--disable-gpu", "--virtual-time-budget=10000",
         "--dump-dom", page.as_uri()], capture_output=True, text=True, timeout=120)
    dom = shot.stdout
    assert "role-mark" in dom, f"nothing drawn (vega did not run): {shot.stderr[-1500:]}"

    height = pd.read_csv(FIGURES / "fig3_height.csv")
    lines = _marks(dom, "figures_full_fig3_height_csv", "line mark")
    assert len(lines) == height["model"].nunique()  # one line per network, not one zig-zag
    assert len({c for _, c in lines}) == len(lines) and all(_xs_increase(d) for d, _ in lines)

    mis = pd.read_csv(FIGURES / "misregistration.csv")
    lines = _marks(dom, "figures_full_misregistration_csv", "line mark")
    assert len(lines) == 2 * mis["method"].nunique()  # translated and rotated panels
    assert len({c for _, c in lines}) == mis["method"].nunique() and all(_xs_increase(d) for d, _ in lines)

    for name, div in (("table1_speed.csv", "figures_full_table1_speed_csv"),
                      ("support_per_scene.csv", "figures_full_support_per_scene_csv")):
        bars = _marks(dom, div, "bar")
        assert len(bars) == len(pd.read_csv(FIGURES / name)), name
        assert all(d and "NaN" not in d for d, _ in bars), name
        heights = [abs(float(v)) for d, _ in bars for v in re.findall(r"v(-?[\d.]+)", d)]
        assert len(heights) == len(bars) and min(heights) > 0, f"{name}: bars drawn without height: {heights}"
    for div in ("figures_full_fig3_height_csv", "figures_full_misregistration_csv", "figures_full_table1_speed_csv",
                "figures_full_support_per_scene_csv"):
        assert len(_numeric_labels(dom, div)) >= 2, f"{div}: no numbered axis ticks drawn"
    routes = {c for _, c in _marks(dom, "figures_full_support_per_scene_csv", "bar")}
    assert len(routes) == pd.read_csv(FIGURES / "support_per_scene.csv")["route"].nunique()
