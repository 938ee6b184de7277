"""Kernels and feature maps written in numpy, plugged into identification.

A Gaussian written in numpy must give the built-in Gaussian's numbers; a feature map must give
the numbers of the kernel ψ(a)ᵀΛψ(b) it defines, solved by another solver; errors raised inside
a callable come back as Python exceptions; estimates on them save, load and pickle with the
kernel supplied again by name.
"""

from __future__ import annotations

import pickle

import numpy as np
import pytest

import structid

SIGMA = 0.3
CUBIC_WEIGHTS = [1.0, 1.0, 0.5, 0.25]


def np_gaussian(a, b, width=SIGMA):
    """The paper's Gaussian (2πσ²)^(−p/2)·exp(−‖a − b‖²/(2σ²)), vectorised."""
    d2 = ((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=2)
    p = a.shape[1]
    return np.exp(-d2 / (2 * width**2)) / (2 * np.pi * width**2) ** (p / 2)


def cubic(z):
    """ψ(z) = [1, z, z², z³]."""
    x = z[:, 0]
    return np.column_stack([np.ones_like(x), x, x**2, x**3])


def cubic_kernel(a, b):
    """ψ(a)ᵀΛψ(b) of :func:`cubic`, as a kernel."""
    return (cubic(a) * CUBIC_WEIGHTS) @ cubic(b).T


@pytest.fixture(scope="module")
def data():
    model = structid.Model.hammerstein(num=[0.0, 0.5, 0.3], den=[1.0, -1.2, 0.5],
                                       dispersion=structid.gaussian(sigma=SIGMA))
    u = 2.0 * np.sin(0.07 * np.arange(300)) + 0.3 * np.cos(0.31 * np.arange(300))
    y = model.with_truth("N", "tanh(2*z0)").simulate(u, noise_std=0.02, seed=3)["y"]
    return model, u, y


def close(a, b, rel):
    a, b = np.asarray(a), np.asarray(b)
    scale = max(np.abs(b).max(), 1e-300)
    assert np.abs(a - b).max() <= rel * scale, np.abs(a - b).max() / scale


def test_a_numpy_gaussian_equals_the_built_in_one(data):
    model, u, y = data
    builtin = structid.identify(model, u, y, beta=1e-4)
    mine = structid.identify(model, u, y, beta=1e-4,
                             dispersion=structid.Kernel(np_gaussian, name="np-gaussian"))
    close(mine.w_hat, builtin.w_hat, 1e-10)
    close(mine.maps["N"].value, builtin.maps["N"].value, 1e-10)
    close(mine.maps["N"].std, builtin.maps["N"].std, 1e-10)
    assert mine.maps["N"].dispersion == "np-gaussian"
    assert mine.report["settings"]["blocks"][0]["kind"] == "user"
    # β chosen by marginal likelihood: the same criterion on the same Gram matrix.
    auto_builtin = structid.identify(model, u, y, beta="auto")
    auto_mine = structid.identify(model, u, y, beta="auto",
                                  dispersion=structid.Kernel(np_gaussian, name="np-gaussian"))
    assert auto_mine.beta == pytest.approx(auto_builtin.beta, rel=1e-8)
    close(auto_mine.w_hat, auto_builtin.w_hat, 1e-8)


def test_a_kernel_with_a_width_takes_sigma(data):
    model, u, y = data
    builtin = structid.identify(model, u, y, beta=1e-4, sigma=0.5)
    k = structid.Kernel(np_gaussian, name="np-gaussian", width=0.1)
    mine = structid.identify(model, u, y, beta=1e-4, sigma=0.5, dispersion=k)
    close(mine.w_hat, builtin.w_hat, 1e-10)
    assert mine.maps["N"].dispersion == "np-gaussian(width=0.5)"


def test_a_feature_map_solves_as_the_kernel_it_defines(data):
    model, u, y = data
    by_features = structid.identify(
        model, u, y, beta=1e-3, dispersion=structid.FeatureMap(cubic, CUBIC_WEIGHTS))
    by_gram = structid.identify(
        model, u, y, beta=1e-3, dispersion=structid.Kernel(cubic_kernel))
    assert by_features.report["diagnostics"]["solver"] != by_gram.report["diagnostics"]["solver"]
    close(by_features.w_hat, by_gram.w_hat, 1e-7)
    close(by_features.maps["N"].value, by_gram.maps["N"].value, 1e-7)


def test_an_exception_in_a_callable_comes_back_as_itself(data):
    model, u, y = data

    def broken(a, b):
        raise KeyError("no such kernel today")

    with pytest.raises(KeyError, match="no such kernel today"):
        structid.identify(model, u, y, beta=1e-4, dispersion=structid.Kernel(broken))

    def wrong_shape(a, b):
        return np.zeros((len(a), len(b) + 1))

    with pytest.raises(ValueError, match="shape"):
        structid.identify(model, u, y, beta=1e-4, dispersion=structid.Kernel(wrong_shape))

    def not_finite(z):
        return np.full((len(z), 2), np.nan)

    with pytest.raises(ValueError, match="non-finite"):
        structid.identify(model, u, y, beta=1e-4,
                          dispersion=structid.FeatureMap(not_finite, [1.0, 1.0]))
    # The next call is clean: nothing of the failures above lingers.
    structid.identify(model, u, y, beta=1e-4, dispersion=structid.Kernel(np_gaussian))


def test_bad_kernel_arguments_are_refused():
    with pytest.raises(structid.StructidError, match="callable"):
        structid.Kernel(3.0)
    with pytest.raises(structid.StructidError, match="weight"):
        structid.FeatureMap(cubic, [1.0, -1.0, 1.0, 1.0])
    with pytest.raises(structid.StructidError, match="width"):
        structid.Kernel(np_gaussian, width=0.0)


def test_an_estimate_on_a_numpy_kernel_predicts_saves_loads_and_pickles(data, tmp_path):
    model, u, y = data
    k = structid.Kernel(np_gaussian, name="np-gaussian")
    fit = structid.identify(model, u, y, beta=1e-4, dispersion=k)
    builtin = structid.identify(model, u, y, beta=1e-4)
    grid = np.linspace(-2, 2, 7)[:, None]
    close(fit.estimate.evaluate("N", grid), builtin.estimate.evaluate("N", grid), 1e-10)
    close(fit.estimate.simulate(u)["y"], builtin.estimate.simulate(u)["y"], 1e-10)
    close(fit.estimate.predict(u, y).predicted, builtin.estimate.predict(u, y).predicted, 1e-10)

    fit.save(tmp_path)
    back = structid.load(tmp_path, kernels=[k])
    np.testing.assert_array_equal(back.estimate.evaluate("N", grid),
                                  fit.estimate.evaluate("N", grid))
    with pytest.raises(structid.StructidError, match="user-defined kernel `np-gaussian`"):
        structid.load(tmp_path)

    again = pickle.loads(pickle.dumps(fit.estimate))
    np.testing.assert_array_equal(again.evaluate("N", grid), fit.estimate.evaluate("N", grid))


def test_a_selected_width_is_kept_through_pickle_and_load(data, tmp_path):
    model, u, y = data
    k = structid.Kernel(np_gaussian, name="np-gaussian", width=0.1)
    fit = structid.identify(model, u, y, beta=1e-4, sigma=0.5, dispersion=k)
    grid = np.linspace(-2, 2, 9)[:, None]
    direct = fit.estimate.evaluate("N", grid)
    again = pickle.loads(pickle.dumps(fit.estimate))
    np.testing.assert_array_equal(again.evaluate("N", grid), direct)
    fit.save(tmp_path)
    back = structid.load(tmp_path, kernels=[k])
    np.testing.assert_array_equal(back.estimate.evaluate("N", grid), direct)


def test_two_blocks_with_kernels_of_their_own():
    exp = structid.paper.spray(samples=300, seed=3)
    f = structid.Kernel(lambda a, b: np_gaussian(a, b, 0.1), name="narrow")
    g = structid.Kernel(lambda a, b: np_gaussian(a, b, 1.0), name="wide")
    fit = structid.identify(exp.model, exp.u, exp.y, beta=1e-3, dispersion={"f": f, "g": g})
    for block in ("f", "g"):
        m = fit.maps[block]
        close(fit.estimate.evaluate(block, m.grid), m.value, 1e-12)
    # Two different callables under one name cannot be told apart in a stored estimate.
    same = structid.Kernel(lambda a, b: np_gaussian(a, b, 1.0), name="narrow")
    with pytest.raises(structid.StructidError, match="named `narrow`"):
        structid.identify(exp.model, exp.u, exp.y, beta=1e-3, dispersion={"f": f, "g": same})


def test_sigma_needs_a_width_to_set(data):
    model, u, y = data
    with pytest.raises(structid.StructidError, match="no width"):
        structid.identify(model, u, y, beta=1e-3, sigma=0.5,
                          dispersion=structid.FeatureMap(cubic, CUBIC_WEIGHTS))


def test_exceptions_stay_with_the_thread_that_caused_them(data):
    import threading
    model, u, y = data
    good = structid.identify(model, u, y, beta=1e-4,
                             dispersion=structid.Kernel(np_gaussian, name="good")).estimate

    state = {"broken": False}

    def flaky(a, b):
        if state["broken"]:
            raise KeyError("flaky kernel")
        return np_gaussian(a, b)

    bad = structid.identify(model, u, y, beta=1e-4,
                            dispersion=structid.Kernel(flaky, name="flaky")).estimate
    state["broken"] = True
    grid = np.linspace(-1, 1, 5)[:, None]
    expected = good.evaluate("N", grid)
    outcomes = {"good": [], "bad": []}

    def run(name, est):
        for _ in range(300):
            try:
                v = est.evaluate("N", grid)
                outcomes[name].append("ok" if name == "bad" or np.array_equal(v, expected)
                                      else "wrong")
            except KeyError:
                outcomes[name].append("raised")

    threads = [threading.Thread(target=run, args=("good", good)),
               threading.Thread(target=run, args=("bad", bad))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert outcomes["good"] == ["ok"] * 300
    assert outcomes["bad"] == ["raised"] * 300
