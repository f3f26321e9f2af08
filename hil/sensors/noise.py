"""The errors of a sensing triad (IEEE Std 952-1997, Annex C: the terms of an Allan deviation
plot), drawn from one seeded generator: the same seed gives the same run bit for bit.

A true vector ``v`` reads as ``(I + S) Rᵀ v + b0 + b_gm + b_rw + w``: S the scale factor
errors, R the misalignment's small rotation, b0 the turn-on bias, b_gm the bias instability
(a first-order Gauss-Markov process), b_rw the rate random walk, w the white noise.
"""

from __future__ import annotations

import math

import numpy as np

from hil.bus_config.sensor_types import TriadErrors
from hil.plant import rpy_to_quat

#: IEEE Std 952's bias instability B puts the Allan deviation's floor at 0.664 B
ALLAN_FLOOR = 0.664
#: samples' normal draws taken from the generator at once (a call per sample cost more than
#: the draws; a fixed batch keeps a seed's sequence the same every run)
DRAWS = 256


def gauss_markov_allan_peak() -> float:
    """The peak of the Allan deviation of a first-order Gauss-Markov process of unit standard
    deviation (0.617, near τ = 1.89 of its correlation time), from the closed form of its Allan
    variance, σ²(τ) = 2σ²T/τ · [1 - T/(2τ) (3 - 4e^(-τ/T) + e^(-2τ/T))]."""
    x = np.arange(1, 4000) / 1000.0
    variance = 2.0 / x * (1 - (3 - 4 * np.exp(-x) + np.exp(-2 * x)) / (2 * x))
    return float(math.sqrt(variance.max()))


GAUSS_MARKOV_PEAK = gauss_markov_allan_peak()


def _rotation(angles: tuple[float, float, float]) -> np.ndarray:
    w, x, y, z = rpy_to_quat(angles)
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
        [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
        [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)]])


class TriadNoise:
    """A triad's errors over samples ``period`` s apart."""

    def __init__(self, errors: TriadErrors, period: float, generator: np.random.Generator):
        self._random = generator
        self._gain = np.diag(1.0 + np.array(errors.scale_factor)) @ _rotation(
            errors.misalignment).T
        self._bias = np.array(errors.bias)
        self._white = errors.noise_density / math.sqrt(period)
        # the Gauss-Markov bias: its Allan peak is the floor the config's bias instability sets
        self._decay = math.exp(-period / errors.correlation_time)
        sigma = ALLAN_FLOOR * errors.bias_instability / GAUSS_MARKOV_PEAK
        self._drive = sigma * math.sqrt(1.0 - self._decay ** 2)
        self._drift = sigma * generator.standard_normal(3)       # stationary from the start
        self._walk_step = errors.random_walk * math.sqrt(period)
        self._walk = np.zeros(3)
        self._draws = np.empty((0, 3, 3))      # drawn DRAWS samples at a time
        self._next = 0

    def apply(self, true: np.ndarray) -> np.ndarray:
        """The triad's reading of the ``true`` vector at the next sample."""
        if self._next == len(self._draws):
            self._draws = self._random.standard_normal((DRAWS, 3, 3))
            self._next = 0
        draws = self._draws[self._next]
        self._next += 1
        self._drift = self._decay * self._drift + self._drive * draws[0]
        self._walk += self._walk_step * draws[1]
        return self._gain @ true + self._bias + self._drift + self._walk + self._white * draws[2]
