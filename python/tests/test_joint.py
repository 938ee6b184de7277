"""The joint fit by simulation error from Python: a play and a map in series, simulated here
with numpy (independently of the bindings), fitted from a wrong start, and the same numbers
as `structid refine --joint` on the same files."""

from __future__ import annotations

import numpy as np
import pytest

import structid
from conftest import read_json, write_csv

# y = G·sat(play(u)): the saturation reads the play's output through D_zw.
TRUTH = """
[lft]
A = [[0.85]]
Bu = [[0.0]]
Be = [[0.0]]
Bw = [[0.0, 0.15]]
Cy = [[1.0]]
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[0.0, 0.0]]
Cz = [[0.0], [0.0]]
Dzu = [[1.0], [0.0]]
Dze = [[0.0], [0.0]]
Dzw = [[0.0, 0.0], [1.0, 0.0]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "backlash"
inputs = [0]
output = 0
operator = { kind = "play", half_width = 0.2 }

[[nonlinearity]]
name = "limit"
inputs = [1]
output = 1
truth = "0.8*tanh(z0/0.8)"
"""

START = (TRUTH.replace("A = [[0.85]]", "A = [[0.75]]")
         .replace("half_width = 0.2", "half_width = 0.05")
         .replace('truth = "0.8*tanh(z0/0.8)"\n', ""))


def plant(u: np.ndarray) -> np.ndarray:
    """The truth written out: play from rest at u[0], saturation, first-order G."""
    x, b, y = 0.0, u[0], np.zeros(len(u))
    for k, uk in enumerate(u):
        b = min(max(b, uk - 0.2), uk + 0.2)
        w1 = 0.8 * np.tanh(b / 0.8)
        y[k] = x
        x = 0.85 * x + 0.15 * w1
    return y


def inputs(n: int, phase: float) -> np.ndarray:
    t = np.arange(n, dtype=float)
    return 1.2 * (np.sin(0.011 * t + phase) * np.cos(0.053 * t) + 0.4 * np.sin(0.0071 * t + 1.0))


def test_the_bindings_simulate_an_operator_model_as_written_out_in_numpy():
    u = inputs(500, 0.0)
    sim = structid.Model.from_toml(TRUTH).simulate(u.reshape(-1, 1))
    np.testing.assert_allclose(sim["y"][:, 0], plant(u), rtol=0, atol=1e-12)


def test_refine_joint_recovers_the_play_and_agrees_with_the_cli(cli, tmp_path):
    u, v = inputs(3000, 0.0), inputs(1500, 1.3)
    est = write_csv(tmp_path / "est.csv", {"u": u, "y": plant(u)})
    val = write_csv(tmp_path / "val.csv", {"u": v, "y": plant(v)})
    start = tmp_path / "start.toml"
    start.write_text(START)
    out = tmp_path / "cli"
    cli("refine", "--joint", "--model", start, "--data", est, "--validation-data", val,
        "--free", "A", "--initial-state", "estimate", "--out", out)
    r = structid.refine_joint(structid.Model.from_toml(START), u, plant(u),
                              validation=(v, plant(v)), free=["A"], initial_state="estimate",
                              out=tmp_path / "py")
    j = read_json(out / "joint.json")
    assert r.beta == j["beta"]
    np.testing.assert_allclose(r.cost, j["cost"], rtol=1e-12)
    np.testing.assert_allclose([f[3] for f in r.free], [f["value"] for f in j["free"]], rtol=1e-12)
    pole = r.free[0][3]
    assert abs(pole - 0.85) < 0.01
    assert r.cost <= r.initial_cost
    assert (tmp_path / "py" / "model.toml").read_text() == (out / "model.toml").read_text()
    # The fitted model simulates the validation record close to the truth.
    sim = r.model.simulate(v.reshape(-1, 1))
    assert np.sqrt(np.mean((sim["y"][:, 0] - plant(v)) ** 2)) < 0.02
    # It has no one-step predictor, and is scored by its simulation as `structid validate` does.
    assert "hysteresis operator" in r.model.why_simulation_only()
    assert [a[1] for a in r.model.block_access()] == ["computable", "in series"]
    score = r.model.score_simulation(v.reshape(-1, 1), plant(v).reshape(-1, 1))
    np.testing.assert_allclose(score["y_sim"][:, 0], sim["y"][:, 0], rtol=0, atol=1e-12)
    expected = np.sqrt(np.mean((plant(v) - sim["y"][:, 0]) ** 2))
    np.testing.assert_allclose(score["rms"][0], expected, rtol=1e-12)
    cli("validate", "--model", out / "model.toml", "--data", val, "--out", tmp_path / "v")
    j = read_json(tmp_path / "v" / "validation.json")
    assert j["prediction"] is None and "operator" in j["why_no_prediction"]


def test_a_named_family_is_fitted_from_python_and_written_back_with_its_parameter():
    # The sensor law s·tanh(z/s) with the level s as a parameter, starting from s = 0.4.
    family = TRUTH.replace('truth = "0.8*tanh(z0/0.8)"',
                           'truth = "s*tanh(z0/s)"\nparameters = { s = 0.4 }')
    u = inputs(3000, 0.0)
    r = structid.refine_joint(structid.Model.from_toml(family), u, plant(u), beta=1e-6)
    text = r.model.to_toml()
    line = next(l for l in text.splitlines() if l.startswith("parameters"))
    s = float(line.split("{ s = ")[1].rstrip(" }"))
    assert abs(s - 0.8) < 0.01 * 0.8, line
    assert r.cost <= r.initial_cost


def test_a_declared_shape_is_kept_beyond_the_data_as_in_the_cli(cli, tmp_path):
    # The saturation declared increasing and started from nothing: the fitted map is increasing
    # well beyond the range the data cover, and the CLI gives the same fit.
    shaped = TRUTH.replace('truth = "0.8*tanh(z0/0.8)"', 'shape = "increasing"')
    model = structid.Model.from_toml(shaped)
    # The same declaration made from Python, and refused where the file would refuse it.
    unshaped = structid.Model.from_toml(TRUTH.replace('truth = "0.8*tanh(z0/0.8)"\n', ""))
    assert unshaped.with_shape("limit", "increasing").to_toml() == model.to_toml()
    assert model.with_shape("limit", None).blocks[1]["shape"] is None
    with pytest.raises(structid.StructidError, match="hysteresis operator has no static shape"):
        model.with_shape("backlash", "increasing")
    with pytest.raises(structid.StructidError, match="upwards"):
        model.with_shape("limit", "upwards")
    assert model.blocks[1]["shape"] == "increasing" and model.blocks[0]["shape"] is None
    u = inputs(2000, 0.0)
    r = structid.refine_joint(model, u, plant(u), beta=1e-8, out=tmp_path / "py")
    est = write_csv(tmp_path / "est.csv", {"u": u, "y": plant(u)})
    start = tmp_path / "start.toml"
    start.write_text(shaped)
    cli("refine", "--joint", "--model", start, "--data", est, "--beta", "1e-8",
        "--out", tmp_path / "cli")
    np.testing.assert_allclose(r.cost, read_json(tmp_path / "cli" / "joint.json")["cost"],
                               rtol=1e-12)
    assert r.cost <= 1e-3 * r.initial_cost
    table = np.loadtxt(tmp_path / "py" / "map_limit.csv", delimiter=",", skiprows=1)
    assert np.all(np.diff(table[:, 1]) >= 0)
    assert 'shape = "increasing"' in r.model.to_toml()
    # Identification by the dispersion criterion cannot keep a shape, and says so.
    static = structid.Model.from_toml("""
[lft]
A = []
Dye = [[1.0]]
Dyw = [[1.0]]
Dzu = [[1.0]]
[signals]
u = ["u"]
y = ["y"]
[[nonlinearity]]
name = "f"
inputs = [0]
output = 0
shape = "increasing"
""")
    with pytest.raises(structid.StructidError, match="shape.*joint fit"):
        structid.identify(static, u, np.tanh(u))


INTEGRATOR = """
[lft]
A = [[1.0]]
Bu = [[0.0]]
Be = [[0.0]]
Bw = [[0.05]]
Cy = [[1.0]]
Dyu = [[0.0]]
Dye = [[1.0]]
Dyw = [[0.0]]
Cz = [[0.0]]
Dzu = [[1.0]]
Dze = [[0.0]]
Dzw = [[0.0]]

[signals]
u = ["u"]
y = ["y"]

[[nonlinearity]]
name = "N"
inputs = [0]
output = 0
"""


def test_an_integrating_plant_is_fitted_in_windows_as_in_the_cli(cli, tmp_path):
    # y = (0.05·q⁻¹/(1 − q⁻¹))·tanh(2u), written out in numpy; its free run drifts, so the fit
    # is by the score of windows, and the CLI gives the same numbers.
    u = inputs(1600, 0.3)
    w = np.tanh(2.0 * u)
    y = np.concatenate([[0.0], 0.05 * np.cumsum(w)[:-1]])
    y = y + 0.005 * np.sin(2.9 * np.arange(len(u)))
    model = structid.Model.from_toml(INTEGRATOR)
    r = structid.refine_joint(model, u, y, beta=1e-8, windows=(200, 20))
    assert r.stages[0][0] == "windows" and r.cost <= r.initial_cost
    est = write_csv(tmp_path / "est.csv", {"u": u, "y": y})
    start = tmp_path / "start.toml"
    start.write_text(INTEGRATOR)
    cli("refine", "--joint", "--model", start, "--data", est, "--beta", "1e-8",
        "--windows", "200:20", "--out", tmp_path / "cli")
    np.testing.assert_allclose(r.cost, read_json(tmp_path / "cli" / "joint.json")["cost"],
                               rtol=1e-12)
    with pytest.raises(structid.StructidError, match="windows"):
        structid.refine_joint(model, u, y, beta=1e-8, windows=(200, 20), segment_length=50)
    with pytest.raises(structid.StructidError, match="pair"):
        structid.refine_joint(model, u, y, beta=1e-8, windows=(200,))


def test_refine_joint_errors_are_python_exceptions():
    model = structid.Model.from_toml(START)
    u = inputs(200, 0.0)
    with pytest.raises(structid.StructidError, match="needs a β"):
        structid.refine_joint(model, u, plant(u))
    with pytest.raises(structid.StructidError, match="free entry `Q"):
        structid.refine_joint(model, u, plant(u), beta=1e-6, free=["Q[0][0]"])


def wiener_hammerstein_plant(u: np.ndarray) -> np.ndarray:
    """x₁⁺ = 0.8x₁ + 0.2u, w = tanh(1.5x₁), x₂⁺ = 0.5x₂ + 0.5w, y = x₂, written out."""
    x1, x2, y = 0.0, 0.0, np.zeros(len(u))
    for k, uk in enumerate(u):
        y[k] = x2
        w = np.tanh(1.5 * x1)
        x1, x2 = 0.8 * x1 + 0.2 * uk, 0.5 * x2 + 0.5 * w
    return y


def test_wiener_hammerstein_finds_both_blocks_and_agrees_with_the_cli(cli, tmp_path):
    rng = np.random.default_rng(11)
    u = np.convolve(rng.uniform(-1, 1, 2000), [1.2, 0.6, 0.3], mode="same")
    v = np.convolve(rng.uniform(-1, 1, 1000), [1.2, 0.6, 0.3], mode="same")
    y = wiener_hammerstein_plant(u) + 0.005 * rng.standard_normal(len(u))
    est = write_csv(tmp_path / "est.csv", {"u": u, "y": y})
    r = structid.wiener_hammerstein(u, y, (2, 1, 2), out=tmp_path / "py")
    cli("wiener-hammerstein", "--data", est, "--orders", "2,1,2", "--out", tmp_path / "cli")
    j = read_json(tmp_path / "cli" / "joint.json")
    np.testing.assert_allclose(r.cost, j["cost"], rtol=1e-12)
    assert (tmp_path / "py" / "model.toml").read_text() == (tmp_path / "cli" / "model.toml").read_text()
    # The pole 0.8 is put in front, and the fit ends at the noise.
    assert len(r.divisions) == 4
    assert abs(r.divisions[0]["front"][1][1] + 0.8) < 0.05
    assert r.rms[0] < 1.5 * 0.005
    sim = r.model.simulate(v.reshape(-1, 1))
    assert np.sqrt(np.mean((sim["y"][:, 0] - wiener_hammerstein_plant(v)) ** 2)) < 0.005
    with pytest.raises(structid.StructidError, match="three whole numbers"):
        structid.wiener_hammerstein(u, y, (2, 1))


def test_hammerstein_wiener_fits_both_maps_and_agrees_with_the_cli(cli, tmp_path):
    def plant(u: np.ndarray) -> np.ndarray:
        x, y = 0.0, np.zeros(len(u))
        for k, uk in enumerate(u):
            y[k] = 0.8 * np.tanh(x / 0.8) + 0.2 * x
            x = 0.7 * x + 0.3 * np.tanh(1.2 * uk)
        return y
    rng = np.random.default_rng(21)
    u = np.convolve(rng.uniform(-1.5, 1.5, 2000), [1.0, 0.5], mode="same")
    v = np.convolve(rng.uniform(-1.5, 1.5, 1000), [1.0, 0.5], mode="same")
    y = plant(u) + 0.005 * rng.standard_normal(len(u))
    est = write_csv(tmp_path / "est.csv", {"u": u, "y": y})
    r = structid.hammerstein_wiener(u, y, (1, 1, 1), out=tmp_path / "py")
    cli("hammerstein-wiener", "--data", est, "--orders", "1,1,1", "--out", tmp_path / "cli")
    assert (tmp_path / "py" / "model.toml").read_text() == (tmp_path / "cli" / "model.toml").read_text()
    assert r.divisions == [] and r.rms[0] < 1.5 * 0.005
    assert [b[0] for b in r.model.block_access()] == ["input", "output"]
    sim = r.model.simulate(v.reshape(-1, 1))
    assert np.sqrt(np.mean((sim["y"][:, 0] - plant(v)) ** 2)) < 0.005
    with pytest.raises(structid.StructidError, match="channel"):
        structid.hammerstein_wiener(np.c_[u, u], y, (1, 1, 1))


def test_a_chain_of_sites_builds_series_and_latent_blocks_as_written_out_in_numpy():
    # G = q⁻¹/(1 − 0.6q⁻¹); an input map around output feedback: y = G·(N₂(u) − N₁(y)).
    m = structid.Model.structure(["output-feedback", "input"], [0.0, 1.0], [1.0, -0.6],
                                 name=["spring", "actuator"])
    assert [b["name"] for b in m.blocks] == ["spring", "actuator"]
    assert [a[1] for a in m.block_access()] == ["computable", "computable"]
    u = inputs(200, 0.3)
    m = m.with_truth("spring", "0.5*z0^3").with_truth("actuator", "tanh(z0)")
    x, y = 0.0, np.zeros(len(u))
    for k, uk in enumerate(u):
        y[k] = x
        x = 0.6 * x + np.tanh(uk) - 0.5 * y[k] ** 3
    np.testing.assert_allclose(m.simulate(u.reshape(-1, 1))["y"][:, 0], y, rtol=0, atol=1e-12)
    # Hammerstein–Wiener: the sensor reads G's output, which u reveals once the actuator is known.
    hw = structid.Model.structure(["input", "output"], [0.0, 1.0], [1.0, -0.6])
    assert [b["name"] for b in hw.blocks] == ["N1", "N2"]
    # Identification by the dispersion cannot reach maps in series; the error says what can.
    with pytest.raises(structid.StructidError, match=r"hint: `structid\.refine_joint`"):
        structid.identify(hw, u, y, beta=0.01)
    with pytest.raises(ValueError, match="names and dispersions"):
        structid.Model.structure(["input", "output"], [0.0, 1.0], [1.0, -0.6], name="N")
    with pytest.raises(ValueError, match="lti"):
        structid.Model.structure(["lti", "input"], [0.0, 1.0], [1.0, -0.6])
