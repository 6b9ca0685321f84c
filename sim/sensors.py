"""What the UAVs sense of the intruders: ADS-B reports, tracked as the runtime tracks them.

The simulator knows every intruder's true track; a UAV knows only the ADS-B reports that reached
it. This module turns the one into the other, batch first, and holds the pieces the runtime's
tracker (`remarl_fc.flight.traffic`) uses itself, so that a policy trains on the picture `fly`
will give it:

* `report_time` — the time a report is taken to describe: its receive time less its age as
  ADSB_VEHICLE.tslc states it (whole seconds).
* `extrapolate` — a report carried to ``now`` at constant velocity, never backwards.
* `is_fresh` and `TRACK_MAX_AGE_S` — a track is used while ``now − report time ≤ 5 s``.

Each intruder (`AdsbTracks`, per environment b and intruder m) transmits at its own rate from a
random phase; each report reaches the runtime after its own latency, or is lost. The newest
report that arrived replaces the one held; between reports the track is extrapolated. Like the
runtime, the tracker does not know the latency: it stamps a report with its receive time less
`ADSB_TSLC_S`, so the picture lags the truth by about the intruder's speed times its latency,
as in flight. With `SensorConfig.adsb_filter` a track fuses its reports instead (`fuse`: a
constant-velocity Kalman filter, the runtime's too). `docs/MODEL.md` gives the numbers and what
the model leaves out.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import overload

import numpy as np

from sim.arrays import BoolArray, FloatArray
from sim.config import SensorConfig

TRACK_MAX_AGE_S = 5.0
"""A track whose report time is older than this (s) is no longer used, here and in flight.

Long enough to ride out lost reports: at the slowest rate (1 Hz) a track expires only when five
reports in a row are lost, once in 10⁵ reports at the 10% loss rate. Short enough that a track
still says where the aircraft is: at 3 m/s velocity error (NACv 2) the extrapolation drifts 15 m in
5 s, within the 10–30 m of the position itself, and an aircraft at 50 m/s in a standard-rate
turn (3°/s) leaves the straight extrapolation by ½·v·ω·t² ≈ 33 m in that time.
"""

ADSB_TSLC_S = 0.0
"""The ADSB_VEHICLE.tslc (s) of a simulated report: the whole seconds of its age the forwarding
receiver or autopilot counts, from when *it* heard the aircraft. At 1–2 Hz a live track was
heard within the last second, and tslc truncates to whole seconds: 0 (the SITL mock sends 0
too). The transponder's and the link's latency are not counted: the runtime cannot correct
for them, and neither does the simulated tracker."""

POSITION_95_TO_SIGMA = 2.448
"""95% radius of a circular 2-D Gaussian in units of its per-axis σ: √(−2 ln 0.05) = 2.4477.
EPU and NACv are 95% horizontal radii, so σ per axis = EPU / 2.448 (NACv likewise)."""


def report_sigmas(epu_m: FloatArray, nacv_m_s: float) -> tuple[FloatArray, float]:
    """(position σ per axis, m; velocity σ per axis, m/s) of reports with these 95% radii.

    >>> pos, vel = report_sigmas(np.array([24.48]), 2.448)
    >>> pos.round(6).tolist(), round(vel, 6)
    ([10.0], 1.0)
    """
    return epu_m / POSITION_95_TO_SIGMA, nacv_m_s / POSITION_95_TO_SIGMA


@overload
def report_time(receive_s: float, tslc_s: float) -> float: ...
@overload
def report_time(receive_s: FloatArray, tslc_s: float | FloatArray) -> FloatArray: ...
def report_time(receive_s: float | FloatArray, tslc_s: float | FloatArray) -> float | FloatArray:
    """The time (s) a report describes as the tracker takes it: receive time less its tslc.

    >>> report_time(10.0, 3.0)
    7.0
    """
    return receive_s - tslc_s


@overload
def is_fresh(t_report_s: float, now_s: float, max_age_s: float = ...) -> bool: ...
@overload
def is_fresh(
    t_report_s: FloatArray, now_s: float | FloatArray, max_age_s: float = ...
) -> BoolArray: ...
def is_fresh(
    t_report_s: float | FloatArray, now_s: float | FloatArray, max_age_s: float = TRACK_MAX_AGE_S
) -> bool | BoolArray:
    """Whether a track with report time ``t_report_s`` is still used at ``now_s`` (age ≤ max).

    >>> is_fresh(0.0, 5.0), is_fresh(0.0, 5.5), is_fresh(-math.inf, 0.0)
    (True, False, False)
    """
    return now_s - t_report_s <= max_age_s


def extrapolate(
    pos: FloatArray, vel: FloatArray, t_report: float | FloatArray, now: float | FloatArray
) -> FloatArray:
    """``pos + vel · max(0, now − t_report)``: a report carried at constant velocity to ``now``.

    Shapes: ``pos``, ``vel`` (..., 2); ``t_report``, ``now`` (...) or scalars (broadcast). A
    report time after ``now`` (clock skew of a shared detection) is not extrapolated backwards.

    >>> extrapolate(np.array([1.0, 2.0]), np.array([3.0, 0.0]), 1.0, 3.0).tolist()
    [7.0, 2.0]
    """
    dt = np.maximum(0.0, np.subtract(now, t_report, dtype=np.float64))  # (...)
    out: FloatArray = pos + vel * dt[..., np.newaxis]
    return out


def gps_error(shape: tuple[int, ...], sigma_m: float, rng: np.random.Generator) -> FloatArray:
    """Gaussian GPS errors of ``sigma_m`` per axis, (shape); zero σ: zeros, no draw.

    The simulator's error of every UAV position and the mock's error of a reported one.
    """
    if sigma_m == 0.0:
        return np.zeros(shape)
    error: FloatArray = rng.standard_normal(shape)
    error *= sigma_m  # σ · draw, in place
    return error


FILTER_GATE = 18.47
"""Innovation gate of the track filter: the χ² value (4 degrees of freedom: a report's position
and velocity, two axes each) that a report the filter expected exceeds once in 1,000. A report
beyond it — an aircraft that turned harder than `SensorConfig.adsb_filter_accel_m_s2` allows,
or a jump — restarts the track from that report alone rather than being averaged away."""


FILTER_VELOCITY_VARIANCE_SCALE = 4.0
"""How many times NACv's variance the track filter takes a reported velocity's error to have.
A velocity error that persists from report to report (a GNSS Doppler bias; the errors
correlated over `SensorConfig.adsb_error_tau_s`) would otherwise be carried through the
filter's memory into the position; trusting the reported velocity less lets the positions'
differences say more. Measured (docs/MODEL.md §18): at 1× the filter flew the shipped generalist
8 points worse than raw reports with errors correlated over 60 s; at 4× as well as raw reports
there, and 12 points better with independent errors; at 16× better correlated, worse
independent."""

MIN_REPORT_VARIANCE = 1e-6
"""Floor of the report variances the track filter assumes (m², (m/s)²): a configuration of
exact reports (EPU and NACv 0) fuses them as near-exact instead of dividing by zero."""


@dataclass(frozen=True)
class TrackNoise:
    """What the track filter assumes of the reports and of the aircraft (`fuse`).

    Attributes:
        pos_var_m2: variance of a report's position error per axis, m².
        vel_var_m2_s2: variance of a report's velocity error per axis, (m/s)².
        accel_var_m2_s4: white acceleration variance per axis, (m/s²)².
    """

    pos_var_m2: float
    vel_var_m2_s2: float
    accel_var_m2_s4: float

    @classmethod
    def of(cls, cfg: SensorConfig) -> TrackNoise:
        """The noise ``cfg`` describes: the middle of its EPU range, its NACv, its acceleration.

        NACv's variance is scaled by `FILTER_VELOCITY_VARIANCE_SCALE`. The runtime cannot know
        a report's EPU (ADSB_VEHICLE carries no NACp), so the filter assumes the middle of the
        configured range for every aircraft, in flight and here.
        """
        pos_sigma = 0.5 * (cfg.adsb_epu_m[0] + cfg.adsb_epu_m[1]) / POSITION_95_TO_SIGMA
        vel_sigma = cfg.adsb_nacv_m_s / POSITION_95_TO_SIGMA
        return cls(
            max(pos_sigma**2, MIN_REPORT_VARIANCE),
            max(FILTER_VELOCITY_VARIANCE_SCALE * vel_sigma**2, MIN_REPORT_VARIANCE),
            cfg.adsb_filter_accel_m_s2**2,
        )


def fuse(
    pos: FloatArray,
    vel: FloatArray,
    cov: FloatArray,
    t: float | FloatArray,
    z_pos: FloatArray,
    z_vel: FloatArray,
    t_z: float | FloatArray,
    noise: TrackNoise,
) -> tuple[FloatArray, FloatArray, FloatArray, FloatArray]:
    """One report fused into a track: a constant-velocity Kalman filter, per axis.

    The track (``pos``, ``vel`` (..., 2) at time ``t`` (...), covariance ``cov`` (..., 3) =
    (P_pp, P_pv, P_vv), alike on both axes) is predicted to the report's time ``t_z`` (never
    backwards) with white acceleration, then corrected by the report's position and velocity
    (``z_pos``, ``z_vel``). A track that holds nothing to fuse — no report yet (t −inf or
    NaN position), or one no longer fresh at ``t_z`` (`is_fresh`) — starts from the report, as
    does one whose report fails the innovation gate (`FILTER_GATE`). Returns the new
    (pos, vel, cov, t), t the later of ``t`` and ``t_z``. Elementwise: the simulator calls it on
    (B, M) tracks, the runtime on one track.

    >>> noise = TrackNoise(pos_var_m2=1.0, vel_var_m2_s2=1.0, accel_var_m2_s4=0.0)
    >>> p, v, c, t = fuse(np.zeros(2), np.zeros(2), np.array([1.0, 0.0, 1.0]), 0.0,
    ...                   np.array([2.0, 0.0]), np.zeros(2), 0.0, noise)
    >>> p.tolist(), c.tolist()
    ([1.0, 0.0], [0.5, 0.0, 0.5])
    """
    t_z = np.asarray(t_z, dtype=np.float64)
    t0 = np.asarray(t, dtype=np.float64)
    finite = np.isfinite(t0) & np.isfinite(t_z)  # no inf − inf below
    t0_at, tz_at = np.where(finite, t0, 0.0), np.where(finite, t_z, 0.0)
    held = finite & np.isfinite(pos).all(axis=-1) & is_fresh(t0_at, tz_at)
    dt = np.where(held, np.maximum(0.0, tz_at - t0_at), 0.0)[..., np.newaxis]
    # predict: x' = F x, P' = F P Fᵀ + Q (F = [[1, dt], [0, 1]], Q of white acceleration)
    q = noise.accel_var_m2_s4
    ppp, ppv, pvv = cov[..., 0:1], cov[..., 1:2], cov[..., 2:3]
    dt2 = dt * dt
    ppp = ppp + 2.0 * dt * ppv + dt2 * pvv + q * dt2 * dt2 / 4.0
    ppv = ppv + dt * pvv + q * dt2 * dt / 2.0
    pvv = pvv + q * dt2
    p_pred = pos + vel * dt
    # correct with z = (position, velocity): S = P' + R, K = P' S⁻¹
    spp, svv = ppp + noise.pos_var_m2, pvv + noise.vel_var_m2_s2
    det = spp * svv - ppv * ppv
    yp, yv = z_pos - p_pred, z_vel - vel  # (..., 2) innovations
    # yᵀ S⁻¹ y summed over both axes: the χ² of the report
    d2 = ((svv * yp * yp - 2.0 * ppv * yp * yv + spp * yv * yv) / det).sum(axis=-1)
    kpp = (ppp * svv - ppv * ppv) / det
    kpv = (ppv * spp - ppp * ppv) / det
    kvp = (ppv * svv - pvv * ppv) / det
    kvv = (pvv * spp - ppv * ppv) / det
    new_pos = p_pred + kpp * yp + kpv * yv
    new_vel = vel + kvp * yp + kvv * yv
    new_cov = np.concatenate(
        [
            (1.0 - kpp) * ppp - kpv * ppv,
            (1.0 - kpp) * ppv - kpv * pvv,
            (1.0 - kvv) * pvv - kvp * ppv,
        ],
        axis=-1,
    )
    fused = held & (d2 <= FILTER_GATE)
    keep = fused[..., np.newaxis]
    start = np.broadcast_to([noise.pos_var_m2, 0.0, noise.vel_var_m2_s2], new_cov.shape)
    return (
        np.where(keep, new_pos, z_pos),
        np.where(keep, new_vel, z_vel),
        np.where(keep, new_cov, start),
        np.where(fused, np.maximum(t0, t_z), t_z),
    )


@dataclass(frozen=True)
class AdsbTracks:
    """ADS-B of M intruders in B environments, and the report each UAV's tracker holds.

    Intruder (b, m) transmits at ``t_k = phase + k · period`` for whole k; report k arrives at
    ``t_k + latency``. Every array is batch first, so `sim.state.merge_where` restarts
    environments. Before the first report: indices and times −inf, position and velocity NaN.

    Attributes:
        period_s: (B, M) time between transmissions, s (1 / rate).
        phase_s: (B, M) time of report 0, in [0, period), s.
        latency_s: (B, M) transmission to arrival, s.
        pos_sigma_m: (B, M) position error σ per axis, m (EPU / 2.448).
        vel_sigma_m_s: (B, M) velocity error σ per axis, m/s (NACv / 2.448).
        error_tau_s: (B, M) correlation time of the report errors, s (0: independent).
        last_index: (B, M) k of the newest report that has arrived, lost or not (whole
            numbers as float64, so −inf can mean none): each report's loss is drawn once.
        t_valid_s: (B, M) time of validity t_k of the report held, s.
        t_report_s: (B, M) its time as the tracker takes it (`report_time` of its arrival), s.
        pos_m: (B, M, 2) its position (at ``t_valid_s``, with its error), m; with the track
            filter (`SensorConfig.adsb_filter`), the filter's position at ``t_report_s``.
        vel_m_s: (B, M, 2) its velocity (with its error), m/s; or the filter's.
        cov: (B, M, 3) the track filter's covariance per axis (P_pp m², P_pv m²/s, P_vv
            (m/s)²; `fuse`); zeros without the filter.
        pos_err_m: (B, M, 2) that position's error, m (0 before the first report): what the
            next report's error is correlated with (`SensorConfig.adsb_error_tau_s`).
        vel_err_m_s: (B, M, 2) that velocity's error, m/s (likewise).
    """

    period_s: FloatArray
    phase_s: FloatArray
    latency_s: FloatArray
    pos_sigma_m: FloatArray
    vel_sigma_m_s: FloatArray
    error_tau_s: FloatArray
    last_index: FloatArray
    t_valid_s: FloatArray
    t_report_s: FloatArray
    pos_m: FloatArray
    vel_m_s: FloatArray
    cov: FloatArray
    pos_err_m: FloatArray
    vel_err_m_s: FloatArray

    @classmethod
    def fresh(cls, b: int, m: int, cfg: SensorConfig, rng: np.random.Generator) -> AdsbTracks:
        """New tracks holding no report; rate, phase, latency, EPU and τ drawn per intruder.

        Rate, latency, EPU and the errors' correlation time are uniform in their
        `SensorConfig` ranges; the phase is uniform in [0, period). Draws, in order: rate,
        phase, latency, EPU, each (b, m), then the correlation time where its range is not a
        single value (so that a fixed one leaves the stream of the others as it was).
        """
        rate = rng.uniform(*cfg.adsb_rate_hz, size=(b, m))
        period = 1.0 / rate
        phase = period * rng.random((b, m))  # [0, period)
        latency = rng.uniform(*cfg.adsb_latency_s, size=(b, m))
        pos_sigma, vel_sigma = report_sigmas(
            rng.uniform(*cfg.adsb_epu_m, size=(b, m)), cfg.adsb_nacv_m_s
        )
        lo, hi = cfg.adsb_error_tau_s
        tau = rng.uniform(lo, hi, size=(b, m)) if hi > lo else np.full((b, m), lo)
        return cls(
            period_s=period,
            phase_s=phase,
            latency_s=latency,
            pos_sigma_m=pos_sigma,
            vel_sigma_m_s=np.full((b, m), vel_sigma),
            error_tau_s=tau,
            last_index=np.full((b, m), -math.inf),
            t_valid_s=np.full((b, m), -math.inf),
            t_report_s=np.full((b, m), -math.inf),
            pos_m=np.full((b, m, 2), math.nan),
            vel_m_s=np.full((b, m, 2), math.nan),
            cov=np.zeros((b, m, 3)),
            pos_err_m=np.zeros((b, m, 2)),
            vel_err_m_s=np.zeros((b, m, 2)),
        )


def _newest_lost(shape: tuple[int, ...], p: float, rng: np.random.Generator) -> FloatArray:
    """How many of the newest reports are lost before one gets through, (shape).

    Each report is lost independently with probability ``p``, so the count is geometric:
    P(≥ j lost) = pʲ, drawn by inversion from one uniform each (always drawn, so the stream
    does not depend on the data). Which of the older reports are lost never matters: they are
    older than the one kept.
    """
    u = rng.random(shape)  # [0, 1)
    if p == 0.0:
        return np.zeros(shape)
    out: FloatArray = np.floor(np.log1p(-u) / math.log(p))  # log(1 − u) ∈ (−inf, 0]
    return out


def update(
    tracks: AdsbTracks,
    true_pos: FloatArray,
    true_vel: FloatArray,
    now_s: float | FloatArray,
    visible_since_s: FloatArray,
    cfg: SensorConfig,
    rng: np.random.Generator,
) -> AdsbTracks:
    """Take the reports that arrived since the last update; the newest one that got through wins.

    Args:
        tracks: the tracks after the previous update (or `AdsbTracks.fresh`).
        true_pos: (B, M, 2) true intruder positions at ``now_s``, m.
        true_vel: (B, M, 2) true intruder velocities, m/s (constant: the intruders fly
            straight, so the position at ``t_k`` is ``true_pos − true_vel · (now − t_k)``).
        now_s: the episode time, s (non-decreasing from one update to the next); a number, or
            (B, 1) for environments at different times.
        visible_since_s: (B, M) when each intruder starts transmitting, s: reports before it
            do not exist (0 from the episode start, later for a pop-up, +inf never, −inf for one
            that has been transmitting all along).
        cfg: the sensor model (``adsb_drop_probability``, the errors' correlation and the
            track filter are used here).
        rng: draws the losses (B, M) and the errors (B, M, 2) twice, always, in that order.

    Returns:
        The tracks at ``now_s``. The reports considered are those with ``t_k ≥
        visible_since_s`` that have arrived (``t_k + latency ≤ now_s``) and were not considered
        before; their number needs no bound: how many of the newest are lost is drawn at once
        (`_newest_lost`). The report taken is never older than the one held.
    """
    period, phase, latency = tracks.period_s, tracks.phase_s, tracks.latency_s
    # In place where the arrays are this function's own: the same operations, fewer arrays.
    newest = np.subtract(now_s, latency)
    newest -= phase
    newest /= period
    np.floor(newest, out=newest)  # (B, M) newest arrived k
    # the quotients may round across a whole number: one step back or forward puts k exactly
    newest -= phase + newest * period + latency > now_s  # never one from the future
    newest += phase + (newest + 1.0) * period + latency <= now_s  # nor one left behind
    oldest = tracks.last_index + 1.0  # oldest new candidate
    if not np.isneginf(visible_since_s).all():  # −inf: every report exists, first k −inf
        first = np.ceil((visible_since_s - phase) / period)  # (B, M) first transmitted k
        first += phase + first * period < visible_since_s  # never one before it
        first -= phase + (first - 1.0) * period >= visible_since_s  # nor one left out
        np.maximum(oldest, first, out=oldest)
    count = newest - oldest
    count += 1.0
    np.maximum(count, 0.0, out=count)  # new candidates (may be +inf)
    lost = _newest_lost(period.shape, cfg.adsb_drop_probability, rng)
    pos_err = rng.standard_normal(tracks.pos_m.shape)
    vel_err = rng.standard_normal(tracks.vel_m_s.shape)

    take = lost < count  # (B, M) a new report got through
    k = np.subtract(newest, lost)
    k *= period
    k += phase  # phase + k · period where taken
    t_k = np.where(take, k, tracks.t_valid_s)
    age = np.subtract(now_s, t_k)
    age[~take] = 0.0
    pos_err *= tracks.pos_sigma_m[..., np.newaxis]
    vel_err *= tracks.vel_sigma_m_s[..., np.newaxis]
    if cfg.adsb_error_tau_s[1] > 0.0:
        pos_err, vel_err = _correlated(tracks, take, t_k, pos_err, vel_err)
    pos = true_pos - true_vel * age[..., np.newaxis]
    pos += pos_err
    vel = true_vel + vel_err
    keep = take[..., np.newaxis]
    reported = t_k + latency
    t_report = np.where(take, report_time(reported, ADSB_TSLC_S), tracks.t_report_s)
    cov = tracks.cov
    if cfg.adsb_filter:
        pos, vel, fused_cov, _ = fuse(
            tracks.pos_m, tracks.vel_m_s, cov, tracks.t_report_s, pos, vel, t_report,
            TrackNoise.of(cfg),
        )  # fmt: skip
        cov = np.where(keep, fused_cov, cov)
    return AdsbTracks(
        period_s=period,
        phase_s=phase,
        latency_s=latency,
        pos_sigma_m=tracks.pos_sigma_m,
        vel_sigma_m_s=tracks.vel_sigma_m_s,
        error_tau_s=tracks.error_tau_s,
        last_index=np.where(count > 0, newest, tracks.last_index),
        t_valid_s=t_k,
        t_report_s=t_report,
        pos_m=np.where(keep, pos, tracks.pos_m),
        vel_m_s=np.where(keep, vel, tracks.vel_m_s),
        cov=cov,
        pos_err_m=np.where(keep, pos_err, tracks.pos_err_m),
        vel_err_m_s=np.where(keep, vel_err, tracks.vel_err_m_s),
    )


def _correlated(
    tracks: AdsbTracks,
    take: BoolArray,
    t_k: FloatArray,
    pos_fresh: FloatArray,
    vel_fresh: FloatArray,
) -> tuple[FloatArray, FloatArray]:
    """The errors of the reports taken, each a first-order Gauss–Markov step from the held one's.

    ``e = ρ·e_held + √(1 − ρ²)·e_fresh`` with ``ρ = exp(−(t_k − t_held)/τ)``, ``e_fresh`` the
    fresh draw at the report's σ: the error keeps that σ (stationary), successive reports Δt
    apart correlate by exp(−Δt/τ), and the first report's error is its fresh draw (ρ = 0), as
    is every error of an intruder whose τ is 0.
    """
    held = np.isfinite(tracks.t_valid_s) & (tracks.error_tau_s > 0.0)  # (B, M)
    since = np.where(held, tracks.t_valid_s, 0.0)  # −inf before the first report
    gap = np.where(take & held, t_k - since, math.inf)
    tau = np.where(held, tracks.error_tau_s, 1.0)
    rho = np.exp(-gap / tau)[..., np.newaxis]
    keep = np.sqrt(1.0 - rho * rho)
    pos: FloatArray = rho * tracks.pos_err_m + keep * pos_fresh
    vel: FloatArray = rho * tracks.vel_err_m_s + keep * vel_fresh
    return pos, vel


def picture(
    tracks: AdsbTracks, now_s: float | FloatArray
) -> tuple[FloatArray, FloatArray, BoolArray]:
    """What the tracker shows at ``now_s``: (pos (B, M, 2), vel (B, M, 2), valid (B, M)).

    Positions are the held reports extrapolated to ``now_s`` (`extrapolate`, from their report
    time); valid = a report is held and `is_fresh` — its age counted from its report time
    (receive time less tslc), exactly as `remarl_fc.flight.traffic` counts it, not from its time
    of validity. Invalid entries are NaN.
    """
    valid = is_fresh(tracks.t_report_s, now_s)  # (B, M); False before the first report
    since = np.where(valid, tracks.t_report_s, now_s)  # no inf − inf for the invalid
    pos = np.where(
        valid[..., np.newaxis], extrapolate(tracks.pos_m, tracks.vel_m_s, since, now_s), math.nan
    )
    vel = np.where(valid[..., np.newaxis], tracks.vel_m_s, math.nan)
    return pos, vel, valid
