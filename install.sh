#!/usr/bin/env bash
# Install everything benchtwin needs on Debian 12 / Python 3.11 with no screen and no GPU:
# Debian packages for headless OpenGL (EGL and OSMesa, Mesa's software rasteriser), a virtual
# environment in .venv, the locked dependencies, and the package itself (editable).
# Idempotent: a second run checks and returns in about a second.
set -euo pipefail
cd "$(dirname "$0")"

# chromium: the headless browser the live-view test opens the page of a running acquisition in
apt_pkgs="libegl1 libgl1 libopengl0 libgl1-mesa-dri libosmesa6 chromium"
PY="${PYTHON:-python3}"
"$PY" -c 'import ensurepip, venv' 2>/dev/null || apt_pkgs="$apt_pkgs python3-venv"
missing=""
for p in $apt_pkgs; do dpkg -s "$p" >/dev/null 2>&1 || missing="$missing $p"; done
if [ -n "$missing" ]; then
  sudo=""; [ "$(id -u)" = 0 ] || sudo="sudo"
  echo "install.sh: installing Debian packages:$missing" >&2
  $sudo apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq --no-install-recommends $missing >/dev/null
fi

"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' \
  || { echo "install.sh: Python 3.11 is required (set PYTHON=/path/to/python3.11)" >&2; exit 1; }
[ -x .venv/bin/python ] || "$PY" -m venv .venv

# requirements.lock is the complete, tested set, installed with --no-deps: pyrender 0.1.45 pins
# PyOpenGL 3.1.0, with which headless rendering fails; the lock deliberately carries 3.1.10
# (README, "Dependencies"). `pip check` reports that one mismatch; it is expected.
stamp=.venv/.benchtwin-installed
want="$(cat requirements.lock pyproject.toml setup.py | sha256sum | cut -d' ' -f1)"
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
  .venv/bin/python -m pip install -q --disable-pip-version-check --no-deps -r requirements.lock
  .venv/bin/python -m pip install -q --disable-pip-version-check --no-deps --no-build-isolation -e .
  echo "$want" > "$stamp"
fi
