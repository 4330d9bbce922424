"""README tables come from the code (issue 15 item 3): the marker blocks are replaced and checked, wall
times excepted; and (slow) `dynsplines bench readme --check` passes on the repository's README."""
from pathlib import Path

import pytest

from runner.cli import main
from runner.readme_tables import Block, compare_blocks, replace_blocks, table, timing
from solver.errors import InputError

REPO = Path(__file__).resolve().parents[2]

DOC = """# Title

text before
<!-- bench:a -->
| old | table |
<!-- /bench:a -->
text between
<!-- bench:b -->
<!-- /bench:b -->
text after
"""


def block_a(evals="1235", wall="44 s"):
    rows = [["flight [s]", "0.252", "0.159"], ["optimization", "", f"{evals} evaluations, " + timing(wall)]]
    return Block("a", table(["", "plain", "optimized"], rows))


def test_blocks_are_replaced_between_their_markers_and_nothing_else(tmp_path):
    p = tmp_path / "README.md"
    p.write_text(DOC)
    replace_blocks(p, [block_a(), Block("b", ["one line"])])
    text = p.read_text()
    assert text.startswith("# Title\n\ntext before\n<!-- bench:a -->\n|  | plain | optimized |\n")
    assert "| optimization |  | 1235 evaluations, 44 s |\n<!-- /bench:a -->\ntext between" in text
    assert "<!-- bench:b -->\none line\n<!-- /bench:b -->\ntext after\n" in text
    assert "old" not in text
    assert compare_blocks(p, [block_a(), Block("b", ["one line"])]) == []


def test_check_skips_wall_times_and_compares_every_other_figure(tmp_path):
    p = tmp_path / "README.md"
    p.write_text(DOC)
    replace_blocks(p, [block_a()])
    assert compare_blocks(p, [block_a(wall="12 s")]) == []  # another machine's time
    problems = compare_blocks(p, [block_a(evals="1224")])  # a figure that changed
    assert len(problems) == 1 and "1224 evaluations" in problems[0] and "1235 evaluations" in problems[0]
    stale = Block("a", table(["", "plain", "optimized"], [["flight [s]", "0.252", "0.227"],
                                                          ["optimization", "", "1235 evaluations, " + timing("1 s")]]))
    assert "0.227" in compare_blocks(p, [stale])[0]


def test_missing_markers_are_named(tmp_path):
    p = tmp_path / "README.md"
    p.write_text("no markers\n")
    with pytest.raises(InputError, match="no markers for a; add '<!-- bench:NAME -->'"):
        replace_blocks(p, [block_a()])
    assert compare_blocks(p, [block_a()]) == [f"{p}: no block bench:a"]


def test_the_readme_has_the_generated_tables():
    from runner.readme_tables import read_blocks

    blocks = read_blocks(REPO / "README.md")
    assert set(blocks) >= {"terms-all", "run-and-step", "refine"}
    assert all(body.strip() for body in blocks.values())  # regenerated, not empty
    assert "../shared" not in (REPO / "README.md").read_text()  # nothing outside the repository
    assert (REPO / "docs" / "design.md").is_file()


@pytest.mark.slow
def test_readme_tables_match_the_current_code(capsys):
    """Runs the run-and-step and --terms all workloads (under a minute): fails when those README tables
    no longer match the code; fix with `dynsplines bench readme`. The refine table (tens of solves,
    many minutes on 2 cores) is checked by `dynsplines bench readme --check --only refine`, not here."""
    code = main(["bench", "readme", "--check", "--only", "run-and-step,terms-all"])
    out = capsys.readouterr().out
    assert code == 0, out
