"""ADS-B traffic as the runtime sees it: one `Intruder` per track, in the mission frame.

`TrafficPicture.update` takes one decoded ADSB_VEHICLE, its monotonic receive time and the
(system id, component id) that sent it; `TrafficPicture.merge_shared` takes one detection that
another process of the swarm published on the bus. Nothing here does I/O. Positions are
converted once, at this boundary, into the mission's local frame (`remarl_fc.frames`).

Nothing on the link is trusted (the runtime's source gate, `remarl_fc.flight.trust`, already
drops ADSB_VEHICLE from anyone but the bound autopilots and the sources the mission names; this
module assumes even those may be wrong):

* **Range checks.** A report is dropped, and counted in `TrafficPicture.rejected` under its
  reason, when its latitude, longitude, altitude, horizontal speed, heading or time since last
  contact is outside what an aircraft can report (the ``*_DEG_E7``, ``*_ALTITUDE_M``,
  `MAX_ADSB_SPEED_M_S`, `MAX_RANGE_M` constants), or it is older than ``max_age_s``.
* **Tracks by (source, ICAO).** One source's report never overwrites another source's track of
  the same ICAO address. When two sources place the same ICAO further apart than
  `conflict_distance_m` (both extrapolated to the same time), the conflict is counted and
  **both tracks stay obstacles**: we cannot tell which one is true, and avoiding a phantom
  costs a detour while ignoring the real one may cost a collision. Tracks of the same ICAO
  that agree are one obstacle (`TrafficPicture.current` returns the freshest).
* **Caps.** At most `MAX_TRACKS_STORED` tracks are kept: when full, stale tracks go first,
  then the track *farthest* from the swarm (the last ``near_ne_m`` given to `current`, else the
  mission origin) — a new report farther than all kept ones is dropped instead. A flood of
  random ICAO addresses therefore cannot grow memory, nor push out a near intruder.
  `TrafficPicture.current` returns at most `MAX_TRACKS_USED`, nearest first.
* **The swarm bus.** Detections shared by other processes are keyed by
  ``(("peer", system id), ICAO)``, pass the same checks on metres and m/s, and give way to our
  own fresh report of the same ICAO.
* **The track filter** (``noise``, `FlyConfig.track_filter`): each report from the link is
  fused into its track by the simulator's filter (`sim.sensors.fuse`: constant velocity, an
  innovation gate that restarts a track on a report it did not expect); without it a track is
  its newest report. A shared detection is the peer's own track, stored as it comes.
"""

from __future__ import annotations

import math
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Literal

import numpy as np

from remarl_fc.flight.tracking import FloatArray
from remarl_fc.frames import GeoPoint, from_deg_e7, geodetic_to_ned
from remarl_fc.mavlink.consts import AdsbFlag
from sim.sensors import TRACK_MAX_AGE_S, TrackNoise, extrapolate, fuse, is_fresh, report_time

LinkSource = tuple[int, int]
"""(system id, component id) of the MAVLink sender of an ADSB_VEHICLE."""

PeerSource = tuple[Literal["peer"], int]
"""("peer", system id) of a vehicle whose detections came over the swarm bus."""

Source = LinkSource | PeerSource
TrackKey = tuple[Source, int]
"""(source, ICAO address): one track."""

MAX_LAT_DEG_E7 = 900_000_000
"""|latitude| ≤ 90°, in degE7: the poles. Anything beyond is not a place."""

MAX_LON_DEG_E7 = 1_800_000_000
"""|longitude| ≤ 180°, in degE7: the antimeridian. Anything beyond is not a place."""

MIN_ALTITUDE_M = -500.0
"""Lowest plausible altitude, metres AMSL: the shore of the Dead Sea, the lowest dry land on
Earth, lies at about −430 m."""

MAX_ALTITUDE_M = 20_000.0
"""Highest plausible altitude, metres AMSL: above FL600 (18,288 m), the ceiling of class A
airspace and above that of every airliner and business jet (FL510 ≈ 15,500 m)."""

MAX_ADSB_SPEED_M_S = 400.0
"""Highest plausible horizontal speed (ground speed), m/s (≈ 780 kt).

Above the speed of sound at sea level (≈ 340 m/s; civil supersonic flight over land is
prohibited, 14 CFR 91.817) and the fastest ground speed recorded by a subsonic airliner
(≈ 370 m/s, in a jet-stream tailwind at cruise); 500 m/s reports are rejected. The 250 kt
(≈ 130 m/s) limit below 10,000 ft MSL (14 CFR 91.117(a); SERA.6001 in Europe) is deliberately
*not* used here: it is a rule, not physics — military training routes are flown at 420–500 kt
below 10,000 ft under its exemptions, airliners above 10,000 ft fly at 250 m/s — and a reject
threshold at 130 m/s would hide exactly the fastest real intruders. A mission may tighten it
(`TrafficPicture.max_speed_m_s`).
"""

MAX_RANGE_M = 100_000.0
"""Farthest plausible track from the mission origin, metres (horizontal).

At `MAX_ADSB_SPEED_M_S` an aircraft needs 250 s to cover it, 50 times the default ``max_age_s``: a
track beyond it cannot reach a swarm flying a few kilometres round the origin before it
expires. It also bounds the error of the tangent-plane conversion (`remarl_fc.frames`, second
order in the distance: ~100 m at this range).
"""

MAX_HEADING_CDEG = 35_999
"""ADSB_VEHICLE.heading, centidegrees 0..35999 (common.xml); more with VALID_HEADING is
malformed."""

MAX_TRACKS_STORED = 256
"""Tracks kept at most (all sources). 2.5× the 100-odd aircraft a 1090 MHz receiver hears over
a busy hub; a flood beyond it replaces the farthest track, never grows memory."""

MAX_TRACKS_USED = 16
"""Tracks `TrafficPicture.current` returns at most, nearest first: more intruders than this
within the height band of a small swarm is an attack or an emergency, not traffic to thread."""

NACP_EPU_M = 92.6
"""Horizontal position uncertainty of a mandated ADS-B Out position (NACp ≥ 8, EPU < 0.05 NM;
14 CFR 91.227(c)(1)(i))."""

TSLC_QUANTUM_S = 1.0
"""ADSB_VEHICLE.tslc is whole seconds, so a track's time is uncertain by up to 1 s."""

CONFLICT_BASE_M = 2 * NACP_EPU_M + 15.0
"""Two honest reports of one aircraft lie within this of each other (both at their EPU, plus
15 m for the quantisation to degE7 and mm and the 25 ft altitude steps); 200 m. Beyond it, and
beyond what the `TSLC_QUANTUM_S` timing error at the faster track's speed explains, the two
sources disagree: a conflict."""

SWEEP_EVERY_S = 0.1
"""A full picture looks for stale tracks to drop at most this often (s) when a new track
arrives, not at every report of a flood; `TrafficPicture.current` always does."""

_SHARED = "shared: "
"""Prefix of the rejection reasons of swarm-bus detections."""

CAPPED = "track cap (farther than all kept)"
"""The rejection reason of a report the full picture had no room for."""

ROUTINE_REJECTIONS = frozenset({"stale", CAPPED, _SHARED + "stale", _SHARED + CAPPED})
"""Rejection reasons that busy but honest traffic produces too (old reports, a full picture):
no sign of a faulty or hostile source, unlike the range checks."""

_VALID_COORDS, _VALID_ALTITUDE = int(AdsbFlag.VALID_COORDS), int(AdsbFlag.VALID_ALTITUDE)
_VALID_HEADING, _VALID_VELOCITY = int(AdsbFlag.VALID_HEADING), int(AdsbFlag.VALID_VELOCITY)


@dataclass
class Intruder:
    """One ADS-B track in the mission frame."""

    ne_m: FloatArray
    height_m: float
    vel_ne_m_s: FloatArray
    t: float
    shared: bool = False  # learnt from another vehicle over the swarm bus
    cov: FloatArray | None = None  # the track filter's (P_pp, P_pv, P_vv); None: unfiltered

    def predicted_ne_m(self, now: float) -> FloatArray:
        """Position extrapolated at constant velocity to ``now`` (`sim.sensors.extrapolate`)."""
        return extrapolate(self.ne_m, self.vel_ne_m_s, self.t, now)


def conflict_distance_m(a: Intruder, b: Intruder) -> float:
    """How far apart (m) two reports of one ICAO may be, at one time, before they conflict."""
    speed = max(math.hypot(*a.vel_ne_m_s.tolist()), math.hypot(*b.vel_ne_m_s.tolist()))
    return CONFLICT_BASE_M + TSLC_QUANTUM_S * speed


def _is_peer(source: Source) -> bool:
    return source[0] == "peer"


@dataclass
class TrafficPicture:
    """ADS-B traffic by (source, ICAO address): checked ADSB_VEHICLE, and shared detections.

    Attributes:
        origin: the mission origin. max_age_s: a track older than this is dropped
            (`sim.sensors.TRACK_MAX_AGE_S`, which the simulator's tracker uses too).
        noise: the track filter's assumptions (`sim.sensors.TrackNoise`); None: no filter,
            a track is its newest report.
        max_speed_m_s: reports faster than this are rejected (`MAX_ADSB_SPEED_M_S`).
        max_stored: tracks kept at most. max_used: tracks `current` returns at most.
        rejected: reports dropped, by reason. conflicts: reports that placed an ICAO further
            than `conflict_distance_m` from another source's fresh track of it.
        evicted: tracks removed to make room for a nearer one.
        reference_ne_m: where "near" is (the swarm centre last given to `current`).
    """

    origin: GeoPoint
    max_age_s: float = TRACK_MAX_AGE_S
    max_speed_m_s: float = MAX_ADSB_SPEED_M_S
    max_stored: int = MAX_TRACKS_STORED
    max_used: int = MAX_TRACKS_USED
    noise: TrackNoise | None = None
    rejected: Counter[str] = field(default_factory=Counter)
    conflicts: int = 0
    evicted: int = 0
    reference_ne_m: FloatArray = field(default_factory=lambda: np.zeros(2))
    _tracks: dict[TrackKey, Intruder] = field(default_factory=dict, init=False, repr=False)
    _by_icao: dict[int, set[TrackKey]] = field(default_factory=dict, init=False, repr=False)
    _far: dict[TrackKey, float] = field(default_factory=dict, init=False, repr=False)
    _swept_at: float = field(default=-math.inf, init=False, repr=False)

    @property
    def tracks(self) -> Mapping[TrackKey, Intruder]:
        """Every track kept, by (source, ICAO), read-only (stale ones until `current` runs)."""
        return MappingProxyType(self._tracks)

    # -- in -------------------------------------------------------------------------------

    def update(self, msg: Any, now: float, *, source: LinkSource) -> bool:
        """Take one ADSB_VEHICLE from ``source`` (system id, component id); True if kept."""
        flags = int(msg.flags)
        if not flags & _VALID_COORDS:
            return self._reject("no valid coordinates")
        lat, lon = int(msg.lat), int(msg.lon)
        if not -MAX_LAT_DEG_E7 <= lat <= MAX_LAT_DEG_E7:
            return self._reject("latitude out of range")
        if not -MAX_LON_DEG_E7 <= lon <= MAX_LON_DEG_E7:
            return self._reject("longitude out of range")
        alt_m = int(msg.altitude) / 1000.0
        has_alt = bool(flags & _VALID_ALTITUDE)
        if has_alt and not MIN_ALTITUDE_M <= alt_m <= MAX_ALTITUDE_M:
            return self._reject("altitude out of range")
        speed = int(msg.hor_velocity) / 100.0 if flags & _VALID_VELOCITY else 0.0
        if speed > self.max_speed_m_s:
            return self._reject("impossible speed")
        heading = int(msg.heading) if flags & _VALID_HEADING else 0
        if not 0 <= heading <= MAX_HEADING_CDEG:
            return self._reject("heading out of range")
        age = float(msg.tslc)
        if age > self.max_age_s:
            return self._reject("stale")
        # ver_velocity is not used (the policy avoids sideways only), so it is not checked.
        n, e, d = geodetic_to_ned(from_deg_e7(lat), from_deg_e7(lon), alt_m, self.origin)
        ne = np.array([float(n), float(e)])
        if math.hypot(*ne.tolist()) > MAX_RANGE_M:
            return self._reject("out of range")
        course = math.radians(heading / 100.0)
        vel = np.array([speed * math.cos(course), speed * math.sin(course)])
        height = -float(d) if has_alt else math.nan  # unknown altitude: at every height
        key: TrackKey = ((int(source[0]), int(source[1])), int(msg.ICAO_address))
        report = Intruder(ne, height, vel, report_time(now, age))
        return self._store(key, self._filtered(key, report), now, "")

    def merge_shared(
        self,
        peer_id: int,
        icao: int,
        ne_m: Sequence[float],
        height_m: float | None,
        vel_ne_m_s: Sequence[float],
        t: float,
        now: float,
    ) -> bool:
        """Take one detection another process published (bus, mission frame); True if kept.

        Args:
            peer_id: the publishing vehicle's system id. icao: the ICAO address.
            ne_m: position (north, east), m. height_m: height above the origin, m; None if
                unknown. vel_ne_m_s: velocity (north, east), m/s.
            t: our monotonic time of the batch. now: our monotonic time.

        Our own fresh report of the same ICAO takes precedence: the detection is then ignored
        (not counted). An older or equally old detection than the one kept from this peer is
        ignored too (the first of a batch wins: `Peers` publishes nearest first).
        """
        values = (*ne_m, *vel_ne_m_s, t, 0.0 if height_m is None else height_m)
        if len(ne_m) != 2 or len(vel_ne_m_s) != 2 or not all(map(math.isfinite, values)):
            return self._reject(_SHARED + "not finite")
        ne = np.array([float(ne_m[0]), float(ne_m[1])])
        vel = np.array([float(vel_ne_m_s[0]), float(vel_ne_m_s[1])])
        if math.hypot(*ne.tolist()) > MAX_RANGE_M:
            return self._reject(_SHARED + "out of range")
        height = math.nan if height_m is None else float(height_m)
        if height_m is not None and not (
            MIN_ALTITUDE_M <= self.origin.alt_m + height <= MAX_ALTITUDE_M
        ):
            return self._reject(_SHARED + "altitude out of range")
        if math.hypot(*vel.tolist()) > self.max_speed_m_s:
            return self._reject(_SHARED + "impossible speed")
        if not is_fresh(t, now, self.max_age_s):
            return self._reject(_SHARED + "stale")
        if t > now + TSLC_QUANTUM_S:
            return self._reject(_SHARED + "from the future")
        if self._own_fresh(int(icao), now):
            return False  # our own ADS-B sees it: keep ours
        key: TrackKey = (("peer", int(peer_id)), int(icao))
        old = self._tracks.get(key)
        if old is not None and old.t >= t:
            return False
        return self._store(key, Intruder(ne, height, vel, float(t), shared=True), now, _SHARED)

    # -- out ------------------------------------------------------------------------------

    def current(
        self,
        now: float,
        height_m: float,
        band_m: float,
        near_ne_m: Sequence[float] | FloatArray | None = None,
    ) -> list[Intruder]:
        """At most ``max_used`` tracks younger than `max_age_s`, within ±``band_m`` of ``height_m``.

        Tracks of unknown altitude (no VALID_ALTITUDE flag) are kept, to be safe. Of the tracks
        of one ICAO, a shared one gives way to our own fresh one, and tracks that agree (within
        `conflict_distance_m` at ``now``) count once, the freshest; conflicting ones all count.
        Nearest (at ``now``) to ``near_ne_m`` first — the swarm centre, which also becomes the
        `reference_ne_m` that decides which track a full picture drops — else to the last
        reference (at first the mission origin).
        """
        if near_ne_m is not None:
            near = np.asarray(near_ne_m, dtype=np.float64).reshape(2)
            if np.all(np.isfinite(near)):
                self.reference_ne_m = near.copy()
        self._expire(now)
        own_icaos = {icao for (src, icao) in self._tracks if not _is_peer(src)}
        groups: dict[int, list[tuple[float, Intruder]]] = {}
        for key, v in self._tracks.items():
            d = self._far[key] = self._distance(v, now)
            src, icao = key
            if _is_peer(src) and icao in own_icaos:
                continue  # our own ADS-B sees it: keep ours
            if math.isnan(v.height_m) or abs(v.height_m - height_m) <= band_m:
                groups.setdefault(icao, []).append((d, v))  # unknown altitude: at every height
        chosen: list[tuple[float, Intruder]] = []
        for group in groups.values():
            kept: list[tuple[float, Intruder]] = []
            for d, v in sorted(group, key=lambda dv: -dv[1].t):  # freshest first
                if all(_gap_m(v, w, now) > conflict_distance_m(v, w) for _, w in kept):
                    kept.append((d, v))
            chosen += kept
        chosen.sort(key=lambda dv: dv[0])
        return [v for _, v in chosen[: self.max_used]]

    def own_tracks(self, now: float) -> list[tuple[int, Intruder]]:
        """(ICAO, track) of our own (not shared) fresh tracks, nearest to the reference first."""
        own = [
            (self._distance(v, now), icao, v)
            for (src, icao), v in self._tracks.items()
            if not _is_peer(src) and is_fresh(v.t, now, self.max_age_s)
        ]
        own.sort(key=lambda x: x[0])
        return [(icao, v) for _, icao, v in own]

    def stats(self) -> dict[str, Any]:
        """JSON-ready counters for the flight summary."""
        shared = sum(1 for src, _ in self._tracks if _is_peer(src))
        return {
            "tracks": len(self._tracks),
            "filtered": self.noise is not None,
            "own": len(self._tracks) - shared,
            "shared": shared,
            "rejected": dict(sorted(self.rejected.items())),
            "conflicts": self.conflicts,
            "evicted": self.evicted,
        }

    # -- inside ---------------------------------------------------------------------------

    def _filtered(self, key: TrackKey, report: Intruder) -> Intruder:
        """``report`` fused into the track held under ``key`` (`sim.sensors.fuse`), if filtering.

        With no track held (or a stale one) the filter starts from the report.
        """
        if self.noise is None:
            return report
        old = self._tracks.get(key)
        if old is not None and old.cov is not None:
            prior = (old.ne_m, old.vel_ne_m_s, old.cov, old.t)
        else:  # nothing to fuse: a time of −inf starts the track from the report
            prior = (np.full(2, math.nan), np.full(2, math.nan), np.zeros(3), -math.inf)
        pos, vel, cov, t = fuse(*prior, report.ne_m, report.vel_ne_m_s, report.t, self.noise)
        return Intruder(pos, report.height_m, vel, float(t), cov=cov)

    def _reject(self, reason: str) -> bool:
        self.rejected[reason] += 1
        return False

    def _distance(self, v: Intruder, now: float) -> float:
        """Horizontal distance (m) of ``v`` at ``now`` from the reference."""
        (n, e), (rn, re) = _at(v, now), self.reference_ne_m
        return math.hypot(n - float(rn), e - float(re))

    def _own_fresh(self, icao: int, now: float) -> bool:
        return any(
            not _is_peer(k[0]) and is_fresh(self._tracks[k].t, now, self.max_age_s)
            for k in self._by_icao.get(icao, ())
        )

    def _store(self, key: TrackKey, new: Intruder, now: float, prefix: str) -> bool:
        """Keep ``new`` under ``key``: room (the cap), then the conflict check, then in."""
        far = self._distance(new, now)
        if key not in self._tracks and len(self._tracks) >= self.max_stored:
            if now - self._swept_at >= SWEEP_EVERY_S:
                self._expire(now)
            if len(self._tracks) >= self.max_stored:
                # distances as of each track's last report or the last `current`: cheap, and
                # good enough to tell the far from the near.
                farthest = max(self._far.values())
                if far >= farthest:
                    return self._reject(prefix + CAPPED)
                self._drop(next(k for k, d in self._far.items() if d == farthest))
                self.evicted += 1
        icao = key[1]
        for other in self._by_icao.get(icao, ()):
            old = self._tracks[other]
            if other[0] == key[0] or not is_fresh(old.t, now, self.max_age_s):
                continue
            if _gap_m(new, old, now) > conflict_distance_m(new, old):
                self.conflicts += 1  # both stay: we cannot tell which one is true
                break
        self._tracks[key] = new
        self._far[key] = far
        self._by_icao.setdefault(icao, set()).add(key)
        return True

    def _drop(self, key: TrackKey) -> None:
        del self._tracks[key], self._far[key]
        keys = self._by_icao[key[1]]
        keys.discard(key)
        if not keys:
            del self._by_icao[key[1]]

    def _expire(self, now: float) -> None:
        self._swept_at = now
        for key in [k for k, v in self._tracks.items() if not is_fresh(v.t, now, self.max_age_s)]:
            self._drop(key)


def _at(v: Intruder, now: float) -> tuple[float, float]:
    """`Intruder.predicted_ne_m` in plain floats (the hot paths call it per track).

    The same operations as `sim.sensors.extrapolate`, so the same bits (tests/sim/test_sensors.py
    checks it), at a tenth of the cost of numpy on two-element arrays.
    """
    dt = max(0.0, now - v.t)
    (n, e), (vn, ve) = v.ne_m.tolist(), v.vel_ne_m_s.tolist()
    return n + vn * dt, e + ve * dt


def _gap_m(a: Intruder, b: Intruder, now: float) -> float:
    """Horizontal distance (m) between two tracks, both extrapolated to ``now``."""
    (an, ae), (bn, be) = _at(a, now), _at(b, now)
    return math.hypot(an - bn, ae - be)
