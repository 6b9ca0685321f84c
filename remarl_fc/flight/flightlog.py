"""Flight logs: read a run's ``.tlog`` and ``decisions.jsonl`` back, and draw the flight.

A log folder (``remarl-fc fly --log DIR``) holds ``flight.tlog`` (or ``linkK.tlog``, one per
connection: every MAVLink frame in and out, pymavlink's format) and ``decisions.jsonl`` (a
``mission`` header line, then one line per vehicle per decision and one per event).
`remarl-fc plot-flight DIR --out flight.png` draws the flown tracks (from the vehicles'
GLOBAL_POSITION_INT, 10 Hz), the intruders (from ADSB_VEHICLE), the targets, and the distances
over time to the nearest intruder and the nearest other vehicle against d_col.
"""

from __future__ import annotations

import dataclasses
import json
import struct
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

import numpy as np
from numpy.typing import NDArray

from remarl_fc.errors import ConfigError
from remarl_fc.flight.mission import Mission
from remarl_fc.frames import GeoPoint, from_deg_e7, geodetic_to_ned
from remarl_fc.mavlink.codec import Codec
from remarl_fc.mavlink.consts import MsgId

FloatArray = NDArray[np.float64]

TLOG_STAMP = struct.Struct(">Q")
"""Each .tlog record: a big-endian µs timestamp, then one MAVLink frame."""

MAVLINK2_HEADER, MAVLINK1_HEADER, SIGNATURE, CRC = 10, 6, 13, 2
"""Frame sizes (bytes) besides the payload."""


class FlightLogError(ConfigError):
    """A log folder that cannot be read."""


def read_tlog(path: str | Path) -> list[tuple[float, Any]]:
    """Every valid message of a .tlog as (wall time s, message), in order."""
    data = Path(path).read_bytes()
    codec = Codec(254, 0)
    out: list[tuple[float, Any]] = []
    i = 0
    while i + TLOG_STAMP.size + 2 <= len(data):
        (stamp,) = TLOG_STAMP.unpack_from(data, i)
        start = i + TLOG_STAMP.size
        magic, length = data[start], data[start + 1]
        if magic == 0xFD:
            size = MAVLINK2_HEADER + length + CRC + (SIGNATURE if data[start + 2] & 1 else 0)
        elif magic == 0xFE:
            size = MAVLINK1_HEADER + length + CRC
        else:  # not at a record boundary: resynchronise one byte on
            i += 1
            continue
        out += [(stamp / 1e6, m) for m in codec.decode(data[start : start + size], "tlog")]
        i = start + size
    return out


class DecisionLog:
    """The writer of ``decisions.jsonl``: the mission header line, then rows and events.

    `read_flight` reads it back; `mission_header` makes the header it needs.
    """

    def __init__(self, fh: IO[str], header: dict[str, Any]) -> None:
        self._fh = fh
        self.write({"mission": header})

    def event(self, t: float, system_id: int, text: str) -> None:
        """One event of one vehicle at flight time ``t`` (s)."""
        self.write({"t": round(t, 3), "system_id": system_id, "event": text})

    def write(self, row: dict[str, Any]) -> None:
        """One JSON line."""
        self._fh.write(json.dumps(row) + "\n")

    def flush(self) -> None:
        """Hand what is written to the OS (after each decision: a crash loses at most one)."""
        self._fh.flush()


def mission_header(
    mission: Mission, *, d_col_m: float, speed_m_s: float, dt_s: float, speedup: float
) -> dict[str, Any]:
    """The first line of ``decisions.jsonl``: what `read_flight` needs to place the tracks."""
    return {
        "origin": dataclasses.asdict(mission.origin),
        "targets_ne_m": {str(p.system_id): list(p.target_ne_m) for p in mission.vehicles},
        "d_col_m": d_col_m,
        "speed_m_s": speed_m_s,
        "dt_s": dt_s,
        "source": mission.source,
        "speedup": speedup,
    }


@dataclass
class FlightRecord:
    """Tracks of one flight in the mission frame.

    Attributes:
        origin: the mission origin; targets_ne_m: system id → (2,) target; d_col_m.
        vehicles: system id → (T, 4) [t, north, east, height]; intruders: ICAO → (T, 3)
        [t, north, east]; events: (t, system id, text).
    """

    origin: GeoPoint
    targets_ne_m: dict[int, FloatArray]
    d_col_m: float
    vehicles: dict[int, FloatArray] = field(default_factory=dict)
    intruders: dict[int, FloatArray] = field(default_factory=dict)
    events: list[tuple[float, int, str]] = field(default_factory=list)


def read_flight(log_dir: str | Path) -> FlightRecord:
    """Read a log folder written by ``remarl-fc fly --log``."""
    folder = Path(log_dir)
    decisions = folder / "decisions.jsonl"
    tlogs = sorted(folder.glob("*.tlog"))
    if not decisions.is_file() or not tlogs:
        raise FlightLogError(
            f"{folder}: not a flight log folder (needs decisions.jsonl and a .tlog); "
            "write one with remarl-fc fly --log DIR"
        )
    lines = decisions.read_text().splitlines()
    try:
        head = json.loads(lines[0])["mission"]
    except (IndexError, KeyError, json.JSONDecodeError) as exc:
        raise FlightLogError(f"{decisions}: the first line is not the mission header") from exc
    origin = GeoPoint(**head["origin"])
    record = FlightRecord(
        origin,
        {int(k): np.array(v) for k, v in head["targets_ne_m"].items()},
        float(head["d_col_m"]),
    )
    for line in lines[1:]:
        row = json.loads(line)
        if "event" in row:
            record.events.append((row["t"], row["system_id"], row["event"]))
    veh: dict[int, list[list[float]]] = defaultdict(list)
    intr: dict[int, list[list[float]]] = defaultdict(list)
    t0: float | None = None
    scale = float(head.get("speedup", 1.0))  # a mock flown faster than real time
    for tlog in tlogs:
        for t, msg in read_tlog(tlog):
            mid = msg.get_msgId()
            if (
                mid == MsgId.GLOBAL_POSITION_INT
                and msg.lat != 0
                and msg.get_srcSystem() in record.targets_ne_m
            ):
                n, e, d = geodetic_to_ned(
                    from_deg_e7(msg.lat), from_deg_e7(msg.lon), msg.alt / 1000, origin
                )
                t0 = t if t0 is None else t0
                veh[msg.get_srcSystem()].append([(t - t0) * scale, float(n), float(e), -float(d)])
            elif mid == MsgId.ADSB_VEHICLE and msg.flags & 1:
                n, e, _ = geodetic_to_ned(from_deg_e7(msg.lat), from_deg_e7(msg.lon), 0.0, origin)
                t0 = t if t0 is None else t0
                intr[int(msg.ICAO_address)].append([(t - t0) * scale, float(n), float(e)])
    record.vehicles = {k: np.array(sorted(v)) for k, v in veh.items()}
    record.intruders = {k: _dedupe(np.array(sorted(v))) for k, v in intr.items()}
    return record


def _dedupe(track: FloatArray) -> FloatArray:
    """One sample per report time (every vehicle relays the same intruder report)."""
    if len(track) == 0:
        return track
    keep = np.concatenate([[True], np.diff(track[:, 0]) > 0.05])
    out: FloatArray = track[keep]
    return out


def distances_over_time(record: FlightRecord, step_s: float = 0.5) -> dict[str, Any]:
    """Per vehicle, on a common time grid: distance to the nearest intruder and vehicle."""
    ends = [tr[-1, 0] for tr in record.vehicles.values() if len(tr)]
    if not ends:
        return {"t": np.zeros(0), "intruder": {}, "vehicle": {}}
    grid = np.arange(0.0, max(ends), step_s)

    def at(track: FloatArray) -> FloatArray:
        return np.stack(
            [np.interp(grid, track[:, 0], track[:, k], left=np.nan, right=np.nan) for k in (1, 2)],
            axis=-1,
        )

    pos = {k: at(v) for k, v in record.vehicles.items() if len(v) > 1}
    obs = [at(v) for v in record.intruders.values() if len(v) > 1]
    to_intr, to_veh = {}, {}
    for k, p in pos.items():
        d_i = [np.hypot(*(p - o).T) for o in obs]
        d_v = [np.hypot(*(p - q).T) for j, q in pos.items() if j != k]
        to_intr[k] = np.fmin.reduce(d_i) if d_i else np.full(len(grid), np.nan)
        to_veh[k] = np.fmin.reduce(d_v) if d_v else np.full(len(grid), np.nan)
    return {"t": grid, "intruder": to_intr, "vehicle": to_veh}


def plot_flight(log_dir: str | Path, out: str | Path) -> dict[str, Any]:
    """Draw the flight of a log folder; returns the figures drawn (min distances)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle

    record = read_flight(log_dir)
    dist = distances_over_time(record)
    fig, (ax, ax_d) = plt.subplots(1, 2, figsize=(13, 5.5), gridspec_kw={"width_ratios": [1.1, 1]})
    colours = plt.get_cmap("tab10")
    for k, (sysid, tr) in enumerate(sorted(record.vehicles.items())):
        c = colours(k % 10)
        ax.plot(tr[:, 2], tr[:, 1], color=c, lw=1.8, label=f"vehicle {sysid}")
        ax.plot(tr[0, 2], tr[0, 1], "o", color=c)
        tgt = record.targets_ne_m.get(sysid)
        if tgt is not None:
            ax.plot(tgt[1], tgt[0], "*", color=c, ms=12)
            ax.add_patch(Circle((tgt[1], tgt[0]), record.d_col_m, color=c, fill=False, ls=":"))
        ax_d.plot(
            dist["t"], dist["intruder"].get(sysid, []), color=c, lw=1.5, label=f"{sysid} ↔ intruder"
        )
        ax_d.plot(
            dist["t"],
            dist["vehicle"].get(sysid, []),
            color=c,
            lw=1.0,
            ls="--",
            label=f"{sysid} ↔ vehicle",
        )
    for icao, tr in record.intruders.items():
        ax.plot(tr[:, 2], tr[:, 1], color="k", lw=2.5, alpha=0.6)
        ax.add_patch(Circle((tr[-1, 2], tr[-1, 1]), record.d_col_m, color="k", alpha=0.15))
        ax.annotate(f"{icao:06X}", (tr[0, 2], tr[0, 1]), fontsize=7)
    ax.set_aspect("equal")
    ax.set_xlabel("east [m]")
    ax.set_ylabel("north [m]")
    ax.set_title("flown tracks (●start, ★target), intruders in black")
    ax.legend(fontsize=7, loc="best")
    ax_d.axhline(record.d_col_m, color="r", lw=1, label="d_col")
    ax_d.set_xlabel("time [s]")
    ax_d.set_ylabel("distance [m]")
    ax_d.set_ylim(0, 150)
    ax_d.set_title("nearest intruder (solid) and vehicle (dashed)")
    ax_d.legend(fontsize=6, ncol=2)
    fig.tight_layout()
    out_path = Path(out)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out_path, dpi=110)
    plt.close(fig)

    def smallest(series: dict[int, FloatArray]) -> float | None:
        vals = [float(np.nanmin(v)) for v in series.values() if np.isfinite(v).any()]
        return round(min(vals), 2) if vals else None

    return {
        "out": str(out_path),
        "vehicles": sorted(record.vehicles),
        "intruders": len(record.intruders),
        "min_distance_to_intruder_m": smallest(dist["intruder"]),
        "min_distance_vehicle_vehicle_m": smallest(dist["vehicle"]),
    }
