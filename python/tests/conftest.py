"""Shared fixtures: the `structid` command-line binary and small records written as CSV.

The bindings are checked against the command-line tool on the same files: the binary is
`$STRUCTID_CLI`, else `target/release/structid` of the repository (built by
`cargo build --release -p structid-cli`; the cargo test that runs this suite passes it).
"""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]

# y = G·N(u) + e with G(q) = (0.5q⁻¹ + 0.3q⁻²)/(1 − 1.2q⁻¹ + 0.5q⁻²): the README's first model.
HAMMERSTEIN_TOML = """
[linear]
structure = "input"
den = [1.0, -1.2, 0.5]
num = [[0.0, 0.5, 0.3]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "N"
inputs = [0]
output = 0
dispersion = { kind = "gaussian", sigma = 0.3 }
"""


def cli_path() -> Path:
    given = os.environ.get("STRUCTID_CLI")
    path = Path(given) if given else REPO / "target" / "release" / "structid"
    if not path.is_file():
        pytest.fail(
            f"the structid binary is not at {path}: build it with "
            "`cargo build --release -p structid-cli` or set STRUCTID_CLI")
    return path


@pytest.fixture(scope="session")
def cli():
    """Runs the command-line tool; fails the test with its stderr when it fails."""
    path = cli_path()

    def run(*args: str) -> str:
        r = subprocess.run([str(path), *map(str, args)], capture_output=True, text=True)
        if r.returncode != 0:
            pytest.fail(f"structid {' '.join(map(str, args))} exited {r.returncode}:\n{r.stderr}")
        return r.stdout

    return run


def write_csv(path: Path, columns: dict) -> Path:
    """A CSV file whose numbers read back bit for bit (17 significant digits)."""
    names = list(columns)
    data = np.column_stack([np.asarray(columns[n], dtype=float) for n in names])
    np.savetxt(path, data, delimiter=",", header=",".join(names), comments="", fmt="%.17g")
    return path


def read_json(path: Path) -> dict:
    with open(path, encoding="utf-8") as f:
        return json.load(f)


def read_csv(path: Path) -> dict:
    a = np.genfromtxt(path, delimiter=",", names=True)
    return {n: np.asarray(a[n], dtype=float) for n in a.dtype.names}


@pytest.fixture(scope="session")
def records():
    """An estimation and a validation record of the Hammerstein model with N = tanh(2z):
    inputs from numpy's generator, outputs from a simulation written out here (independent of
    the bindings)."""
    rng = np.random.default_rng(7)

    def record(n: int) -> dict:
        u = np.convolve(rng.uniform(-2.0, 2.0, n), np.ones(3) / 3.0, mode="same")
        w = np.tanh(2.0 * u)
        y = np.zeros(n)
        # y_k = 1.2 y_(k−1) − 0.5 y_(k−2) + 0.5 w_(k−1) + 0.3 w_(k−2), then noise.
        for k in range(n):
            y[k] = (1.2 * y[k - 1] if k >= 1 else 0.0) - (0.5 * y[k - 2] if k >= 2 else 0.0) \
                + (0.5 * w[k - 1] if k >= 1 else 0.0) + (0.3 * w[k - 2] if k >= 2 else 0.0)
        y_clean = y.copy()
        y = y + 0.05 * rng.standard_normal(n)
        return {"u": u, "y": y, "y_clean": y_clean, "w": w}

    return {"estimation": record(300), "validation": record(200)}


@pytest.fixture()
def files(tmp_path, records):
    """The model file and the two records as files."""
    model = tmp_path / "model.toml"
    model.write_text(HAMMERSTEIN_TOML)
    est = records["estimation"]
    val = records["validation"]
    return {
        "model": model,
        "data": write_csv(tmp_path / "data.csv", {"u": est["u"], "y": est["y"]}),
        "val": write_csv(tmp_path / "val.csv", {"u": val["u"], "y": val["y"]}),
        "dir": tmp_path,
    }
