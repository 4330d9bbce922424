"""The layering and lint contracts of docs/architecture.md, run as tests: import-linter (contracts in
pyproject.toml [tool.importlinter]) and ruff (rules in [tool.ruff]).

The contracts name the layout (runner/commands/, runner/capture/, runner/render/, runner/console.py, ...,
runner/bench/sphere_reference/) and `ruff check` must report nothing. Each test
skips, with the reason, when its tool is not installed (`pip install -e ".[test]"` installs both).
"""
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


def _tool(name: str) -> str:
    """The tool next to this Python (the venv's bin), else on PATH; skip when it is not installed."""
    here = Path(sys.executable).parent / name
    found = str(here) if here.exists() else shutil.which(name)
    if found is None:
        pytest.skip(f"{name} is not installed (pip install -e '.[test]')")
    return found


def _run(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run(argv, cwd=REPO, capture_output=True, text=True, timeout=300)


def test_import_contracts():
    """solver never imports runner; runner.bench.sphere_reference imports nothing from solver nor
    anything else from runner; runner's layers (docs/architecture.md); no cycles."""
    r = _run(_tool("lint-imports"), "--no-cache")
    assert r.returncode == 0, f"lint-imports failed:\n{r.stdout}\n{r.stderr}"
    assert "0 broken" in r.stdout, r.stdout


def test_ruff():
    r = _run(_tool("ruff"), "check", "--no-cache", "solver", "runner", "tests")
    assert r.returncode == 0, f"ruff check found problems:\n{r.stdout}\n{r.stderr}"


#: where the structure's rules hold function length to one screen: the orchestration a reader follows
#: (the solve's outer loop, the one run, the commands' argument glue)
SHORT_FUNCTIONS = ("solver/solve.py", "runner/run.py", "runner/commands/*.py")
MAX_FUNCTION_LINES = 80


def test_orchestration_functions_fit_on_a_screen():
    import ast

    long = []
    for pattern in SHORT_FUNCTIONS:
        for path in sorted(REPO.glob(pattern)):
            for node in ast.walk(ast.parse(path.read_text())):
                if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_FUNCTION_LINES:
                        long.append(f"{path.relative_to(REPO)}:{node.lineno} {node.name} ({n} lines)")
    assert not long, "functions over 80 lines: " + ", ".join(long)


def test_the_command_line_imports_no_video_or_bench_code():
    """The `dynsplines` parser (every command's options) loads none of the video writer (OpenGL drawing,
    Pillow, imageio), the plots (matplotlib), the glTF writer, nor the benchmarks' BVP reference
    (scipy.integrate): a command pays for them only when it uses them (`mocap --no-render` never)."""
    code = ("import sys, runner.cli; runner.cli.build_parser(); "
            "print(' '.join(m for m in ('runner.render.gl', 'runner.render.video', 'PIL', 'imageio', 'matplotlib', "
            "'pygltflib', 'scipy.integrate') if m in sys.modules))")
    r = _run(sys.executable, "-c", code)
    assert r.returncode == 0, r.stderr
    assert r.stdout.split() == [], r.stdout
