#!/usr/bin/env bash
# Installs the Debian packages rscalib builds and tests against. Idempotent: apt runs only when
# something is missing. Needs root (or sudo) on Debian/Ubuntu.
set -euo pipefail

packages=(g++ make libceres-dev libeigen3-dev libsuitesparse-dev libgtest-dev clang-format)
# The real consumers of our exported camera files, for the tests (docs/formats.md): mrcal (PyPI has no
# wheel for it) and ROS's camera_info parser. They install for the system Python; the tests call it.
packages+=(python3-mrcal python3-camera-calibration-parsers)
# A real browser for the report tests (tests/python/test_report_browser.py opens report.html headless).
packages+=(chromium)
python3 -c "import venv, ensurepip" 2>/dev/null || packages+=(python3-venv)
command -v python3 >/dev/null || packages+=(python3 python3-dev python3-venv)

missing=()
for p in "${packages[@]}"; do
  dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
done
if [ ${#missing[@]} -eq 0 ]; then
  echo "system packages: all present"
  exit 0
fi
echo "system packages: installing ${missing[*]}"
sudo=""
[ "$(id -u)" -eq 0 ] || sudo="sudo"
export DEBIAN_FRONTEND=noninteractive
$sudo apt-get update -qq
$sudo apt-get install -y -qq --no-install-recommends "${missing[@]}"
