"""Array types of the simulator: numpy arrays, batch first (shapes are in each docstring)."""

from __future__ import annotations

import numpy as np
from numpy.typing import NDArray

FloatArray = NDArray[np.float64]
"""float64: positions (m), headings (rad), speeds (m/s), field values, rewards."""

BoolArray = NDArray[np.bool_]
"""Masks: active UAVs, collisions, environments to reset."""

IntArray = NDArray[np.int64]
"""Counts and indices: steps per episode."""

Float32Array = NDArray[np.float32]
"""float32: observations, actions, and the sub-step grid of the swept checks."""
