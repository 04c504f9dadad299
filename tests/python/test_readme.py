"""The README works as written: every `sh` and `python` snippet runs, in order, in one empty folder
(a snippet preceded by `<!-- readme-test: skip (reason) -->` is the set-up this test already
stands on), and every `yaml` snippet is a target file that loads."""
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from rscalib import load_target

README = Path(__file__).resolve().parents[2] / "README.md"
BLOCK = re.compile(r"(?:<!-- readme-test: skip \((?P<reason>[^)]*)\) -->\n)?```(?P<lang>\w+)\n(?P<body>.*?)```",
                   re.DOTALL)


def snippets(lang: str) -> list[tuple[str, bool]]:
    """(body, skipped) of the README's code blocks in `lang`, in order."""
    return [(m["body"], m["reason"] is not None) for m in BLOCK.finditer(README.read_text()) if m["lang"] == lang]


def test_the_readme_has_runnable_snippets():
    runnable = [b for lang in ("sh", "python") for b, skipped in snippets(lang) if not skipped]
    assert len(runnable) >= 5
    assert any("rscalib linedelay" in b for b in runnable) and any("import rscalib" in b for b in runnable)
    # the set-up the rest stands on is shown, and only that is skipped
    skipped = [b for b, s in snippets("sh") if s]
    assert any("make demo" in b and "make test" in b for b in skipped)


def test_every_sh_and_python_snippet_runs_in_order(tmp_path):
    blocks = [m for m in BLOCK.finditer(README.read_text()) if m["lang"] in ("sh", "python") and not m["reason"]]
    env = dict(os.environ, PATH=f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
               RSCALIB_CACHE_DIR=str(tmp_path / "cache"), MPLBACKEND="Agg")
    for i, block in enumerate(blocks):
        run_env = env
        if block["lang"] == "sh":
            argv = ["bash", "-euo", "pipefail", "-c", block["body"]]
        else:   # as a user runs it: a script file, with an empty detection cache (its workers start)
            script = tmp_path / f"readme_snippet_{i + 1}.py"
            script.write_text(block["body"])
            argv = [sys.executable, str(script)]
            run_env = dict(env, RSCALIB_CACHE_DIR=str(tmp_path / f"cache_snippet_{i + 1}"))
        result = subprocess.run(argv, cwd=tmp_path, env=run_env, capture_output=True, text=True, timeout=900)
        assert result.returncode == 0, (f"README snippet {i + 1} ({block['lang']}) failed with exit "
                                        f"{result.returncode}:\n{block['body']}\nstdout:\n{result.stdout[-2000:]}"
                                        f"\nstderr:\n{result.stderr[-2000:]}")
        assert "Traceback" not in result.stderr
        if block["lang"] == "python":   # the detection ran here, not from the shell snippets' cache
            assert any((tmp_path / f"cache_snippet_{i + 1}").rglob("*")), "the snippet did not detect"


@pytest.mark.parametrize("body", [b for b, _ in snippets("yaml")])
def test_every_target_example_loads(tmp_path, body):
    path = tmp_path / "target.yaml"
    path.write_text(body)
    target = load_target(path)
    assert target.num_points > 0
