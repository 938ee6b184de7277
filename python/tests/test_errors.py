"""Bad input raises StructidError (a ValueError) with the library's message."""

from __future__ import annotations

import threading
import time

import numpy as np
import pytest

import structid
from conftest import HAMMERSTEIN_TOML


@pytest.fixture()
def model():
    return structid.Model.from_toml(HAMMERSTEIN_TOML)


@pytest.fixture()
def record():
    u = np.sin(0.07 * np.arange(200)) * 2.0
    return u, np.tanh(u) + 0.01 * np.cos(np.arange(200))


def test_error_is_a_value_error():
    assert issubclass(structid.StructidError, ValueError)


def test_nan_input(model, record):
    u, y = record
    u = u.copy()
    u[5] = np.nan
    with pytest.raises(structid.StructidError, match=r"column `u` has the non-finite value NaN in row 5"):
        structid.identify(model, u, y)


def test_infinite_output(model, record):
    u, y = record
    y = y.copy()
    y[0] = np.inf
    with pytest.raises(structid.StructidError, match="non-finite"):
        structid.identify(model, u, y)


def test_mismatched_lengths(model, record):
    u, y = record
    with pytest.raises(structid.StructidError, match=r"has 200 values but column `u` has 150"):
        structid.identify(model, u[:150], y)


@pytest.mark.parametrize("sigma", [0.0, -1.0, float("nan")])
def test_sigma_not_positive(model, record, sigma):
    with pytest.raises(structid.StructidError, match="sigma .* greater than zero"):
        structid.identify(model, *record, sigma=sigma)


def test_sigma_not_positive_in_dispersion():
    with pytest.raises(structid.StructidError, match="greater than zero"):
        structid.Model.hammerstein([0.0, 1.0], [1.0, -0.5], structid.gaussian(sigma=-0.1))


@pytest.mark.parametrize("beta", [0.0, -1e-3, float("inf")])
def test_beta_not_positive(model, record, beta):
    with pytest.raises(structid.StructidError, match="beta"):
        structid.identify(model, *record, beta=beta)


def test_wrong_channel_count(model, record):
    u, y = record
    with pytest.raises(structid.StructidError, match="2 channel"):
        structid.identify(model, np.column_stack([u, u]), y)


def test_malformed_model_file_names_the_line():
    bad = HAMMERSTEIN_TOML.replace('num = [[0.0, 0.5, 0.3]]', 'num = "x"')
    with pytest.raises(structid.StructidError, match="line"):
        structid.Model.from_toml(bad)


def test_unknown_names(model, record):
    with pytest.raises(structid.StructidError, match="solver `fast`"):
        structid.identify(model, *record, solver="fast")
    with pytest.raises(structid.StructidError, match="dispersion kind `rbf`"):
        model.with_dispersion("rbf")
    fit = structid.identify(model, *record)
    with pytest.raises(structid.StructidError, match="no block `M`"):
        fit.evaluate("M", [0.0])


def test_selection_without_auto(model, record):
    with pytest.raises(structid.StructidError, match="needs beta=\"auto\""):
        structid.identify(model, *record, selection="gcv")


def test_long_call_releases_the_gil(model):
    """Another Python thread keeps running while identify works."""
    n = 2500
    u = np.sin(0.05 * np.arange(n)) * 2.0
    y = np.tanh(u) + 0.01 * np.cos(np.arange(n))
    done = threading.Event()
    ticks = []

    def tick():
        while not done.is_set():
            ticks.append(time.perf_counter())
            time.sleep(0.005)

    t = threading.Thread(target=tick)
    t.start()
    start = time.perf_counter()
    try:
        structid.identify(model, u, y, beta=0.01, solver="exact")
    finally:
        end = time.perf_counter()
        done.set()
        t.join()
    during = [s for s in ticks if start < s < end]
    # Holding the GIL for the whole solve would leave at most a tick or two inside it.
    assert end - start > 0.05, "the problem is too small to tell"
    assert len(during) >= 5, (len(during), end - start)


def test_constant_input_is_refused_as_the_tool_does(model):
    """A map input that does not vary shows the map at one point: refused before fitting, by
    identify and by refine, with the tool's message."""
    u = np.full(200, 0.7)
    y = np.linspace(0.0, 1.0, 200)
    with pytest.raises(structid.StructidError, match="is constant"):
        structid.identify(model, u, y, beta=0.01)
    with pytest.raises(structid.StructidError, match="is constant"):
        structid.refine(model, u, y, beta=0.01)
    # over several records, z is refused when it takes one value in all of them
    with pytest.raises(structid.StructidError, match="is constant"):
        structid.identify(model, [u, u.copy()], [y, y.copy()], beta=0.01)


@pytest.mark.parametrize("sigma", [1e7, 1e-8])
def test_absurd_sigma_for_the_data_range_is_refused(model, record, sigma):
    """σ a million times wider or narrower than the range of the map's input: refused, as
    `structid identify --sigma` refuses it."""
    u, y = record
    with pytest.raises(structid.StructidError, match=r"invalid value \S+ for sigma: the input `z0` of block `N` spans"):
        structid.identify(model, u, y, beta=0.01, sigma=sigma)
    with pytest.raises(structid.StructidError, match="for sigma"):
        structid.refine(model, u, y, beta=0.01, sigma=sigma)


@pytest.mark.parametrize("fraction", [0.0, 1.0, 1.5, float("nan")])
def test_silverbox_validation_fraction_out_of_range(tmp_path, fraction):
    # Checked before the file is read: the path need not exist.
    with pytest.raises(structid.StructidError, match="strictly between 0 and 1"):
        structid.silverbox_discovery(tmp_path / "missing.csv", validation_fraction=fraction)
