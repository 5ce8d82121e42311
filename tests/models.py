"""Touch models with a known answer, for tests of the learned methods."""

import numpy as np

from meshsal.attention import CHANNELS
from meshsal.points.learned import FEATURES, TouchModel


def one_feature_model(name: str) -> TouchModel:
    """A model whose prediction is one feature's value; equal channel weights."""
    coef = np.zeros(len(FEATURES))
    coef[FEATURES.index(name)] = 1.0
    return TouchModel(np.zeros(len(FEATURES)), np.ones(len(FEATURES)), coef, 0.0, dict.fromkeys(CHANNELS, 1.0))
