"""Transfer rate of the same frames against two upper maps: the scene's mesh (what `semmatch bench
transfer` indexes) and the fused ground-truth upper map of a pipeline run (what Table 1 indexes).

Usage::

    python scripts/speed_by_map.py DATA_ROOT [N_FRAMES]   # e.g. data/confirm/seeds-8001-8006 8

Prints CPU FPS (`time_methods`, one thread) and coverage per method for the fused map (from its
index cache and freshly indexed) and for the mesh, on the first evaluation scene's lower frames
at 640x480. Used on 2026-11-26 to explain why Table 1 of the confirmatory run is slower than the
benchmark (docs/speed.md, "Map density").
"""
import json
import sys

from semmatch.experiments.layout import Layout
from semmatch.experiments.speed import GT, _frames_at
from semmatch.io import read_map
from semmatch.sim import generate_scene
from semmatch.transfer import as_map_index, load_index
from semmatch.transfer.benchmark import time_methods

METHODS = ["2d-slic", "3d-projected-sp", "3d-slic", "dbscan", "3d-neighborhood"]


def main(data_root: str, n_frames: int = 8) -> None:
    layout = Layout(data_root)
    sd = layout.scene_dirs("eval")[0]
    frames = _frames_at(sd, n_frames, 640, 480)
    meta = json.loads((sd / "scene.json").read_text())
    path = layout.upper_map(sd.name, GT)
    fused = read_map(path)
    mesh = generate_scene(meta["kind"], int(meta["seed"])).to_semantic_map()
    print(f"{sd.name}: fused map {len(fused.points)} points, mesh {len(mesh.points)} vertices, {len(frames)} frames")
    for name, index in (("fused (index cache)", load_index(path)), ("fused (indexed here)", as_map_index(fused)),
                        ("mesh", as_map_index(mesh))):
        r = time_methods(frames, index, METHODS, exact_variant=False)["methods"]
        print(f"{name:22s}", "  ".join(f"{m} {r[m]['fps']:.1f} FPS cov {r[m]['coverage']:.2f}" for m in METHODS))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 8)
