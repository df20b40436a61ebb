"""
Small fully connected networks: scikit-learn's MLP to train, numpy to evaluate.

A Network standardises its inputs, column by column, and its outputs by one spread (the
MLP's weight penalty is set against a loss of order one: outputs in metres, of order 1e-2,
would leave it nothing to fit; one spread keeps their relative weights as given) and
trains by L-BFGS (full-batch quasi-Newton: at some thousands of points it trains in seconds
where stochastic solvers need tuning). Evaluating through scikit-learn costs some 100 us a
call in input checks; a Network runs the same arithmetic in numpy, a few microseconds for
one input, so it is as quick to call one input at a time as in batch.
"""

import warnings

import numpy as np
from sklearn.exceptions import ConvergenceWarning
from sklearn.neural_network import MLPRegressor

ACTIVATIONS = {'tanh': np.tanh, 'relu': lambda x: np.maximum(x, 0.0),
               'logistic': lambda x: 1.0 / (1.0 + np.exp(-x)), 'identity': lambda x: x}


class Network:
    """Inputs (i,) -> outputs (o,): hidden layers of the given widths, then linear."""

    def __init__(self, layers, activation='tanh', seed=0, max_iterations=5000):
        """
        Set up an untrained network.

        :param layers: hidden layer widths
        :param activation: 'tanh', 'relu' or 'logistic' (sigmoid)
        :param seed: its initial weights
        :param max_iterations: L-BFGS iterations at most
        """
        self.mlp = MLPRegressor(hidden_layer_sizes=tuple(layers), activation=activation,
                                solver='lbfgs', max_iter=max_iterations, tol=1e-7,
                                random_state=seed)
        self.hidden = ACTIVATIONS[activation]

    def fit(self, inputs, outputs):
        """Train on (N, i) inputs and (N, o) outputs; return self."""
        inputs, outputs = np.asarray(inputs, float), np.asarray(outputs, float)
        self.inputs = inputs.mean(axis=0), _spread(inputs)
        # one spread for every output: each keeps its weight in the loss, as given
        self.outputs = outputs.mean(axis=0), max(float(outputs.std()), 1e-300)
        with warnings.catch_warnings():   # L-BFGS ending on its budget is the plan, not news
            warnings.simplefilter('ignore', ConvergenceWarning)
            self.mlp.fit(self._standard(inputs, self.inputs),
                         self._standard(outputs, self.outputs))
        return self

    def __call__(self, inputs):
        """Return (N, o) outputs of (N, i) or (i,) inputs."""
        x = self._standard(np.atleast_2d(inputs), self.inputs)
        weights, biases = self.mlp.coefs_, self.mlp.intercepts_
        for w, b in zip(weights[:-1], biases[:-1]):
            x = self.hidden(x @ w + b)
        mean, spread = self.outputs
        return (x @ weights[-1] + biases[-1]) * spread + mean

    @staticmethod
    def _standard(values, scaling):
        mean, spread = scaling
        return (values - mean) / spread


def _spread(values):
    """Return each column's standard deviation (1 where a column does not vary)."""
    spread = values.std(axis=0)
    return np.where(spread > 0.0, spread, 1.0)
