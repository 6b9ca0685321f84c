"""Policy files are verified before they fly: format, schema, checksum, finite in-range weights.

Every bad file is a `PolicyError` with a one-line message that says what to do, never another
exception. Synthetic policies are built in numpy (no torch): the 2u1o scenario, 4 hidden units;
generalists (a set network for 1 to 50 UAVs, k = 6, m = 8) on the 3u2o scenario. Zoo files
(schema 1) load and act as before.
"""

from __future__ import annotations

import contextlib
import hashlib
import json
import math
import re
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from safetensors.numpy import load_file, save_file
from tiny_policy import (
    DELETE,
    changed_tensors,
    mutate,
    tiny_generalist_meta,
    tiny_generalist_tensors,
    tiny_meta,
    tiny_tensors,
    write_tiny_generalist,
)

from remarl_fc.errors import PolicyError, PolicySpecMismatch, PolicyUavRangeMismatch
from remarl_fc.policy_io import (
    PolicyChecksumFailed,
    PolicyFileInvalid,
    load_policy,
    zoo_dir,
    zoo_names,
)
from sim.observation import build_observations
from sim.policy_file import (
    CHECKSUM_KEY,
    METADATA_KEY,
    REQUIRED_KEYS,
    WEIGHT_BOUND,
    metadata_problems,
    policy_checksum,
    verify_policy,
)
from sim.scenarios import load_scenario, scenario_names
from sim.setnet import set_actor, set_critic
from sim.swarm import SwarmSim

# ------------------------------------------------------------------------------------ helpers


def write(path: Path, tensors: dict[str, np.ndarray], meta: Any, *, sign: bool = True) -> Path:
    """A policy file; ``sign`` computes the checksum over whatever ``meta`` holds (so a bad
    value can be "validly signed")."""
    if sign and isinstance(meta, dict):
        meta = {k: v for k, v in meta.items() if k != CHECKSUM_KEY}
        with contextlib.suppress(ValueError):  # NaN in the metadata: left unsigned
            meta[CHECKSUM_KEY] = policy_checksum(tensors, meta)
    save_file(tensors, str(path), metadata={METADATA_KEY: json.dumps(meta)})
    return path


@pytest.fixture
def good(tmp_path):
    meta = tiny_meta()
    tensors = tiny_tensors(meta)
    return write(tmp_path / "good.safetensors", tensors, meta), tensors, meta


GOOD_META = tiny_meta()
GOOD_TENSORS = tiny_tensors(GOOD_META)
GENERALIST_META = tiny_generalist_meta(hidden=4)
GOOD_FILES = {  # kind → (metadata, tensors): a zoo-like MLP, a generalist
    "mlp": (GOOD_META, GOOD_TENSORS),
    "generalist": (GENERALIST_META, tiny_generalist_tensors(GENERALIST_META)),
}


def one_line(exc: BaseException) -> str:
    text = str(exc)
    assert "\n" not in text and text.strip() == text
    return text


# --------------------------------------------------------------------------------- good files


@pytest.mark.parametrize("name", zoo_names())
def test_every_zoo_policy_loads_and_verifies(name):
    policy = load_policy(name)
    assert policy.checksum.startswith("sha256:")
    tensors = load_file(str(zoo_dir() / f"{name}.safetensors"))
    assert policy_checksum(tensors, policy.meta) == policy.checksum
    verify_policy(tensors, policy.meta)
    assert max(float(np.abs(t).max()) for t in tensors.values()) < WEIGHT_BOUND / 100


def test_the_checksum_recipe_is_the_documented_one():
    """An independent implementation of the recipe gives the zoo's checksum (format pinned)."""
    path = zoo_dir() / "2u1o.safetensors"
    tensors = load_file(str(path))
    meta = load_policy(path).meta
    h = hashlib.sha256(b"remarl-fc policy checksum v1\n")
    for name in sorted(tensors):
        arr = tensors[name]
        head = json.dumps(
            {"dtype": "<f4", "name": name, "shape": list(arr.shape)}, separators=(",", ":")
        ).encode()
        data = arr.astype("<f4").tobytes(order="C")
        h.update(struct.pack("<Q", len(head)) + head + struct.pack("<Q", len(data)) + data)
    rest = {k: v for k, v in meta.items() if k != "checksum"}
    m = json.dumps(rest, sort_keys=True, separators=(",", ":"), allow_nan=False).encode()
    h.update(struct.pack("<Q", len(m)) + m)
    assert meta["checksum"] == "sha256:" + h.hexdigest()


def test_a_synthetic_policy_loads_and_acts(good):
    path, tensors, meta = good
    policy = load_policy(path)
    assert policy.agents == 2 and policy.critic
    assert policy.checksum == policy_checksum(tensors, meta)
    assert policy.act(np.zeros((5, 2, policy.layout.size))).shape == (5, 2)
    assert policy.q_values(np.zeros((2, policy.layout.size)), np.zeros(2)).shape == (2,)
    assert policy.actor["l1"][0].tobytes() == tensors["actor.l1.weight"].tobytes()


def test_a_shared_policy_without_critic_loads(tmp_path):
    meta = tiny_meta(shared=True)
    tensors = {k: v for k, v in tiny_tensors(meta).items() if k.startswith("actor.")}
    assert tensors["actor.l1.weight"].shape[0] == 1
    policy = load_policy(write(tmp_path / "s.safetensors", tensors, meta))
    assert policy.critic == {}
    assert policy.act(np.zeros((2, policy.layout.size))).shape == (2,)


# -------------------------------------------------------------------------- format, checksum


def test_a_file_without_checksum_says_how_to_add_one(tmp_path, good):
    _, tensors, meta = good
    path = write(tmp_path / "old.safetensors", tensors, meta, sign=False)
    with pytest.raises(PolicyChecksumFailed) as info:
        load_policy(path)
    text = one_line(info.value)
    assert info.value.kind == "unsigned"
    assert "older" in text and f"python -m policies.export --rehash {path}" in text


def test_a_damaged_checksum_key_is_not_mistaken_for_an_old_file(good):
    path, _, _ = good
    raw = path.read_bytes()
    assert raw.count(b'\\"checksum\\"') == 1
    path.write_bytes(raw.replace(b'\\"checksum\\"', b'\\"checksuM\\"'))
    with pytest.raises(PolicyFileInvalid, match="checksuM: unknown key") as info:
        load_policy(path)
    assert info.value.kind == "schema"


@pytest.fixture(scope="module")
def tiny_file_bytes(tmp_path_factory):
    meta = tiny_meta()
    path = write(tmp_path_factory.mktemp("tiny") / "t.safetensors", tiny_tensors(meta), meta)
    data = path.read_bytes()
    return data, 8 + struct.unpack("<Q", data[:8])[0]  # bytes, start of the tensor data


def flipped(data: bytes, offset: int, bit: int) -> bytes:
    out = bytearray(data)
    out[offset] ^= 1 << bit
    return bytes(out)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_a_bit_flip_in_the_tensor_data_is_a_checksum_error(tmp_path_factory, tiny_file_bytes, data):
    raw, start = tiny_file_bytes
    offset = data.draw(st.integers(start, len(raw) - 1), label="offset")
    bit = data.draw(st.integers(0, 7), label="bit")
    path = tmp_path_factory.mktemp("flip") / "f.safetensors"
    path.write_bytes(flipped(raw, offset, bit))
    with pytest.raises(PolicyChecksumFailed, match="corrupt: checksum mismatch") as info:
        load_policy(path)
    assert info.value.kind == "checksum"
    assert one_line(info.value).endswith("re-export it or restore the file")


@pytest.mark.parametrize("where", ["first", "exponent", "last"])
def test_bit_flips_that_make_nan_or_huge_weights_are_checksum_errors(tmp_path, good, where):
    path, _, _ = good
    raw = path.read_bytes()
    start = 8 + struct.unpack("<Q", raw[:8])[0]
    offset, bit = {"first": (start, 0), "exponent": (start + 3, 6), "last": (len(raw) - 1, 7)}[
        where
    ]
    path.write_bytes(flipped(raw, offset, bit))
    with pytest.raises(PolicyChecksumFailed, match="checksum mismatch"):
        load_policy(path)


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.data())
def test_a_bit_flip_anywhere_is_refused_or_harmless(tmp_path_factory, tiny_file_bytes, data):
    """Header, metadata or data: the file is refused, or it loads exactly what was written."""
    raw, _ = tiny_file_bytes
    offset = data.draw(st.integers(0, len(raw) - 1), label="offset")
    bit = data.draw(st.integers(0, 7), label="bit")
    base = tmp_path_factory.mktemp("flip")
    (base / "a.safetensors").write_bytes(raw)
    (base / "b.safetensors").write_bytes(flipped(raw, offset, bit))
    try:
        policy = load_policy(base / "b.safetensors")
    except PolicyError as exc:
        one_line(exc)
        return
    original = load_policy(base / "a.safetensors")  # e.g. \u00e9 vs \u00E9 in a JSON string
    assert policy.meta == original.meta
    for name, (w, b) in original.actor.items():
        assert policy.actor[name][0].tobytes() == w.tobytes()
        assert policy.actor[name][1].tobytes() == b.tobytes()


@pytest.mark.parametrize("keep", [0, 3, 8, 20, "header-1", "data-1", "last-1"])
def test_a_truncated_file_is_not_a_policy_file(tmp_path, good, keep):
    path, _, _ = good
    raw = path.read_bytes()
    start = 8 + struct.unpack("<Q", raw[:8])[0]
    n = {"header-1": start - 1, "data-1": start + 1, "last-1": len(raw) - 1}.get(keep, keep)
    assert isinstance(n, int)
    path.write_bytes(raw[:n])
    with pytest.raises(PolicyFileInvalid, match=r"not a policy file \(") as info:
        load_policy(path)
    assert info.value.kind == "format"
    assert one_line(info.value).endswith(": re-export it with remarl-fc export")


@settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    blob=st.one_of(
        st.binary(max_size=300),
        st.binary(max_size=200).map(lambda b: struct.pack("<Q", len(b)) + b),
        st.binary(min_size=1, max_size=64).map(lambda b: struct.pack("<Q", 2**40) + b),
    )
)
def test_random_bytes_are_not_a_policy_file(tmp_path_factory, blob):
    path = tmp_path_factory.mktemp("junk") / "junk.safetensors"
    path.write_bytes(blob)
    with pytest.raises(PolicyFileInvalid, match="not a policy file") as info:
        load_policy(path)
    one_line(info.value)


@pytest.mark.parametrize(
    ("text", "match"),
    [
        (None, "no remarl_policy metadata"),
        ("{not json", "not valid JSON"),
        ("[1, 2]", "must be a JSON object"),
        ("[" * 100_000, "not valid JSON"),
        ('{"a": 1' + "0" * 5000 + "}", "not valid JSON"),
    ],
)
def test_unreadable_metadata_is_a_clear_error(tmp_path, good, text, match):
    _, tensors, _ = good
    path = tmp_path / "m.safetensors"
    save_file(tensors, str(path), metadata=None if text is None else {METADATA_KEY: text})
    with pytest.raises(PolicyFileInvalid, match=match) as info:
        load_policy(path)
    one_line(info.value)


def test_a_pickle_is_refused_without_being_run(tmp_path):
    import pickle

    marker = tmp_path / "executed"

    class Boom:
        def __reduce__(self):
            return (marker.write_text, ("yes",))

    evil = tmp_path / "evil.safetensors"
    evil.write_bytes(pickle.dumps(Boom()))
    with pytest.raises(PolicyFileInvalid, match="not a policy file"):
        load_policy(evil)
    assert not marker.exists()


# ---------------------------------------------------------------------------------- weights


@pytest.mark.parametrize("name", ["actor.l1.weight", "actor.out.bias", "critic.l2.weight"])
@pytest.mark.parametrize("value", [math.nan, math.inf, -math.inf])
def test_a_validly_signed_non_finite_weight_is_named(tmp_path, good, name, value):
    _, tensors, meta = good
    tensors = {k: v.copy() for k, v in tensors.items()}
    tensors[name].flat[-1] = value
    path = write(tmp_path / "nan.safetensors", tensors, meta)
    with pytest.raises(PolicyFileInvalid, match="non-finite") as info:
        load_policy(path)
    assert info.value.kind == "weights" and info.value.key == name
    assert f"bad weights ({name}: 1 non-finite value(s)" in one_line(info.value)


@pytest.mark.parametrize("value", [1e30, -1e30, 2 * WEIGHT_BOUND, np.finfo(np.float32).max])
def test_a_validly_signed_huge_weight_is_out_of_range(tmp_path, good, value):
    _, tensors, meta = good
    tensors = {k: v.copy() for k, v in tensors.items()}
    tensors["critic.out.weight"].flat[0] = value
    path = write(tmp_path / "huge.safetensors", tensors, meta)
    with pytest.raises(PolicyFileInvalid, match="beyond the bound") as info:
        load_policy(path)
    assert info.value.kind == "weights" and info.value.key == "critic.out.weight"
    one_line(info.value)


def test_weights_at_the_bound_load(tmp_path, good):
    _, tensors, meta = good
    tensors = {k: v.copy() for k, v in tensors.items()}
    tensors["actor.l1.weight"].flat[0] = -WEIGHT_BOUND
    load_policy(write(tmp_path / "edge.safetensors", tensors, meta))


@pytest.mark.parametrize(
    ("kind", "change", "key", "match"),
    [
        ("mlp", "drop actor.out.bias", "actor.out.bias", "missing tensor"),
        ("mlp", "drop critic.l2.weight", "critic.l2.weight", "missing tensor"),
        ("mlp", "add actor.l3.weight", "actor.l3.weight", "unexpected tensor"),
        ("mlp", "float64 actor.l1.weight", "actor.l1.weight", "must be float32"),
        ("mlp", "reshape actor.l1.weight", "actor.l1.weight", "metadata says"),
        ("mlp", "reshape critic.act_l.bias", "critic.act_l.bias", "metadata says"),
        ("generalist", "drop actor.nb1.weight", "actor.nb1.weight", "missing tensor"),
        ("generalist", "drop critic.in2.bias", "critic.in2.bias", "missing tensor"),
        ("generalist", "add actor.obs_l.weight", "actor.obs_l.weight", "(a set policy holds"),
        ("generalist", "float64 actor.self.weight", "actor.self.weight", "must be float32"),
        ("generalist", "reshape actor.l1.weight", "actor.l1.weight", "says (1, 20, 4)"),
        ("generalist", "reshape critic.l1.weight", "critic.l1.weight", "says (1, 21, 4)"),
        ("generalist", "members actor.out.bias", "actor.out.bias", "says (1, 1, 1)"),
    ],
)
def test_tensors_must_fit_the_metadata(tmp_path, kind, change, key, match):
    meta, tensors = GOOD_FILES[kind]
    tensors = changed_tensors(tensors, change)
    path = write(tmp_path / "t.safetensors", tensors, meta)
    with pytest.raises(PolicyFileInvalid, match=re.escape(match)) as info:
        load_policy(path)
    assert info.value.kind == "tensors" and info.value.key == key
    assert one_line(info.value).endswith("re-export it with remarl-fc export")


# --------------------------------------------------------------------------------- metadata


ISSUE_MUTATIONS = [
    ("agents", "three", "agents"),
    ("hidden", None, "hidden"),
    ("scenario_config", DELETE, "scenario_config"),
]
MORE_MUTATIONS = [
    ("agents", 0, "agents"),
    ("agents", True, "agents"),
    ("agents", 3, "agents"),
    ("agents", 2.0, "agents"),
    ("hidden", -4, "hidden"),
    ("hidden", [4], "hidden"),
    ("shared", "no", "shared"),
    ("schema", 3, "schema"),
    ("schema", 1.0, "schema"),
    ("schema", "1", "schema"),
    ("schema", DELETE, "schema"),
    ("scenario", "../../etc/passwd", "scenario"),
    ("scenario", "3u2o", "scenario"),
    ("scenario_hash", "00", "scenario_hash"),
    ("scenario_hash", "0" * 64, "scenario_hash"),
    ("scenario_config", [], "scenario_config"),
    ("scenario_config.uav", None, "scenario_config.uav"),
    ("scenario_config.uav.count", "2", "scenario_config.uav.count"),
    ("scenario_config.uav.formation", "blob", "scenario_config.uav.formation"),
    ("scenario_config.uav.center_m", [1.0], "scenario_config.uav.center_m"),
    ("scenario_config.sensing.range_m", -1.0, "scenario_config.sensing.range_m"),
    ("scenario_config.substeps", 7, "scenario_config.reward.quadrature_intervals"),
    ("scenario_config.surprise", 1, "scenario_config.surprise"),
    ("scenario_config.name", DELETE, "scenario_config.name"),
    ("observation", "wide", "observation"),
    ("observation.size", 29, "observation.size"),
    ("observation.rows", 7, "observation.rows"),
    ("observation.columns", 5, "observation.columns"),
    ("observation.clip", 5.0, "observation.clip"),
    ("observation.max_obstacles", "4", "observation.max_obstacles"),
    ("observation.range_m", 50.0, "observation.range_m"),
    ("observation.aperture_rad", 7.0, "observation.aperture_rad"),
    ("observation.speed_m_s", DELETE, "observation.speed_m_s"),
    ("action.max_turn_rad", 4.0, "action.max_turn_rad"),
    ("action.max_turn_rad", 0.5, "action.max_turn_rad"),
    ("action.normalised_bound", 2.0, "action.normalised_bound"),
    ("dt_s", 0, "dt_s"),
    ("dt_s", math.nan, "dt_s"),
    ("speed_m_s", math.inf, "speed_m_s"),
    ("d_col_m", "20", "d_col_m"),
    ("reward", 1, "reward"),
    ("training", None, "training"),
    ("training.steps", -1, "training.steps"),
    ("metrics", 3, "metrics"),
    ("metrics.success_rate", math.nan, "metrics.success_rate"),
    ("checksum", "md5:00", "checksum"),
]


@pytest.mark.parametrize(("path", "value", "key"), ISSUE_MUTATIONS + MORE_MUTATIONS)
@pytest.mark.parametrize("sign", [True, False], ids=["signed", "unsigned"])
def test_bad_metadata_names_the_key(tmp_path, good, path, value, key, sign):
    _, tensors, meta = good
    if path == "checksum":
        meta = {**meta, "checksum": "sha256:" + "0" * 64}
    bad = mutate(meta, path, value)
    file = write(tmp_path / "bad.safetensors", tensors, bad, sign=sign and path != "checksum")
    with pytest.raises(PolicyFileInvalid) as info:
        load_policy(file)
    assert info.value.kind == "schema", info.value
    assert key in [k for k, _ in info.value.problems], info.value.problems
    text = one_line(info.value)
    assert text.startswith(f"{file}: bad policy metadata (") and f"{key}: " in text
    assert text.endswith("re-export it with remarl-fc export")


@pytest.mark.parametrize("key", REQUIRED_KEYS)
def test_every_required_key_is_required(tmp_path, good, key):
    _, tensors, meta = good
    with pytest.raises(PolicyFileInvalid, match=f"{key}: required key is missing"):
        load_policy(write(tmp_path / "k.safetensors", tensors, mutate(meta, key, DELETE)))


def test_the_exporters_metadata_is_valid():
    assert metadata_problems(tiny_meta()) == []
    assert metadata_problems(tiny_meta("10u1o", hidden=256, shared=True)) == []


def meta_paths(node: Any, prefix: str = "") -> list[str]:
    out = []
    if isinstance(node, dict):
        for k, v in node.items():
            out.append(prefix + k)
            out += meta_paths(v, f"{prefix}{k}.")
    return out


JSON_VALUES = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**70), 2**70)
    | st.floats(allow_nan=True, allow_infinity=True)
    | st.text(max_size=8),
    lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner),
    max_leaves=6,
)


@pytest.mark.parametrize("kind", ["mlp", "generalist"])
@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), value=st.just(DELETE) | JSON_VALUES, sign=st.booleans())
def test_random_metadata_mutations_are_policy_errors(tmp_path_factory, kind, data, value, sign):
    meta, tensors = GOOD_FILES[kind]
    path = data.draw(st.sampled_from(meta_paths(meta)), label="path")
    bad = mutate(meta, path, value)
    file = write(tmp_path_factory.mktemp("m") / "m.safetensors", tensors, bad, sign=sign)
    error: PolicyFileInvalid | None = None
    try:
        policy = load_policy(file)
    except PolicyFileInvalid as exc:
        error = exc
    if error is not None:
        one_line(error)
        if error.kind == "schema":
            assert error.problems and all(f"{k}: " in str(error) for k, _ in error.problems[:4])
        return
    assert metadata_problems(policy.meta) == []  # a harmless change, validly signed
    for n in set(policy.uav_range):  # the zoo's: exactly its agents
        assert policy.act(np.zeros((n, policy.layout.size))).shape == (n,)


# ------------------------------------------------------------------------------ generalists


@pytest.fixture(scope="module")
def generalist(tmp_path_factory):
    path = write_tiny_generalist(tmp_path_factory.mktemp("g") / "g.safetensors", seed=3)
    return load_policy(path), load_file(str(path))


def params(tensors: dict[str, np.ndarray], net: str) -> dict[str, Any]:
    names = {k.split(".")[1] for k in tensors if k.startswith(net + ".")}
    return {n: (tensors[f"{net}.{n}.weight"], tensors[f"{net}.{n}.bias"]) for n in names}


def v2_observations(policy, n: int, intruders: int, seed: int = 0, envs: int = 2) -> np.ndarray:
    """(envs, n, D) observations of a random swarm of n UAVs among ``intruders`` intruders,
    every vehicle within 150 m (some in range, some not)."""
    rng = np.random.default_rng(seed)
    pos = rng.uniform(-150, 150, (envs, n, 2))
    return build_observations(
        policy.layout,
        pos,
        rng.uniform(-np.pi, np.pi, (envs, n)),
        rng.normal(0, 10, (envs, n, 2)),
        pos + rng.uniform(-500, 500, (envs, n, 2)),
        np.repeat(pos.mean(axis=1, keepdims=True), n, axis=1),  # one swarm's p*
        rng.uniform(-150, 150, (envs, intruders, 2)),
        rng.normal(0, 5, (envs, intruders, 2)),
    ).flat()


def test_a_generalist_round_trips(generalist):
    policy, tensors = generalist
    assert policy.generalist and policy.uav_range == (1, 50) and policy.agents == 50
    assert policy.layout.version == 2 and policy.layout.max_neighbours == 6
    assert policy.layout.max_obstacles == 8 and policy.layout.size == 110
    assert set(policy.actor) == set(policy.critic) == set(params(tensors, "actor"))
    obs = v2_observations(policy, 7, 5)
    actions = policy.act(obs)
    assert actions.dtype == np.float32 and actions.shape == (2, 7)
    np.testing.assert_array_equal(actions, set_actor(params(tensors, "actor"), obs, policy.layout))
    q = policy.q_values(obs, actions)
    assert q.shape == (2, 7)
    np.testing.assert_array_equal(
        q, set_critic(params(tensors, "critic"), obs, actions, policy.layout)
    )


def test_a_generalist_ignores_the_order_of_neighbours_and_intruders(generalist):
    policy, _ = generalist
    blocks = policy.layout.blocks()
    k, m = policy.layout.max_neighbours, policy.layout.max_obstacles
    rng = np.random.default_rng(1)
    obs = v2_observations(policy, 30, 8, seed=2, envs=3).reshape(-1, policy.layout.size)
    assert obs[:, blocks["neighbour_mask"]].sum() > 0 and obs[:, blocks["intruder_mask"]].sum() > 0
    assert (obs[:, blocks["intruder_mask"]] == 0).any()  # masked rows among them
    before = policy.act(obs[:, None])
    shuffled = obs.copy()
    for row in shuffled:
        for rows, mask, width, count in (
            ("neighbours", "neighbour_mask", 8, k),
            ("intruders", "intruder_mask", 5, m),
        ):
            order = rng.permutation(count)
            row[blocks[rows]] = row[blocks[rows]].reshape(count, width)[order].reshape(-1)
            row[blocks[mask]] = row[blocks[mask]][order]
    assert not np.array_equal(shuffled, obs)
    np.testing.assert_allclose(policy.act(shuffled[:, None]), before, atol=1e-6, rtol=0)


def test_a_generalist_flies_1_to_50_uavs_among_0_to_8_intruders(generalist):
    policy, _ = generalist
    for n in range(1, 51):
        for intruders in range(9):
            actions = policy.act(v2_observations(policy, n, intruders, seed=n * 9 + intruders))
            assert actions.shape == (2, n) and np.isfinite(actions).all()
            assert np.abs(actions).max() <= 1.0


def test_a_generalist_flies_the_simulators_observations_of_its_layout(generalist):
    policy, _ = generalist
    cfg = load_scenario("50u8o")  # observation version 1, m = 4: the policy brings its own
    policy.check_scenario(cfg)
    sim = SwarmSim(cfg, scored=False)
    state = sim.initial_state(np.random.default_rng(0), 2)
    obs = sim.observe(state, layout=policy.layout).flat()
    assert obs.shape == (2, 50, 110) and policy.act(obs).shape == (2, 50)
    with pytest.raises(PolicySpecMismatch, match="observation size is 28 here"):
        policy.act(sim.observe(state).flat())


@pytest.mark.parametrize("n", [51, 80])
def test_a_generalist_refuses_more_uavs_than_it_flies(generalist, n):
    policy, _ = generalist
    with pytest.raises(PolicyUavRangeMismatch) as info:
        policy.act(np.zeros((n, policy.layout.size), np.float32))
    assert isinstance(info.value, PolicySpecMismatch)
    assert info.value.field == "number of UAVs"
    assert (info.value.expected, info.value.actual) == ((1, 50), n)
    assert f"{n} UAVs here but the policy flies 1 to 50; fly it with 1 to 50 UAVs" in one_line(
        info.value
    )


def test_a_generalist_checks_the_scenarios_size_dynamics_and_not_its_sensing(tmp_path):
    path = write_tiny_generalist(tmp_path / "g.safetensors", uavs=(2, 5), critic=False)
    policy = load_policy(path)
    assert policy.critic == {} and policy.uav_range == (2, 5) and policy.agents == 5
    for name in ("2u1o", "3u2o", "5u2o"):  # v1 sensing, other m: fine
        policy.check_scenario(load_scenario(name))
    for name, n in (("7u1o", 7), ("10u1o", 10)):
        with pytest.raises(PolicyUavRangeMismatch, match=f"{n} UAVs here but the policy flies 2"):
            policy.check_scenario(load_scenario(name))
    with pytest.raises(PolicyUavRangeMismatch):
        policy.act(np.zeros((1, policy.layout.size)))
    for override, field in (
        ({"dt_s": 0.5}, "decision step dt_s"),
        ({"uav": {"speed_m_s": 12.0}}, "UAV speed speed_m_s"),
    ):
        with pytest.raises(PolicySpecMismatch) as info:
            policy.check_scenario(load_scenario("3u2o", **override))
        assert info.value.field == field
    with pytest.raises(PolicyError, match="no critic"):
        policy.q_values(np.zeros((3, policy.layout.size)), np.zeros(3))


@pytest.mark.parametrize(
    ("change", "kind", "key"),
    [
        ("nan critic.l2.weight", "weights", "critic.l2.weight"),
        ("meta uavs", "schema", "uavs"),
        ("meta observation.max_neighbours", "schema", "observation.max_neighbours"),
        ("meta network", "schema", "network"),
    ],
)
def test_a_bad_generalist_file_names_what_is_wrong(tmp_path, change, kind, key):
    meta = tiny_generalist_meta()
    tensors = tiny_generalist_tensors(meta)
    verb, name = change.split()
    if verb == "meta":
        meta = mutate(meta, name, {"uavs": [50, 1], "network": "rnn"}.get(name, -2))
    else:
        tensors = changed_tensors(tensors, change)
    with pytest.raises(PolicyFileInvalid) as info:
        load_policy(write(tmp_path / "bad.safetensors", tensors, meta))
    assert info.value.kind == kind and info.value.key == key, info.value.problems
    one_line(info.value)


def test_a_corrupt_generalist_is_a_checksum_error(tmp_path):
    path = write_tiny_generalist(tmp_path / "g.safetensors")
    raw = bytearray(path.read_bytes())
    raw[-5] ^= 1 << 6
    path.write_bytes(bytes(raw))
    with pytest.raises(PolicyChecksumFailed, match="checksum mismatch"):
        load_policy(path)


# ------------------------------------------------------------------------ the zoo, unchanged


def mlp_forward(tensors: dict[str, np.ndarray], obs: np.ndarray) -> np.ndarray:
    """The zoo's actor, written out: per agent, tanh(relu(x W1 + b1) W2 + b2)."""
    w1, b1 = tensors["actor.l1.weight"], tensors["actor.l1.bias"]
    w2, b2 = tensors["actor.out.weight"], tensors["actor.out.bias"]
    n = obs.shape[-2]
    out = np.empty(obs.shape[:-1], np.float32)
    for i in range(n):
        a = 0 if w1.shape[0] == 1 else i
        h = np.maximum(obs[..., i, :] @ w1[a] + b1[a, 0], 0.0)
        out[..., i] = np.tanh(h @ w2[a] + b2[a, 0])[..., 0]
    return out


@pytest.mark.parametrize("name", [n for n in zoo_names() if n in scenario_names()])
def test_zoo_policies_are_mlps_that_act_as_before(name):
    policy = load_policy(name)
    assert not policy.generalist and policy.meta["schema"] == 1
    assert policy.uav_range == (policy.agents, policy.agents)
    assert policy.layout.version == 1 and policy.layout.max_neighbours == 0
    cfg = load_scenario(name)
    policy.check_scenario(cfg)
    sim = SwarmSim(cfg, scored=False)
    state = sim.initial_state(np.random.default_rng(0), 3)
    obs = sim.observe(state).flat()
    tensors = load_file(str(zoo_dir() / f"{name}.safetensors"))
    np.testing.assert_allclose(policy.act(obs), mlp_forward(tensors, obs), atol=1e-6)
    with pytest.raises(PolicySpecMismatch, match="number of UAVs") as info:
        policy.act(np.zeros((policy.agents + 1, policy.layout.size), np.float32))
    assert not isinstance(info.value, PolicyUavRangeMismatch)
