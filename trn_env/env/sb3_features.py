"""A stable-baselines3 features extractor for `TerrainNavEnv`: every observation element mapped to [-1, 1]
by the observation space's bounds (the env's documented per-element min/max).

The raw elements span very different ranges (goal offsets in km up to 300, sines in [-1, 1], log10 sigmas
up to 8); fed as they are, the large ones saturate the first tanh layer. The fixed affine map keeps the
policy a function of the raw observation (no running statistics to save beside the model, unlike
`VecNormalize`), so a saved model evaluates on a plain env. Needs the `rl` extra (torch, sb3).
"""

from __future__ import annotations

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor


class BoundsScaledExtractor(BaseFeaturesExtractor):
    """obs -> 2 (obs - low) / (high - low) - 1, element by element (a Box with finite bounds)."""

    def __init__(self, observation_space: spaces.Box):
        low = np.asarray(observation_space.low, np.float64)
        high = np.asarray(observation_space.high, np.float64)
        if low.ndim != 1 or not (np.all(np.isfinite(low)) and np.all(np.isfinite(high))) \
                or np.any(high <= low):
            raise ValueError("BoundsScaledExtractor needs a 1-D Box with finite bounds, high > low")
        super().__init__(observation_space, features_dim=low.size)
        self.register_buffer("_scale", torch.as_tensor(2.0 / (high - low), dtype=torch.float32))
        self.register_buffer("_offset", torch.as_tensor(-1.0 - 2.0 * low / (high - low), dtype=torch.float32))

    def forward(self, observations: torch.Tensor) -> torch.Tensor:
        return observations.float() * self._scale + self._offset


__all__ = ["BoundsScaledExtractor"]
