"""The error tree crosses process boundaries whole: a worker's error reaches the user as raised."""

from __future__ import annotations

import importlib
import pickle

import pytest

from remarl_fc import errors
from sim.errors import RemarlError
from sim.policy_problems import PolicyFileError, Problem

ERROR_MODULES = (
    "sim.errors",
    "sim.policy_problems",
    "sim.policy_metadata",
    "sim.policy_checksum",
    "sim.policy_file",
    "remarl_fc.errors",
    "remarl_fc.flight.mission",
    "remarl_fc.flight.flightlog",
)
"""Every module of `sim` and `remarl_fc` that defines a class of the tree."""


def problems() -> list[Problem]:
    return [Problem("actor.l1.weight", "holds NaN"), Problem("checksum", "does not match")]


def samples() -> list[RemarlError]:
    """One instance of every class of the tree, made by its own constructor."""
    from remarl_fc.flight.flightlog import FlightLogError
    from remarl_fc.flight.mission import MissionError, VehicleCountMismatch
    from sim.policy_checksum import PolicyChecksumError, PolicyUnsignedError
    from sim.policy_file import PolicyTensorError, PolicyWeightsError
    from sim.policy_metadata import PolicyFormatError, PolicySchemaError

    file_errors = [
        PolicyFileError(problems()),
        PolicyFormatError(problems()),
        PolicySchemaError(problems()),
        PolicyUnsignedError(problems()),
        PolicyChecksumError("sha256:" + "a" * 64, "sha256:" + "b" * 64),
        PolicyTensorError(problems()),
        PolicyWeightsError(problems()),
    ]
    return [
        RemarlError("plain"),
        errors.ConfigError("bad value"),
        errors.ScenarioError("unknown", source="s.toml", key="uav.count"),
        errors.WorkerFailed("process 1 exited with -9; resume the run"),
        errors.SigningKeyError("not 32 bytes", path="k.key"),
        errors.PolicyError("missing", source="p.safetensors"),
        errors.PolicySpecMismatch("p", "scenario", "3u2o", "5u1o"),
        errors.PolicyUavRangeMismatch("p", (1, 50), 60),
        errors.PolicyFileInvalid(file_errors[0], source="p", path="p.safetensors"),
        errors.PolicyChecksumFailed(file_errors[4], source="p", path="p.safetensors"),
        errors.LinkError("refused", link="udp:127.0.0.1:14550"),
        errors.LinkTimeout(link="udp:127.0.0.1:14550", waited_for="HEARTBEAT", timeout_s=3.0),
        errors.LinkLost("socket closed", link="udp:127.0.0.1:14550"),
        errors.SpoofingDetected(link="udp:127.0.0.1:14550", system_id=2, sources=("a", "b")),
        errors.CommandRejected(
            command=400,
            command_name="COMPONENT_ARM_DISARM",
            result=4,
            result_name="FAILED",
            system_id=1,
            reason="PreArm: GPS",
        ),
        errors.UnsafeParameters(system_id=1, problems=("FS_GCS_ENABLE is 0",)),
        MissionError("no vehicles", source="m.toml", key="vehicles"),
        VehicleCountMismatch("m.toml", (1, 50), 60),
        FlightLogError("no tlog"),
        *file_errors,
    ]


@pytest.mark.parametrize("error", samples(), ids=lambda e: type(e).__name__)
def test_every_error_survives_pickle_with_its_message_and_attributes(error):
    again = pickle.loads(pickle.dumps(error))
    assert type(again) is type(error)
    assert str(again) == str(error) and again.args == error.args
    assert vars(again) == vars(error)
    with pytest.raises(type(error)):  # still raises and is caught as itself
        raise again


def test_every_class_of_the_tree_has_a_sample():
    for name in ERROR_MODULES:
        importlib.import_module(name)
    tree: set[type] = set()
    todo: list[type] = [RemarlError]
    while todo:
        cls = todo.pop()
        tree.add(cls)
        todo += cls.__subclasses__()
    mine = {cls for cls in tree if cls.__module__ in ERROR_MODULES}
    assert mine == {type(error) for error in samples()}
