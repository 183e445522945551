"""The conventions charter of gpsdr: frames, units, signs, time base, column names.

Declared once here; every module follows it and says so in its docstring.

Time
    int64 nanoseconds since the UTC epoch (1970-01-01T00:00:00Z, no leap seconds)
    everywhere inside the code.  Inputs in POSIX seconds are converted on read.
    Time steps ``T`` handed to the filters are float seconds.

Frames
    Geodetic: WGS84 latitude/longitude in degrees (the only place degrees appear
    besides headings).  Local frame: east ``e`` and north ``n`` in metres, in the
    projection of :mod:`gpsdr_cli.geodesy` (default: a transverse Mercator centred
    on the first valid fix; any projected CRS by EPSG code on request).

Signs
    Heading ``psi = atan2(v_e, v_n)``: clockwise from north, radians inside the
    code, ``heading_deg`` in outputs (0..360).
    Yaw rate as read from a gyro: about the vehicle's up axis, **positive
    counter-clockwise seen from above** (ROS REP-103, z up).  Hence
    ``d(psi)/dt = -yaw_rate``.  A log with the other sign is declared by an
    option, never guessed.

Units
    SI: metres, seconds, radians, m/s, m/s^2, rad/s.  Names carry ``_sd`` for a
    standard deviation and ``_var`` for a variance; suffixes ``_m``, ``_s``,
    ``_mps``, ``_radps``, ``_deg`` where a name could be read two ways.

Missing values
    float NaN inside arrays means "not measured at this epoch"; outputs turn it
    into a Parquet null.  Infinity never reaches an output.
"""

from __future__ import annotations

NS_PER_S = 1_000_000_000

#: GNSS fix quality as in NMEA GGA field 6 (0 = no fix; 6 = dead reckoning).
FIX_NONE = 0
FIX_GPS = 1
FIX_DGPS = 2
FIX_PPS = 3
FIX_RTK = 4
FIX_FLOAT_RTK = 5
FIX_DR = 6

#: Track Parquet: the contract's required columns, in order, with units.
TRACK_COLUMNS: dict[str, str] = {
    "time": "UTC timestamp, ns",
    "lat": "deg, WGS84 latitude",
    "lon": "deg, WGS84 longitude",
    "e": "m, east in the local frame",
    "n": "m, north in the local frame",
    "v_e": "m/s, east velocity",
    "v_n": "m/s, north velocity",
    "speed": "m/s, horizontal speed",
    "heading_deg": "deg, clockwise from north, 0..360",
    "sigma_e": "m, 1-sigma east position from the filter covariance",
    "sigma_n": "m, 1-sigma north position from the filter covariance",
    "gnss_used": "bool, a GNSS fix was applied in the update at this epoch",
    "pdop": "dimensionless, PDOP of the latest GNSS epoch (null where none)",
}

#: Track Parquet: extra columns gpsdr writes (used by `gpsdr stats` and `plot`).
TRACK_EXTRA_COLUMNS: dict[str, str] = {
    "gnss_e": "m, east of the GNSS fix at this epoch (null where none)",
    "gnss_n": "m, north of the GNSS fix at this epoch (null where none)",
    "gnss_rejected": "bool, a GNSS fix was present but rejected by the innovation gate",
    "gnss_outage": "bool, epoch lies in a GNSS outage (no valid fix for longer than the gap threshold)",
    "static": "bool, standstill detected (zero-velocity update applied)",
    "nis": "dimensionless, normalised innovation squared of the GNSS update (2 dof; null where none)",
}

#: Track Parquet: the forward/backward quality-check columns (gpsdr_cli.qc; docs/qc.md).
QC_COLUMNS: dict[str, str] = {
    "separation_m": "m, horizontal distance between the forward and an independent backward "
                    "pass of the filter (null where not computed)",
    "quality": "class 1 best .. 6 worst, from the horizontal sigma, the separation and the "
               "GNSS state (docs/qc.md)",
}

#: Track Parquet: columns only the graph smoother writes (the default with a gyro or odometer).
GRAPH_TRACK_COLUMNS: dict[str, str] = {
    "gnss_weight": "dimensionless, robust weight of the GNSS fix in the graph smoother (1: full "
                   "weight; null where no fix)",
}

#: Statistics Parquet columns (one row per filter x segment).
STATS_COLUMNS: dict[str, str] = {
    "filter": "filter name",
    "segment": "all, open, degraded, outage, static, or outage_<i> for one outage",
    "epochs": "count of epochs in the segment",
    "rmse_m": "m, horizontal RMS error against the reference",
    "mean_m": "m, mean horizontal error",
    "cep50_m": "m, 50th percentile of horizontal error",
    "cep95_m": "m, 95th percentile of horizontal error",
    "max_m": "m, largest horizontal error",
    "along_rmse_m": "m, RMS of the along-track error component",
    "cross_rmse_m": "m, RMS of the cross-track error component",
    "nis_in_95_share": "share of GNSS updates whose NIS is inside the 95 % chi-square(2) bound",
    "gnss_separation_rmse_m": "m, RMS distance between the GNSS fixes and the fused track",
    "duration_s": "s, length of the outage",
    "distance_m": "m, distance driven during the outage",
    "end_error_m": "m, horizontal error at the outage's end",
    "end_error_pct_distance": "%, end error as a share of the distance driven in the outage",
}
