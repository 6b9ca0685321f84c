"""The generalist network: one actor (and critic) for every UAV, for any number of vehicles.

A version-2 observation (`sim.observation`) holds the UAV's own block, k neighbour rows and m
intruder rows with masks. The network reads each set with a permutation-invariant encoder (deep
sets): every row through the same two-layer ReLU encoder, then the max and the mean over the
rows the mask keeps. The max is exact in any order (the encodings are ≥ 0, so the masked rows,
zeroed, never win, and an empty set gives 0), and the mean sums the rows' encodings sorted,
so its additions are the same in any order. So neither the number of neighbours or intruders
nor their order matters (the action is the same to the last bit):

    own block → self (ReLU)                                                     h
    each neighbour row → nb1 (ReLU) → nb2 (ReLU), pooled max and mean           2h
    each intruder row → in1 (ReLU) → in2 (ReLU), pooled max and mean            2h
    concat (5h) [+ the action, critic] → l1 (ReLU) → l2 (ReLU) → out          1

The actor's output goes through tanh (a normalised heading change in [−1, 1]); the critic's is
the Q-value. This module is the one definition of the layers (names, shapes) and of the numpy
forward pass that `remarl-fc fly` runs without torch; `policies.generalist` is the same network
in torch, with the same parameter names, and the tests hold the two to each other.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from numpy.typing import NDArray

from sim.observation import INTRUDER_COLUMNS, NEIGHBOUR_COLUMNS, SELF_SIZE, ObservationLayout

SET_LAYERS = ("self", "nb1", "nb2", "in1", "in2", "l1", "l2", "out")
"""Layers of a set network, actor and critic alike: ``<net>.<layer>.weight`` (A, in, out) and
``.bias`` (A, 1, out), A = 1 (one network shared by every UAV)."""

POOLED = 5
"""Blocks of h entries the head reads: self, neighbours' max and mean, intruders' max and mean."""

Layer = tuple[NDArray[np.floating[Any]], NDArray[np.floating[Any]]]
"""(weight (1, in, out), bias (1, 1, out)): float32 as stored, or float64 converted once."""


def set_shapes(hidden: int, critic: bool) -> dict[str, tuple[int, int]]:
    """Layer name → (in, out) of the actor (``critic`` False) or the critic."""
    h = hidden
    return {
        "self": (SELF_SIZE, h),
        "nb1": (NEIGHBOUR_COLUMNS, h),
        "nb2": (h, h),
        "in1": (INTRUDER_COLUMNS, h),
        "in2": (h, h),
        "l1": (POOLED * h + (1 if critic else 0), h),
        "l2": (h, h),
        "out": (h, 1),
    }


def _dense(x: NDArray[np.float64], layer: Layer, relu: bool = True) -> NDArray[np.float64]:
    w, b = layer
    y: NDArray[np.float64] = np.matmul(x, np.asarray(w[0], dtype=np.float64))
    y += b[0, 0]
    if relu:
        np.maximum(y, 0.0, out=y)
    return y


def _pool(
    rows: NDArray[np.float64], mask: NDArray[np.float64], first: Layer, second: Layer
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Max and mean (..., h) of the encodings of the rows (..., R, c) the mask (..., R) keeps."""
    # One matrix product over every row of every UAV (a stacked product costs one call per
    # UAV): each row's encoding is computed alone all the same, wherever it sits.
    flat = rows.reshape(-1, rows.shape[-1])
    h = second[0].shape[-1]
    e = _dense(_dense(flat, first), second).reshape(*rows.shape[:-1], h)  # (..., R, h), ≥ 0
    e *= mask[..., None]
    count = np.maximum(mask.sum(axis=-1, keepdims=True), 1.0)
    if e.shape[-2] == 0:
        zero = np.zeros((*e.shape[:-2], e.shape[-1]))
        return zero, zero.copy()
    # Sorted along the rows before the sum: the same additions in the same order whatever the
    # order of the rows, so the mean is exactly order-free too.
    return e.max(axis=-2), np.sort(e, axis=-2).sum(axis=-2) / count


def encode(
    params: Mapping[str, Layer], obs: NDArray[np.floating[Any]], layout: ObservationLayout
) -> NDArray[np.float64]:
    """(..., 5h) the pooled features of flat version-2 observations (..., D), float64.

    numpy computes in float64 (the weights are float32): a row's encoding then rounds the
    same wherever the row sits in the matrix product, so the order of the rows leaves the
    action unchanged to float32 precision.
    """
    x = np.asarray(obs, dtype=np.float64)
    blocks = layout.blocks()
    k, m = layout.max_neighbours, layout.max_obstacles
    lead = x.shape[:-1]
    own = _dense(x[..., blocks["self"]], params["self"])
    nb = x[..., blocks["neighbours"]].reshape(*lead, k, NEIGHBOUR_COLUMNS)
    nb_max, nb_mean = _pool(nb, x[..., blocks["neighbour_mask"]], params["nb1"], params["nb2"])
    it = x[..., blocks["intruders"]].reshape(*lead, m, INTRUDER_COLUMNS)
    it_max, it_mean = _pool(it, x[..., blocks["intruder_mask"]], params["in1"], params["in2"])
    return np.concatenate([own, nb_max, nb_mean, it_max, it_mean], axis=-1)


def set_actor(
    params: Mapping[str, Layer], obs: NDArray[np.floating[Any]], layout: ObservationLayout
) -> NDArray[np.float32]:
    """Normalised actions (...,) in [−1, 1] of flat version-2 observations (..., D)."""
    h = _dense(_dense(encode(params, obs, layout), params["l1"]), params["l2"])
    out: NDArray[np.float32] = np.tanh(_dense(h, params["out"], relu=False))[..., 0].astype(
        np.float32
    )
    return out


def set_critic(
    params: Mapping[str, Layer],
    obs: NDArray[np.floating[Any]],
    action: NDArray[np.floating[Any]],
    layout: ObservationLayout,
) -> NDArray[np.float32]:
    """Q-values (...,) of normalised actions (...,) at flat version-2 observations (..., D)."""
    a = np.asarray(action, dtype=np.float64)[..., None]
    z = np.concatenate([encode(params, obs, layout), a], axis=-1)
    h = _dense(_dense(z, params["l1"]), params["l2"])
    q: NDArray[np.float32] = _dense(h, params["out"], relu=False)[..., 0].astype(np.float32)
    return q
