"""One flight's settings and I/O bookkeeping: `FlyConfig`, `Clock` and `Member`.

Also the messages asked of every vehicle (`TELEMETRY`) and the bus endpoint's core (`bus_core`).

Kept apart from `remarl_fc.flight.runtime` so that the command layer
(`remarl_fc.flight.commands`), the swarm bus glue (`remarl_fc.flight.peers`) and the tools
(`remarl_fc.bench.fly`, `remarl_fc.demo`) share them without importing the flight itself.
"""

from __future__ import annotations

import asyncio
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import numpy as np

from remarl_fc.bus.core import BusCore
from remarl_fc.errors import ConfigError
from remarl_fc.flight.mission import Mission
from remarl_fc.flight.tracking import VehicleTrack
from remarl_fc.mavlink.codec import SigningConfig
from remarl_fc.mavlink.consts import MavComponent, MsgId
from remarl_fc.mavlink.link import LinkAddress, MavlinkLink
from sim.config import SensorConfig
from sim.shield import ShieldConfig

HoldMode = Literal["brake", "loiter"]

FLY_SHIELD = ShieldConfig(mode="on")
"""The safety shield a flight flies behind unless told otherwise (`FlyConfig.shield`): on, with
`sim.shield.ShieldConfig`'s horizon, margin and candidates, and its track growth for a policy
that sees its neighbours; `remarl-fc fly`, `demo` and `remarl_fc.demo.fly_on_mock` keep the
growth for the policy flown (`sim.shield.track_growth_behind`)."""

ARDUPILOT_PROFILE = "arducopter"
"""The vehicle profile the shield predicts an ArduPilot vehicle with unless told otherwise:
fitted to ArduCopter SITL's traces (`sim/vehicles/arducopter.toml`)."""

PX4_PROFILE = "px4"
"""The vehicle profile the shield predicts a PX4 vehicle with unless told otherwise: fitted to
PX4 SIH's traces (`sim/vehicles/px4.toml`)."""

TELEMETRY: dict[int, float] = {
    MsgId.GLOBAL_POSITION_INT: 10.0,
    MsgId.ATTITUDE: 10.0,
    MsgId.EKF_STATUS_REPORT: 2.0,
    MsgId.EXTENDED_SYS_STATE: 1.0,
}
"""Messages the runtime asks every vehicle for, Hz (SET_MESSAGE_INTERVAL)."""

PX4_TELEMETRY = frozenset({MsgId.GLOBAL_POSITION_INT, MsgId.ATTITUDE, MsgId.EXTENDED_SYS_STATE})
"""The subset PX4 has (no EKF_STATUS_REPORT)."""


class Clock:
    """The runtime's time: monotonic, optionally scaled to follow a faster-than-real mock.

    Args:
        speedup: simulated seconds per wall second (1 for real vehicles).
    """

    def __init__(self, speedup: float = 1.0) -> None:
        if not speedup > 0:
            raise ValueError(f"speedup must be > 0, not {speedup}")
        self.speedup = speedup
        self._t0 = time.monotonic()

    def now(self) -> float:
        """Seconds since the clock started (scaled)."""
        return (time.monotonic() - self._t0) * self.speedup

    def at(self, t_mono: float) -> float:
        """A monotonic stamp on this clock."""
        return (t_mono - self._t0) * self.speedup

    async def sleep(self, seconds: float) -> None:
        """Sleep ``seconds`` of this clock."""
        await asyncio.sleep(max(0.0, seconds) / self.speedup)

    def timeout(self, seconds: float) -> asyncio.Timeout:
        """`asyncio.timeout` for ``seconds`` of this clock."""
        return asyncio.timeout(seconds / self.speedup)


@dataclass(frozen=True)
class FlyConfig:
    """Settings of one flight (the CLI fills them; defaults are the safe ones)."""

    connections: tuple[str, ...]
    mission: Mission
    takeoff_m: float | None = None
    """Take off to this height above the origin first (overrides the mission's alt_m)."""
    takeoff_to_mission_alt: bool = False
    """Take off first, each vehicle to its mission ``alt_m`` (when `takeoff_m` is None; with
    neither, the vehicles must already be flying)."""
    dry_run: bool = False
    """Compute and log setpoints, send no command and no setpoint."""
    log_dir: Path | None = None
    """Write flight.tlog and decisions.jsonl here."""
    signing: SigningConfig | None = None
    setpoint_hz: float = 10.0
    """Setpoint stream rate (≥ 10 Hz: ArduPilot stops after GUID_TIMEOUT, PX4 after 1 s)."""
    stale_s: float = 1.0
    """Telemetry older than this marks a vehicle lost."""
    hold: HoldMode = "brake"
    """ArduPilot hold mode: BRAKE holds position and height without RC; LOITER needs the
    pilot's sticks (without RC ArduCopter descends in LOITER). PX4 always uses Hold."""
    ready_timeout_s: float = 90.0
    """Wait this long for heartbeats, telemetry and a position."""
    takeoff_timeout_s: float = 60.0
    adsb_band_m: float = 50.0
    """Intruders within ±this height of a vehicle are obstacles."""
    track_filter: bool = SensorConfig.adsb_filter
    """Fuse each ADS-B track's reports in the simulator's track filter (`sim.sensors.fuse`,
    with `sim.config.SensorConfig`'s noise), rather than hold the newest report; docs/FLYING.md
    says when it helps ("ADS-B traffic")."""
    system_id: int = 255
    """The controller's MAVLink system id (ArduPilot's MAV_GCS_SYSID default)."""
    component_id: int = MavComponent.ONBOARD_COMPUTER
    speedup: float = 1.0
    """Scale every period and deadline (only to fly a mock running faster than real time)."""
    max_flight_s: float = 600.0
    """Hold everything after this long under control."""
    vehicles: frozenset[int] | None = None
    """System ids this process flies (one per process over MQTT); None: every vehicle."""
    swarm: str = "swarm"
    """The swarm's name on the bus (topics PREFIX/SWARM/uav/ID/...)."""
    bus_prefix: str = "remarl"
    """Topic prefix on the bus."""
    peer_timeout_s: float = 1.5
    """A peer silent on the bus this long is treated as lost (an obstacle at its last track)."""
    lost_timeout_s: float = 30.0
    """Once no vehicle of this process is under control, a lost one is waited for this long
    (it may come back and must then be told to hold); then the flight ends, not reached."""
    require_signing: bool = False
    """Refuse to fly without a signing key (`signing`)."""
    check_params: bool = True
    """Read and judge every vehicle's failsafe parameters before arming
    (`remarl_fc.flight.paramcheck`); an error finding stops the flight."""
    shield: ShieldConfig = FLY_SHIELD
    """The safety shield behind the policy (`sim.shield`, docs/FLYING.md "The safety shield"):
    "on" replaces a decision that would come within d_col + margin of an obstacle or of the
    swarm; "monitor" only records it; "off" computes nothing."""
    vehicle_profile: str | None = None
    """The vehicle profile (`sim/vehicles`: a name or a file) the shield predicts this
    process's vehicles with (``shield.vehicle_model`` "fitted"); None: the one fitted to each
    vehicle's autopilot, `ARDUPILOT_PROFILE` or `PX4_PROFILE` (docs/FLYING.md, "The safety
    shield")."""

    def __post_init__(self) -> None:
        if not self.connections:
            raise ValueError("give at least one --connection")
        for url in self.connections:
            LinkAddress.parse(url)  # a bad URL fails here, before anything is opened
        if self.setpoint_hz < 10.0:
            raise ValueError(f"setpoint_hz must be ≥ 10 Hz, not {self.setpoint_hz}")
        if self.takeoff_m is not None and not self.takeoff_m > 0:
            raise ValueError(f"takeoff height must be > 0 m, not {self.takeoff_m}")
        ceiling = self.mission.geofence.max_alt_m if self.mission.geofence else None
        if self.takeoff_m is not None and ceiling is not None and self.takeoff_m > ceiling:
            raise ValueError(
                f"take-off height {self.takeoff_m:g} m is above the mission's geofence ceiling "
                f"max_alt_m {ceiling:g} m"
            )
        if self.require_signing and self.signing is None:
            raise ValueError(
                "--require-signing: give the link's key with --signing-key FILE "
                "(docs/FLYING.md, signing)"
            )
        if not self.lost_timeout_s > 0:
            raise ValueError(f"lost timeout must be > 0 s, not {self.lost_timeout_s}")


@dataclass
class Member:
    """One vehicle's I/O side: its telemetry track, link, counters and event log.

    Its status and setpoint stream live in the flight's immutable decision state
    (`remarl_fc.flight.core.Vehicle`), not here.
    """

    slot: int
    system_id: int
    track: VehicleTrack
    link: MavlinkLink | None = None
    sent: int = 0
    events: list[tuple[float, str]] = field(default_factory=list)
    local: bool = True  # flown by this process (else a peer's, known from the swarm bus)
    remote_status: str | None = None  # a peer's status as its process publishes it
    remote_said: str | None = None  # the last it published (``remote_status`` turns lost)
    remote_arc: tuple[float, float, float, float] | None = None
    """A peer's arc as its process last published it, in this controller's terms: (heading at
    its start, rad, the simulator's frame; turn, rad; speed, m/s; start, this flight's clock)."""
    ready_ne_m: np.ndarray | None = None  # where it was when it became ready to start
    ready_t: float | None = None  # when (UNIX s): every process derives the same start


def members_of(mission: Mission, local: frozenset[int] | None) -> list[Member]:
    """Every vehicle of the mission in slot order, ``local`` ones flown by this process.

    Raises:
        ConfigError: ``local`` names a vehicle that is not in the mission.
    """
    ids = {p.system_id for p in mission.vehicles}
    mine = local if local is not None else frozenset(ids)
    unknown = sorted(mine - ids)
    if unknown:
        raise ConfigError(
            f"vehicle(s) {unknown} are not in the mission {mission.source} "
            f"(its system ids: {sorted(ids)})"
        )
    return [
        Member(
            p.slot,
            p.system_id,
            VehicleTrack(p.system_id, mission.origin),
            local=p.system_id in mine,
        )
        for p in mission.by_slot()
    ]


def bus_core(cfg: FlyConfig, local: frozenset[int]) -> BusCore:
    """The receive-side bookkeeping of this flight's swarm bus endpoint."""
    ids = frozenset(p.system_id for p in cfg.mission.vehicles)
    return BusCore(cfg.bus_prefix, cfg.swarm, local, ids, speedup=cfg.speedup)
