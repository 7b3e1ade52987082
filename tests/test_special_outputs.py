"""No output of any verb replaces a special file: a FIFO, a character device (``/dev/null``) or a
link to an open file (``/dev/stdout``) is written through, a block device is refused, an output
folder pointed at any of them is refused; the special file is still what it was afterwards.

One case per family of writers: tables (``evaluate --csv/--markdown``, ``panoptic evaluate
--csv``), figures (``evaluate --figure``), pages (``show --html``), maps (``reconstruct --out``)
and output folders (``transfer --out``).
"""

from __future__ import annotations

import os
import stat
import threading
from pathlib import Path

import numpy as np
import pytest

from semmatch.cli import main
from semmatch.io import SemanticMap, SequenceWriter, write_map
from semmatch.io.files import atomic_write_text, writes_through
from semmatch.io.geometry import Intrinsics

pytestmark = pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="FIFOs are POSIX")


@pytest.fixture(scope="module")
def inputs(tmp_path_factory) -> Path:
    """``a.ply`` / ``b.ply`` (labelled maps with instances) and ``seq`` (three frames of a wall)."""
    d = tmp_path_factory.mktemp("special")
    rng = np.random.default_rng(0)
    xy = rng.uniform(-1, 1, (4000, 2))
    pts = np.c_[xy, np.full(len(xy), 2.0)]
    labels = np.where(xy[:, 0] < 0, 3, 5).astype(np.uint8)
    write_map(d / "a.ply", SemanticMap(pts, labels, instances=(xy[:, 0] < 0).astype(np.int32) + 1))
    write_map(d / "b.ply", SemanticMap(pts + 0.01, labels, instances=(xy[:, 0] < 0).astype(np.int32) + 1))
    intr = Intrinsics(32, 24, 30.0, 30.0, 16.0, 12.0)
    with SequenceWriter(d / "seq", intr) as w:
        for i in range(3):
            pose = np.eye(4)
            pose[0, 3] = 0.05 * i
            w.add(np.full((24, 32, 3), 120, np.uint8), np.full((24, 32), 2.0), pose,
                  labels=np.full((24, 32), 3, np.uint8))
    return d


def _read_fifo(fifo: Path) -> tuple[threading.Thread, list[bytes]]:
    got: list[bytes] = []

    def read() -> None:
        with open(fifo, "rb") as fh:
            got.append(fh.read())

    t = threading.Thread(target=read, daemon=True)
    t.start()
    return t, got


CASES = {
    "evaluate --csv": (["evaluate", "{i}/a.ply", "{i}/b.ply", "--csv", "{out}"], "out.csv", b"jaccard"),
    "evaluate --markdown": (["evaluate", "{i}/a.ply", "{i}/b.ply", "--markdown", "{out}"], "out.md", b"| "),
    "evaluate --figure": (["evaluate", "{i}/a.ply", "{i}/b.ply", "--figure", "{out}"], "out.png", b"\x89PNG"),
    "panoptic evaluate --csv": (["panoptic", "evaluate", "{i}/a.ply", "{i}/b.ply", "--csv", "{out}"], "pq.csv", b"pq"),
    "show --html": (["show", "{i}/a.ply", "--plotlyjs", "cdn", "--html", "{out}"], "page.html", b"<html"),
    "reconstruct --out": (["reconstruct", "{i}/seq", "--quiet", "--out", "{out}"], "map.ply", b"ply\n"),
}


def _argv(case: str, inputs: Path, out: Path) -> list[str]:
    return [a.format(i=inputs, out=out) for a in CASES[case][0]]


@pytest.mark.parametrize("case", list(CASES))
def test_a_fifo_is_written_through(inputs, tmp_path, case):
    fifo = tmp_path / CASES[case][1]
    os.mkfifo(fifo)
    reader, got = _read_fifo(fifo)
    assert main(_argv(case, inputs, fifo)) == 0
    reader.join(30)
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode), "the FIFO was replaced"
    assert got and got[0].startswith(CASES[case][2]) or CASES[case][2] in got[0][:200], got[:1]
    assert sorted(p.name for p in tmp_path.iterdir()) == [fifo.name]  # no temporary file beside it


@pytest.mark.parametrize("case", ["evaluate --csv", "show --html"])
def test_a_link_to_stdout_is_written_through_not_replaced(inputs, tmp_path, capfd, case):
    link = tmp_path / "stdout"  # what /dev/stdout is: a link to /proc/self/fd/1
    link.symlink_to("/proc/self/fd/1")
    capfd.readouterr()
    assert main(_argv(case, inputs, link)) == 0
    assert link.is_symlink() and os.readlink(link) == "/proc/self/fd/1"
    assert CASES[case][2] in capfd.readouterr().out.encode()


def test_dev_null_stays_a_device():
    before = os.stat("/dev/null")
    atomic_write_text("/dev/null", "nothing\n")
    after = os.stat("/dev/null")
    assert stat.S_ISCHR(after.st_mode) and after.st_rdev == before.st_rdev and after.st_ino == before.st_ino
    assert writes_through("/dev/null") and writes_through("/dev/stdout")


def test_a_block_device_is_refused(tmp_path, capsys, inputs):
    disk = tmp_path / "disk.csv"
    try:
        os.mknod(disk, 0o600 | stat.S_IFBLK, os.makedev(7, 200))
    except (PermissionError, OSError) as e:
        pytest.skip(f"cannot make a block device node here ({e})")
    assert main(_argv("evaluate --csv", inputs, disk)) == 2
    assert "disk.csv: is a block device (a disk); semmatch writes its outputs to files" in capsys.readouterr().err
    assert stat.S_ISBLK(os.lstat(disk).st_mode)


def test_an_output_folder_on_a_special_file_is_refused(inputs, tmp_path, capsys):
    fifo = tmp_path / "labels"
    os.mkfifo(fifo)
    link = tmp_path / "stdout"
    link.symlink_to("/proc/self/fd/1")
    for target in (fifo, link, Path("/dev/null")):
        rc = main(["transfer", str(inputs / "seq"), "--map", str(inputs / "a.ply"), "--method", "3d-neighborhood",
                   "--quiet", "--out", str(target)])
        assert rc == 2
        assert "is not a folder" in capsys.readouterr().err
    assert stat.S_ISFIFO(os.lstat(fifo).st_mode) and link.is_symlink()
    assert stat.S_ISCHR(os.stat("/dev/null").st_mode)


def test_output_folders_get_the_users_umask_not_0700(inputs, tmp_path):
    from semmatch.io import write_labels_folder

    old = os.umask(0o022)
    try:
        write_labels_folder(tmp_path / "labels", [np.zeros((4, 5), np.uint8)])
        with SequenceWriter(tmp_path / "seq", Intrinsics(8, 6, 5.0, 5.0, 4.0, 3.0)) as w:
            w.add(np.zeros((6, 8, 3), np.uint8), np.ones((6, 8)), np.eye(4))
        os.umask(0o027)
        write_labels_folder(tmp_path / "private", [np.zeros((4, 5), np.uint8)])
    finally:
        os.umask(old)
    assert stat.S_IMODE(os.stat(tmp_path / "labels").st_mode) == 0o755
    assert stat.S_IMODE(os.stat(tmp_path / "seq").st_mode) == 0o755
    assert stat.S_IMODE(os.stat(tmp_path / "private").st_mode) == 0o750
