"""Every number in solver/ that a reader might tune is named in docs/design.md's "Numbers you can tune", and the
tunable ones are at most 40 (the least change's design budget).

A number here is a module or class constant, or a function's default, whose value holds a numeric literal other
than 0 and 1 (found by parsing solver/, so a new constant without its line in the manual fails this test). The
manual sorts each into the tunable tables (counted: a row's backticked names, one number each) or the lists of
numbers fixed by physics, mathematics, the paper or the acceptance bounds, and numbers that are not results.
"""
import ast
import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
#: [numbers] the design's budget of numbers chosen by judgement in solver/
MAX_TUNABLE = 40
#: names that hold derivative orders (a term's `needs`: 0 for the pose, 1 qvel, 2 qacc), not quantities
ORDERS = {"needs", "required"}


def _numeric(node: ast.AST) -> bool:
    return any(isinstance(c, ast.Constant) and type(c.value) in (int, float) and c.value not in (0, 1)
               for c in ast.walk(node))


def _solver_numbers() -> list[tuple[str, str]]:
    """(module path, name) of every numbered constant, class field and default in solver/: NAME,
    Class.field, or function(argument=)."""
    found = []
    for path in sorted((REPO / "solver").rglob("*.py")):
        rel, tree = str(path.relative_to(REPO)), ast.parse(path.read_text())
        scopes = [(None, tree)] + [(c.name, c) for c in ast.walk(tree) if isinstance(c, ast.ClassDef)]
        for owner, scope in scopes:
            for s in scope.body:
                target = s.targets[0] if isinstance(s, ast.Assign) else getattr(s, "target", None)
                if not isinstance(target, ast.Name) or getattr(s, "value", None) is None or target.id in ORDERS:
                    continue
                if _numeric(s.value):
                    found.append((rel, target.id if owner is None or target.id.isupper() else f"{owner}.{target.id}"))
        for owner, f in _functions(tree):
            a = f.args
            pairs = list(zip(a.args[len(a.args) - len(a.defaults):], a.defaults)) + list(zip(a.kwonlyargs, a.kw_defaults))
            name = owner if f.name == "__init__" else f.name                  # a constructor's: Class(argument=)
            found += [(rel, f"{name}({arg.arg}=)") for arg, d in pairs if d is not None and _numeric(d) and arg.arg not in ORDERS]
    return found


def _functions(tree: ast.Module):
    """(class name or None, function) of every function in a module."""
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef):
            yield from ((node.name, f) for f in node.body if isinstance(f, ast.FunctionDef))
        elif isinstance(node, ast.Module):
            yield from ((None, f) for f in node.body if isinstance(f, ast.FunctionDef))


def _section() -> str:
    text = (REPO / "docs" / "design.md").read_text()
    start = text.index("## Numbers you can tune")
    return text[start:text.index("\n## ", start + 1)]


def test_every_number_in_solver_is_named_in_the_manual():
    section = _section()
    numbers = _solver_numbers()
    assert len(numbers) > 40, "the scan found too few numbers: it no longer reads solver/"
    missing = [f"{path}: {name}" for path, name in numbers
               if name not in section]
    assert not missing, "numbers in solver/ not named in docs/design.md 'Numbers you can tune': " + ", ".join(missing)


def test_the_tunable_numbers_are_at_most_forty():
    """The tables' rows (before "Fixed by"), a row's first cell naming one number per backticked name, and
    the count the manual states agree, and are at most MAX_TUNABLE."""
    section = _section()
    tables = section[:section.index("**Fixed by")]
    rows = [line.split("|")[1] for line in tables.splitlines()
            if line.startswith("| `")]
    count = sum(len(re.findall(r"`[^`]+`", cell)) for cell in rows)
    stated = int(re.search(r"That is (\d+) numbers", section).group(1))
    assert count == stated, f"the tables name {count} numbers; the manual says {stated}"
    assert count <= MAX_TUNABLE
