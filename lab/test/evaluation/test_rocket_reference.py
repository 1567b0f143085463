"""The rocket group's transform against aeon's MiniRocket, the independent reference.

``data/minirocket_aeon.json`` holds aeon 1.6.0's MiniRocket (its fitted
parameters and features) on small seeded integer inputs, recorded by
running aeon on them: aeon pins numba < 0.64 and this package 0.68, so it is
not installed beside it.  When aeon is importable the same comparison also
runs on fresh inputs.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from tactile_descriptors_ros.core import fast, rocket

FIXTURE = json.loads((Path(__file__).parent / "data" / "minirocket_aeon.json").read_text())


def _params(case: dict, n_channels: int, n_samples: int) -> rocket.RocketParameters:
    return rocket.RocketParameters(
        n_channels, n_samples, np.array(case["dilations"]), np.array(case["features_per_dilation"]),
        np.array(case["channels_per_combination"]), np.array(case["channel_indices"]), np.array(case["biases"]))


@pytest.mark.parametrize("backend", ["numba", fast.REFERENCE])
@pytest.mark.parametrize("index", range(len(FIXTURE["transform"])))
def test_transform_equals_aeons_recorded_features(index, backend):
    case = FIXTURE["transform"][index]
    x = np.array(case["input"])
    previous = fast.set_backend(backend)
    try:
        got = rocket.transform(x, _params(case, x.shape[1], x.shape[2]))
    finally:
        fast.set_backend(previous)
    # aeon averages the counts in float32: equal to its rounding, and the counts themselves exactly
    expected = np.array(case["features"])
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-6)
    assert got.shape == expected.shape and np.all((got >= 0) & (got <= 1))


def test_transform_equals_aeon_on_fresh_input():
    aeon = pytest.importorskip("aeon.transformations.collection.convolution_based",
                               reason="aeon is not installed (it pins numba < 0.64, this package 0.68): the "
                                      "recorded features above stand in")
    rng = np.random.default_rng(7)
    for shape in ((6, 22, 100), (4, 1, 400)):
        x = rng.integers(0, 4096, size=shape)
        model = aeon.MiniRocket(n_kernels=336, random_state=1).fit(x.astype(np.float32))
        ncpc, ci, dil, fpd, b = model.parameters
        p = rocket.RocketParameters(shape[1], shape[2], dil.astype(np.int64), fpd.astype(np.int64),
                                    ncpc.astype(np.int64), ci.astype(np.int64), b.astype(np.float64))
        np.testing.assert_allclose(rocket.transform(x, p), np.asarray(model.transform(x.astype(np.float32))),
                                   rtol=0, atol=1e-6)


@pytest.mark.parametrize("case", FIXTURE["dilations"], ids=lambda c: f"{c['n_samples']}x{c['n_features']}")
def test_dilations_equal_aeons(case):
    """aeon's dilations, recorded; where ``2^e`` is an integer aeon's value is its floor of a vectorised power
    (one bit under it on the machine that recorded them: 11 for 12), ours the integer on every machine."""
    d, n = rocket.fit_dilations(case["n_samples"], case["n_features"])
    assert n.tolist() == case["features_per_dilation"] and len(d) == len(case["dilations"])
    per_kernel = case["n_features"] // rocket.N_KERNELS
    exponents = np.linspace(0.0, np.log2((case["n_samples"] - 1) / 8), min(per_kernel, 32))
    integers = {int(round(2.0 ** e)) for e in exponents if abs(2.0 ** e - round(2.0 ** e)) < 1e-9}
    for ours, theirs in zip(d.tolist(), case["dilations"]):
        assert ours == theirs or (ours in integers and theirs == ours - 1), (d.tolist(), case["dilations"])


