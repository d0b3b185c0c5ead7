#!/usr/bin/env bash
# Installs what the Python checks in tools/ need: Debian's libusb (open3d imports it) and a
# virtualenv at .venv with tools/requirements.txt. Safe to run again; quick when done.
set -euo pipefail
cd "$(dirname "$0")/.."
if ! ldconfig -p 2>/dev/null | grep -q 'libusb-1.0.so.0'; then
  echo "tools/setup.sh: installing libusb-1.0-0 (needed by open3d)"
  SUDO=""; [ "$(id -u)" = 0 ] || SUDO="sudo"
  $SUDO apt-get update -qq
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libusb-1.0-0 >/dev/null
fi
stamp=.venv/.requirements
if [ ! -x .venv/bin/python ] || ! cmp -s tools/requirements.txt "$stamp"; then
  echo "tools/setup.sh: creating .venv"
  python3 -m venv .venv
  .venv/bin/pip install -q --upgrade pip
  .venv/bin/pip install -q -r tools/requirements.txt
  cp tools/requirements.txt "$stamp"
fi
.venv/bin/python -c "import open3d, trimesh, mcap_ros2, rosbags" >/dev/null
