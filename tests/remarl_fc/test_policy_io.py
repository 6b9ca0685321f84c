"""Policy files are verified before they fly: format, schema, checksum, finite in-range weights.

Every bad file is a `PolicyError` with a one-line message that says what to do, never another
exception. Synthetic policies are built in numpy (no torch): the 2u1o scenario, 4 hidden units.
"""

from __future__ import annotations

import contextlib
import copy
import hashlib
import json
import math
import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from safetensors.numpy import load_file, save_file
from tiny_policy import tiny_meta, tiny_tensors

from remarl_fc.errors import PolicyError
from remarl_fc.policy_io import (
    PolicyChecksumFailed,
    PolicyFileInvalid,
    load_policy,
    zoo_dir,
    zoo_names,
)
from sim.policy_file import (
    CHECKSUM_KEY,
    METADATA_KEY,
    REQUIRED_KEYS,
    WEIGHT_BOUND,
    metadata_problems,
    policy_checksum,
    verify_policy,
)

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
    ("change", "key", "match"),
    [
        ("drop actor.out.bias", "actor.out.bias", "missing tensor"),
        ("drop critic.l2.weight", "critic.l2.weight", "missing tensor"),
        ("add actor.l3.weight", "actor.l3.weight", "unexpected tensor"),
        ("float64 actor.l1.weight", "actor.l1.weight", "must be float32"),
        ("reshape actor.l1.weight", "actor.l1.weight", "metadata says"),
        ("reshape critic.act_l.bias", "critic.act_l.bias", "metadata says"),
    ],
)
def test_tensors_must_fit_the_metadata(tmp_path, good, change, key, match):
    _, tensors, meta = good
    tensors = dict(tensors)
    verb, name = change.split()
    if verb == "drop":
        del tensors[name]
    elif verb == "add":
        tensors[name] = np.zeros((2, 4, 4), np.float32)
    elif verb == "float64":
        tensors[name] = tensors[name].astype(np.float64)
    else:
        tensors[name] = np.zeros((*tensors[name].shape[:-1], 3), np.float32)
    path = write(tmp_path / "t.safetensors", tensors, meta)
    with pytest.raises(PolicyFileInvalid, match=match) as info:
        load_policy(path)
    assert info.value.kind == "tensors" and info.value.key == key
    assert one_line(info.value).endswith("re-export it with remarl-fc export")


# --------------------------------------------------------------------------------- metadata


def mutate(meta: dict[str, Any], path: str, value: Any) -> dict[str, Any]:
    """A deep copy with ``path`` (dotted) set to ``value``, or deleted for `DELETE`."""
    out = copy.deepcopy(meta)
    *parents, last = path.split(".")
    node = out
    for p in parents:
        node = node[p]
    if value is DELETE:
        del node[last]
    else:
        node[last] = value
    return out


DELETE = object()

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
    ("schema", 2, "schema"),
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
GOOD_META = tiny_meta()
GOOD_TENSORS = tiny_tensors(GOOD_META)


@settings(max_examples=300, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    path=st.sampled_from(meta_paths(GOOD_META)),
    value=st.just(DELETE) | JSON_VALUES,
    sign=st.booleans(),
)
def test_random_metadata_mutations_are_policy_errors(tmp_path_factory, path, value, sign):
    bad = mutate(GOOD_META, path, value)
    file = write(tmp_path_factory.mktemp("m") / "m.safetensors", GOOD_TENSORS, bad, sign=sign)
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
    assert policy.act(np.zeros((policy.agents, policy.layout.size))).shape == (policy.agents,)
