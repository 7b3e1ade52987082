"""Small executed copies of the pipeline's notebooks, viewable without running anything.

The executed notebooks of a pipeline run (``reports/<profile>/NN_*.ipynb``) are pipeline outputs
(DVC-tracked, several MB: full-size PNGs, interactive plotly maps). :func:`snapshot_reports`
writes a small copy of each for git (``reports/snapshot/<profile>/``; GitHub and any notebook
viewer render them): figures re-encoded as JPEG no wider than ``max_width`` pixels (kept as PNG
where that is smaller), interactive outputs (plotly maps, widgets) replaced by a line saying how
to get them, and the commit and profile they were executed with in the notebook's metadata.
Printed warnings say nothing of the machine they ran on (:func:`clean_stream`): a library's
start-up warning that is no result (numba's TBB threading-layer notice) is left out, and paths
are shown from the repository or from ``site-packages`` instead of from the machine's root.
"""

from __future__ import annotations

import base64
import io
import os
import re
import subprocess
from pathlib import Path

__all__ = ["snapshot_notebook", "snapshot_reports", "clean_stream", "clean_streams"]

_INTERACTIVE = ("application/vnd.plotly.v1+json", "application/vnd.jupyter.widget-view+json")
_NOTE = ("*(interactive output left out of this snapshot: run the notebook, or view a map with "
         "`semmatch show MAP.ply --html OUT.html`)*")


#: a warning as Python prints it: ``FILE:LINE: CATEGORY: message`` (its source line follows, indented)
_WARNING_LINE = re.compile(r"^\S.*?:\d+: (\w+Warning): ")
#: warnings of no result that only say how a library was set up on the machine that ran the notebook
_MACHINE_NOTICES = (("NumbaWarning", "TBB"),)
#: an absolute path into an installed package: shown from the package (``numba/np/...``)
_SITE_PACKAGES = re.compile(r"/[^\s:'\"]*/(?:site|dist)-packages/")
#: an absolute path into a clone of the repository: shown from the repository (``semmatch/...``)
#: (also the folder itself: ``/tmp/run/data`` -> ``data``)
_REPOSITORY = re.compile(r"(?<![\w.~-])/[^\s:'\"]*?/"
                         r"(?=(?:semmatch|data|figures|reports|models|notebooks|scripts)(?:/|(?![\w.-])))")


def clean_stream(text: str) -> str:
    """A notebook's printed output without what only describes the machine that ran it.

    Warnings listed in :data:`_MACHINE_NOTICES` (category and a word of their message) are left
    out with their source line; absolute paths into ``site-packages`` or into the repository
    lose the machine's part (``/work/clone/semmatch/x.py`` -> ``semmatch/x.py``).

    Parameters
    ----------
    text : str
        A ``stream`` output's text.

    Returns
    -------
    str
    """
    records: list[list[str]] = []  # a line that is not indented starts a record; indented ones join it
    for line in text.splitlines(keepends=True):
        if records and line[:1].isspace():
            records[-1].append(line)
        else:
            records.append([line])
    out = []
    for record in records:
        joined = "".join(record)
        m = _WARNING_LINE.match(joined)
        if not (m and any(m[1] == category and word in joined for category, word in _MACHINE_NOTICES)):
            out.append(joined)
    return _REPOSITORY.sub("", _SITE_PACKAGES.sub("", "".join(out)))


def _machine_free(value):
    """``value`` (papermill metadata: strings, lists, dicts) with its paths shown from the repository."""
    if isinstance(value, str):
        return _REPOSITORY.sub("", _SITE_PACKAGES.sub("", value))
    if isinstance(value, list):
        return [_machine_free(v) for v in value]
    if isinstance(value, dict):
        return {k: _machine_free(v) for k, v in value.items()}
    return value


def clean_streams(nb) -> None:
    """Apply :func:`clean_stream` to every ``stream`` output of a notebook (in place; outputs
    left empty are removed), and show the paths of its papermill metadata, of papermill's
    injected-parameters cell and of printed values (``text/plain``) from the repository."""
    if "papermill" in nb.metadata:
        nb.metadata["papermill"] = _machine_free(nb.metadata["papermill"])
    for cell in nb.cells:
        if cell.get("cell_type") != "code":
            continue
        if "injected-parameters" in cell.get("metadata", {}).get("tags", ()):  # papermill's cell: data_root = "/tmp/.../data"
            cell.source = _machine_free(cell.source)
        outputs = []
        for out in cell.get("outputs", []):
            if out.get("output_type") == "stream":
                text = out["text"] if isinstance(out["text"], str) else "".join(out["text"])
                out["text"] = clean_stream(text)
                if not out["text"]:
                    continue
            elif "text/plain" in out.get("data", {}):  # a printed value: TrainConfig(out='/tmp/.../data/...')
                out["data"]["text/plain"] = _machine_free(out["data"]["text/plain"])
            outputs.append(out)
        cell.outputs = outputs


def _small_image(png_b64: str, max_width: int, quality: int) -> tuple[str, str]:
    """(mime, base64) of the smaller of a downscaled JPEG and the (downscaled) PNG."""
    from PIL import Image

    img = Image.open(io.BytesIO(base64.b64decode(png_b64)))
    img.load()
    if img.width > max_width:
        img = img.resize((max_width, max(1, round(img.height * max_width / img.width))), Image.LANCZOS)
    rgb = img.convert("RGBA")
    flat = Image.new("RGB", rgb.size, (255, 255, 255))
    flat.paste(rgb, mask=rgb.getchannel("A"))
    jpg, png = io.BytesIO(), io.BytesIO()
    flat.save(jpg, "JPEG", quality=quality, optimize=True)
    img.save(png, "PNG", optimize=True)
    best = ("image/jpeg", jpg) if jpg.tell() < png.tell() else ("image/png", png)
    return best[0], base64.b64encode(best[1].getvalue()).decode()


def snapshot_notebook(src: str | os.PathLike, dst: str | os.PathLike, *, max_width: int = 960,
                      quality: int = 80, meta: dict | None = None) -> Path:
    """Write a small copy of one executed notebook.

    Parameters
    ----------
    src, dst : path
        Executed notebook and where its snapshot goes (written atomically).
    max_width : int
        Figures wider than this are scaled down (pixels).
    quality : int
        JPEG quality (1-95).
    meta : dict, optional
        Stored as the notebook's ``semmatch_snapshot`` metadata.

    Returns
    -------
    Path
        ``dst``.

    Raises
    ------
    ValueError
        If ``src`` is not a notebook (named in the message) or the settings are out of range.
    """
    import nbformat

    from ..io import atomic_path

    if max_width < 16 or not 1 <= quality <= 95:
        raise ValueError(f"max_width must be >= 16 and quality in 1..95, got {max_width}, {quality}")
    try:
        nb = nbformat.read(str(src), as_version=4)
    except Exception as e:  # nbformat raises several types for a broken file
        raise ValueError(f"{src}: not a readable notebook ({e})") from None
    for cell in nb.cells:
        outputs = []
        for out in cell.get("outputs", []):
            data = out.get("data")
            if data is not None:
                if any(k in data for k in _INTERACTIVE):
                    for k in _INTERACTIVE:
                        data.pop(k, None)
                    if not any(k.startswith("image/") or k in ("text/html", "text/markdown") for k in data):
                        out["data"] = data = {"text/markdown": _NOTE}
                        out.get("metadata", {}).clear()
                if "image/png" in data:
                    mime, b64 = _small_image(data.pop("image/png"), max_width, quality)
                    data[mime] = b64
                    out.get("metadata", {}).pop("image/png", None)
            outputs.append(out)
        if cell.cell_type == "code":
            cell.outputs = outputs
    clean_streams(nb)
    nb.metadata.pop("widgets", None)
    nb.metadata["semmatch_snapshot"] = dict(meta or {})
    dst = Path(dst)
    dst.parent.mkdir(parents=True, exist_ok=True)
    with atomic_path(dst) as tmp:
        nbformat.write(nb, str(tmp))
    return dst


def snapshot_reports(src_dir: str | os.PathLike, dst_dir: str | os.PathLike, *, profile: str,
                     max_width: int = 960, quality: int = 80, root: str | os.PathLike | None = None) -> list[Path]:
    """Snapshot every executed notebook of ``src_dir`` into ``dst_dir``.

    Parameters
    ----------
    src_dir : path
        Executed notebooks (``reports/<profile>``).
    dst_dir : path
        Where the snapshots go (``reports/snapshot/<profile>``).
    profile : str
        The profile they were executed with (stored in each snapshot's metadata).
    max_width, quality : int
        See :func:`snapshot_notebook`.
    root : path, optional
        The repository whose commit the snapshots record (default: the one ``src_dir`` is in).

    Returns
    -------
    list of Path
        The snapshots written.

    Raises
    ------
    FileNotFoundError
        If ``src_dir`` holds no executed notebook.
    """
    src = sorted(Path(src_dir).glob("[0-9][0-9]_*.ipynb"))
    if not src:
        raise FileNotFoundError(f"{src_dir}: no executed notebooks (NN_*.ipynb); run the pipeline first")
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root or src_dir, capture_output=True,
                                text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        commit = ""
    meta = {"profile": profile, "commit": commit or "unknown"}
    return [snapshot_notebook(p, Path(dst_dir) / p.name, max_width=max_width, quality=quality, meta=meta)
            for p in src]
