"""refine, discover and the paper's spray example: the bindings against the tool."""

from __future__ import annotations

import numpy as np
import pytest

import structid
from conftest import HAMMERSTEIN_TOML, REPO, read_csv, read_json, write_csv


def test_spray_matches_the_demo(cli, tmp_path):
    out = tmp_path / "spray"
    cli("demo", "spray", "--samples", "300", "--seed", "3", "--out", out)
    data = read_csv(out / "data.csv")
    exp = structid.paper.spray(samples=300, seed=3)
    np.testing.assert_array_equal(exp.u[:, 0], data["u"])
    np.testing.assert_array_equal(exp.y[:, 0], data["y"])
    np.testing.assert_array_equal(exp.w_true[:, 0], data["f_true"])
    summary = read_json(out / "summary.json")
    for row in summary["results"]:
        fit = structid.identify(exp.model, exp.u, exp.y, beta=row["beta"])
        centred = lambda a, b: np.sqrt(np.mean(((a - a.mean()) - (b - b.mean())) ** 2))
        np.testing.assert_allclose(centred(fit.w_hat[:, 0], exp.w_true[:, 0]),
                                   row["centred_rms_error_f"], rtol=1e-12)
        np.testing.assert_allclose(centred(fit.w_hat[:, 1], exp.w_true[:, 1]),
                                   row["centred_rms_error_g"], rtol=1e-12)
        np.testing.assert_allclose(fit.cost["total"], row["cost_total"], rtol=1e-12)


def test_refine_matches_the_tool(cli, tmp_path, records):
    # The linear part is off: refinement must move it towards the true one.
    wrong = HAMMERSTEIN_TOML.replace("den = [1.0, -1.2, 0.5]", "den = [1.0, -1.1, 0.45]")
    model_path = tmp_path / "wrong.toml"
    model_path.write_text(wrong)
    est, val = records["estimation"], records["validation"]
    data = write_csv(tmp_path / "data.csv", {"u": est["u"], "y": est["y"]})
    vdata = write_csv(tmp_path / "val.csv", {"u": val["u"], "y": val["y"]})
    out = tmp_path / "refined"
    cli("refine", "--model", model_path, "--data", data, "--validation-data", vdata,
        "--beta", "0.001", "--out", out)
    r = structid.refine(structid.Model.from_file(model_path), est["u"], est["y"],
                        validation=(val["u"], val["y"]), beta=0.001)
    tool = structid.Model.from_file(out / "model.toml")
    assert r.model == tool
    np.testing.assert_allclose(r.fit.w_hat[:, 0], read_csv(out / "estimate.csv")["N"],
                               rtol=1e-12, atol=1e-12)
    report = read_json(out / "report.json")["refinement"]
    assert r.best == report["best"]
    assert len(r.iterations) == len(report["iterations"])
    before = r.iterations[0]["validation_rms"]
    after = r.iterations[r.best]["validation_rms"]
    assert after < before


def test_refine_of_an_lft_model_matches_the_tool(cli, tmp_path, records):
    # An [lft] model whose one map sits at the input of G: refined as that structure, by the
    # tool and by the bindings alike, and written as [linear].
    text = (REPO / "examples" / "models" / "hammerstein.toml").read_text()
    wrong = text.replace("[1.2, -0.5],", "[1.1, -0.4],")
    assert wrong != text
    model_path = tmp_path / "wrong.toml"
    model_path.write_text(wrong)
    est, val = records["estimation"], records["validation"]
    data = write_csv(tmp_path / "data.csv", {"u": est["u"], "y": est["y"]})
    vdata = write_csv(tmp_path / "val.csv", {"u": val["u"], "y": val["y"]})
    out = tmp_path / "refined"
    cli("refine", "--model", model_path, "--data", data, "--validation-data", vdata,
        "--beta", "0.001", "--out", out)
    r = structid.refine(structid.Model.from_file(model_path), est["u"], est["y"],
                        validation=(val["u"], val["y"]), beta=0.001)
    assert r.model == structid.Model.from_file(out / "model.toml")
    assert "[linear]" in r.model.to_toml()
    np.testing.assert_allclose(r.fit.w_hat[:, 0], read_csv(out / "estimate.csv")["N"],
                               rtol=1e-12, atol=1e-12)


def _hammerstein_record(rng, n):
    """A record of the Hammerstein model with N = tanh(2z), from rest, a little noise."""
    u = np.convolve(rng.uniform(-2.0, 2.0, n), np.ones(3) / 3.0, mode="same")
    w = np.tanh(2.0 * u)
    y = np.zeros(n)
    for k in range(n):
        y[k] = (1.2 * y[k - 1] if k >= 1 else 0.0) - (0.5 * y[k - 2] if k >= 2 else 0.0) \
            + (0.5 * w[k - 1] if k >= 1 else 0.0) + (0.3 * w[k - 2] if k >= 2 else 0.0)
    return u, y + 0.05 * rng.standard_normal(n)


@pytest.mark.parametrize("initial_state", ["zero", "estimate"])
def test_refine_over_several_records_matches_the_tool(cli, tmp_path, initial_state):
    """`refine(model, [u1, u2], [y1, y2], validation=([uv1, uv2], [yv1, yv2]))` is
    `structid refine --data a --data b --validation-data c --validation-data d`; its kept
    validation error is the pooled one `Fit.validate([uv1, uv2], [yv1, yv2])` and the tool's
    `validate` compute; and gluing the records is a different problem."""
    wrong = HAMMERSTEIN_TOML.replace("den = [1.0, -1.2, 0.5]", "den = [1.0, -1.1, 0.45]")
    model_path = tmp_path / "wrong.toml"
    model_path.write_text(wrong)
    rng = np.random.default_rng(21)
    recs = [_hammerstein_record(rng, n) for n in (250, 200, 150, 120)]
    paths = [write_csv(tmp_path / f"r{i}.csv", {"u": u, "y": y}) for i, (u, y) in enumerate(recs)]
    out = tmp_path / "refined"
    cli("refine", "--model", model_path, "--data", paths[0], "--data", paths[1],
        "--validation-data", paths[2], "--validation-data", paths[3], "--beta", "0.001",
        "--initial-state", initial_state, "--out", out)
    model = structid.Model.from_file(model_path)
    r = structid.refine(model, [recs[0][0], recs[1][0]], [recs[0][1], recs[1][1]],
                        validation=([recs[2][0], recs[3][0]], [recs[2][1], recs[3][1]]),
                        beta=0.001, initial_state=initial_state)
    assert r.model == structid.Model.from_file(out / "model.toml")
    np.testing.assert_allclose(r.fit.w_hat[:, 0], read_csv(out / "estimate.csv")["N"],
                               rtol=1e-12, atol=1e-12)
    assert r.fit.w_hat.shape[0] == 250 + 200
    report = read_json(out / "report.json")["refinement"]
    assert r.best == report["best"]
    assert len(r.iterations) == len(report["iterations"])
    for mine, tool in zip(r.iterations, report["iterations"]):
        for key in ("cost_after_maps", "estimation_rms", "validation_rms"):
            np.testing.assert_allclose(mine[key], tool[key], rtol=1e-12)
    kept = r.iterations[r.best]["validation_rms"]
    assert kept < r.iterations[0]["validation_rms"]
    # The kept validation error, recomputed: each validation record simulated from rest.
    v = r.fit.validate([recs[2][0], recs[3][0]], [recs[2][1], recs[3][1]])
    assert isinstance(v, structid.RecordsValidation) and len(v.records) == 2
    assert v.samples == 150 + 120
    np.testing.assert_allclose(v.rms[0], kept, rtol=1e-12)
    vout = tmp_path / "validation"
    cli("validate", "--model", out / "model.toml", "--estimate", out, "--data", paths[2],
        "--data", paths[3], "--out", vout)
    overall = read_json(vout / "validation.json")["overall"]["outputs"][0]
    np.testing.assert_allclose(v.rms[0], overall["rms"], rtol=1e-12)
    np.testing.assert_allclose(v.fit_percent[0], overall["fit_percent"], rtol=1e-12)
    for i, rec in enumerate(v.records):
        one = read_json(vout / f"record_{i + 1}" / "validation.json")["outputs"][0]
        np.testing.assert_allclose(rec.rms[0], one["rms"], rtol=1e-12)
    # The glued record is a different problem.
    glued = structid.refine(model, np.concatenate([recs[0][0], recs[1][0]]),
                            np.concatenate([recs[0][1], recs[1][1]]), beta=0.001,
                            initial_state=initial_state)
    assert np.max(np.abs(glued.fit.w_hat[:, 0] - r.fit.w_hat[:, 0])) > 1e-6
    with pytest.raises(structid.StructidError, match="several records"):
        structid.refine(model, [recs[0][0], recs[1][0]], [recs[0][1]], beta=0.001)


@pytest.fixture(scope="module")
def duffing(tmp_path_factory):
    """A nominal linear model that misses a cubic stiffness in feedback from y."""
    num, den = [0.0, 0.2], [1.0, -1.5, 0.7]
    plant = structid.Model.output_feedback(num, den, structid.gaussian(sigma=0.2)) \
        .with_truth("N", "2*z0^3")
    rng = np.random.default_rng(3)

    def record(n, seed):
        u = np.convolve(rng.standard_normal(n), np.ones(4) / 4, mode="same")
        return u, plant.simulate(u, noise_std=0.002, seed=seed)["y"][:, 0]

    (u, y), (uv, yv) = record(1200, 1), record(600, 2)
    nominal = structid.Model.structure("lti", num, den)
    d = tmp_path_factory.mktemp("duffing")
    nominal.save(d / "nominal.toml")
    write_csv(d / "est.csv", {"u": u, "y": y})
    write_csv(d / "val.csv", {"u": uv, "y": yv})
    return nominal, (u, y, uv, yv), d


def test_discover_matches_the_tool(cli, duffing):
    nominal, (u, y, uv, yv), d = duffing
    cli("discover", "--model", d / "nominal.toml", "--data", d / "est.csv", "--validate",
        d / "val.csv", "--out", d / "found")
    report = read_json(d / "found" / "report.json")
    found = structid.discover(nominal, u, y, uv, yv)
    assert found.finding is not None
    assert found.finding.location == "output-feedback"
    assert found.verdict_kind == report["verdict_kind"] == "missing-effect"
    # The linear rival is the tool's: G with one more mode, two more poles than the nominal.
    rival, tool_rival = found.linear_rival, report["linear_rival"]
    assert rival is not None and tool_rival is not None
    np.testing.assert_allclose(rival["validation_rms"], tool_rival["validation_rms"], rtol=1e-12)
    np.testing.assert_allclose(rival["den"], tool_rival["g"]["den"], rtol=1e-12)
    assert len(rival["den"]) == 5
    if rival["p_worse"] is not None:
        np.testing.assert_allclose(rival["p_worse"], tool_rival["comparison"]["p_worse"],
                                   rtol=1e-12)
    tool = {h["location"]: h["validation_rms"] for h in report["hypotheses"]}
    mine = {h["location"]: h["validation_rms"] for h in found.hypotheses}
    assert tool.keys() == mine.keys()
    for k in tool:
        np.testing.assert_allclose(mine[k], tool[k], rtol=1e-12)
    # The augmented model simulates the validation record far better than the nominal one.
    sim = found.finding.estimate.simulate(uv)["y"][:, 0]
    assert np.sqrt(np.mean((sim - yv) ** 2)) < 0.5 * found.nominal_validation_rms
    # The candidate table is the tool's, and its choice follows the rule: the best eligible
    # row is as good as itself, no ineligible row is, the chosen row is as good as the best,
    # and no family as good as the best has fewer parameters than a chosen family.
    rows = found.finding.table
    tool_rows = report["finding"]["candidate_table"]
    assert [r["label"] for r in rows] == [r["label"] for r in tool_rows]
    for mine_row, tool_row in zip(rows, tool_rows):
        np.testing.assert_allclose(mine_row["validation_rms"], tool_row["validation_rms"],
                                   rtol=1e-12)
    eligible = [r for r in rows if r["eligible"]]
    assert min(eligible, key=lambda r: r["validation_rms"])["as_good"]
    assert not any(r["as_good"] for r in rows if not r["eligible"])
    chosen = [r for r in rows if r["chosen"]]
    assert len(chosen) == 1 and chosen[0]["as_good"] and chosen[0]["eligible"]
    for r in rows:
        if r["eligible"] and r["p_worse_than_best"] is not None:
            assert r["as_good"] == (r["p_worse_than_best"] >= 0.05)
    families = [r for r in rows if not r["label"].startswith("nonparametric")]
    if not chosen[0]["label"].startswith("nonparametric"):
        assert all(r["parameters"] >= chosen[0]["parameters"]
                   for r in families if r["as_good"] and r["eligible"])
    assert found.finding.time_varying is False
    # The cubic explains the output: not a poor model, in the tool's report too.
    assert found.finding.poor_model is False
    assert report["finding"]["poor_model"] is False
    with pytest.raises(structid.StructidError, match="significance"):
        structid.discover(nominal, u, y, uv, yv, significance=0.7)


def test_discover_around_a_model_with_maps_and_options_matches_the_tool(cli, duffing):
    """The augmented model of a first discovery (its map known, kept fixed) is a nominal model
    for the next, in the bindings as in the tool, with the tool's options."""
    nominal, (u, y, uv, yv), d = duffing
    first = d / "first"
    cli("discover", "--model", d / "nominal.toml", "--data", d / "est.csv", "--validate",
        d / "val.csv", "--out", first)
    augmented = first / "augmented.toml"
    args = ["--locations", "input,output", "--sigma-fraction", "0.2", "--trend", "2"]
    cli("discover", "--model", augmented, "--data", d / "est.csv", "--validate",
        d / "val.csv", "--out", d / "second", *args)
    report = read_json(d / "second" / "report.json")
    found = structid.discover(structid.Model.from_file(augmented), u, y, uv, yv,
                              locations=["input", "output"], sigma_fraction=0.2, trend=2)
    assert found.verdict_kind == report["verdict_kind"]
    tool = {h["location"]: h["validation_rms"] for h in report["hypotheses"]}
    mine = {h["location"]: h["validation_rms"] for h in found.hypotheses}
    assert set(mine) == set(tool) and set(mine) <= {"input", "output"}
    # The nominal model with its fixed map simulates the validation record as the tool's.
    np.testing.assert_allclose(found.nominal_validation_rms,
                               report["gap_before"]["validation"]["rms"], rtol=1e-12)
    for k in tool:
        np.testing.assert_allclose(mine[k], tool[k], rtol=1e-12)
    with pytest.raises(structid.StructidError, match="sigma_fraction"):
        structid.discover(nominal, u, y, uv, yv, sigma_fraction=-1.0)
    with pytest.raises(structid.StructidError, match="elsewhere"):
        structid.discover(nominal, u, y, uv, yv, locations=["elsewhere"])


def test_discover_on_several_records_matches_the_tool(cli, tmp_path):
    """Two estimation and two validation records, as lists of arrays and as repeated --data
    and --validation-data files: the same hypotheses, finding and per-record gaps."""
    num, den = [0.0, 0.2], [1.0, -1.5, 0.7]
    plant = structid.Model.output_feedback(num, den, structid.gaussian(sigma=0.2)) \
        .with_truth("N", "2*z0^3")
    rng = np.random.default_rng(5)

    def record(n, seed):
        u = np.convolve(rng.standard_normal(n), np.ones(4) / 4, mode="same")
        return u, plant.simulate(u, noise_std=0.002, seed=seed)["y"][:, 0]

    est = [record(700, 11), record(600, 12)]
    val = [record(500, 13), record(400, 14)]
    nominal = structid.Model.structure("lti", num, den)
    nominal.save(tmp_path / "nominal.toml")
    args = ["discover", "--model", tmp_path / "nominal.toml"]
    for flag, recs, name in [("--data", est, "est"), ("--validation-data", val, "val")]:
        for i, (u, y) in enumerate(recs):
            args += [flag, write_csv(tmp_path / f"{name}{i}.csv", {"u": u, "y": y})]
    cli(*args, "--out", tmp_path / "found")
    report = read_json(tmp_path / "found" / "report.json")
    found = structid.discover(nominal, [u for u, _ in est], [y for _, y in est],
                              [u for u, _ in val], [y for _, y in val])
    assert found.finding is not None
    assert found.finding.location == report["finding"]["location"] == "output-feedback"
    tool = {h["location"]: h["validation_rms"] for h in report["hypotheses"]}
    mine = {h["location"]: h["validation_rms"] for h in found.hypotheses}
    assert tool.keys() == mine.keys()
    for k in tool:
        np.testing.assert_allclose(mine[k], tool[k], rtol=1e-12)
    gap = report["gap_before"]["validation"]
    np.testing.assert_allclose(found.nominal_validation_rms, gap["rms"], rtol=1e-12)
    np.testing.assert_allclose(found.extra["nominal_validation_rms_records"],
                               [r["rms"] for r in gap["records"]], rtol=1e-12)
    after = report["finding"]["gap_after"]["validation"]
    np.testing.assert_allclose(found.extra["validation_rms_records"],
                               [r["rms"] for r in after["records"]], rtol=1e-12)
    assert len(found.extra["nominal_estimation_rms_records"]) == 2
    # Lists of different lengths are refused with a clear message.
    with pytest.raises(structid.StructidError, match="lists of arrays"):
        structid.discover(nominal, [est[0][0], est[1][0]], [est[0][1]], val[0][0], val[0][1])


def test_a_backlash_at_the_input_is_reported_with_its_play(cli, tmp_path):
    """A play of half-width 0.3 between the command and G, the nominal G fitted by output error
    to the same record (it absorbs part of the play's lag): discover reports a dynamic effect
    at the input with the play's half-width, as the tool's report.json does."""
    num, den = [0.0, 0.2, 0.1], [1.0, -1.2, 0.5]
    rng = np.random.default_rng(7)

    def record(phase):
        t = np.arange(1500.0)
        u = 1.5 * np.sin(0.013 * t + phase) + 0.5 * np.sin(0.057 * t + 2 * phase)
        b = np.empty_like(u)
        follower = u[0]
        for k, x in enumerate(u):
            follower = min(max(follower, x - 0.3), x + 0.3)
            b[k] = follower
        y = np.zeros_like(u)
        for k in range(len(u)):
            y[k] = sum(num[i] * b[k - i] for i in range(1, 3) if k - i >= 0) \
                - sum(den[i] * y[k - i] for i in range(1, 3) if k - i >= 0)
        return u, y + 0.01 * rng.standard_normal(len(u))

    (u, y), (uv, yv) = record(0.0), record(1.0)
    nominal = structid.linear(u, y, (2, 2, 1), method="oe").model
    found = structid.discover(nominal, u, y, uv, yv)
    assert found.finding is not None
    assert found.finding.location == "input"
    assert found.finding.effect.startswith("dynamic")
    h = found.finding.input_hysteresis
    assert h is not None and h["play"]
    assert abs(h["threshold"] - 0.3) < 0.03
    assert h["validation_rms"] < h["without_hysteresis_rms"] / 2
    nominal.save(tmp_path / "nominal.toml")
    cli("discover", "--model", tmp_path / "nominal.toml",
        "--data", write_csv(tmp_path / "est.csv", {"u": u, "y": y}),
        "--validate", write_csv(tmp_path / "val.csv", {"u": uv, "y": yv}),
        "--out", tmp_path / "found")
    report = read_json(tmp_path / "found" / "report.json")
    np.testing.assert_allclose(report["finding"]["input_hysteresis"]["threshold"],
                               h["threshold"], rtol=1e-12)


def test_discover_effects_matches_the_tool(cli, duffing):
    """``effects=2`` runs the iteration as ``--effects 2`` does: the same steps, the same
    adoption, and the same second-block row where a step's map was re-estimated with one."""
    nominal, (u, y, uv, yv), d = duffing
    cli("discover", "--model", d / "nominal.toml", "--data", d / "est.csv", "--validate",
        d / "val.csv", "--out", d / "effects", "--effects", "2")
    tool = read_json(d / "effects" / "report.json")["effects"]
    found = structid.discover(nominal, u, y, uv, yv, effects=2)
    steps = found.extra["steps"]
    assert len(steps) == len(tool["steps"]) >= 1
    assert steps[0]["adopted"] and "cubic" in steps[0]["effect"]
    for mine, theirs in zip(steps, tool["steps"]):
        assert mine["adopted"] == theirs["adopted"]
        assert (mine["second_block"] is None) == (theirs["second_block"] is None)
        if mine["second_block"] is not None:
            assert mine["second_block"]["site"] == theirs["second_block"]["site"]
            np.testing.assert_allclose(mine["second_block"]["validation_rms"],
                                       theirs["second_block"]["validation_rms"], rtol=1e-12)
    assert found.extra["stop"] == tool["stop_text"]
