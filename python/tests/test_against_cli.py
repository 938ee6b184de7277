"""The bindings give the command-line tool's numbers on the same files."""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import structid
from conftest import read_csv, read_json, write_csv

RTOL = 1e-12


def close(a, b, rtol=RTOL, atol=1e-12):
    np.testing.assert_allclose(np.asarray(a, dtype=float), np.asarray(b, dtype=float),
                               rtol=rtol, atol=atol)


def run_both(cli, files, cli_args, **kwargs):
    out = files["dir"] / "cli"
    cli("identify", "--model", files["model"], "--data", files["data"], "--out", out, *cli_args)
    model = structid.Model.from_file(files["model"])
    data = read_csv(files["data"])
    fit = structid.identify(model, data["u"], data["y"], **kwargs)
    return out, fit


def check_identification(out, fit):
    report = read_json(out / "report.json")
    est = read_csv(out / "estimate.csv")
    close(fit.w_hat[:, 0], est["N"])
    close(fit.e_hat[:, 0], est["e0"])
    for key in ("total", "noise", "beta"):
        close(fit.cost[key], report["cost"][key])
    close(fit.cost["dispersions"], report["cost"]["dispersions"])
    assert fit.diagnostics["solver"] == report["diagnostics"]["solver"]
    grid = read_csv(out / "map_N.csv")
    close(fit.maps["N"].grid[:, 0], grid["z0"])
    close(fit.maps["N"].value, grid["value"])
    if "std" in grid:
        close(fit.maps["N"].std, grid["std"], rtol=1e-7)
    return report


def test_gaussian_fixed_beta(cli, files):
    out, fit = run_both(cli, files, ["--beta", "0.001"], beta=0.001)
    report = check_identification(out, fit)
    assert report["diagnostics"]["solver"] == "exact"
    assert fit.maps["N"].std is not None


def test_fourier_features(cli, files):
    out, fit = run_both(cli, files, ["--beta", "0.001", "--dispersion", "fourier"],
                        beta=0.001, dispersion="fourier")
    check_identification(out, fit)
    assert fit.diagnostics["solver"].startswith("features")


def test_total_variation(cli, files):
    out, fit = run_both(cli, files, ["--beta", "0.01", "--dispersion", "tv"],
                        beta=0.01, dispersion=structid.total_variation())
    # The same interior-point solver on the same data through the same workflow.
    report = read_json(out / "report.json")
    est = read_csv(out / "estimate.csv")
    close(fit.w_hat[:, 0], est["N"], rtol=1e-12)
    close(fit.cost["total"], report["cost"]["total"], rtol=1e-12)
    assert fit.maps["N"].std is None


def test_automatic_beta_and_sigma(cli, files):
    out, fit = run_both(cli, files, ["--beta", "auto", "--sigma", "auto"],
                        beta="auto", sigma="auto")
    report = check_identification(out, fit)
    close(fit.beta, report["selection"]["beta"])
    close(fit.sigma, report["selection"]["sigma"])
    assert fit.report["selection"]["criterion"] == report["selection"]["criterion"]


def test_validate_and_predict_match_the_tool(cli, files):
    out, fit = run_both(cli, files, ["--beta", "0.001"], beta=0.001)
    val = read_csv(files["val"])
    checked = files["dir"] / "check"
    cli("validate", "--estimate", out / "estimate.json", "--data", files["val"], "--out", checked)
    doc = read_json(checked / "validation.json")["outputs"][0]
    v = fit.validate(val["u"], val["y"])
    close(v.rms[0], doc["rms"])
    close(v.fit_percent[0], doc["fit_percent"])
    close(v.prediction_rms[0], doc["prediction_rms"])
    sim = read_csv(checked / "simulation.csv")
    y_sim_column = [n for n in sim if n.endswith("sim") or "simulated" in n]
    assert y_sim_column, f"no simulated column in {list(sim)}"
    close(v.simulated[:, 0], sim[y_sim_column[0]])

    predicted = files["dir"] / "pred"
    cli("predict", "--estimate", out / "estimate.json", "--data", files["val"], "--horizon", "3",
        "--out", predicted)
    doc = read_json(predicted / "prediction.json")["outputs"][0]
    p = fit.predict(val["u"], val["y"], horizon=3)
    close(p.rms[0], doc["rms"])
    close(p.fit_percent[0], doc["fit_percent"])


def test_saved_fit_is_read_by_the_tool_and_the_tools_result_by_load(cli, files):
    out, fit = run_both(cli, files, ["--beta", "0.001"], beta=0.001)
    saved = files["dir"] / "saved"
    fit.save(saved)
    checked = files["dir"] / "check-saved"
    cli("validate", "--estimate", saved / "estimate.json", "--data", files["val"], "--out", checked)
    doc = read_json(checked / "validation.json")["outputs"][0]
    val = read_csv(files["val"])
    close(fit.validate(val["u"], val["y"]).rms[0], doc["rms"])

    loaded = structid.load(out)
    close(loaded.w_hat, fit.w_hat)
    close(loaded.e_hat, fit.e_hat)
    close(loaded.maps["N"].value, fit.maps["N"].value)
    close(loaded.cost["total"], fit.cost["total"])
    again = structid.load(saved)
    assert again.model == fit.model
    close(again.simulate(val["u"])["y"], fit.simulate(val["u"])["y"], rtol=0, atol=0)


def test_structure_builder_is_the_model_file(cli, files):
    """Model.hammerstein gives the file's model: its saved TOML identifies as the file does."""
    built = structid.Model.hammerstein(num=[0.0, 0.5, 0.3], den=[1.0, -1.2, 0.5],
                                       dispersion=structid.gaussian(sigma=0.3))
    path = files["dir"] / "built.toml"
    built.save(path)
    out = files["dir"] / "cli-built"
    cli("identify", "--model", path, "--data", files["data"], "--out", out, "--beta", "0.001")
    data = read_csv(files["data"])
    fit = structid.identify(built, data["u"], data["y"], beta=0.001)
    close(fit.w_hat[:, 0], read_csv(out / "estimate.csv")["N"])
    from_file = structid.identify(structid.Model.from_file(files["model"]), data["u"], data["y"],
                                  beta=0.001)
    close(fit.w_hat, from_file.w_hat)


def test_pickle_keeps_the_fit(files, records):
    est = records["estimation"]
    model = structid.Model.from_file(files["model"])
    fit = structid.identify(model, est["u"], est["y"], beta=0.001)
    back = pickle.loads(pickle.dumps(fit))
    u = records["validation"]["u"]
    # The stored form reads back bit for bit, so the simulation is identical.
    np.testing.assert_array_equal(back.simulate(u)["y"], fit.simulate(u)["y"])
    np.testing.assert_array_equal(back.w_hat, fit.w_hat)
    assert back.model == model
    assert back.report == fit.report
    # The posterior is not part of the stored form.
    assert fit.estimate.has_posterior and not back.estimate.has_posterior
    assert back.band("N", [0.0]) is None


def test_map_recovers_the_truth(files, records):
    """Against the known map tanh(2z), not against the tool."""
    est = records["estimation"]
    fit = structid.identify(structid.Model.from_file(files["model"]), est["u"], est["y"],
                            beta="auto")
    z = np.linspace(-1.2, 1.2, 25)
    err = fit.evaluate("N", z) - np.tanh(2.0 * z)
    assert np.max(np.abs(err)) < 0.1, np.max(np.abs(err))
    std = fit.band("N", z)
    assert std is not None and np.all(std > 0)


def test_two_records_match_the_tool_and_not_their_concatenation(cli, files):
    # Two records, each from its own state: the tool's `--data a --data b`.
    out = files["dir"] / "two"
    cli("identify", "--model", files["model"], "--data", files["data"], "--data", files["val"],
        "--beta", "0.001", "--out", out)
    model = structid.Model.from_file(files["model"])
    a, b = read_csv(files["data"]), read_csv(files["val"])
    fit = structid.identify(model, [a["u"], b["u"]], [a["y"], b["y"]], beta=0.001)
    est = read_csv(out / "estimate.csv")
    assert fit.w_hat.shape[0] == len(a["u"]) + len(b["u"])
    close(fit.w_hat[:, 0], est["N"])
    close(fit.cost["total"], read_json(out / "report.json")["cost"]["total"])
    # one record glued from both carries the state over the joint: a different problem
    glued = structid.identify(model, np.concatenate([a["u"], b["u"]]),
                              np.concatenate([a["y"], b["y"]]), beta=0.001)
    assert np.max(np.abs(glued.w_hat[:, 0] - fit.w_hat[:, 0])) > 1e-6
    with pytest.raises(structid.StructidError, match="several records"):
        structid.identify(model, [a["u"], b["u"]], [a["y"]], beta=0.001)


def test_simulate_matches_the_tool(cli, files):
    """`structid simulate` of a stored estimate and of a model's truths, against Python's."""
    out, fit = run_both(cli, files, ["--beta", "0.001"], beta=0.001)
    val = read_csv(files["val"])
    sim = files["dir"] / "sim.csv"
    cli("simulate", "--estimate", out / "estimate.json", "--input", files["val"], "--out", sim)
    close(read_csv(sim)["y"], fit.simulate(val["u"])["y"][:, 0], rtol=1e-12)
    truth = structid.Model.from_file(files["model"]).with_truth("N", "tanh(2*z0)")
    path = files["dir"] / "truth.toml"
    truth.save(path)
    sim_truth = files["dir"] / "sim-truth.csv"
    cli("simulate", "--model", path, "--input", files["val"], "--out", sim_truth)
    close(read_csv(sim_truth)["y"], truth.simulate(val["u"])["y"][:, 0], rtol=1e-12)
