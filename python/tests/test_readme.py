"""Every ```python block of README.md and docs/*.md runs as printed.

Each block runs on its own in a temporary directory (its working directory), with the line
numbers of its page in tracebacks. Blocks with stated results get their checks in CHECKS, keyed
by the page and the heading of the section the block is in. The other blocks of the pages
(shell commands, model files, Rust) are run by crates/structid-cli/tests/docs_blocks.rs and
the doc tests of src/readme_doctests.rs.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass

import numpy as np
import pytest

from conftest import REPO


@dataclass
class Block:
    page: str     # relative to the repository: "README.md", "docs/cli.md"
    line: int     # line of the opening fence
    section: str  # the heading above it
    code: str


def pages() -> list[str]:
    return ["README.md"] + sorted(f"docs/{p.name}" for p in (REPO / "docs").glob("*.md"))


def python_blocks() -> list[Block]:
    out = []
    for page in pages():
        lines = (REPO / page).read_text(encoding="utf-8").splitlines()
        section, i = "", 0
        while i < len(lines):
            line = lines[i]
            if line.startswith("#"):
                section = line.strip()
            fence = re.match(r"^ {0,3}(`{3,}|~{3,})\s*(\S*)", line)
            if fence:
                start, marker, lang = i, fence.group(1), fence.group(2)
                i += 1
                while i < len(lines) and not lines[i].strip().startswith(marker):
                    i += 1
                if lang == "python":
                    out.append(Block(page, start + 1, section, "\n".join(lines[start + 1:i]) + "\n"))
            i += 1
    return out


def check_readme_python(scope: dict, tmp_path) -> None:
    """The README's example: its map is tanh(2z); the saved fit reads back the same."""
    fit, again = scope["fit"], scope["again"]
    z = np.linspace(-1.0, 1.0, 11)
    assert np.max(np.abs(fit.evaluate("N", z) - np.tanh(2 * z))) < 0.1
    np.testing.assert_array_equal(again.evaluate("N", z), fit.evaluate("N", z))
    assert os.path.isfile(tmp_path / "fit-dir" / "report.json")
    # The example's own kernel finds the same map.
    mine = scope["mine"]
    assert mine.maps["N"].dispersion == "laplace"
    assert np.max(np.abs(mine.evaluate("N", z) - np.tanh(2 * z))) < 0.1


CHECKS = {("README.md", "## Python"): check_readme_python}

BLOCKS = python_blocks()


def test_the_pages_have_python_blocks():
    # The README's example at least: an empty list would make the test below vacuous.
    assert any(b.page == "README.md" and b.section == "## Python" for b in BLOCKS), BLOCKS


def test_every_check_has_its_block():
    found = {(b.page, b.section) for b in BLOCKS}
    assert set(CHECKS) <= found, f"CHECKS for blocks no page has any more: {set(CHECKS) - found}"


@pytest.mark.parametrize("block", BLOCKS, ids=[f"{b.page}:{b.line}" for b in BLOCKS])
def test_python_block_runs(block: Block, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    scope: dict = {"__name__": "__main__"}
    # Blank lines in front, so that a traceback gives the line of the page.
    source = "\n" * block.line + block.code
    exec(compile(source, str(REPO / block.page), "exec"), scope)
    check = CHECKS.get((block.page, block.section))
    if check is not None:
        check(scope, tmp_path)
