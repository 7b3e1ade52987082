#!/usr/bin/env bash
# Set up everything semmatch needs on a fresh Debian 12 / Python 3.11 machine that reaches only
# the package registries: Debian's libusb-1.0-0 (Open3D needs it), a .venv with the pinned
# dependencies (CPU torch), semmatch itself in editable mode. Idempotent and quick when done.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${VENV:-.venv}
PYTHON=${PYTHON:-python3}
TORCH="torch==2.13.0"  # the same pin as environment.yml (tests/test_packaging.py)
TORCH_CPU_INDEX=${TORCH_CPU_INDEX:-https://download.pytorch.org/whl/cpu}

if ! /sbin/ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "setup: installing Debian's libusb-1.0-0 (needed by Open3D)"
    apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq libusb-1.0-0 >/dev/null
  else
    echo "setup: error: Open3D needs the system library libusb-1.0-0, which is missing." >&2
    echo "setup: install it as root:  apt-get install libusb-1.0-0   (or: sudo apt-get install libusb-1.0-0)" >&2
    exit 1
  fi
fi

# headless chromium: only the browser test of `semmatch show` pages needs it (skipped without it)
if ! command -v chromium >/dev/null && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "setup: installing Debian's chromium (browser test of the 3D viewer pages)"
  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium >/dev/null; } \
    || echo "setup: warning: could not install chromium; the browser test will be skipped" >&2
fi

# Mesa's EGL and software OpenGL: the rasterising renderer (semmatch.sim.raster) draws headless
# through them; without them it falls back to ray casting and its tests are skipped
if ! /sbin/ldconfig -p 2>/dev/null | grep -q 'libEGL_mesa.so.0' && [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
  echo "setup: installing Debian's Mesa EGL / software OpenGL (headless rasteriser)"
  { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends libegl1 libegl-mesa0 libgl1-mesa-dri >/dev/null; } \
    || echo "setup: warning: could not install Mesa EGL; rendering falls back to ray casting" >&2
fi

if [ ! -x "$VENV/bin/python" ]; then
  echo "setup: creating $VENV"
  "$PYTHON" -m venv "$VENV"
fi
stamp="$VENV/.semmatch-installed"
# pip on some machines warns once per package about unreachable local index folders: drop those lines
pip_install() { "$VENV/bin/python" -m pip install -q "$@" 2> >(grep -v "^WARNING: Location .* is ignored" >&2); }
if [ ! -f "$stamp" ] || [ requirements.txt -nt "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "setup: installing pinned dependencies into $VENV (CPU torch)"
  pip_install --upgrade pip
  # torch first and alone: a pinned CPU build, so nothing can pull a CUDA build. PyTorch's own CPU
  # wheel index when it answers (any Linux machine: PyPI's torch is the CUDA build, several GB of
  # nvidia wheels); else, fast, the ordinary index (machines whose pip already resolves to a CPU build)
  if "$VENV/bin/python" -c "import urllib.request as u; u.urlopen('$TORCH_CPU_INDEX/torch/', timeout=4)" 2>/dev/null; then
    echo "setup: torch from PyTorch's CPU wheel index"
    pip_install --index-url "$TORCH_CPU_INDEX" "$TORCH"
  else
    echo "setup: PyTorch's CPU wheel index not reachable: torch from the configured index"
    pip_install "$TORCH"
  fi
  pip_install -r requirements.txt
  pip_install --no-deps -e .
  touch "$stamp"
fi

# Dash (a dependency of Open3D; semmatch does not use it) installs a JupyterLab source extension
# that makes JupyterLab open with "Build Recommended: @plotly/dash-jupyterlab". Remove it from the
# environment's lab folder (pip puts it back on reinstall: checked every run) and disable it.
rm -f "$VENV"/share/jupyter/lab/extensions/dash-jupyterlab*.tgz
if [ -x "$VENV/bin/jupyter" ] && ! grep -qs '"@plotly/dash-jupyterlab": true' "$VENV/etc/jupyter/labconfig/page_config.json"; then
  "$VENV/bin/jupyter" labextension disable --level=sys_prefix @plotly/dash-jupyterlab >/dev/null 2>&1 \
    || echo "setup: warning: could not disable the Dash JupyterLab extension" >&2
fi
