#!/usr/bin/env bash
# Fails (exit 1) when a C++ file under cpp/ or tests/cpp/ is not clang-format clean
# (.clang-format at the top level). Fix with:
#   clang-format -i $(git ls-files 'cpp/*.cpp' 'cpp/*.hpp' 'tests/cpp/*.cpp' 'tests/cpp/*.hpp')
set -euo pipefail
cd "$(dirname "$0")/.."
if ! command -v clang-format >/dev/null; then
  echo "check-format: clang-format is not installed (scripts/install-system-deps.sh)" >&2
  exit 2
fi
mapfile -t files < <(git ls-files --cached --others --exclude-standard \
  'cpp/*.cpp' 'cpp/*.hpp' 'tests/cpp/*.cpp' 'tests/cpp/*.hpp')
if [ ${#files[@]} -eq 0 ]; then
  echo "check-format: no C++ files found" >&2
  exit 2
fi
if clang-format --dry-run --Werror "${files[@]}"; then
  echo "check-format: ${#files[@]} C++ files are clang-format clean"
else
  echo "check-format: the files above are not clang-format clean" >&2
  exit 1
fi
