#!/usr/bin/env bash
# The real consumers of rscalib's exported camera files, for tests/python/io/test_camera_formats.py
# (docs/formats.md). Idempotent: apt runs only when something is missing. Needs root (or sudo).
# - Debian python3-mrcal: mrcal's cameramodel reader, projection and corners.vnl reader
#   (mrcal is not installable with pip on this Python: PyPI has no wheel for it);
# - Debian python3-camera-calibration-parsers: ROS's camera_info reader (C++ behind a Python wrapper).
# They install for the system Python (/usr/bin/python3); the tests call them there.
# pycolmap (PyPI) goes into the venv with the Makefile's other test tools.
set -euo pipefail

packages=(python3-mrcal python3-camera-calibration-parsers)
missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "test consumers: all present"
  exit 0
fi
echo "test consumers: installing ${missing[*]}"
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
