"""The package's direction rules (docs/architecture.md), read from the source with `ast`.

    cli -> engines (linedelay, selfcalib, flicker, intrinsics) -> detection -> io -> base
    base = _core, errors, checks, observations, _progress, _version
    sim may use io, base and engine constants; no production module imports sim (only cli may).
    batch sits beside cli: it may use cli (the commands it runs), io and base; only cli imports it.

Also: no `from .x import _name` across modules, no import cycle (through module-level and
function-level imports alike: a lazy import is still a dependency), engines never import cli and
never print, and no default of an options field is written outside its wing's options.py (a
parameter named like a field of an `*Options` class may default to None, meaning "not given", but
to no other constant). The lab: experiments/ import only rscalib's public names (and the
simulators, rscalib.sim), and no benchmark or experiment script imports another script. The checks
are run on the real tree and, to show they can fail, on small trees with one deliberate violation
each.
"""
from __future__ import annotations

import ast
import textwrap
from pathlib import Path

import pytest

REPOSITORY = Path(__file__).resolve().parents[2]
PACKAGE = REPOSITORY / "python" / "rscalib"

BASE = {"_core", "errors", "checks", "observations", "_progress", "_version", "verdict", "readout", "reference_cameras"}
ENGINES = {"linedelay", "selfcalib", "flicker", "intrinsics"}
# layer -> the layers it may import (its own layer always allowed)
ALLOWED = {
    "base": {"base"},
    "io": {"base"},
    "detection": {"io", "base"},
    "engine": {"detection", "io", "base"},
    "sim": {"engine", "io", "base"},
    "cli": {"engine", "detection", "io", "base", "sim", "batch"},
    "batch": {"io", "base"},   # it runs the commands as processes (cli.job) and is handed their parser
    "api": {"engine", "detection", "io", "base"},  # the package __init__ (lazy re-exports)
}


def module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)  # "" is the package itself


def layer(module: str) -> str:
    top = module.split(".")[0]
    if module == "":
        return "api"
    if top in BASE:
        return "base"
    if top in ENGINES:
        return "engine"
    if top in ("io", "detection", "sim", "cli", "batch"):
        return top
    if top == "__main__":  # `python -m rscalib`
        return "cli"
    raise AssertionError(f"module {module!r} belongs to no layer: add it to tests/python/test_architecture.py "
                         "and docs/architecture.md")


def _resolve(module: str, is_package: bool, node: ast.ImportFrom) -> str | None:
    """Absolute name (without 'rscalib.') of what a `from ... import` imports from; None if outside."""
    if node.level == 0:
        name = node.module or ""
        if name == "rscalib" or name.startswith("rscalib."):
            return name[len("rscalib."):] if name != "rscalib" else ""
        return None
    package = module.split(".") if module else []
    if not is_package:
        package = package[:-1]
    package = package[: len(package) - (node.level - 1)] if node.level > 1 else package
    return ".".join(package + ([node.module] if node.module else []))


def imports_of(path: Path, root: Path) -> list[tuple[str, list[str], bool, int]]:
    """(imported module, names, at module level, line) for every import of the package."""
    module = module_name(path, root)
    tree = ast.parse(path.read_text(), str(path))
    top_level = {id(n) for n in tree.body}
    for node in tree.body:  # imports under `if TYPE_CHECKING:` are for type checkers only
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            top_level |= {id(n) for n in ast.walk(node)}
            for sub in ast.walk(node):
                sub._type_checking = True
    found = []
    for node in ast.walk(tree):
        if getattr(node, "_type_checking", False):
            continue
        if isinstance(node, ast.ImportFrom):
            target = _resolve(module, path.name == "__init__.py", node)
            if target is None:
                continue
            names = [a.name for a in node.names]
            # `from . import x` where x is a submodule
            folder = root.joinpath(*(target.split(".") if target else []))
            submodules = [n for n in names if (folder / n).is_dir() or any(folder.glob(n + ".*"))]
            if submodules:
                for n in submodules:
                    found.append((f"{target}.{n}" if target else n, [], id(node) in top_level, node.lineno))
                names = [n for n in names if n not in submodules]
                if not names:
                    continue
            found.append((target, names, id(node) in top_level, node.lineno))
        elif isinstance(node, ast.Import):
            for alias in node.names:
                if alias.name.startswith("rscalib."):
                    found.append((alias.name[len("rscalib."):], [], id(node) in top_level, node.lineno))
    return found


def violations(root: Path) -> list[str]:
    problems = []
    graph: dict[str, set[str]] = {}
    for path in sorted(root.rglob("*.py")):
        module = module_name(path, root)
        if module == "_core":
            continue
        own = layer(module)
        graph.setdefault(module, set())
        for target, names, _top, line in imports_of(path, root):
            where = f"{path.relative_to(root)}:{line}"
            target_layer = layer(target) if target else "api"
            if target_layer != own and target_layer not in ALLOWED[own]:
                problems.append(f"{where}: {own} module {module or 'rscalib'} imports {target_layer} "
                                f"module {target or 'rscalib'}")
            if own == "engine" and target_layer == "engine" and target.split(".")[0] != module.split(".")[0]:
                problems.append(f"{where}: engine {module} imports another engine, {target}")
            private = [n for n in names if n.startswith("_") and not n.startswith("__")]
            if private and target != "_core":
                problems.append(f"{where}: {module or 'rscalib'} imports private {', '.join(private)} from {target}")
            if target != module:   # module-level and lazy (function-level) imports alike
                graph[module].add(target)
        if own in ("engine", "detection", "io", "base", "batch"):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                    problems.append(f"{path.relative_to(root)}:{node.lineno}: {own} module {module} prints "
                                    "(report through a progress callback or a return value)")
    problems += [f"import cycle: {' -> '.join(c)}" for c in cycles(graph)]
    return problems


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """Cycles among imports (a package's own __init__ importing its children is not one)."""
    found, state = [], {}

    def visit(node: str, stack: list[str]) -> None:
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if node == "":
                continue  # the package face re-exports lazily
            if state.get(nxt) == 1:
                found.append(stack[stack.index(nxt):] + [nxt])
            elif nxt not in state:
                visit(nxt, stack)
        stack.pop()
        state[node] = 2

    for node in sorted(graph):
        if node not in state:
            visit(node, [])
    return found


def options_fields(options_file: Path) -> dict[str, str]:
    """field name -> the options class that defines it, in one wing's options.py (the dataclasses
    named *Options)."""
    fields = {}
    for node in ast.parse(options_file.read_text()).body:
        if isinstance(node, ast.ClassDef) and node.name.endswith("Options"):
            for item in node.body:
                if isinstance(item, ast.AnnAssign) and isinstance(item.target, ast.Name):
                    fields.setdefault(item.target.id, node.name)
    return fields


def default_violations(root: Path) -> list[str]:
    """In a wing with an options.py, parameters named like a field of its options classes with a
    constant default other than None, outside options.py: a default written twice."""
    problems = []
    for options_file in sorted(root.rglob("options.py")):
        fields = options_fields(options_file)
        for path in sorted(options_file.parent.rglob("*.py")):
            if path == options_file:
                continue
            for node in ast.walk(ast.parse(path.read_text())):
                if not isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    continue
                args = node.args
                positional = args.posonlyargs + args.args
                pairs = list(zip(positional[len(positional) - len(args.defaults):], args.defaults))
                pairs += [(a, d) for a, d in zip(args.kwonlyargs, args.kw_defaults) if d is not None]
                for arg, default in pairs:
                    if arg.arg in fields and isinstance(default, ast.Constant) and default.value is not None:
                        problems.append(f"{path.relative_to(root)}:{node.lineno}: {node.name}({arg.arg}="
                                        f"{default.value!r}) writes a default of {fields[arg.arg]} outside "
                                        f"{options_file.relative_to(root)}")
    return problems


def public_names(root: Path) -> set[str]:
    """What `rscalib` exports (its __init__'s _EXPORTS, InputError and __version__)."""
    tree = ast.parse((root / "__init__.py").read_text())
    for node in tree.body:
        if isinstance(node, ast.Assign) and any(getattr(t, "id", "") == "_EXPORTS" for t in node.targets):
            return {k.value for k in node.value.keys} | {"InputError", "__version__"}
    raise AssertionError("rscalib/__init__.py has no _EXPORTS")


def lab_violations(folders: list[Path], public: set[str]) -> list[str]:
    """Experiments (experiments/exp_*.py) import only rscalib's public names and rscalib.sim (the
    simulators); no script (exp_*.py, bench_*.py) imports another script."""
    scripts = {p.stem for folder in folders for p in folder.glob("*.py")
               if p.stem.startswith(("exp_", "bench_"))}
    problems = []
    for folder in folders:
        for path in sorted(folder.glob("*.py")):
            where = f"{folder.name}/{path.name}"
            experiment = folder.name == "experiments"
            for node in ast.walk(ast.parse(path.read_text())):
                if experiment and isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) \
                        and node.value.id == "rscalib" and node.attr not in public:
                    problems.append(f"{where}:{node.lineno}: uses rscalib.{node.attr}, not public")
                if isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                    modules, names = [node.module], [a.name for a in node.names]
                elif isinstance(node, ast.Import):
                    modules, names = [a.name for a in node.names], []
                else:
                    continue
                for module in modules:
                    if module.split(".")[0] in scripts:
                        problems.append(f"{where}:{node.lineno}: a script imports the script {module}")
                    if not experiment or module.split(".")[0] != "rscalib":
                        continue
                    if module == "rscalib":
                        private = [n for n in names if n not in public]
                        if private:
                            problems.append(f"{where}:{node.lineno}: imports {', '.join(private)}, not public in "
                                            "rscalib")
                    elif not (module == "rscalib.sim" or module.startswith("rscalib.sim.")) or \
                            any(n.startswith("_") for n in names):
                        problems.append(f"{where}:{node.lineno}: imports {module} (experiments use rscalib's "
                                        "public names and rscalib.sim only)")
    return problems


def test_no_options_default_is_written_twice():
    assert default_violations(PACKAGE) == []


def test_the_lab_uses_the_front_doors():
    folders = [REPOSITORY / "experiments", REPOSITORY / "benchmarks"]
    assert (REPOSITORY / "experiments").is_dir()
    assert lab_violations(folders, public_names(PACKAGE)) == []


def test_the_lab_checks_can_fail(tmp_path):
    experiments, benchmarks = tmp_path / "experiments", tmp_path / "benchmarks"
    experiments.mkdir()
    benchmarks.mkdir()
    (benchmarks / "bench_a.py").write_text("import numpy\n")
    (experiments / "exp_ok.py").write_text("import rscalib\nfrom rscalib import calibrate_video\n"
                                           "from rscalib.sim.target_video import render_video\n"
                                           "rscalib.calibrate_video\n")
    (experiments / "exp_private.py").write_text("from rscalib.linedelay.spline import calibrate_line_delay\n")
    (experiments / "exp_core.py").write_text("from rscalib import _core\n")
    (experiments / "exp_attr.py").write_text("import rscalib\nrscalib._core.CameraModel\n")
    (experiments / "exp_script.py").write_text("from bench_a import x\n")
    found = lab_violations([experiments, benchmarks], {"calibrate_video"})
    assert not [p for p in found if "exp_ok" in p], found
    for name, words in [("exp_private", "rscalib.linedelay.spline"), ("exp_core", "_core"),
                        ("exp_attr", "rscalib._core"), ("exp_script", "imports the script bench_a")]:
        assert any(name in p and words in p for p in found), (name, found)


def test_the_options_default_check_can_fail(tmp_path):
    root = tmp_path / "rscalib"
    (root / "linedelay").mkdir(parents=True)
    (root / "linedelay" / "options.py").write_text(textwrap.dedent("""
        from dataclasses import dataclass
        @dataclass
        class LineDelayOptions:
            max_rounds: int = 8
            robust_loss: str = "none"
    """))
    (root / "linedelay" / "spline.py").write_text(textwrap.dedent("""
        def solve(x, max_rounds=8, *, robust_loss=None):
            pass
        def other(x, *, robust_loss="none"):
            pass
    """))
    found = default_violations(root)
    assert len(found) == 2 and "solve(max_rounds=8)" in found[0] and "other(robust_loss='none')" in found[1], found


def test_the_package_follows_the_direction_rules():
    assert violations(PACKAGE) == []


def test_every_module_has_a_layer_and_a_docstring():
    for path in PACKAGE.rglob("*.py"):
        module = module_name(path, PACKAGE)
        layer(module)
        if path.stat().st_size > 0:
            assert ast.get_docstring(ast.parse(path.read_text())), f"{path.relative_to(PACKAGE)} has no docstring"


def _tree(tmp_path: Path, files: dict[str, str]) -> Path:
    root = tmp_path / "rscalib"
    base = {"__init__.py": "", "errors.py": "", "observations.py": "", "io/__init__.py": "", "io/video.py": "",
            "detection/__init__.py": "", "detection/pipeline.py": "from ..io.video import open_source\n",
            "linedelay/__init__.py": "", "linedelay/spline.py": "from ..detection.pipeline import detect_video\n",
            "selfcalib/__init__.py": "", "selfcalib/calibrate.py": "", "sim/__init__.py": "",
            "sim/target_video.py": "from ..io import video\n", "cli/__init__.py": "",
            "cli/linedelay.py": "from ..linedelay.spline import calibrate\nfrom ..sim import target_video\n"}
    for name, text in {**base, **files}.items():
        path = root / name
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(textwrap.dedent(text))
    return root


def test_a_clean_tree_passes(tmp_path):
    assert violations(_tree(tmp_path, {})) == []


@pytest.mark.parametrize("files, expected", [
    ({"io/video.py": "from ..detection.pipeline import detect_video\n"}, "io module io.video imports detection"),
    ({"linedelay/spline.py": "from ..cli import main\n"}, "engine module linedelay.spline imports cli"),
    ({"linedelay/spline.py": "from ..sim.target_video import render\n"}, "imports sim module"),
    ({"linedelay/spline.py": "from ..selfcalib.calibrate import x\n"}, "imports another engine"),
    ({"linedelay/spline.py": "from ..io.video import _private\n"}, "imports private _private"),
    ({"linedelay/spline.py": "import rscalib.cli\n"}, "imports cli"),
    ({"detection/pipeline.py": "def f():\n    print('hi')\n"}, "prints"),
    ({"io/video.py": "from . import targets\n", "io/targets.py": "from .video import open_source\n"},
     "import cycle: io.video -> io.targets -> io.video"),
    ({"linedelay/spline.py": "def f():\n    from ..cli import linedelay\n"}, "imports cli"),
    ({"linedelay/spline.py": "from ..batch.runner import run_batch\n"}, "engine module linedelay.spline imports batch"),
    ({"batch/runner.py": "from ..linedelay.spline import calibrate\n"}, "batch module batch.runner imports engine"),
])
def test_a_violation_is_caught(tmp_path, files, expected):
    found = violations(_tree(tmp_path, files))
    assert any(expected in p for p in found), found


def test_type_checking_imports_do_not_make_cycles_but_lazy_imports_do(tmp_path):
    root = _tree(tmp_path, {"io/video.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                                           "    from .targets import Target\n",
                            "io/targets.py": "from .video import open_source\n",
                            "io/cameras.py": "def f():\n    from .targets import t\n"})
    assert violations(root) == []
    lazy = _tree(tmp_path / "lazy", {"io/video.py": "def f():\n    from .targets import Target\n",
                                     "io/targets.py": "from .video import open_source\n"})
    assert any("import cycle: io.video -> io.targets -> io.video" in p for p in violations(lazy)), violations(lazy)
