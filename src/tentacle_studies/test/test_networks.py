"""Small networks: numpy's forward pass is scikit-learn's; outputs in metres are learnt."""

import numpy as np
from tentacle_studies.networks import Network
from tentacle_studies.surrogate import Surrogate


def test_the_numpy_pass_is_scikit_learns_predict():
    rng = np.random.default_rng(0)
    inputs = rng.normal(3.0, 2.0, (200, 4))
    outputs = np.column_stack([np.sin(inputs[:, 0]), inputs[:, 1] * inputs[:, 2]]) * 1e-3
    network = Network((8, 8), max_iterations=50).fit(inputs, outputs)
    new = rng.normal(3.0, 2.0, (30, 4))
    mean, spread = network.inputs
    scaled = network.mlp.predict((new - mean) / spread)
    mean, spread = network.outputs
    np.testing.assert_allclose(network(new), scaled * spread + mean, rtol=1e-12, atol=1e-15)
    np.testing.assert_allclose(network(new[0]), network(new)[:1], rtol=1e-12, atol=1e-15)


def test_outputs_in_metres_are_learnt_not_flattened_by_the_weight_penalty():
    rng = np.random.default_rng(1)
    angles = rng.uniform(-np.pi, np.pi, (600, 2))

    def tip_m(a):   # of the order of a tentacle's deflections: centimetres
        return 0.02 * np.column_stack([np.sin(a[:, 0]) + 0.5 * np.cos(a[:, 1]),
                                       np.cos(a[:, 0] - a[:, 1])])

    surrogate = Surrogate((16, 16), max_iterations=500).fit(angles[:500], tip_m(angles[:500]))
    error = surrogate(angles[500:]) - tip_m(angles[500:])
    assert np.sqrt(np.mean(error ** 2)) < 0.02 * 0.02   # under 2% of the outputs' scale
    turned = angles[500:] + 2 * np.pi                  # a turn is a turn
    np.testing.assert_allclose(surrogate(turned), surrogate(angles[500:]), atol=1e-12)
