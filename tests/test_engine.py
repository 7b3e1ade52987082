"""Per-scene work on Dask (semmatch.runtime.engine): the same files serially and on a local cluster; clear
errors; no orphans; a killed worker's task reruns elsewhere. A scheduler and workers started
separately: tests/test_dask_cluster.py."""

from __future__ import annotations

import hashlib
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from semmatch.io.geometry import DEFAULT_INTRINSICS
from semmatch.runtime import engine
from semmatch.sim import generate_dataset

pytestmark = pytest.mark.slow

TINY = dict(train_seeds=[1, 2], eval_seeds=[9001], kinds=["living_room", "bedroom"], n_frames_upper=3,
            n_frames_lower=3, heights_sweep=None, intrinsics=DEFAULT_INTRINSICS.scaled(48, 36), progress=False)


def digests(root: Path) -> dict[str, str]:
    return {p.relative_to(root).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(root.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def serial(tmp_path_factory) -> dict[str, str]:
    root = tmp_path_factory.mktemp("serial")
    generate_dataset(root, jobs=1, **TINY)
    return digests(root)


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    try:  # a zombie is dead
        return Path(f"/proc/{pid}/status").read_text().split("State:")[1].split()[0] != "Z"
    except (OSError, IndexError):
        return False


def test_local_cluster_writes_the_same_files_as_a_serial_run(serial, tmp_path):
    generate_dataset(tmp_path, jobs=2, **TINY)
    assert digests(tmp_path) == serial
    assert engine.map_tasks(abs, [-3, 4, -5], jobs=2, progress=False) == [3, 4, 5]  # input order
    cluster = engine._LOCAL["cluster"]
    assert engine.map_tasks(abs, [-3, 4], jobs=3, progress=False) == [3, 4]
    assert engine._LOCAL["cluster"] is cluster  # two workers are enough: the running cluster is reused


def test_an_unreachable_scheduler_is_a_clear_error_before_anything_is_written(tmp_path, monkeypatch):
    monkeypatch.setenv(engine.SCHEDULER_ENV, "tcp://127.0.0.1:9")  # the discard port: nothing listens
    t = time.perf_counter()
    with pytest.raises(ValueError, match=r"cannot reach the Dask scheduler at 'tcp://127.0.0.1:9' within 6 s"):
        generate_dataset(tmp_path / "data", **TINY)
    assert time.perf_counter() - t < 20  # the 6 s connect timeout and start-up on a loaded machine; Dask alone waits 30 s
    assert not (tmp_path / "data").exists() or not any((tmp_path / "data").rglob("*.png"))


def test_a_killed_worker_s_task_reruns_and_the_output_is_complete(serial, tmp_path):
    client = engine._local_client(2)
    pid_of = client.run(os.getpid)  # worker address -> process id
    out = tmp_path / "data"
    done: dict = {}
    th = threading.Thread(target=lambda: done.update(r=generate_dataset(out, jobs=2, **TINY)))
    th.start()
    deadline = time.time() + 60
    victim = None
    while victim is None and time.time() < deadline and th.is_alive():
        busy = [a for a, tasks in client.processing().items() if tasks and a in pid_of]
        if busy and list(out.glob("**/.*.partial")):  # a worker holds a scene and one is being written
            victim = busy[0]
        else:
            time.sleep(0.02)
    assert victim is not None, "no worker was caught with a task"
    os.kill(pid_of[victim], signal.SIGKILL)
    th.join(timeout=300)
    assert "r" in done, "the run did not finish after a worker was killed"
    assert not _alive(pid_of[victim]) and victim not in client.run(os.getpid)  # the nanny started a new worker
    assert digests(out) == serial
    engine.close_local_cluster()


def _sleep_write(args: tuple[str, int]) -> int:
    """Item -1 fails at once; the others sleep 30 s, then write a file."""
    folder, i = args
    if i < 0:
        raise RuntimeError("task -1 fails on purpose")
    time.sleep(30)
    (Path(folder) / f"{i}.txt").write_text(str(i))
    return i


def test_a_failed_local_run_ends_its_running_tasks_before_the_error(tmp_path):
    pids = list(engine._local_client(2).run(os.getpid).values())
    with pytest.raises(RuntimeError, match="fails on purpose"):
        engine.map_tasks(_sleep_write, [(str(tmp_path), -1), (str(tmp_path), 1), (str(tmp_path), 2)], jobs=2,
                         progress=False)
    assert not engine._LOCAL  # the cluster was closed
    assert not any(_alive(pid) for pid in pids)  # its workers, one of them inside a task, are gone
    assert not list(tmp_path.iterdir())


def test_local_workers_die_with_a_killed_parent(tmp_path):
    script = tmp_path / "parent.py"
    script.write_text(
        "import os, sys, time\n"
        "from semmatch.runtime import engine\n"
        "if __name__ == '__main__':\n"
        "    c = engine._local_client(2)\n"
        "    print(' '.join(str(p) for p in c.run(os.getpid).values()), flush=True)\n"
        "    engine.map_tasks(time.sleep, [60, 60], jobs=2, progress=False)\n")
    p = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        pids = [int(x) for x in p.stdout.readline().split()]
        assert len(pids) == 2 and all(_alive(x) for x in pids)
        time.sleep(1.0)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=30)
        deadline = time.time() + 20
        while any(_alive(x) for x in pids) and time.time() < deadline:
            time.sleep(0.2)
        assert not any(_alive(x) for x in pids), "Dask workers outlived their killed parent"
    finally:
        if p.poll() is None:
            p.kill()


def test_training_views_rendered_on_a_local_cluster_equal_the_serial_ones():
    import numpy as np

    from semmatch.segment.data import make_scenes, render_views

    scenes = make_scenes(["living_room", "office", "bedroom"], [11, 12, 13])
    heights = np.array([[1.4, 1.7], [0.5, 0.9], [1.0, 1.2]])
    kw = dict(intrinsics=DEFAULT_INTRINSICS.scaled(48, 36), seed=3, progress=False)
    a = render_views(scenes, heights, 4, **kw)
    b = render_views(scenes, heights, 4, jobs=2, **kw)
    assert len(a) == 3 * 2 * 4
    for f in ("rgb", "depth", "labels", "scene", "height"):
        assert getattr(a, f).dtype == getattr(b, f).dtype and np.array_equal(getattr(a, f), getattr(b, f)), f


class _ReddishNet:
    """A picklable stand-in for a Segmenter: labels from the red channel."""

    def predict_labels(self, rgb):
        import numpy as np

        return (np.asarray(rgb)[..., 0] // 40).astype(np.uint8) + 1

    def predict_labels_batch(self, rgb, depth=None):
        return self.predict_labels(rgb)


def test_per_scene_experiment_rows_on_a_local_cluster_equal_the_serial_ones(tmp_path):
    from semmatch.experiments.adapt import adapted_lower_maps
    from semmatch.experiments.layout import Layout
    from semmatch.fusion import reconstruct
    from semmatch.io import read_sequence, write_map

    root = tmp_path / "data"
    generate_dataset(root / "scenes", **{**TINY, "train_seeds": [], "eval_seeds": [9001, 9002],
                                         "n_frames_lower": 6, "intrinsics": DEFAULT_INTRINSICS.scaled(64, 48)})
    layout = Layout(root)
    for sd in layout.scene_dirs("eval"):
        write_map(layout.lower_reference(sd.name), reconstruct(read_sequence(layout.lower_sequence(sd)), None, 0.08))
    nets = {"reddish": _ReddishNet()}
    serial_rows = adapted_lower_maps(root, nets, voxel_size=0.08, eval_voxel_size=0.1, progress=False)
    cluster_rows = adapted_lower_maps(root, nets, voxel_size=0.08, eval_voxel_size=0.1, jobs=2, progress=False)
    assert list(serial_rows["scene"]) == [sd.name for sd in layout.scene_dirs("eval")]
    assert serial_rows.equals(cluster_rows)


def test_the_runner_refuses_an_unreachable_scheduler_before_running_a_notebook(tmp_path, monkeypatch):
    from semmatch.experiments.pipeline import main

    monkeypatch.delenv(engine.SCHEDULER_ENV, raising=False)
    reports = tmp_path / "reports"
    t = time.perf_counter()
    rc = main(["run", "04_label_transfer", "--profile", "smoke", "--reports-dir", str(reports),
               "--scheduler", "tcp://127.0.0.1:9", "--quiet"])
    assert rc != 0 and time.perf_counter() - t < 20  # as above: no 30 s wait
    assert not reports.exists()  # nothing written, no kernel started
    assert engine.map_tasks(abs, [-1, 2], jobs=None, progress=False) == [1, 2]  # None: one worker per core


def test_height_sweep_scores_on_a_local_cluster_equal_the_serial_ones(tmp_path):
    from semmatch.experiments.height import sweep_sequences
    from semmatch.segment.viewpoint import viewpoint_gap_sequences

    root = tmp_path / "data"
    generate_dataset(root / "scenes", **{**TINY, "train_seeds": [], "eval_seeds": [9001, 9002],
                                         "heights_sweep": [0.4, 1.2], "n_frames_sweep": 3})
    sweeps = sweep_sequences(root)
    assert {h: len(p) for h, p in sweeps.items()} == {0.4: 4, 1.2: 4}
    for per_scene in (True, False):
        serial_rows = viewpoint_gap_sequences({"reddish": _ReddishNet()}, sweeps, per_scene=per_scene, progress=False)
        cluster_rows = viewpoint_gap_sequences({"reddish": _ReddishNet()}, sweeps, per_scene=per_scene, jobs=2,
                                               progress=False)
        assert len(serial_rows) == (8 if per_scene else 2) and serial_rows.equals(cluster_rows)
    every = viewpoint_gap_sequences({"reddish": _ReddishNet()}, sweeps, per_scene=True, progress=False)
    every_2nd = viewpoint_gap_sequences({"reddish": _ReddishNet()}, sweeps, per_scene=True, frame_step=2,
                                        progress=False)
    assert set(every["n_frames"]) == {3} and set(every_2nd["n_frames"]) == {2}  # frames 0 and 2 of 3
    with pytest.raises(ValueError, match="frame_step"):
        viewpoint_gap_sequences({"reddish": _ReddishNet()}, sweeps, frame_step=0, progress=False)


@pytest.mark.skipif(not hasattr(os, "sched_getaffinity") or len(os.sched_getaffinity(0)) < 2,
                    reason="pinning needs two CPUs")
def test_local_workers_are_pinned_each_to_its_own_cpu():
    engine.map_tasks(abs, [-1, 2], jobs=2, progress=False)
    per_worker = engine._LOCAL["client"].run(os.sched_getaffinity, 0)
    cpus = [frozenset(c) for c in per_worker.values()]
    assert len(cpus) == 2 and all(len(c) == 1 for c in cpus)
    assert cpus[0] != cpus[1]
    assert len(os.sched_getaffinity(0)) >= 2  # the calling process keeps every CPU
