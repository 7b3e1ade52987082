"""``semmatch bench segment``: inference speed of the segmentation networks on this machine."""

from __future__ import annotations

import argparse
import os
import time

from semmatch.cli.common import add_json, emit, number

from . import add_thread_flags, apply_threads, thread_rows


def register(sub) -> None:
    """Add ``semmatch bench segment``."""
    p = sub.add_parser("segment", help="segmentation networks: frames per second at 320x240 and 640x480")
    p.add_argument("--model", nargs="*", default=[],
                   help="checkpoints to time (default: untrained compact and strong networks at the full "
                        "training profile's input size; speed does not depend on the weights)")
    p.add_argument("--frames", type=number(int, lo=1), default=20, help="timed frames per size")
    p.add_argument("--device", choices=("auto", "cpu", "cuda"), default="cpu", help="where the networks run")
    p.add_argument("--no-flip", action="store_true",
                   help="time one network pass (default: two, with the mirror-image average, as predictions run)")
    add_thread_flags(p, "segment")
    add_json(p, "the timings")
    p.set_defaults(func=run)


def time_predict(segmenter, width: int, height: int, frames: int, *, seed: int = 0) -> tuple[float, float]:
    """Frames per second of ``segmenter.predict`` on random ``width`` x ``height`` RGB(-D) images:
    per wall-clock second and per CPU-second of this process (less sensitive to other processes)."""
    import numpy as np

    rng = np.random.default_rng(seed)
    imgs = rng.integers(0, 256, (4, height, width, 3), dtype=np.uint8)
    depth = rng.uniform(0.5, 5.0, (height, width)).astype(np.float32)
    for i in range(3):
        segmenter.predict(imgs[i % 4], depth)
    t, c = time.perf_counter(), time.process_time()
    for i in range(frames):
        segmenter.predict(imgs[i % 4], depth)
    return frames / (time.perf_counter() - t), frames / max(time.process_time() - c, 1e-9)


def run(args: argparse.Namespace) -> int:
    """Time every network and print a table or JSON."""
    if args.thread_rows:
        return _print_thread_rows(args)
    limits = apply_threads(args)
    import torch

    from semmatch.segment import load_model
    from semmatch.segment.models import build_network
    from semmatch.segment.predict import Segmenter
    from semmatch.segment.training import make_config

    if args.frames < 1:
        raise ValueError("--frames must be >= 1")
    device = None if args.device == "auto" else args.device
    nets = {}
    if args.model:
        for path in args.model:
            seg = load_model(path, device=device, flip=not args.no_flip)
            nets[seg.name] = seg
    else:
        for arch in ("compact", "strong"):
            torch.manual_seed(0)
            cfg = make_config("full", arch=arch).model_config()
            nets[arch] = Segmenter(build_network(cfg), cfg, device=device or "cpu", flip=not args.no_flip)
    result = {"networks": {}, "threads": torch.get_num_threads(), "limits": limits, "frames": args.frames,
              "load_average": os.getloadavg()[0]}
    rows = []
    for name, seg in nets.items():
        r = {}
        for w, h in ((320, 240), (640, 480)):
            fps, cpu_fps = time_predict(seg, w, h, args.frames)
            r[f"fps_{w}x{h}"], r[f"cpu_fps_{w}x{h}"] = round(fps, 2), round(cpu_fps, 2)
        r["input"] = f"{seg.config.width}x{seg.config.height}"
        r["device"] = str(seg.device)
        r["flip"] = seg.flip
        result["networks"][name] = r
        rows.append(f"{name:<12} {r['input']:>9} {r['fps_320x240']:>12.1f} {r['fps_640x480']:>12.1f} "
                    f"{r['cpu_fps_320x240']:>12.1f} {r['cpu_fps_640x480']:>12.1f}")
    table = "\n".join([f"{'network':<12} {'runs at':>9} {'FPS 320x240':>12} {'FPS 640x480':>12} "
                       f"{'CPU 320x240':>12} {'CPU 640x480':>12}", *rows,
                       f"(FPS: per wall-clock second; CPU: per CPU-second of this process; torch threads: "
                       f"{result['threads']}, {args.frames} frames per size, load {result['load_average']:.1f})"])
    return emit(result, args.json, table)


def _print_thread_rows(args: argparse.Namespace) -> int:
    """``--thread-rows``: the benchmark in a fresh process per thread environment, one row each."""
    rows = thread_rows(args, "segment")
    nets = list(rows[0]["networks"])
    sizes = ("320x240", "640x480")
    head = " ".join(f"{n + ' ' + s:>22}" for n in nets for s in sizes)
    lines = [f"{'environment':<30} {'torch':>5} {'load':>5} {head}"]
    for r in rows:
        fps = " ".join(f"{r['networks'][n][f'fps_{s}']:>10.2f} /{r['networks'][n][f'cpu_fps_{s}']:>10.2f}"
                       for n in nets for s in sizes)
        lines.append(f"{r['row']:<30} {r['threads']:>5} {r['load_average']:5.1f} {fps}")
    lines.append(f"(frames per wall-clock second / per CPU-second, {args.frames} frames per size; "
                 f"{os.cpu_count()} CPUs)")
    return emit({"rows": rows}, args.json, "\n".join(lines))
