"""The generalist network: one actor (and critic) for every UAV, for any number of vehicles.

A version-2 observation (`sim.observation`) holds the UAV's own block, k neighbour rows and m
intruder rows with masks. The network reads each set with a permutation-invariant encoder (deep
sets): every row through the same two-layer ReLU encoder, then the max and the mean over the
rows the mask keeps. The max is exact in any order (the encodings are ≥ 0, so the masked rows,
zeroed, never win, and an empty set gives 0); the mean sums the rows in float64, so their order
moves it by float64 rounding (≈ 1e-16). So neither the number of neighbours or intruders nor
their order matters (the action is the same to 1e-15, far inside the 1e-6 the tests ask):

    own block → self (ReLU)                                                     h
    each neighbour row → nb1 (ReLU) → nb2 (ReLU), pooled max and mean           2h
    each intruder row → in1 (ReLU) → in2 (ReLU), pooled max and mean            2h
    concat (5h) [+ the action, critic] → l1 (ReLU) → l2 (ReLU) → out          1

With ``pooling`` "max-attention" the mean of each set gives way to attention pooling: a query
from the self block's features (``nbq``, ``inq``: h → h, no activation) reads the rows'
encodings in `ATTENTION_HEADS` heads, head j taking its h/H channels of every encoding, and
each head's softmax over the kept rows weighs them: a neighbour on a collision course can carry
the pooled feature alone where the mean dilutes it among formation mates that look alike.

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
"""Layers of a set network with max and mean pooling, actor and critic alike:
``<net>.<layer>.weight`` (A, in, out) and ``.bias`` (A, 1, out), A = 1 (one network shared by
every UAV)."""

QUERY_LAYERS = ("nbq", "inq")
"""The attention queries of the neighbour and intruder sets (pooling "max-attention")."""

POOLINGS = ("max-mean", "max-attention")
"""How a set network pools each set: the max and the mean of the rows' encodings (deep sets),
or the max and an attention-weighted sum with a query from the self block."""

ATTENTION_HEADS = 4
"""Heads of the attention pooling: each weighs the rows for h / 4 channels of the encoding."""

POOLED = 5
"""Blocks of h entries the head reads: self, neighbours' max and mean, intruders' max and mean."""

Layer = tuple[NDArray[np.floating[Any]], NDArray[np.floating[Any]]]
"""(weight (1, in, out), bias (1, 1, out)): float32 as stored, or float64 converted once."""


def set_layers(pooling: str = "max-mean") -> tuple[str, ...]:
    """The layers of a set network that pools by ``pooling`` (`POOLINGS`)."""
    if pooling not in POOLINGS:
        raise ValueError(f"pooling must be one of {POOLINGS}, got {pooling!r}")
    return SET_LAYERS if pooling == "max-mean" else (*SET_LAYERS, *QUERY_LAYERS)


def set_shapes(hidden: int, critic: bool, pooling: str = "max-mean") -> dict[str, tuple[int, int]]:
    """Layer name → (in, out) of the actor (``critic`` False) or the critic.

    Attention pooling needs ``hidden`` divisible by `ATTENTION_HEADS`.
    """
    h = hidden
    if pooling == "max-attention" and h % ATTENTION_HEADS:
        raise ValueError(f"attention pooling needs hidden divisible by {ATTENTION_HEADS}, got {h}")
    queries = {name: (h, h) for name in set_layers(pooling) if name in QUERY_LAYERS}
    return {
        "self": (SELF_SIZE, h),
        "nb1": (NEIGHBOUR_COLUMNS, h),
        "nb2": (h, h),
        "in1": (INTRUDER_COLUMNS, h),
        "in2": (h, h),
        "l1": (POOLED * h + (1 if critic else 0), h),
        "l2": (h, h),
        "out": (h, 1),
    } | queries


def _dense(x: NDArray[np.float64], layer: Layer, relu: bool = True) -> NDArray[np.float64]:
    w, b = layer
    y: NDArray[np.float64] = np.matmul(x, np.asarray(w[0], dtype=np.float64))
    y += b[0, 0]
    if relu:
        np.maximum(y, 0.0, out=y)
    return y


def _pool(
    rows: NDArray[np.float64],
    mask: NDArray[np.float64],
    first: Layer,
    second: Layer,
    query: NDArray[np.float64] | None = None,
) -> tuple[NDArray[np.float64], NDArray[np.float64]]:
    """Max and mean (..., h) of the encodings of the rows (..., R, c) the mask (..., R) keeps.

    With a ``query`` (..., h): max and attention (`attend`) instead of the mean.
    """
    # One matrix product over the kept rows of every UAV (a stacked product costs one call
    # per UAV): each row's encoding is computed alone all the same, wherever it sits. A
    # dropped row's encoding is 0 and is never computed: most intruder slots of a swarm are
    # empty (50u8o: 46 of its 400 rows kept, on average), and they were half the actor's time.
    flat = rows.reshape(-1, rows.shape[-1])
    kept = mask.reshape(-1)
    rows_kept = np.flatnonzero(kept)
    h = second[0].shape[-1]
    e = np.zeros((flat.shape[0], h))
    if rows_kept.size:
        e[rows_kept] = _dense(_dense(flat[rows_kept], first), second) * kept[rows_kept, None]
    e = e.reshape(*rows.shape[:-1], h)  # (..., R, h), ≥ 0
    if e.shape[-2] == 0:
        zero = np.zeros((*e.shape[:-2], e.shape[-1]))
        return zero, zero.copy()
    if query is not None:
        return e.max(axis=-2), attend(e, mask, query)
    count = np.maximum(mask.sum(axis=-1, keepdims=True), 1.0)
    # In the rows' order (float64: a permutation moves it by rounding only). Sorting the rows
    # first made it order-exact to the last bit, at half the actor's time for 50 UAVs.
    return e.max(axis=-2), e.sum(axis=-2) / count


def attend(
    e: NDArray[np.float64], mask: NDArray[np.float64], query: NDArray[np.float64]
) -> NDArray[np.float64]:
    """(..., h) the attention pooling of encodings e (..., R, h) under a query (..., h).

    Head j's score of row r is q_j·e_rj / √(h/H) over its h/H channels; the kept rows' softmax
    weighs their channels of head j. Rows the mask drops weigh 0; no kept row gives 0. The
    sums over the rows run in float64 in the rows' order, as the mean's: a permutation moves
    the result by float64 rounding (≈ 1e-16).
    """
    *lead, rows, h = e.shape
    d = h // ATTENTION_HEADS
    heads = e.reshape(*lead, rows, ATTENTION_HEADS, d)
    score = (e * query[..., None, :]).reshape(*lead, rows, ATTENTION_HEADS, d).sum(axis=-1)
    score *= 1.0 / np.sqrt(d)  # (..., R, H)
    score[~np.broadcast_to(mask[..., None] > 0, score.shape)] = -np.inf
    top = score.max(axis=-2, keepdims=True)
    top[~np.isfinite(top)] = 0.0  # no kept row: every weight is exp(−inf) = 0
    weight = np.exp(score - top)
    weight /= np.maximum(weight.sum(axis=-2, keepdims=True), np.finfo(np.float64).tiny)
    pooled: NDArray[np.float64] = np.einsum("...rhd,...rh->...hd", heads, weight)
    return pooled.reshape(*lead, h)


def encode(
    params: Mapping[str, Layer], obs: NDArray[np.floating[Any]], layout: ObservationLayout
) -> NDArray[np.float64]:
    """(..., 5h) the pooled features of flat version-2 observations (..., D), float64.

    ``params`` holding the query layers (`QUERY_LAYERS`) pool by max and attention, else by
    max and mean.

    numpy computes in float64 (the weights are float32): a row's encoding then rounds the
    same wherever the row sits in the matrix product, so the order of the rows leaves the
    action unchanged to float32 precision.
    """
    x = np.asarray(obs, dtype=np.float64)
    blocks = layout.blocks()
    k, m = layout.max_neighbours, layout.max_obstacles
    lead = x.shape[:-1]
    own = _dense(x[..., blocks["self"]], params["self"])
    attention = "nbq" in params  # the layers a network holds say how it pools
    nb_q = _dense(own, params["nbq"], relu=False) if attention else None
    it_q = _dense(own, params["inq"], relu=False) if attention else None
    nb = x[..., blocks["neighbours"]].reshape(*lead, k, NEIGHBOUR_COLUMNS)
    nb_max, nb_mean = _pool(
        nb, x[..., blocks["neighbour_mask"]], params["nb1"], params["nb2"], nb_q
    )
    it = x[..., blocks["intruders"]].reshape(*lead, m, INTRUDER_COLUMNS)
    it_max, it_mean = _pool(it, x[..., blocks["intruder_mask"]], params["in1"], params["in2"], it_q)
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
