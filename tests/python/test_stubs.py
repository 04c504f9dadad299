"""The shipped type information: `_core.pyi` matches the built extension (stale stubs fail; `make
stubs` regenerates them) and the package carries `py.typed` so type checkers read it."""
import subprocess
import sys
from pathlib import Path

import rscalib

SOURCE = Path(__file__).resolve().parents[2] / "python" / "rscalib"


def test_core_stubs_match_the_built_extension(tmp_path):
    result = subprocess.run([sys.executable, "-m", "pybind11_stubgen", "rscalib._core", "-o", str(tmp_path)],
                            capture_output=True, text=True, timeout=120)
    assert result.returncode == 0, result.stderr
    generated = (tmp_path / "rscalib" / "_core.pyi").read_text()
    checked_in = (SOURCE / "_core.pyi").read_text()
    assert generated == checked_in, "python/rscalib/_core.pyi is stale: run `make stubs` and commit it"


def test_the_package_ships_its_type_information():
    installed = Path(rscalib.__file__).parent
    assert (installed / "py.typed").is_file()
    assert (installed / "_core.pyi").is_file()
