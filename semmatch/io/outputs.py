"""The output policy of every command: no output on an input, temporary folders that never linger.

Every ``semmatch`` verb declares which of its arguments are inputs and which are outputs
(:func:`declare_paths`); before any work :func:`check_cli_paths` refuses

* an output that is an input (the same path, a link to it, or a hard link of it),
* an output that lies inside an input folder (``--out SEQ/poses.txt``), or that contains an
  input (``--out DIR`` where ``DIR/scene.ply`` is read),
* two outputs on the same path.

Output folders are replaced only when semmatch wrote them (their marker file,
:func:`semmatch.io.check_output_dir`); files are written to a temporary name and renamed.

Temporary folders carry the id of the process that made them (:func:`temp_dir`): they are
removed when the command fails or is stopped by SIGINT or SIGTERM (:func:`terminate_as_interrupt`
turns SIGTERM into an exception so that clean-up code runs), and a later writer of the same
output sweeps those whose process is gone (:func:`sweep_stale`).
"""

from __future__ import annotations

import argparse
import contextlib
import os
import re
import shutil
import signal
import socket
import tempfile
from collections.abc import Iterable, Iterator
from pathlib import Path

__all__ = ["declare_paths", "check_paths", "check_cli_paths", "temp_dir", "sweep_stale",
           "terminate_as_interrupt", "Terminated", "writer_tag", "writer_alive", "HOST_TAG", "umask"]

PathLike = str | os.PathLike

_INPUTS, _OUTPUTS = "_semmatch_inputs", "_semmatch_outputs"


def declare_paths(parser: argparse.ArgumentParser, *, inputs: Iterable[str] = (), outputs: Iterable[str] = ()) -> None:
    """Declare which arguments (``dest`` names) of a verb's parser are input and output paths.

    Parameters
    ----------
    parser : argparse.ArgumentParser
        The verb's (or sub-command's) parser.
    inputs, outputs : iterables of str
        Argument ``dest`` names; their values may be None, a path or a list of paths.
    """
    parser.set_defaults(**{_INPUTS: tuple(inputs), _OUTPUTS: tuple(outputs)})


def _flag(dest: str) -> str:
    return dest if dest in {"seq", "sequence", "map", "gt", "pred"} else "--" + dest.replace("_", "-")


def _values(args: argparse.Namespace, dests: Iterable[str]) -> list[tuple[str, Path]]:
    out = []
    for dest in dests:
        v = getattr(args, dest, None)
        for p in v if isinstance(v, list | tuple) else [v]:
            if p not in (None, ""):
                out.append((_flag(dest), Path(p)))
    return out


def _relation(out: Path, inp: Path) -> str | None:
    """How output ``out`` collides with input ``inp``: ``"is"``, ``"lies inside"``, ``"contains"`` or None."""
    o, i = out.resolve(), inp.resolve()
    if o == i:
        return "is"
    with contextlib.suppress(OSError):
        if out.exists() and inp.exists() and os.path.samefile(out, inp):
            return "is"  # a hard link
    if i in o.parents:
        return "lies inside"
    if o in i.parents:
        return "contains"
    return None


def check_paths(outputs: Iterable[tuple[str, PathLike]], inputs: Iterable[tuple[str, PathLike]]) -> None:
    """Refuse outputs that are, lie inside or contain an input, and outputs that collide.

    Parameters
    ----------
    outputs, inputs : iterables of (name, path)
        ``name`` is how the message calls the argument (e.g. ``"--out"``).

    Raises
    ------
    ValueError
        Naming both paths.
    """
    outputs = [(n, Path(p)) for n, p in outputs]
    inputs = [(n, Path(p)) for n, p in inputs if os.path.lexists(p)]  # what is not there cannot be harmed
    for on, o in outputs:
        for iname, i in inputs:
            rel = _relation(o, i)
            if rel is not None:
                raise ValueError(f"{on} {o} {rel} the input {i} ({iname}); semmatch never writes over or "
                                 "into its inputs: choose an output outside the inputs")
    for k, (an, a) in enumerate(outputs):
        for bn, b in outputs[k + 1:]:
            rel = _relation(a, b)
            if rel is not None:
                raise ValueError(f"{an} {a} {rel} the other output {b} ({bn}); give each output its own path")


def check_cli_paths(args: argparse.Namespace) -> None:
    """:func:`check_paths` on the arguments a verb declared with :func:`declare_paths`."""
    check_paths(_values(args, getattr(args, _OUTPUTS, ())), _values(args, getattr(args, _INPUTS, ())))


# ----------------------------------------------------------------------------- temporary folders
#: This machine in temporary names: the letters and digits of its host name (at most 24). A process
#: id means something only on the machine that gave it, and an output folder may lie on a file
#: system that several machines share (a cluster's workers, docs/cluster.md).
HOST_TAG = re.sub(r"[^A-Za-z0-9]", "", socket.gethostname())[:24] or "host"

#: ``.NAME[.TAG].HOST_PID-RANDOM.partial`` (``HOST_`` absent in names written before 2026-11-27).
_TEMP = re.compile(r"\.(?:(?P<host>[A-Za-z0-9]+)_)?(?P<pid>\d+)-[0-9a-z_]+\.partial$")


def writer_tag() -> str:
    """``HOST_PID``: the writer of a temporary file or folder, as its name carries it."""
    return f"{HOST_TAG}_{os.getpid()}"


def writer_alive(pid: int, host: str | None = None) -> bool:
    """Whether the writer ``pid`` of machine ``host`` may still be running.

    A writer on another machine always may: its process id means nothing here, so only that
    machine sweeps its temporary files. ``host`` None (a name without a host) means this machine.
    """
    if host is not None and host != HOST_TAG:
        return True
    if pid == os.getpid():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def umask() -> int:
    """This process's file mode creation mask (read without changing it where Linux tells it)."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)  # elsewhere: set and restore (the only portable way to read it)
    os.umask(mask)
    return mask


def temp_dir(path: PathLike, tag: str = "") -> Path:
    """A new temporary folder beside ``path``: ``.NAME[.TAG].HOST_PID-RANDOM.partial``.

    The machine and process id let :func:`sweep_stale` tell the folders of a killed writer from
    those of a live one, also where several machines write into one shared folder. The folder
    gets the permissions of any folder the user makes (``0o777`` less the umask), not
    ``mkdtemp``'s private ``0o700``: it becomes the output folder, which colleagues on a shared
    disk should be able to read as they read the user's other folders.
    """
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    prefix = f".{path.name}.{tag + '.' if tag else ''}{writer_tag()}-"
    tmp = Path(tempfile.mkdtemp(prefix=prefix, suffix=".partial", dir=path.parent))
    os.chmod(tmp, 0o777 & ~umask())
    return tmp


def sweep_stale(path: PathLike) -> list[Path]:
    """Remove the temporary folders (:func:`temp_dir`) beside ``path`` whose process has ended
    (this machine's writers only: :func:`writer_alive`).

    Returns
    -------
    list of Path
        The folders removed.
    """
    path = Path(path)
    gone = []
    for tmp in path.parent.glob(f".{glob_escape(path.name)}.*.partial"):
        m = _TEMP.search(tmp.name)
        if m and not writer_alive(int(m["pid"]), m["host"]):
            shutil.rmtree(tmp, ignore_errors=True)
            gone.append(tmp)
    return gone


def glob_escape(name: str) -> str:
    """``name`` with glob wildcards escaped."""
    return re.sub(r"([*?\[])", r"[\1]", name)


# ----------------------------------------------------------------------------- signals
class Terminated(KeyboardInterrupt):
    """SIGTERM, raised in the main thread like Ctrl-C so that ``finally`` blocks clean up."""


@contextlib.contextmanager
def terminate_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (a KeyboardInterrupt) in the main thread.

    Outside the main thread (where handlers cannot be set) the block runs unchanged.
    """
    def _raise(signum, frame):
        raise Terminated(f"stopped by signal {signum}")

    try:
        old = signal.signal(signal.SIGTERM, _raise)
    except ValueError:  # not the main thread
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)
