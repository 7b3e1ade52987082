"""Write .dvc/plots/offline.html: the page template of `dvc plots show` with vega inlined.

DVC's default page loads vega, vega-lite and vega-embed from a CDN, so offline it stays blank.
This template carries the three libraries (BSD-3-Clause, .dvc/plots/LICENSE-vega) in the page
itself; .dvc/config names it (``plots.html_template``), so a plain ``dvc plots show`` works
without a network. Rerun to change the versions (needs npm and the npm registry):

    python scripts/vendor_vega.py            # fetch the pinned versions with `npm pack`
    python scripts/vendor_vega.py --from DIR # or use already unpacked packages in DIR/<name>/
"""

from __future__ import annotations

import argparse
import os
import subprocess
import tarfile
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / ".dvc" / "plots" / "offline.html"
#: package -> (version, minified browser build inside the package)
PACKAGES = {
    "vega": ("5.33.1", "build/vega.min.js"),
    "vega-lite": ("5.23.0", "build/vega-lite.min.js"),
    "vega-embed": ("6.29.0", "build/vega-embed.min.js"),
}

PAGE = """<!DOCTYPE html>
<html>
<head>
    {refresh_tag}
    <meta charset="utf-8">
    <title>DVC plots</title>
    <!-- @VERSIONS@: inlined (BSD-3-Clause, see LICENSE-vega beside this
         template) so that the page draws without a network. Written by scripts/vendor_vega.py. -->
@SCRIPTS@
    <style>
        body { font-family: sans-serif; }
        table { border-spacing: 15px; }
    </style>
</head>
<body>
    {plot_divs}
</body>
</html>
"""


def _unpack(dest: Path) -> Path:
    """``npm pack`` the pinned versions into ``dest`` and unpack them to ``dest/<name>/``."""
    specs = [f"{name}@{ver}" for name, (ver, _) in PACKAGES.items()]
    subprocess.run(["npm", "pack", "--silent", *specs], cwd=dest, check=True, stdout=subprocess.DEVNULL)
    for name, (ver, _) in PACKAGES.items():
        with tarfile.open(dest / f"{name}-{ver}.tgz") as tar:
            tar.extractall(dest / name, filter="data")
        (dest / name / "package").rename(dest / name / "pkg")
    return dest


def build(source: Path, out: Path = OUT) -> Path:
    """Write the template from unpacked packages ``source/<name>/pkg/`` (as ``_unpack`` leaves them).

    Parameters
    ----------
    source : Path
        Folder with one unpacked npm package per name.
    out : Path
        Template to write (atomically).

    Returns
    -------
    Path
    """
    scripts = []
    for name, (_, build_file) in PACKAGES.items():
        js = (source / name / "pkg" / build_file).read_text(encoding="utf-8")
        if "</script" in js:
            raise ValueError(f"{name}/{build_file} contains '</script' and cannot be inlined as is")
        scripts.append(f"    <script>/* {name} */\n{js}\n    </script>")
    versions = ", ".join(f"{n} {v}" for n, (v, _) in PACKAGES.items())
    page = PAGE.replace("@VERSIONS@", versions).replace("@SCRIPTS@", "\n".join(scripts))
    tmp = out.with_suffix(".tmp")
    tmp.write_text(page, encoding="utf-8")
    os.replace(tmp, out)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--from", dest="source", type=Path, help="unpacked packages (default: npm pack into a temp folder)")
    args = ap.parse_args()
    if args.source:
        print(build(args.source))
        return
    with tempfile.TemporaryDirectory() as d:
        print(build(_unpack(Path(d))))


if __name__ == "__main__":
    main()
