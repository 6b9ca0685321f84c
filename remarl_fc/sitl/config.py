"""Settings of the SITL mock: one frozen dataclass per concern, every default named once.

Autopilot parameters carry the real parameter's name and default (ArduCopter `Parameters.cpp`,
PX4 `commander_params.yaml` and the PX4 docs); values that are the mock's own choices say so.
The named ones are also served over MAVLink's parameter protocol (`remarl_fc.sitl.params`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

from remarl_fc.frames import GeoPoint

Flavour = Literal["ardupilot", "px4"]
FLAVOURS: tuple[Flavour, ...] = ("ardupilot", "px4")
Transport = Literal["udp", "tcp"]

DEFAULT_HOME = GeoPoint(47.397742, 8.545594, 488.0)
"""Home of the arena origin: the PX4 SITL default location (Zurich), lat/lon degrees, AMSL m."""

SITL_PORTS: dict[tuple[Transport, Flavour], tuple[int, int]] = {
    ("udp", "ardupilot"): (14550, 10),
    ("udp", "px4"): (18570, 1),
    ("tcp", "ardupilot"): (5760, 10),
    ("tcp", "px4"): (5760, 10),
}
"""The real SITLs' port layouts, (base, step): instance i listens on base + step·i.

ArduPilot SITL: 14550 + 10·i over UDP (every port +10 per instance); its SERIAL0 as a TCP
server: 5760 + 10·i (the mock's TCP vehicles use that layout for either flavour). PX4 SITL:
instance i's GCS link listens on 18570 + i (and sends to 14540 + i)."""


ARDUCOPTER_EKF_READY_S = 39.0
"""Seconds from start until ArduCopter SITL's EKF uses GPS, s: measured (V4.7.0-dev, quad
model, 1× time) as arming refused 20–40 s after boot, and control beginning 52.8 s after start
in a `fly --takeoff 20` flight whose take-off (ACK to 19.5 m) took 13.5 s."""

ARDUCOPTER_CLIMB_START_S = 4.5
"""Seconds from NAV_TAKEOFF's ACK to 1 m of height on ArduCopter SITL (measured, 20 m
take-off)."""

MOCK_CLIMB_TO_1M_S = 1.0
"""Seconds the mock's own climb (`VerticalAxis` defaults, 2.5 m/s WPNAV_SPEED_UP) takes from
standstill to 1 m: measured on the mock, 0.98 s."""

ARDUCOPTER_TAKEOFF_DELAY_S = ARDUCOPTER_CLIMB_START_S - MOCK_CLIMB_TO_1M_S
"""The mock's wait between NAV_TAKEOFF's ACK and its climb, s (3.5 s)."""


@dataclass(frozen=True)
class ArduPilotParams:
    """ArduCopter parameters the mock honours (names and defaults of ArduCopter 4.x)."""

    guid_timeout_s: float = 3.0
    """GUID_TIMEOUT: velocity/acceleration targets are zeroed after this long without one."""
    disarm_delay_s: float = 10.0
    """DISARM_DELAY: auto-disarm this long after landing or arming on the ground (0: never)."""
    wpnav_speed_up_m_s: float = 2.5
    """WPNAV_SPEED_UP: take-off climb rate (250 cm/s)."""
    wpnav_speed_dn_m_s: float = 1.5
    """WPNAV_SPEED_DN: descent rate above LAND_ALT_LOW (150 cm/s)."""
    land_speed_m_s: float = 0.5
    """LAND_SPEED: final descent rate (50 cm/s)."""
    land_alt_low_m: float = 10.0
    """LAND_ALT_LOW: below this the final descent rate applies (1000 cm)."""
    rtl_alt_m: float = 15.0
    """RTL_ALT: RTL climbs to at least this height above home first (1500 cm)."""
    rtl_speed_m_s: float = 5.0
    """WPNAV_SPEED: horizontal speed of RTL (500 cm/s)."""
    fs_gcs_enable: int = 0
    """FS_GCS_ENABLE: GCS failsafe, 0 disabled (ArduCopter default, `Parameters.cpp`; the SITL
    defaults file leaves it). Served for pre-flight checks; the mock models no GCS failsafe, so
    it takes 0 only."""
    fence_enable: int = 0
    """FENCE_ENABLE: 0, no fence (AC_Fence default; the SITL runs had the fence not enabled).
    Served for pre-flight checks; the mock models no fence, so it takes 0 only."""
    avd_enable: int = 0
    """AVD_ENABLE: ADS-B avoidance off (AP_Avoidance default 0). The mock models no avoidance,
    so it takes 0 only."""
    avd_f_action: int = 1
    """AVD_F_ACTION: 1 Report (AP_Avoidance default `MAV_COLLISION_ACTION_REPORT`); inert while
    AVD_ENABLE is 0, so any option 0–6 is taken."""
    boot_s: float = 2.0
    """Time in MAV_STATE_BOOT after start; a mode set then is ACKed and then overwritten by
    the initial mode, as measured on ArduCopter SITL (≈ 2.3 s there)."""
    position_estimate_s: float = ARDUCOPTER_EKF_READY_S
    """Time after start until the EKF uses GPS (arming, GUIDED, NAV_TAKEOFF and
    LOCAL_POSITION_NED wait for it; EKF_STATUS_REPORT lacks the position flags until then):
    `ARDUCOPTER_EKF_READY_S`, as measured on ArduCopter SITL. Tests that do not rehearse the
    start use a few seconds (`QUICK_START`)."""
    takeoff_delay_s: float = ARDUCOPTER_TAKEOFF_DELAY_S
    """Time from NAV_TAKEOFF's ACCEPTED to the start of the climb, the vehicle armed on the
    ground meanwhile (ArduCopter spools the motors up and ramps the throttle over
    TKOFF_SLEW_TIME first): `ARDUCOPTER_TAKEOFF_DELAY_S`, so that 1 m is reached 4.5 s after
    the ACK as on ArduCopter SITL."""


PX4_EKF_READY_S = 4.0
"""Seconds from start until PX4 SITL arms, s: on PX4 v1.16 SIH an arming request 3.3 s after
start was denied ("Resolve system health failures first") and the retry 1 s later accepted
(three fresh-start runs of the recorded traces)."""

PX4_COM_RC_IN_MODE = 3
"""COM_RC_IN_MODE default of PX4 v1.14–v1.16: 3, "RC or MAVLink, keep first"
(`src/modules/commander/commander_params.yaml`)."""

PX4_GF_ACTION = 2
"""GF_ACTION default of PX4 v1.14–v1.16: 2, Hold mode
(`src/modules/navigator/geofence_params.yaml`)."""


@dataclass(frozen=True)
class Px4Params:
    """PX4 parameters the mock honours (names and defaults of PX4 v1.14–v1.16)."""

    com_of_loss_t_s: float = 1.0
    """COM_OF_LOSS_T: OFFBOARD is left this long after the last setpoint."""
    com_fail_act_t_s: float = 5.0
    """COM_FAIL_ACT_T: a failsafe holds this long before its action."""
    com_obl_rc_act: Literal["position", "hold", "return", "land"] = "position"
    """COM_OBL_RC_ACT: the offboard-loss action (0 Position, 5 Hold, 3 Return, 4 Land)."""
    com_disarm_prflt_s: float = 10.0
    """COM_DISARM_PRFLT: auto-disarm this long after arming without taking off (≤ 0: never)."""
    com_disarm_land_s: float = 2.0
    """COM_DISARM_LAND: auto-disarm this long after landing (≤ 0: never)."""
    mis_takeoff_alt_m: float = 2.5
    """MIS_TAKEOFF_ALT: take-off height above home when NAV_TAKEOFF gives none."""
    mpc_tko_speed_m_s: float = 1.5
    """MPC_TKO_SPEED: take-off climb rate."""
    mpc_land_speed_m_s: float = 0.7
    """MPC_LAND_SPEED: landing descent rate."""
    rtl_return_alt_m: float = 30.0
    """RTL_RETURN_ALT: RTL climbs to at least this height above home first."""
    rtl_speed_m_s: float = 5.0
    """MPC_XY_CRUISE: horizontal speed of RTL (and of PX4's other auto modes)."""
    nav_dll_act: int = 0
    """NAV_DLL_ACT: data-link-loss action, 0 disabled (`commander_params.yaml` default). Served
    for pre-flight checks; the mock models no data-link-loss failsafe, so it takes 0 only."""
    com_rc_in_mode: int = PX4_COM_RC_IN_MODE
    """COM_RC_IN_MODE: manual control input source (`PX4_COM_RC_IN_MODE`). The mock has no RC
    and does not change with it, so it takes the default only."""
    gf_action: int = PX4_GF_ACTION
    """GF_ACTION: geofence breach action (`PX4_GF_ACTION`); inert without a geofence (the
    mock has none), so any option 0–5 is taken."""
    boot_s: float = 1.0
    """Time in MAV_STATE_BOOT after start (the mock's choice)."""
    position_estimate_s: float = PX4_EKF_READY_S
    """Time after start until a global position is valid (`PX4_EKF_READY_S`)."""


QUICK_START_S = 5.0
"""EKF-ready time of a quick-start mock, s (the mock's value before the slow start was modelled)."""

ARDUPILOT_QUICK_START = ArduPilotParams(position_estimate_s=QUICK_START_S, takeoff_delay_s=0.0)
"""ArduCopter parameters that skip the slow start: the EKF ready after `QUICK_START_S` and
the climb at once after NAV_TAKEOFF's ACK. For tests and rehearsals that do not exercise the
start (``SitlConfig(ardupilot=ARDUPILOT_QUICK_START)``); the defaults are the real firmware's."""


@dataclass(frozen=True)
class VerticalAxis:
    """The mock's vertical response: first order, capped.

    The SITL traces fit only the horizontal plane, which follows the vehicle profile.
    """

    tau_s: float = 0.8
    """Vertical velocity tracking time constant."""
    max_accel_m_s2: float = 2.5
    """Vertical acceleration limit."""
    max_climb_m_s: float = 5.0
    """Vertical speed limit, up and down."""

    def __post_init__(self) -> None:
        if not self.tau_s > 0:
            raise ValueError(f"tau_s must be > 0, not {self.tau_s}")


@dataclass(frozen=True)
class VehicleModelConfig:
    """The simulated multirotor beyond its horizontal response.

    Horizontal velocity and yaw follow a vehicle profile (`sim.vehicle`, the simulator's own
    model): by default the profile fitted to the flavour's real SITL traces (``arducopter`` or
    ``px4``); ``responsive`` is the mock's tuning from before the fits. The vertical axis, the
    limits, gusts and GPS noise are set here.
    """

    profile: str = "flavour"
    """Vehicle profile name or file (``sim/vehicles``); "flavour": the flavour's fitted one."""
    max_speed_m_s: float = 20.0
    """Horizontal speed limit."""
    vertical: VerticalAxis = field(default_factory=VerticalAxis)
    position_gain_1_s: float = 0.8
    """Position-target controller gain (m/s per m of error), capped by `max_speed_m_s`."""
    gust_m_s: float = 0.0
    """Standard deviation of the gust velocity the controllers leave uncorrected (0 = calm);
    steady wind is cancelled by the autopilot's loops and not modelled."""
    gust_tau_s: float = 3.0
    """Correlation time of the gusts (Ornstein–Uhlenbeck)."""
    gps_noise_m: float = 0.0
    """Standard deviation of the horizontal noise on reported positions (0 = exact)."""

    def __post_init__(self) -> None:
        for name in ("gust_tau_s",):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0, not {getattr(self, name)}")
        for name in ("gust_m_s", "gps_noise_m"):
            if getattr(self, name) < 0:
                raise ValueError(f"{name} must be ≥ 0, not {getattr(self, name)}")


@dataclass(frozen=True)
class SitlConfig:
    """A mock fleet.

    Attributes are documented below; `remarl-fc sitl --help` mirrors them.
    """

    vehicles: int = 1
    """Number of vehicles (system ids 1..N)."""
    flavour: Flavour = "ardupilot"
    """Which autopilot to imitate."""
    host: str = "127.0.0.1"
    """Address every vehicle binds."""
    transport: Transport = "udp"
    """"udp": each vehicle a UDP endpoint; "tcp": each a TCP server taking one client at a time
    (ArduPilot SITL's serial-over-TCP port; a new client replaces the previous one)."""
    base_port: int | None = None
    """Port of vehicle 0; None = the SITL default (UDP 14550 ArduPilot, 18570 PX4; TCP 5760)."""
    port_step: int | None = None
    """Port increment per vehicle; None = the SITL default (10 ArduPilot and TCP, 1 PX4)."""
    out: tuple[str, int] | None = None
    """Address every vehicle also sends to from the start (PX4 style), or None to send only
    to the peer it last heard from (ArduPilot style)."""
    out_step: int = 0
    """Port increment of `out` per vehicle (1 = PX4's 14540 + i; 0 = one client hears all)."""
    home: GeoPoint = DEFAULT_HOME
    """Arena origin: the simulator's (0, 0) at ground level."""
    speedup: float = 1.0
    """Simulated seconds per wall second (time_boot_ms follows the simulated clock)."""
    physics_hz: float = 50.0
    """Vehicle model and ground-truth rate, simulated Hz."""
    heartbeat_hz: float = 1.0
    """HEARTBEAT rate (1 Hz on both autopilots)."""
    adsb_hz: float = 2.0
    """ADSB_VEHICLE rate per intruder until a client asks for another with
    MAV_CMD_SET_MESSAGE_INTERVAL (246), per vehicle."""
    adsb_noise: bool = False
    """ADS-B reports carry the simulator's report errors (`sim.config.SensorConfig`'s EPU and
    NACv; `remarl_fc.sitl.traffic.ReportErrors`); off: exact reports, as ArduPilot's SITL
    sends them."""
    cruise_alt_m: float = 20.0
    """Height above the origin at which scenario intruders fly."""
    seed: int = 0
    """Seed of the mock's random generator (intruder spawn, noise, faults)."""
    model: VehicleModelConfig = field(default_factory=VehicleModelConfig)
    ardupilot: ArduPilotParams = field(default_factory=ArduPilotParams)
    px4: Px4Params = field(default_factory=Px4Params)

    def __post_init__(self) -> None:
        if self.flavour not in FLAVOURS:
            raise ValueError(f"flavour {self.flavour!r} is not one of {', '.join(FLAVOURS)}")
        if not 1 <= self.vehicles <= 250:
            raise ValueError(f"vehicles must be 1..250 (system ids), not {self.vehicles}")
        if not self.speedup > 0:
            raise ValueError(f"speedup must be > 0, not {self.speedup}")
        if not self.adsb_hz > 0:
            raise ValueError(f"adsb_hz must be > 0, not {self.adsb_hz}")
        if self.transport not in ("udp", "tcp"):
            raise ValueError(f"transport {self.transport!r} is not udp or tcp")
        if self.transport == "tcp" and self.out is not None:
            raise ValueError("--out is for UDP: a TCP vehicle sends to the client connected to it")
        if not self.physics_hz >= 10:
            raise ValueError(f"physics_hz must be ≥ 10, not {self.physics_hz}")
        last = self.port(self.vehicles - 1)
        if self.port(0) != 0 and not 1 <= last <= 65535:
            raise ValueError(f"ports {self.port(0)}..{last} do not fit in 1..65535")

    def port(self, index: int) -> int:
        """UDP port vehicle ``index`` binds (0 = any free port for every vehicle)."""
        if self.base_port == 0:
            return 0
        base, step = SITL_PORTS[self.transport, self.flavour]
        if self.base_port is not None:
            base = self.base_port
        if self.port_step is not None:
            step = self.port_step
        return base + step * index

    def out_address(self, index: int) -> tuple[str, int] | None:
        """Where vehicle ``index`` sends before (and besides) hearing a peer."""
        if self.out is None:
            return None
        return self.out[0], self.out[1] + self.out_step * index
