"""Writing files safely: atomic writes, and output folders that never replace what semmatch did not write.

A file is written to a temporary name beside it and renamed; an output folder is written beside
its final name, carries :data:`OUTPUT_MARKER`, and replaces only an earlier output of the same
kind (the old one moved aside, the new one moved in, the old one removed: a kill at any point
leaves one of them complete). One writer at a time holds a lock on the output.
"""

from __future__ import annotations

import contextlib
import json
import os
import re
import shutil
import stat
import sys
import uuid
from collections.abc import Iterator
from collections.abc import Sequence as _SequenceABC
from pathlib import Path

from .outputs import writer_alive, writer_tag

__all__ = ['atomic_path', 'atomic_write_text', 'save_figure', 'write_json', 'OUTPUT_MARKER', 'output_kind', 'check_output_dir', 'replace_output_dir',
           'output_dir_writer', 'writes_through']

PathLike = str | os.PathLike


# ----------------------------------------------------------------------------- atomic writes
#: links to an open file of a process: written through, never replaced (``/dev/stdout`` is a link
#: to ``/proc/self/fd/1``, which may be a terminal, a pipe or the file a shell redirected it to)
_OPEN_FILE_LINK = re.compile(r"^/dev/(stdout|stderr|fd/\d+)$|^/proc/(self|thread-self|\d+)/fd/\d+$")


def _open_file_link(path: Path) -> re.Match | None:
    """The first link to an open file on the way from ``path`` (any number of hops), else None."""
    hop = os.path.abspath(path)
    for _ in range(40):  # the kernel's own limit on nested links
        m = _OPEN_FILE_LINK.match(hop)
        if m or not os.path.islink(hop):
            return m
        hop = os.path.normpath(os.path.join(os.path.dirname(hop), os.readlink(hop)))
    return None


def _own_descriptor(path: Path) -> int | None:
    """The descriptor of this process that ``path`` names (``/dev/stdout``: 1), else None."""
    m = _open_file_link(path)
    if m is None:
        return None
    if m[1]:  # /dev/stdout, /dev/stderr, /dev/fd/N
        return {"stdout": 1, "stderr": 2}.get(m[1]) or int(m[1].split("/")[1])
    if m[2] in ("self", "thread-self", str(os.getpid())):
        return int(m[0].rsplit("/", 1)[1])
    return None


def writes_through(path: PathLike) -> bool:
    """Whether an output at ``path`` is written through (streamed into) rather than replaced.

    A FIFO, a character device (a terminal, ``/dev/null``) and a link to an open file
    (``/dev/stdout``, ``/dev/fd/N``, ``/proc/self/fd/N``) are written through; replacing them
    would put a regular file where the reader, or the system, expects them. Anything else
    (a regular file, a new path) is replaced atomically.

    Parameters
    ----------
    path : path

    Returns
    -------
    bool

    Raises
    ------
    ValueError
        ``path`` is a block device (a disk) or a socket: semmatch writes neither.
    """
    path = Path(path)
    try:
        mode = os.stat(path).st_mode
    except OSError:  # not there (or not reachable): an ordinary new file, or the writer's own error
        return False
    if stat.S_ISBLK(mode) or stat.S_ISSOCK(mode):
        what = "a block device (a disk)" if stat.S_ISBLK(mode) else "a socket"
        raise ValueError(f"{path}: is {what}; semmatch writes its outputs to files, FIFOs and character devices "
                         "(such as /dev/stdout), never to a disk or a socket: choose a file")
    if stat.S_ISFIFO(mode) or stat.S_ISCHR(mode):
        return True
    return stat.S_ISREG(mode) and _open_file_link(path) is not None


@contextlib.contextmanager
def _written_through(path: Path) -> Iterator[Path]:
    """Yield a temporary file (in a private temporary folder); copy it into ``path`` when the
    block succeeds, opened for appending (a FIFO's reader, a terminal or the file behind
    ``/dev/stdout`` receives the bytes; nothing is created or replaced where ``path`` is)."""
    import tempfile

    with tempfile.TemporaryDirectory(prefix="semmatch-out-") as folder:
        tmp = Path(folder) / (path.name or "output")
        yield tmp
        fd = _own_descriptor(path)
        try:
            with open(tmp, "rb") as src:
                if fd is None:
                    with open(path, "ab") as dst:
                        shutil.copyfileobj(src, dst)
                else:  # this process's own stdout (...): write at its position, after what was printed
                    for stream in (sys.stdout, sys.stderr):
                        stream.flush()
                    with os.fdopen(os.dup(fd), "wb") as dst:
                        shutil.copyfileobj(src, dst)
        except OSError as e:
            raise type(e)(e.errno, f"cannot write {path}: {e.strerror}", str(path)) from None


@contextlib.contextmanager
def atomic_path(path: PathLike) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; rename it to ``path`` when the block succeeds.

    The temporary file keeps the suffix of ``path`` so that libraries choosing a format by
    extension (OpenCV, Open3D, matplotlib) still work. On error it is removed; its name carries
    the writer's machine and process id, so the temporary files of a killed writer are removed by the next
    process that writes into the same folder.

    A FIFO, a character device or ``/dev/stdout`` at ``path`` is never replaced: the finished
    temporary file is written through into it (:func:`writes_through`); a block device or a
    socket is refused.
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a folder; give the name of the file to write")
    if writes_through(path):
        with _written_through(path) as tmp:
            yield tmp
        return
    path.parent.mkdir(parents=True, exist_ok=True)
    _sweep_stale_files(path.parent)
    tmp = path.with_name(f".{path.stem}.{writer_tag()}-{uuid.uuid4().hex[:8]}.tmp{path.suffix}")
    try:
        yield tmp
        os.replace(tmp, path)
    except OSError as e:
        if e.filename is not None and Path(e.filename).name == tmp.name:  # name the file the user asked for
            raise type(e)(e.errno, f"cannot write {path}: {e.strerror}", str(path)) from None
        raise
    finally:
        if tmp.exists():
            tmp.unlink()


_TEMP_FILE = re.compile(r"^\..+\.(?:(?P<host>[A-Za-z0-9]+)_)?(?P<pid>\d+)-[0-9a-f]{8}\.tmp(\.[^.]*)?$")
_SWEPT: set[str] = set()  # folders this process has swept


def _sweep_stale_files(folder: Path) -> list[Path]:
    """Remove the temporary files of :func:`atomic_path` in ``folder`` whose writer has ended (a
    SIGKILL runs no clean-up; those of live writers, and of other machines, stay). Once per folder
    and process: the first atomic write into a folder lists it, later ones do not."""

    key = os.path.abspath(folder)
    if key in _SWEPT:
        return []
    gone = []
    with os.scandir(folder) as entries:
        for e in entries:
            m = _TEMP_FILE.match(e.name) if e.name.startswith(".") else None
            if m and not writer_alive(int(m["pid"]), m["host"]) and e.is_file(follow_symlinks=False):
                Path(e.path).unlink(missing_ok=True)
                gone.append(Path(e.path))
    _SWEPT.add(key)
    return gone


def atomic_write_text(path: PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def save_figure(fig, path: PathLike, *, dpi: int = 120, close: bool = True, **kwargs) -> Path:
    """Save a matplotlib figure (format from the suffix) atomically; close it by default."""
    path = Path(path)
    with atomic_path(path) as tmp:
        fig.savefig(tmp, dpi=dpi, **kwargs)
    if close:
        import matplotlib.pyplot as plt

        plt.close(fig)
    return path


def write_json(path: PathLike, obj) -> None:
    """Write ``obj`` as indented JSON, atomically."""
    atomic_write_text(path, json.dumps(obj, indent=2, sort_keys=False) + "\n")



#: marker file of a folder semmatch wrote (``{"kind": ...}``); only such folders are ever replaced
OUTPUT_MARKER = ".semmatch-output"


def output_kind(path: PathLike) -> str | None:
    """The kind of semmatch output folder ``path`` is (its :data:`OUTPUT_MARKER`), else None."""
    marker = Path(path) / OUTPUT_MARKER
    try:
        return str(json.loads(marker.read_text()).get("kind"))
    except (OSError, ValueError, AttributeError):
        return None


def check_output_dir(path: PathLike, kind: str, *, overwrite: bool = False, inputs: _SequenceABC[PathLike] = ()) -> Path:
    """Refuse an output folder whose replacement could destroy what semmatch did not write.

    Parameters
    ----------
    path : path
        The folder to write.
    kind : str
        The kind of output (e.g. ``"labels"``).
    overwrite : bool
        Allow replacing an existing complete semmatch output of the same kind.
    inputs : sequence of paths
        Inputs of the command: the output may be neither one of them, nor inside one, nor
        contain one.

    Returns
    -------
    Path

    Raises
    ------
    ValueError
        The output is, lies inside or contains an input.
    FileExistsError
        ``path`` exists and is not an empty folder or a semmatch output of this kind, or it is
        one and ``overwrite`` is False (the message names ``--overwrite``).
    """
    path = Path(path)
    target = path.resolve()
    for inp in inputs:
        src = Path(inp).resolve()
        if target == src or src in target.parents or target in src.parents:
            raise ValueError(f"{path}: the output folder is, lies inside or contains the input {inp}; "
                             f"choose an --out outside the inputs")
    if not path.exists() and not path.is_symlink():
        return path
    if not path.is_dir() or path.is_symlink():
        raise FileExistsError(f"{path} exists and is not a folder; choose another --out")
    if not any(path.iterdir()):
        return path
    have = output_kind(path)
    if have != kind:
        what = f"a semmatch {have} output" if have else "files semmatch did not write"
        raise FileExistsError(f"{path} holds {what}; refusing to replace it with {kind} (choose another --out)")
    if not overwrite:
        raise FileExistsError(f"{path} already holds semmatch {kind}; pass --overwrite to replace it")
    return path


@contextlib.contextmanager
def _writer_lock(path: Path) -> Iterator[None]:
    """Hold an exclusive lock for writing ``path`` (a second writer gets a clear error)."""
    import fcntl

    lock = path.parent / f".{path.name}.lock"
    fd = os.open(lock, os.O_CREAT | os.O_RDWR, 0o644)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise FileExistsError(f"{path}: another semmatch process is writing it right now") from None
        try:
            yield
        finally:
            lock.unlink(missing_ok=True)  # still held: a writer waiting on this file fails clearly
    finally:
        os.close(fd)


def _recover(path: Path) -> None:
    """Clean up after a writer of ``path`` that was killed: drop partial folders, and bring back
    the previous output when the kill fell between moving it aside and moving the new one in."""
    from .outputs import _TEMP, glob_escape, sweep_stale

    name = glob_escape(path.name)
    olds = sorted(path.parent.glob(f".{name}.*.old"))
    if olds and not path.exists():
        os.replace(olds[-1], path)
        olds = olds[:-1]
    sweep_stale(path)  # temporary folders of writers that are gone (those of live ones stay)
    legacy = [p for p in path.parent.glob(f".{name}.*.partial") if not _TEMP.search(p.name)]
    for junk in [*legacy, *olds]:
        shutil.rmtree(junk, ignore_errors=True)


def replace_output_dir(tmp: PathLike, path: PathLike, kind: str) -> Path:
    """Move the complete folder ``tmp`` to ``path``, replacing a previous output of ``kind``.

    The new folder gets the :data:`OUTPUT_MARKER`; an existing ``path`` is moved aside, the
    new one moved in, then the old one removed: a kill at any point leaves the old or the new
    output complete (a later writer restores the old one if the kill fell between the moves).
    """
    tmp, path = Path(tmp), Path(path)
    (tmp / OUTPUT_MARKER).write_text(json.dumps({"kind": kind}) + "\n")
    old = None
    if path.exists():
        old = path.parent / f".{path.name}.{uuid.uuid4().hex[:8]}.old"
        os.replace(path, old)
    os.replace(tmp, path)
    if old is not None:
        shutil.rmtree(old, ignore_errors=True)
    return path


@contextlib.contextmanager
def output_dir_writer(path: PathLike, kind: str, *, overwrite: bool = False,
                      inputs: _SequenceABC[PathLike] = ()) -> Iterator[Path]:
    """Write the output folder ``path`` of ``kind``: yield a new temporary folder beside it, swapped
    in (:func:`replace_output_dir`) when the block succeeds and removed when it fails.

    The output is checked (:func:`check_output_dir`) before and again under the writer's lock,
    and what a killed writer left beside it is cleaned up first. Whoever writes into the
    temporary folder (this process, or its worker processes) must have finished when the block ends.

    Parameters
    ----------
    path : path
        The output folder.
    kind : str
        Its kind, recorded in its :data:`OUTPUT_MARKER` (e.g. ``"labels"``).
    overwrite : bool
        Replace an existing semmatch output of this kind.
    inputs : sequence of paths
        Inputs of the command (the output may not be, lie inside or contain one).

    Yields
    ------
    Path
        The temporary folder to fill.

    Raises
    ------
    FileExistsError, ValueError
        See :func:`check_output_dir`; also a second process writing the same folder.
    """
    from .outputs import temp_dir

    path = Path(path)
    check_output_dir(path, kind, overwrite=overwrite, inputs=inputs)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _writer_lock(path):
        _recover(path)
        check_output_dir(path, kind, overwrite=overwrite, inputs=inputs)
        tmp = temp_dir(path)
        try:
            yield tmp
            replace_output_dir(tmp, path, kind)
        finally:
            shutil.rmtree(tmp, ignore_errors=True)
