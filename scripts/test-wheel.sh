#!/usr/bin/env bash
# The portable wheel works on its own: install dist/wheelhouse's manylinux wheel into a fresh virtual
# environment, check with ldd that the extension resolves nothing outside the wheel but the C and C++
# runtime (so the system's Ceres, glog, SuiteSparse, BLAS are not needed), then run `rscalib demo` from
# an empty folder with no LD_LIBRARY_PATH. Exit 1 on any failure.
set -euo pipefail
cd "$(dirname "$0")/.."
wheel=$(ls -t dist/wheelhouse/rscalib-*-manylinux*.whl 2>/dev/null | head -1)
[ -n "$wheel" ] || { echo "test-wheel: no repaired wheel in dist/wheelhouse (make wheel)" >&2; exit 1; }
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
python3 -m venv "$work/venv"
"$work/venv/bin/pip" install -q --disable-pip-version-check "$wheel" 2>&1 | grep -v "WARNING: Location" || true
"$work/venv/bin/python" -c "import rscalib" || { echo "test-wheel: the installed wheel does not import" >&2; exit 1; }
site=$("$work/venv/bin/python" -c "import sysconfig; print(sysconfig.get_paths()['platlib'])")
extension=$(ls "$site"/rscalib/_core*.so)
[ -f "$site/rscalib/py.typed" ] && [ -f "$site/rscalib/_core.pyi" ] || { echo "test-wheel: py.typed or _core.pyi missing" >&2; exit 1; }
# Only the C/C++ runtime may come from the system; everything else from rscalib.libs inside the wheel.
runtime='^(linux-vdso|ld-linux[-a-z0-9_]*|libc|libm|libstdc\+\+|libgcc_s|libpthread|libdl|librt)\.so'
bad=0
while read -r name arrow path rest; do
  [ "$arrow" = "=>" ] || continue
  if [ "$path" = "not" ]; then echo "test-wheel: $name not found" >&2; bad=1; continue; fi
  case "$(realpath -m "$path")" in "$(realpath -m "$site")"/rscalib.libs/*) continue ;; esac
  if ! [[ "$name" =~ $runtime ]]; then echo "test-wheel: $name resolves outside the wheel: $path" >&2; bad=1; fi
done < <(env -u LD_LIBRARY_PATH ldd "$extension")
[ $bad -eq 0 ] || exit 1
bundled=$(ls "$site/rscalib.libs" | wc -l)
echo "test-wheel: $(basename "$wheel"): extension needs only the C/C++ runtime from the system; $bundled libraries bundled"
cd "$work"
env -u LD_LIBRARY_PATH MPLBACKEND=Agg RSCALIB_CACHE_DIR="$work/cache" "$work/venv/bin/rscalib" demo --duration 2 --out demo >"$work/demo.txt" 2>&1 \
  || { cat "$work/demo.txt" >&2; echo "test-wheel: rscalib demo failed in the wheel's environment" >&2; exit 1; }
grep -E "estimate|error" "$work/demo.txt"
# The guides travel with the wheel: every verdict points at `rscalib guide capture`.
"$work/venv/bin/rscalib" guide capture >"$work/guide.txt" && grep -q "How to film for rscalib" "$work/guide.txt" \
  && [ -f "$(dirname "$("$work/venv/bin/rscalib" guide capture --path)")/capture/framing.png" ] \
  || { echo "test-wheel: rscalib guide capture does not show the installed guide" >&2; exit 1; }
echo "test-wheel: 2 passed, 0 failed"
