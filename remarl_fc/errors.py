"""The error tree of remarl-fc.

Everything the project raises on purpose derives from `RemarlError`; third-party errors are
converted where they enter (``raise X from exc``), so callers need to know only this tree::

    RemarlError
     ├── ConfigError (also a ValueError)     bad configuration value or file
     │    └── ScenarioError                  scenario name/file that cannot be used
     │    └── SigningKeyError                a MAVLink signing key file that cannot be used
     ├── PolicyError                         a policy file that cannot be used
     │    ├── PolicySpecMismatch             ... for this scenario or vehicle set
     │    │    └── PolicyUavRangeMismatch    ... for this number of UAVs (a generalist)
     │    └── PolicyFileInvalid              ... failing a check of its format, schema, weights
     │         └── PolicyChecksumFailed      ... with no checksum or a wrong one
     ├── LinkError                           a MAVLink link that cannot be used
     │    ├── LinkTimeout                    an awaited message did not come in time
     │    ├── LinkLost                       the socket failed or the peer went silent
     │    └── SpoofingDetected               two sources speak for one vehicle before take-off
     ├── CommandRejected                     an autopilot answered a command with a refusal
     ├── UnsafeParameters                    a vehicle's failsafe parameters would defeat `fly`
     └── WorkerFailed                        a process of a run (training's rollouts) stopped

Messages say what to do next. Every error of the tree crosses a process boundary whole: one
raised in a worker (`remarl-fc eval --workers`, a training's rollout process) reaches the
parent with its class, message and attributes (`RemarlError.__reduce__`).
"""

from __future__ import annotations

from sim.errors import ConfigError, RemarlError, ScenarioError, WorkerFailed
from sim.policy_file import PolicyFileError

__all__ = [
    "CommandRejected",
    "ConfigError",
    "LinkError",
    "LinkLost",
    "LinkTimeout",
    "PolicyChecksumFailed",
    "PolicyError",
    "PolicyFileInvalid",
    "PolicySpecMismatch",
    "PolicyUavRangeMismatch",
    "RemarlError",
    "ScenarioError",
    "SigningKeyError",
    "SpoofingDetected",
    "UnsafeParameters",
    "WorkerFailed",
]


class PolicyError(RemarlError):
    """A policy file is missing, corrupt or not a remarl-fc policy.

    Attributes:
        source: the file or zoo name.
    """

    def __init__(self, message: str, *, source: str) -> None:
        super().__init__(f"{source}: {message}")
        self.source = source


class PolicySpecMismatch(PolicyError):
    """A policy does not fit the scenario or the vehicles it is asked to fly.

    Attributes:
        field: the mismatching value's name; expected / actual: the two values.
    """

    def __init__(self, source: str, field: str, expected: object, actual: object) -> None:
        super().__init__(
            f"{field} is {actual!r} here but the policy was trained with {expected!r}; "
            "use a policy trained for this scenario (remarl-fc train) or fix the scenario",
            source=source,
        )
        self.field, self.expected, self.actual = field, expected, actual


class PolicyUavRangeMismatch(PolicySpecMismatch):
    """A policy for a range of swarm sizes (a generalist) asked to fly a number outside it.

    ``field`` is "number of UAVs", ``expected`` the (fewest, most) it flies, ``actual`` N.
    """

    def __init__(self, source: str, uavs: tuple[int, int], actual: int) -> None:
        low, high = uavs
        PolicyError.__init__(
            self,
            f"{actual} UAVs here but the policy flies {low} to {high}; fly it with {low} to "
            f"{high} UAVs or use a policy trained for {actual} (remarl-fc train)",
            source=source,
        )
        self.field, self.expected, self.actual = "number of UAVs", uavs, actual


class PolicyFileInvalid(PolicyError):
    """A policy file that fails a check of `sim.policy_file` (format, schema, tensors, weights).

    Attributes:
        kind: which check failed: "format", "schema", "unsigned", "checksum", "tensors" or
            "weights". problems: (key or tensor, message) pairs. key: the first problem's key.
    """

    def __init__(self, exc: PolicyFileError, *, source: str, path: str) -> None:
        super().__init__(exc.describe(path), source=source)
        self.kind = exc.kind
        self.problems = tuple((p.key, p.message) for p in exc.problems)
        self.key = exc.key


class PolicyChecksumFailed(PolicyFileInvalid):
    """The file has no checksum, or a wrong one.

    ``kind`` is "unsigned" (written before policy files carried checksums) or "checksum" (the
    file changed after it was written).
    """


class SigningKeyError(ConfigError):
    """A MAVLink 2 signing key file is missing or not 32 bytes (raw, hex or base64).

    Attributes:
        path: the key file.
    """

    def __init__(self, message: str, *, path: str) -> None:
        super().__init__(f"{path}: {message}")
        self.path = path


class LinkError(RemarlError):
    """A MAVLink link cannot be used.

    Attributes:
        link: the link's address as the user gave it (``udp:127.0.0.1:14550``).
    """

    def __init__(self, message: str, *, link: str) -> None:
        super().__init__(f"{link}: {message}")
        self.link = link


class LinkTimeout(LinkError):
    """A message awaited on a link did not arrive within its deadline (monotonic clock).

    Attributes:
        waited_for: what was awaited; timeout_s: the deadline in seconds.
    """

    def __init__(self, *, link: str, waited_for: str, timeout_s: float) -> None:
        super().__init__(
            f"timed out after {timeout_s:g} s waiting for: {waited_for}; check that the vehicle "
            "is powered, the address and port are right and nothing else holds the port",
            link=link,
        )
        self.waited_for, self.timeout_s = waited_for, timeout_s


class LinkLost(LinkError):
    """The link failed: the socket closed or errored, or the peer stopped talking."""


class SpoofingDetected(LinkError):
    """Before take-off, a second source claimed a vehicle that another source had bound.

    Without signing nothing tells which one is the vehicle, so `fly` flies none of them.

    Attributes:
        system_id: the vehicle; sources: what each source was (link, address, component).
    """

    def __init__(self, *, link: str, system_id: int, sources: tuple[str, ...]) -> None:
        super().__init__(
            f"vehicle {system_id} is claimed by more than one source ({'; '.join(sources)}): "
            "a spoofer or a routing loop on the network. Nothing was armed. Sign the link "
            "(--signing-key, docs/FLYING.md security) or remove the other sender",
            link=link,
        )
        self.system_id, self.sources = system_id, sources


class CommandRejected(RemarlError):
    """An autopilot refused a command (COMMAND_ACK with a result other than ACCEPTED).

    Attributes:
        command: the MAV_CMD number; command_name: its name; result: the MAV_RESULT number;
        result_name: its name; system_id: the vehicle that refused; reason: the autopilot's
        STATUSTEXT explanation when one came with the refusal, else "".
    """

    def __init__(
        self,
        *,
        command: int,
        command_name: str,
        result: int,
        result_name: str,
        system_id: int,
        reason: str = "",
    ) -> None:
        why = f" ({reason})" if reason else ""
        super().__init__(
            f"vehicle {system_id} refused {command_name} ({command}) with {result_name} "
            f"({result}){why}; check the vehicle's mode, arming state and pre-arm messages"
        )
        self.command, self.command_name = command, command_name
        self.result, self.result_name = result, result_name
        self.system_id, self.reason = system_id, reason


class UnsafeParameters(RemarlError):
    """A vehicle's parameters would make the flight fail (checked before anything is armed).

    Attributes:
        system_id: the vehicle; problems: one sentence per parameter, saying what to set.
    """

    def __init__(self, *, system_id: int, problems: tuple[str, ...]) -> None:
        super().__init__(
            f"vehicle {system_id} has unsafe parameters: {'; '.join(problems)}. Set them on the "
            "ground station (docs/FLYING.md, autopilot parameters), or fly with --no-param-check "
            "if you are sure"
        )
        self.system_id, self.problems = system_id, problems
