"""The linear part from Python (``structid.linear``, ``structid.response``) against the
command-line tool's ``structid linear`` and against closed forms computed here with numpy, and
data files (``structid.read_data``) against the same numbers read another way."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

import structid
from conftest import REPO, write_csv

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    tomllib = None

ARRAYS = REPO / "crates" / "structid-io" / "tests" / "data" / "arrays"


def filtered(b, a, u):
    """y = B(q⁻¹)/A(q⁻¹)·u from rest, by the difference equation (independent of the library)."""
    y = np.zeros(len(u))
    for k in range(len(u)):
        acc = sum(b[i] * u[k - i] for i in range(len(b)) if k - i >= 0)
        acc -= sum(a[i] * y[k - i] for i in range(1, len(a)) if k - i >= 0)
        y[k] = acc / a[0]
    return y


B_TRUE = [0.0, 0.4, 0.25]
A_TRUE = [1.0, -1.3, 0.6]


def record(seed, n=600, noise=0.01):
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(n)
    return u, filtered(B_TRUE, A_TRUE, u) + noise * rng.standard_normal(n)


def model_file_polynomials(path: Path):
    with open(path, "rb") as f:
        lin = tomllib.load(f)["linear"]
    return [np.asarray(b, dtype=float) for b in lin["num"]], np.asarray(lin["den"], dtype=float)


@pytest.mark.skipif(tomllib is None, reason="tomllib needs Python 3.11")
@pytest.mark.parametrize("method", ["oe", "arx"])
def test_linear_equals_the_tool(tmp_path, cli, method):
    u, y = record(3)
    data = write_csv(tmp_path / "d.csv", {"u": u, "y": y})
    out = tmp_path / "g.toml"
    cli("linear", "--data", data, "--orders", "2,3,0", "--method", method, "-o", out)
    num, den = model_file_polynomials(out)
    fit = structid.linear(u, y, (2, 3, 0), method=method)
    np.testing.assert_allclose(fit.den, den, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fit.num[0], num[0], rtol=1e-12, atol=1e-12)
    # and both are near the truth, whose output the fit simulates to within the noise
    np.testing.assert_allclose(fit.den, A_TRUE, atol=0.02)
    assert fit.fit_percent[0] > 95.0
    # the model it returns is the tool's model file and simulates as G does
    sim = fit.model.simulate(u)["y"][:, 0]
    np.testing.assert_allclose(sim, filtered(fit.num[0], fit.den, u), rtol=1e-9, atol=1e-9)


@pytest.mark.skipif(tomllib is None, reason="tomllib needs Python 3.11")
def test_several_records_equal_the_tool_and_not_the_glued_record(tmp_path, cli):
    (u1, y1), (u2, y2) = record(5, 400), record(6, 300)
    a = write_csv(tmp_path / "a.csv", {"u": u1, "y": y1})
    b = write_csv(tmp_path / "b.csv", {"u": u2, "y": y2})
    out = tmp_path / "g.toml"
    cli("linear", "--data", a, "--data", b, "--orders", "2,3,0", "--method", "arx", "-o", out)
    num, den = model_file_polynomials(out)
    fit = structid.linear([u1, u2], [y1, y2], (2, 3, 0), method="arx")
    np.testing.assert_allclose(fit.den, den, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(fit.num[0], num[0], rtol=1e-12, atol=1e-12)
    assert len(fit.fit_percent) == 2
    glued = structid.linear(np.concatenate([u1, u2]), np.concatenate([y1, y2]), (2, 3, 0),
                            method="arx")
    assert np.max(np.abs(glued.den - fit.den)) > 1e-9
    # output error over both records recovers G too
    oe = structid.linear([u1, u2], [y1, y2], (2, 3, 0), method="oe")
    np.testing.assert_allclose(oe.den, A_TRUE, atol=0.02)
    np.testing.assert_allclose(oe.num[0], B_TRUE, atol=0.02)


def test_a_fixed_integrator_is_kept_at_one():
    # y = 0.05 q⁻¹/((1 − q⁻¹)(1 − 0.7 q⁻¹))·u: a position driven through a lag
    rng = np.random.default_rng(11)
    u = rng.standard_normal(800)
    a = np.convolve([1.0, -1.0], [1.0, -0.7])
    y = filtered([0.0, 0.05], a, u) + 0.002 * rng.standard_normal(800)
    fit = structid.linear(u, y, (1, 1, 1), method="oe", integrators=1)
    # one root of A at exactly z = 1, the other near 0.7
    poles = np.sort(np.roots(fit.den).real)
    assert abs(poles[-1] - 1.0) < 1e-9
    assert abs(poles[0] - 0.7) < 0.02
    np.testing.assert_allclose(fit.num[0][1], 0.05, rtol=0.05)


def test_responses_match_the_closed_forms():
    num, den = [0.0, 0.4, 0.25], [1.0, -1.3, 0.6]
    f = np.array([0.0, 0.01, 0.1, 0.25, 0.5])
    r = structid.response(num, den, frequencies=f, steps=400)
    z = np.exp(-2j * np.pi * f)  # q⁻¹ on the unit circle
    g = np.polyval(num[::-1], z) / np.polyval(den[::-1], z)
    np.testing.assert_allclose(r.magnitude, np.abs(g), rtol=1e-12)
    np.testing.assert_allclose(np.cos(r.phase), np.cos(np.angle(g)), atol=1e-9)
    np.testing.assert_allclose(np.sin(r.phase), np.sin(np.angle(g)), atol=1e-9)
    np.testing.assert_allclose(r.step, filtered(num, den, np.ones(400)), rtol=1e-12, atol=1e-12)
    assert abs(r.step[-1] - sum(num) / sum(den)) < 1e-6
    np.testing.assert_allclose(np.sort_complex(r.poles), np.sort_complex(np.roots(den)), atol=1e-12)
    np.testing.assert_allclose(r.zeros, [-0.625], atol=1e-12)
    assert r.magnitude_std is None


def test_the_fits_band_comes_from_its_covariance():
    u, y = record(8, 500, noise=0.05)
    fit = structid.linear(u, y, (2, 3, 0), method="oe")
    assert fit.covariance is not None
    np.testing.assert_allclose(np.sqrt(np.diag(fit.covariance)), fit.parameter_std, rtol=1e-9)
    r = fit.response(frequencies=16)
    assert r.magnitude_std is not None and r.magnitude_std.shape == r.magnitude.shape
    assert np.all(r.magnitude_std > 0)
    # quadrupling the covariance doubles the band (first-order propagation)
    r4 = structid.response(fit.num, fit.den, frequencies=16, covariance=4 * fit.covariance)
    np.testing.assert_allclose(r4.magnitude_std, 2 * r.magnitude_std, rtol=1e-6)


def test_read_data_reads_mat_and_numpy_files_by_name(tmp_path):
    csv = np.genfromtxt(ARRAYS / "signals.csv", delimiter=",", names=True)
    d = structid.read_data(ARRAYS / "signals_v5.mat", "u=vir,y=qm")
    assert list(d) == ["u", "y"]
    np.testing.assert_array_equal(d["u"], csv["u"])
    np.testing.assert_array_equal(d["y"], csv["y"])
    path = tmp_path / "rec.npz"
    np.savez(path, force=np.arange(5.0), position=np.linspace(0, 1, 5))
    d = structid.read_data(path, "u=force,y=position")
    np.testing.assert_array_equal(d["u"], np.arange(5.0))
    np.testing.assert_array_equal(d["y"], np.linspace(0, 1, 5))
    c = structid.read_data(ARRAYS / "signals.csv")
    np.testing.assert_array_equal(c["y"], csv["y"])


@pytest.mark.parametrize("select", ["bic", "validation"])
def test_selection_structure_and_initial_state_equal_the_tool(tmp_path, cli, select):
    # Orders selected, a map in output feedback with its own numerator, the initial state
    # estimated: the same model file as `structid linear` with the same options.
    u, y = record(5, n=800, noise=0.02)
    vu, vy = record(6, n=400, noise=0.02)
    data = write_csv(tmp_path / "d.csv", {"u": u, "y": y})
    val = write_csv(tmp_path / "v.csv", {"u": vu, "y": vy})
    out = tmp_path / "g.toml"
    args = ["linear", "--data", data, "--select", select, "--max-order", "3",
            "--min-delay", "1", "--max-delay", "2", "--initial-state", "estimate",
            "--structure", "output-feedback", "--separate-numerator", "--map", "spring",
            "--dispersion", "gaussian", "--trend", "3", "-o", out]
    if select == "validation":
        args += ["--validation-data", val]
    cli(*args)
    fit = structid.linear(u, y, select=select, max_order=3, delays=(1, 2),
                          validation=(vu, vy) if select == "validation" else None,
                          initial_state="estimate", structure="output-feedback",
                          separate_numerator=True, map="spring", dispersion="gaussian", trend=3)
    assert fit.toml == out.read_text()
    na, nb, nk = fit.orders
    assert 1 <= na <= 3 and 1 <= nb[0] <= 3 and nk[0] in (1, 2)
    if select == "validation":
        # The simulation error on a fresh record finds the truth's orders: second order,
        # two numerator coefficients after a delay of one sample. (BIC on the ARX equation
        # error, with output noise, may take more.)
        assert fit.orders == (2, [2], [1]), fit.orders
    criterion, candidates = fit.selection
    assert candidates == 3 * 3 * 2
    assert criterion.lower().startswith(select[:3])
    assert fit.model.blocks[0]["name"] == "spring"


def test_bad_input_gets_a_clear_error(tmp_path):
    with pytest.raises(structid.StructidError, match="qx"):
        structid.read_data(ARRAYS / "signals_v5.mat", "u=vir,y=qx")
    with pytest.raises(structid.StructidError, match="vars"):
        structid.read_data(ARRAYS / "signals_v5.mat", "u=")
    with pytest.raises(structid.StructidError):
        structid.read_data(tmp_path / "missing.mat")
    u, y = record(1, 50)
    with pytest.raises(structid.StructidError, match="samples"):
        structid.linear(u, y[:40], (2, 2, 1))
    y_nan = y.copy()
    y_nan[7] = np.nan
    with pytest.raises(structid.StructidError, match="sample 7"):
        structid.linear(u, y_nan, (2, 2, 1))
    with pytest.raises(structid.StructidError, match="method"):
        structid.linear(u, y, (2, 2, 1), method="n4sid")
    with pytest.raises(structid.StructidError, match="validation"):
        structid.linear(u, y, select="validation")
    with pytest.raises(structid.StructidError, match="structure"):
        structid.linear(u, y, (2, 2, 1), structure="rate-feedback")
    with pytest.raises(structid.StructidError, match="transient"):
        structid.linear(u, y, (2, 2, 1), method="arx", transient=5)
    with pytest.raises(structid.StructidError, match="0 … 0.5"):
        structid.response([0.0, 1.0], [1.0, -0.5], frequencies=[0.7])
