"""The README's Python example runs as printed."""

from __future__ import annotations

import os
import re

import numpy as np

from conftest import REPO


def test_readme_example_runs(tmp_path, monkeypatch):
    text = (REPO / "README.md").read_text(encoding="utf-8")
    section = text[text.index("## Python"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(tmp_path)
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)
    fit, again = scope["fit"], scope["again"]
    # The example's map is tanh(2z): the estimate must be close to it, and the saved fit the same.
    z = np.linspace(-1.0, 1.0, 11)
    assert np.max(np.abs(fit.evaluate("N", z) - np.tanh(2 * z))) < 0.1
    np.testing.assert_array_equal(again.evaluate("N", z), fit.evaluate("N", z))
    assert os.path.isfile(tmp_path / "fit-dir" / "report.json")
    # The example's own kernel finds the same map.
    mine = scope["mine"]
    assert mine.maps["N"].dispersion == "laplace"
    assert np.max(np.abs(mine.evaluate("N", z) - np.tanh(2 * z))) < 0.1
