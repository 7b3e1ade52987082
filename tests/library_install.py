"""The library-install dry run of ``tests/test_library_install.py``, run in the background.

Resolving the ~250 pinned packages in a fresh venv is one package-index request after another
(about a second each from this machine to PyPI): minutes of waiting on the network for a few
CPU-seconds. ``tests/conftest.py`` starts it (:class:`DryRun`) as soon as the session has collected
the test, so that it resolves while the other tests run; the test then waits for it and reads the
report. The steps are this file run as a script: ``python tests/library_install.py OUT ROOT``.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import venv
from pathlib import Path

#: node id (end) of the test that reads the result
TEST = "test_library_install.py::test_a_fresh_venv_resolves_cpu_torch_2_13_and_no_nvidia_wheel"
#: PyTorch's CPU wheel index, as in the README's line (used when this machine reaches it)
CPU_INDEX = "https://download.pytorch.org/whl/cpu"
#: the run the session started (tests/conftest.py), if any
STARTED: DryRun | None = None


def resolve(out: Path, root: Path) -> dict:
    """A fresh venv in ``out``, then ``pip install --dry-run -c constraints.txt ROOT``: the outcome
    as a dict (``skip``: no index holds torch 2.13.0; else ``returncode``, ``stderr``, ``report``)."""
    venv.create(out / "venv", with_pip=True)
    python = str(out / "venv" / "bin" / "python")
    probe = subprocess.run([python, "-m", "pip", "install", "--dry-run", "--no-deps", "--quiet", "torch==2.13.0"],
                           capture_output=True, text=True, timeout=600)
    if probe.returncode != 0:
        return {"skip": f"pip reaches no index with torch 2.13.0: {probe.stderr.strip()[-300:]}"}
    report = out / "report.json"
    index = ["--extra-index-url", CPU_INDEX] if _reachable(CPU_INDEX) else []  # else pip's own configuration
    run = subprocess.run([python, "-m", "pip", "install", "--dry-run", "--quiet", "--report", str(report), *index,
                          "-c", str(root / "constraints.txt"), str(root)],
                         capture_output=True, text=True, timeout=1200)
    outcome = {"returncode": run.returncode, "stderr": run.stderr[-2000:], "report": str(report),
               "venv": str(out / "venv"), "cpu_index": bool(index)}
    # a real install of semmatch alone (the dependencies as tested: this interpreter's packages, by a .pth
    # file, instead of ~2 GB downloaded again), then the installed command
    inst = subprocess.run([python, "-m", "pip", "install", "--no-deps", "--quiet", str(root)],
                          capture_output=True, text=True, timeout=600)
    site = subprocess.run([python, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                          capture_output=True, text=True, check=True).stdout.strip()
    tested = subprocess.run([sys.executable, "-c", "import sysconfig; print(sysconfig.get_path('purelib'))"],
                            capture_output=True, text=True, check=True).stdout.strip()
    Path(site, "tested_environment.pth").write_text(tested + "\n")
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    version = subprocess.run([str(out / "venv" / "bin" / "semmatch"), "--version"], capture_output=True, text=True,
                             timeout=300, cwd=out, env=env)
    where = subprocess.run([python, "-c", "import json, semmatch, torch; print(json.dumps([semmatch.__file__, "
                            "torch.version.cuda]))"], capture_output=True, text=True, timeout=300, cwd=out, env=env)
    semmatch_from, torch_cuda = json.loads(where.stdout) if where.returncode == 0 else (where.stderr[-500:], "?")
    return {**outcome, "version_rc": version.returncode if inst.returncode == 0 else inst.returncode,
            "version_out": (version.stdout + version.stderr) if inst.returncode == 0 else inst.stderr[-2000:],
            "semmatch_from": semmatch_from, "torch_cuda": torch_cuda}


def _reachable(url: str) -> bool:
    """Whether ``url`` answers within 10 s (an unreachable extra index costs pip five retries per package)."""
    import urllib.request

    try:
        with urllib.request.urlopen(url, timeout=10):
            return True
    except OSError:
        return False


class DryRun:
    """:func:`resolve` in a separate process (its own session: stopped with its children)."""

    def __init__(self, root: Path):
        self.out = Path(tempfile.mkdtemp(prefix="semmatch-library-install-"))
        with open(self.out / "log.txt", "w") as log:
            self.proc = subprocess.Popen([sys.executable, __file__, str(self.out), str(root)], stdout=log,
                                         stderr=subprocess.STDOUT, start_new_session=True)

    def result(self, timeout: float = 1800) -> dict:
        """Wait for the outcome (:func:`resolve`'s dict)."""
        self.proc.wait(timeout=timeout)
        done = self.out / "result.json"
        assert done.is_file(), f"the dry run ended with exit {self.proc.returncode}: " \
                               f"{(self.out / 'log.txt').read_text()[-2000:]}"
        return json.loads(done.read_text())

    def stop(self) -> None:
        """End the process (if still running) and remove its folder."""
        if self.proc.poll() is None:
            os.killpg(self.proc.pid, signal.SIGKILL)
            self.proc.wait()
        shutil.rmtree(self.out, ignore_errors=True)


if __name__ == "__main__":
    out_dir, root_dir = Path(sys.argv[1]), Path(sys.argv[2])
    outcome = resolve(out_dir, root_dir)
    (out_dir / "result.json").write_text(json.dumps(outcome))
