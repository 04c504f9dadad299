# make demo: install everything, run the demo.   make test: install everything, run all tests.
VENV   := .venv
PY     := $(VENV)/bin/python
PIP    := $(PY) -m pip
# One persistent build tree serves pip (incremental rebuilds) and ctest.
BUILD  := build/py
PIP_BUILD_FLAGS := --no-build-isolation -C build-dir=$(BUILD) -C cmake.define.RSCALIB_BUILD_TESTS=ON

.PHONY: all deps venv install lint test test-cpp test-python demo bench stubs clean

all: install

deps:
	bash scripts/install-system-deps.sh

# Pinned: the checked-in _core.pyi and the lint verdicts depend on these tools' versions.
$(VENV)/.deps-stamp: pyproject.toml Makefile
	test -x $(PY) || python3 -m venv $(VENV)
	$(PIP) install -q --upgrade pip
	$(PIP) install -q "scikit-build-core>=0.10" "pybind11==3.1.0" "cmake>=3.22" ninja "pytest>=7" \
	  "numpy>=1.24" "scipy>=1.10" "ruff==0.17.6" "pybind11-stubgen==3.0.0" "opencv-python-headless>=4.8,<5" "matplotlib>=3.7" "rich>=13" "pyyaml>=6"
	touch $@

venv: $(VENV)/.deps-stamp

# flock: several shells may install at once while developing; one build tree, one at a time.
install: deps venv
	@mkdir -p build
	flock build/.install.lock $(PIP) install -q $(PIP_BUILD_FLAGS) .

test-cpp: install
	$(VENV)/bin/ctest --test-dir $(BUILD) --output-on-failure -j2

test-python: install
	$(PY) -m pytest -q tests/python

# Style is checked, not hoped for: ruff (pyproject.toml) and clang-format (.clang-format).
lint: deps venv
	$(VENV)/bin/ruff check python tests benchmarks
	bash scripts/check-format.sh

test: lint test-cpp test-python

demo: install
	$(VENV)/bin/rscalib demo

bench: install
	$(PY) benchmarks/bench_spline.py

# Regenerate python/rscalib/_core.pyi from the built extension (tests/python/test_stubs.py fails when stale).
stubs: install
	$(VENV)/bin/pybind11-stubgen rscalib._core -o python

clean:
	rm -rf build $(VENV)
