"""The policy file format's schema 2 (generalists: a set network for a range of swarm sizes),
next to schema 1 (the zoo's MLPs), in numpy: which schema is written, what each key may hold,
which tensors a set network has; every bad key and tensor is a named `Problem` (misshapen
tensors through the loader: `tests/remarl_fc/test_policy_io.py`)."""

from __future__ import annotations

import json
from typing import Any

import pytest
from tiny_policy import (
    DELETE,
    changed_tensors,
    mutate,
    tiny_generalist_meta,
    tiny_generalist_tensors,
    tiny_meta,
    tiny_tensors,
)

from sim.observation import ObservationLayout
from sim.policy_file import (
    POLICY_SCHEMA,
    POLICY_SCHEMAS,
    SET_LAYERS,
    expected_shapes,
    metadata_problems,
    network_layers,
    network_of,
    observation_layout,
    read_policy_file,
    scenario_hash,
    sign_policy,
    tensor_problems,
    uav_range,
    weight_problems,
)
from sim.policy_metadata import OBSERVATION_KEYS, OBSERVATION_V2_KEYS
from sim.policy_problems import PolicyFileError
from sim.scenarios import load_scenario
from sim.setnet import QUERY_LAYERS, set_shapes


def problem_keys(meta: Any) -> list[str]:
    return [p.key for p in metadata_problems(meta)]


# ------------------------------------------------------------------------------- the design


def test_schemas():
    assert POLICY_SCHEMA == 2 and POLICY_SCHEMAS == (1, 2)


def test_an_mlp_is_still_written_as_schema_1():
    meta = tiny_meta()
    assert meta["schema"] == 1 and "network" not in meta and "uavs" not in meta
    assert tuple(meta["observation"]) == OBSERVATION_KEYS
    assert network_of(meta) == "mlp" and uav_range(meta) == (2, 2)
    assert observation_layout(meta) == ObservationLayout.from_scenario(load_scenario("2u1o"))
    assert network_layers(meta) == (("l1", "out"), ("obs_l", "act_l", "l2", "out"))


def test_a_generalist_is_schema_2_with_network_uavs_and_a_v2_observation():
    meta = tiny_generalist_meta(hidden=8, k=6, m=8, uavs=(1, 50))
    assert metadata_problems(json.loads(json.dumps(meta))) == []
    assert meta["schema"] == 2 and meta["network"] == "set" and meta["uavs"] == [1, 50]
    assert meta["shared"] is True and meta["agents"] == 3  # the base scenario's (3u2o)
    obs = meta["observation"]
    assert set(obs) == set(OBSERVATION_V2_KEYS)
    assert obs["version"] == 2 and obs["max_neighbours"] == 6 and obs["max_obstacles"] == 8
    assert (obs["self_size"], obs["neighbour_size"], obs["intruder_size"]) == (8, 8, 5)
    layout = observation_layout(meta)
    assert layout.version == 2 and layout.max_neighbours == 6 and layout.size == obs["size"] == 110
    assert network_of(meta) == "set" and uav_range(meta) == (1, 50)
    assert network_layers(meta) == (SET_LAYERS, SET_LAYERS)


def test_a_set_networks_tensors_are_setnets_shapes_with_one_member():
    meta = tiny_generalist_meta(hidden=8)
    shapes = expected_shapes(meta)
    for net, critic in (("actor", False), ("critic", True)):
        for layer, (n_in, n_out) in set_shapes(8, critic).items():
            assert shapes[f"{net}.{layer}.weight"] == (1, n_in, n_out)
            assert shapes[f"{net}.{layer}.bias"] == (1, 1, n_out)
    assert len(shapes) == 4 * len(SET_LAYERS)


def test_an_attention_generalist_says_so_and_holds_the_query_layers():
    meta = json.loads(json.dumps(tiny_generalist_meta(hidden=8, pooling="max-attention")))
    assert metadata_problems(meta) == [] and meta["pooling"] == "max-attention"
    layers = (*SET_LAYERS, *QUERY_LAYERS)
    assert network_layers(meta) == (layers, layers)
    shapes = expected_shapes(meta)
    assert shapes["actor.nbq.weight"] == shapes["critic.inq.weight"] == (1, 8, 8)
    assert tensor_problems(tiny_generalist_tensors(meta), meta) == []
    plain = tiny_generalist_meta(hidden=8)
    assert "pooling" not in plain  # the default is not written: older files read as before
    missing = {p.key for p in tensor_problems(tiny_generalist_tensors(plain), meta)}
    assert "actor.nbq.weight" in missing and "critic.inq.bias" in missing


@pytest.mark.parametrize(
    ("path", "value", "key"),
    [("pooling", "mean", "pooling"), ("pooling", 2, "pooling"), ("hidden", 6, "hidden")],
)
def test_bad_pooling_metadata_names_the_key(path, value, key):
    meta = json.loads(json.dumps(tiny_generalist_meta(hidden=8, pooling="max-attention")))
    assert key in problem_keys(mutate(meta, path, value))


def test_only_a_set_network_of_schema_2_pools():
    mlp = json.loads(json.dumps(tiny_meta()))
    assert "pooling" in problem_keys(mutate(mlp, "pooling", "max-mean"))  # schema 1
    mlp["schema"], mlp["network"], mlp["uavs"] = 2, "mlp", [2, 2]
    mlp["observation"]["version"] = 1
    assert problem_keys(mutate(mlp, "pooling", "max-attention")) == ["pooling"]


def test_every_zoo_file_reads_as_before():
    """The zoo's MLPs (schema 1): no network, no uavs, no observation.version; their implied
    values."""
    from remarl_fc.policy_io import zoo_dir, zoo_names

    schema_1 = 0
    for name in zoo_names():
        tensors, _, meta = read_policy_file(zoo_dir() / f"{name}.safetensors")
        assert metadata_problems(meta) == [] and tensor_problems(tensors, meta) == []
        if meta["schema"] == 1:
            schema_1 += 1
            assert network_of(meta) == "mlp" and uav_range(meta) == (meta["agents"],) * 2
            assert observation_layout(meta).version == 1
    assert schema_1 >= 8


# -------------------------------------------------------------------------------- bad keys

GENERALIST = json.loads(json.dumps(tiny_generalist_meta()))

V2_MUTATIONS = [
    ("network", DELETE, "network"),
    ("network", "cnn", "network"),
    ("network", 1, "network"),
    ("network", "mlp", "network"),  # an mlp does not read observation version 2
    ("uavs", DELETE, "uavs"),
    ("uavs", [0, 50], "uavs"),
    ("uavs", [5, 2], "uavs"),
    ("uavs", [1], "uavs"),
    ("uavs", [1, 50, 60], "uavs"),
    ("uavs", "1-50", "uavs"),
    ("uavs", [1.0, 50], "uavs"),
    ("uavs", [True, 50], "uavs"),
    ("uavs", [4, 50], "uavs"),  # the base scenario's 3 UAVs outside
    ("shared", False, "shared"),
    ("observation.version", DELETE, "observation.version"),
    ("observation.version", 3, "observation.version"),
    ("observation.version", "2", "observation.version"),
    ("observation.version", 1, "network"),  # a set network reads version 2
    ("observation.max_neighbours", DELETE, "observation.max_neighbours"),
    ("observation.max_neighbours", -1, "observation.max_neighbours"),
    ("observation.max_neighbours", 5, "observation.size"),
    ("observation.max_obstacles", 0, "observation.max_obstacles"),
    ("observation.size", 111, "observation.size"),
    ("observation.self_size", 9, "observation.self_size"),
    ("observation.neighbour_size", 7, "observation.neighbour_size"),
    ("observation.intruder_size", DELETE, "observation.intruder_size"),
    ("observation.rows", 2, "observation.rows"),  # a v1 key
    ("observation.range_m", 50.0, "observation.range_m"),
    ("observation.clip", 5.0, "observation.clip"),
    ("observation.frame", "", "observation.frame"),
    ("schema", 3, "schema"),
    ("schema", 2.0, "schema"),
]


@pytest.mark.parametrize(("path", "value", "key"), V2_MUTATIONS)
def test_bad_generalist_metadata_names_the_key(path, value, key):
    keys = problem_keys(mutate(GENERALIST, path, value))
    assert key in keys, keys


def test_a_schema_1_file_may_not_hold_schema_2_keys():
    meta = json.loads(json.dumps(tiny_meta()))
    for path, value in (
        ("network", "mlp"),
        ("uavs", [2, 2]),
        ("observation.version", 1),
        ("observation.max_neighbours", 0),
    ):
        assert path in problem_keys(mutate(meta, path, value))


def test_a_schema_1_file_is_version_1_of_its_scenario():
    meta = json.loads(json.dumps(tiny_meta()))
    bad = mutate(meta, "scenario_config.sensing.observation", 2)
    bad["scenario_hash"] = scenario_hash(bad["scenario_config"])
    assert problem_keys(bad) == ["scenario_config.sensing.observation"]


def test_the_observation_must_be_the_scenarios():
    bad = mutate(GENERALIST, "scenario_config.sensing.max_neighbours", 4)
    bad["scenario_hash"] = scenario_hash(bad["scenario_config"])
    assert problem_keys(bad) == ["observation.max_neighbours"]
    bad = mutate(GENERALIST, "scenario_config.sensing.observation", 1)
    bad["scenario_config"]["sensing"]["max_neighbours"] = 0
    bad["scenario_hash"] = scenario_hash(bad["scenario_config"])
    assert "observation.version" in problem_keys(bad)


def test_a_schema_2_mlp_is_valid_for_exactly_its_agents():
    meta = json.loads(json.dumps(tiny_meta()))
    meta["schema"], meta["network"], meta["uavs"] = 2, "mlp", [2, 2]
    meta["observation"]["version"] = 1
    assert metadata_problems(meta) == []
    assert tensor_problems(tiny_tensors(meta), meta) == []
    assert problem_keys(mutate(meta, "uavs", [1, 2])) == ["uavs"]
    assert problem_keys(mutate(meta, "observation.version", 2))  # v2 keys missing


# --------------------------------------------------------------------------------- tensors


def test_a_generalist_without_critic_is_valid_but_half_a_critic_is_not():
    meta = tiny_generalist_meta()
    actor_only = tiny_generalist_tensors(meta, critic=False)
    assert tensor_problems(actor_only, meta) == []
    half = {**actor_only, "critic.self.weight": tiny_generalist_tensors(meta)["critic.self.weight"]}
    assert {p.key for p in tensor_problems(half, meta)} == {
        f"critic.{layer}.{part}" for layer in SET_LAYERS for part in ("weight", "bias")
    } - {"critic.self.weight"}


def test_non_finite_generalist_weights_are_named():
    tensors = tiny_generalist_tensors(tiny_generalist_meta())
    tensors = changed_tensors(tensors, "nan actor.nb2.weight")
    assert [p.key for p in weight_problems(tensors)] == ["actor.nb2.weight"]


def test_signing_refuses_a_generalist_the_loader_would_refuse():
    meta = tiny_generalist_meta()
    tensors = tiny_generalist_tensors(meta)
    with pytest.raises(PolicyFileError) as info:
        sign_policy({k: v for k, v in tensors.items() if k != "actor.out.weight"}, meta)
    assert info.value.kind == "tensors" and info.value.key == "actor.out.weight"
    with pytest.raises(PolicyFileError) as info:
        sign_policy(tensors, {**meta, "uavs": [0, 50]})
    assert info.value.kind == "schema" and info.value.key == "uavs"
