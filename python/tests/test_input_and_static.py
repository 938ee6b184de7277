"""Input design and the staticness test: the bindings against the tool, and the properties
the signals and the test must have, checked here with numpy."""

from __future__ import annotations

import numpy as np
import pytest

import structid
from conftest import read_csv, read_json, write_csv


@pytest.mark.parametrize("kind,args,kwargs", [
    ("prbs", ["--clock", "2"], {"clock": 2}),
    ("multisine", ["--odd", "--period", "128", "--min-crest"],
     {"odd": True, "period": 128, "minimise_crest": True}),
    ("noise", ["--band", "0,0.2"], {"band": (0.0, 0.2)}),
    ("chirp", ["--band", "0.01,0.3", "--sweep", "log"],
     {"band": (0.01, 0.3), "sweep": "logarithmic"}),
    ("steps", ["--hold", "3,12"], {"hold": (3, 12)}),
])
def test_each_input_equals_the_tool(cli, tmp_path, kind, args, kwargs):
    out = tmp_path / f"{kind}.csv"
    cli("input", kind, "--length", "512", "--amplitude", "0.7", "--offset", "0.2", "--seed", "5",
        *args, "--out", out)
    ours = getattr(structid.input, kind)(512, amplitude=0.7, offset=0.2, seed=5, **kwargs)
    assert ours.shape == (512,)
    np.testing.assert_allclose(ours, read_csv(out)["u"], rtol=1e-14, atol=1e-15)


def test_an_odd_multisine_excites_odd_lines_only():
    period, periods = 256, 4
    u = structid.input.multisine(period * periods, period=period, odd=True, band=(0.0, 0.25))
    spectrum = np.abs(np.fft.rfft(u[:period]))
    excited = spectrum > 1e-6 * spectrum.max()
    lines = np.flatnonzero(excited)
    assert lines.size > 10
    assert np.all(lines % 2 == 1), lines[lines % 2 == 0]
    # every odd harmonic inside the band (f = k/period < 0.25) is present
    assert set(range(1, period // 4, 2)) <= set(lines.tolist())
    # the signal is periodic and its peak is the amplitude
    np.testing.assert_allclose(u[:period], u[period:2 * period], atol=1e-12)
    assert abs(np.max(np.abs(u)) - 1.0) < 1e-12


def test_a_prbs_has_one_more_high_bit_per_period():
    order = 7
    u = structid.input.prbs(2 ** order - 1, order=order, clock=1)
    assert set(np.unique(u)) == {-1.0, 1.0}
    assert np.sum(u > 0) - np.sum(u < 0) == 1
    assert abs(structid.input.crest_factor(u) - 1.0) < 0.01


def _scatter(kind: str, n: int = 1500, seed: int = 4):
    rng = np.random.default_rng(seed)
    z = np.cumsum(rng.normal(size=n))
    z = 2.0 * (z - z.mean()) / np.ptp(z)
    if kind == "atan":
        w = np.arctan(3.0 * z)
    else:  # a first-order filter of z: w depends on past z
        w = np.zeros(n)
        for k in range(1, n):
            w[k] = 0.9 * w[k - 1] + 0.1 * z[k]
        w *= 5.0
    return z, w + 0.02 * rng.normal(size=n)


def test_staticness_equals_the_tool(cli, tmp_path):
    z, w = _scatter("atan")
    data = write_csv(tmp_path / "scatter.csv", {"z": z, "w": w})
    cli("static", "--data", data, "--z", "z", "--w", "w", "--out", tmp_path / "out")
    tool = read_json(tmp_path / "out" / "report.json")["result"]
    ours = structid.staticness(z, w)
    assert ours.verdict == tool["verdict"]
    for key in ("unexplained_ratio", "explained_share", "sigma", "beta", "noise_variance"):
        np.testing.assert_allclose(ours.report[key], tool[key], rtol=1e-9, err_msg=key)
    assert ours.fitted.shape == z.shape


def test_an_atan_is_static_and_a_filter_is_not():
    atan = structid.staticness(*_scatter("atan"), noise_std=0.02)
    lti = structid.staticness(*_scatter("lti"), noise_std=0.02)
    assert atan.verdict == "static", atan.verdict_text
    assert lti.verdict != "static", lti.verdict_text
    assert lti.unexplained_ratio > 10.0 * atan.unexplained_ratio
    # the fitted map is the atan inside the data
    z, _ = _scatter("atan")
    inside = (atan.grid_z > z.min() + 0.1) & (atan.grid_z < z.max() - 0.1)
    np.testing.assert_allclose(atan.grid_w[inside], np.arctan(3.0 * atan.grid_z[inside]),
                               atol=0.05)


def test_bad_inputs_are_structid_errors():
    z, w = _scatter("atan", n=200)
    z[17] = np.nan
    with pytest.raises(structid.StructidError, match="non-finite value NaN at sample 17"):
        structid.staticness(z, w)
    with pytest.raises(structid.StructidError):
        structid.staticness(np.arange(10.0), np.arange(12.0))
    with pytest.raises(structid.StructidError, match="noise"):
        structid.staticness(*_scatter("atan", n=200), noise_std=-1.0)
    with pytest.raises(structid.StructidError, match="band"):
        structid.input.noise(100, band=(0.3, 0.1))
    with pytest.raises(structid.StructidError, match="sweep"):
        structid.input.chirp(100, sweep="cubic")
