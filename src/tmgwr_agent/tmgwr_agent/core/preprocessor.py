"""Sensory preprocessor (section 3.2, Fig. 1a): raw observation -> feature vector.

The agent senses the coordinates of its cell. The preprocessor scales them so that one
sensor resolution step (one cell; in another world the resolution step it declares,
:class:`~tmgwr_agent.core.senses.Senses` ``resolution``, e.g. PointMaze's primitive move)
is ``feature_scale`` apart in feature space, whatever the size of the maze: the map's
thresholds (activity a_T, the goal similarity width) are then expressed per resolution
step and transfer to mazes of any size. Optionally an exponential
moving average filters noisy sensors (``filter_alpha`` < 1; 1 = no filtering); the filter
restarts at every episode start because the agent is moved there, not walked.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from tmgwr_common.params import Config, param


@dataclass(frozen=True)
class PreprocessorConfig(Config):
    feature_scale: float = param(0.1, "feature-space distance of one sensor resolution step "
                                 "(one maze cell)", low=0.0, low_open=True, high=100.0)
    sensor_resolution: float = param(1.0, "sensor units per resolution step, in the world's "
                                     "declared resolution steps (Senses.resolution: 1 cell "
                                     "in the maze simulator)", low=0.0, low_open=True,
                                     high=1e6)
    filter_alpha: float = param(1.0, "EMA weight of the newest observation (1 = no "
                                "filtering)", low=0.0, low_open=True, high=1.0)


class SensoryPreprocessor:
    """x = feature_scale * raw / (sensor_resolution * resolution), optionally EMA-filtered
    (``resolution``: the world's declared resolution step, Senses.resolution)."""

    def __init__(self, config: PreprocessorConfig = PreprocessorConfig(),
                 resolution: float = 1.0):
        self.config = config
        self.gain = config.feature_scale / (config.sensor_resolution * resolution)
        self.feature_scale = config.feature_scale
        self.filter_alpha = config.filter_alpha
        self._state: np.ndarray | None = None

    def __call__(self, raw: np.ndarray, episode_start: bool = False) -> np.ndarray:
        x = self.gain * np.asarray(raw, dtype=float)
        if self.filter_alpha < 1.0 and self._state is not None and not episode_start:
            x = self.filter_alpha * x + (1.0 - self.filter_alpha) * self._state
        self._state = x
        return x

    def goal_features(self, raw_goal: np.ndarray) -> np.ndarray:
        """The goal state in feature space (no filtering: it is not a sensor stream)."""
        return self.gain * np.asarray(raw_goal, dtype=float)
