#!/usr/bin/env bash
# Installs what the Python checks in tools/ need: Debian's libusb (open3d imports it) and a
# virtualenv at .venv with tools/requirements*.txt and the Python package of python/. Safe
# to run again; quick when done. Nothing is cached outside the checkout (pip keeps no wheels), so a
# run takes no more disk than its .venv and target.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  echo "tools/setup.sh: installing libusb-1.0-0 (needed by open3d)"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libusb-1.0-0 >/dev/null
fi
stamp=.venv/.requirements
if [ ! -x .venv/bin/python ] || ! cat tools/requirements*.txt | cmp -s - "$stamp"; then
  echo "tools/setup.sh: creating .venv"
  python3 -m venv .venv
  .venv/bin/pip install -q --no-cache-dir --upgrade pip
  .venv/bin/pip install -q --no-cache-dir -r tools/requirements.txt -r tools/requirements-python.txt
  cat tools/requirements*.txt > "$stamp"
fi
.venv/bin/python -c "import open3d, trimesh, mcap_ros2, rosbags, dask.distributed" >/dev/null
# The Python package `tarn` (python/): built by maturin with the dev profile into this
# checkout's target folder, whose profiles python/Cargo.toml repeats, so most dependencies
# are compiled once for it and for `cargo build` (docs/distributed.md has the count).
# Cargo skips the build when nothing changed.
echo "tools/setup.sh: pip install ./python"
PATH="$PWD/.venv/bin:$PATH" CARGO_TARGET_DIR="$PWD/target" MATURIN_PEP517_ARGS="--profile dev" \
  .venv/bin/pip install -q --no-cache-dir --no-build-isolation ./python
.venv/bin/python -c "import tarn, tarn.dask" >/dev/null
