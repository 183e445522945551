"""Every parameter of gpsdr with its default, documented in one place.

The defaults are the TOML text below: it is what ``gpsdr fuse --print-config``
starts from, and a user's ``--config PARAMS.toml`` overrides any subset of it.
Units are in the names (see :mod:`gpsdr_cli.conventions`).  Defaults marked
"(benchmark)" were chosen by ``benchmarks/accuracy.py``.

``Params`` is a plain ``dict[str, dict[str, value]]`` (section -> key -> value),
validated against the defaults: unknown sections or keys and wrong types are a
:class:`~gpsdr_cli.errors.ConfigError`, never silently ignored.
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path
from typing import Any

from .errors import ConfigError

Params = dict[str, dict[str, Any]]

DEFAULTS_TOML = """\
[filter]
name = "aekf"            # ekf | aekf | fkf | fafkf
smooth = false           # fixed-interval RTS smoother over the forward pass

[frame]
epsg = 0                 # 0: transverse Mercator centred on the first fix; else a projected EPSG code
origin_lat_deg = nan     # DR-only drives (no GNSS): start position, degrees
origin_lon_deg = nan
initial_heading_deg = nan  # DR-only drives: start heading, clockwise from north

[time]
gnss_offset_s = 0.0      # added to every GNSS stamp; a positive value compensates receiver latency
gyro_offset_s = 0.0      # added to every gyro stamp
odo_offset_s = 0.0       # added to every odometer stamp
outage_gap_s = 1.5       # no valid fix for longer than max(this, 2.5 x median fix interval) = outage

[gnss]
uere_m = 2.5             # base sigma = HDOP x UERE when the receiver gives no GST/covariance (benchmark)
sigma_default_m = 5.0    # base sigma when neither GST, covariance nor HDOP is known
sigma_min_m = 0.05       # floor on any base sigma (RTK receivers report centimetres)
min_fix_quality = 1      # GGA quality >= this is used ...
use_dr_fixes = false     # ... except quality 6 (the receiver's own dead reckoning) unless true
pdop_mode = "regimes"    # regimes (seed 000's three) | continuous (log k interpolated over PDOP)
pdop_good = 3.0          # PDOP < pdop_good: good
pdop_poor = 6.0          # PDOP >= pdop_poor: poor; in between: medium
k_good = 1.0             # R scale factor k1 = k2 per regime (seed 000, rescaled: see ALGORITHMS.md 1)
k_medium = 3.0
k_poor = 10.0
ka_good = 1.0            # Q scale factor K_a per regime (seed 000)
ka_medium = 0.9
ka_poor = 0.003
gate = true              # chi-square innovation gate on GNSS fixes
gate_prob = 0.9999       # gate at this chi-square(2) quantile
gate_reset_s = 10.0      # after this long with every fix rejected, accept again (no lock-out)
gate_mode = "inflate"    # ekf/aekf: reject | inflate (NIS above the gate: accept with R x NIS/gate, robust;
                         #   above gate_inflate_max x the gate still rejected; benchmark: ekf one_hour 6.4 -> 4.1 m,
                         #   urban 6.8 -> 5.0 m (seed 3), tunnels RTS 15 -> 3 m (seed 1))
gate_inflate_max = 10.0  # inflate mode: largest R factor (a 100 m jump at a 2.5 m sigma is ~80 x the gate;
                         #   benchmark: 5, 10, 20 within 0.1 m; 10 keeps 40 m outliers out)
gate_inflate_after_s = 0.0  # inflate mode: only after the fixes have failed the gate this long (s); a shorter
                         #   burst is rejected as in reject mode (benchmark: 0.3 s / 1 s cost the ekf on one_hour
                         #   seed 3 3.75 -> 4.9 / 6.2 m; the aekf within 0.1 m)
gate_warmup_fixes = 5    # every filter: no gate before this many fixes were accepted (a first fix 30 m off
                         #   must not lock the good ones out)

[gyro]
t_column = "t"
column = "yaw_rate"
units = "rad/s"          # rad/s | deg/s
sign = "ccw"             # ccw: positive counter-clockwise seen from above (REP-103) | cw
time = "posix"           # posix: UTC POSIX seconds | relative: seconds + start_posix_s
start_posix_s = 0.0
noise_sd_radps = 0.0017453  # 0.1 deg/s per sample (seed 000)
bias_tau_s = 3600.0      # Gauss-Markov correlation time of the gyro drift (MEMS in-run wander; a turn-on bias
                         #   with a 300 s tau made the outage sigmas 5x the error: the heading variance now grows
                         #   with the drift's)
bias_sd_radps = 0.005    # steady-state sigma of the drift
bias_init_sd_radps = 0.1 # initial sigma of the drift (covers a 4 deg/s bias)
scale_sd = 0.005         # ekf/aekf: sigma of the gyro scale error (not a state): the heading variance grows
                         #   by scale_sd^2 x the angle turned (rad), a random walk per radian turned
max_rate_radps = 3.0     # ekf/aekf: a reading beyond this (172 deg/s) is a glitch, treated as missing
saturation_min_count = 20  # ekf/aekf: this many readings exactly at the drive's largest magnitude = a clipping
                         #   gyro; those readings are treated as missing
bias_init_sd_dr_radps = 0.005  # ekf/aekf: the same when the drive has no GNSS fix at all: the drift is then
                         #   observable only at standstill, and a 0.1 rad/s prior lets the heading run free

[odo]
t_column = "t"
kind = "auto"            # auto | speed (m/s) | distance (m since the previous row) | ticks (cumulative)
column = ""              # empty: the column named like kind
ticks_per_m = 0.0        # required for kind = ticks
time = "posix"
start_posix_s = 0.0
noise_sd_mps = 0.1       # speed sigma; distance sigma over T is noise_sd_mps x T (seed 000: 0.1)
scale_init_sd = 0.05     # initial sigma of the scale factor k_s: a wheel odometer is within a few %
scale_rw_sd = 0.0001     # random-walk sigma of k_s per sqrt(s)
max_speed_mps = 100.0    # ekf/aekf: a reading beyond this is a glitch, treated as missing

[standstill]
enabled = true           # zero-velocity update and held position while stopped (seed 004)
speed_mps = 0.05         # odometer speed below this = stopped
min_stop_s = 0.3         # ... for at least this long: shorter runs of zero readings are dropped (align.flicker_zeros;
                         #   a wheel-tick odometer at walking pace reads 1, 0, 0, 1 m/s, and every zero fired a
                         #   zero-velocity update: 10 ticks/m, open sky ekf 1.97 m against 0.94 for its oracle)
zupt_sd_mps = 0.01       # sigma of the zero-velocity pseudo-measurement
zupt_keeps_position = "outage"  # never | outage | always (ekf/aekf): the zero-velocity update does not move
                         #   the position (consider states): through P's velocity-position correlation it halved
                         #   the position sigma at a stop inside a GNSS outage, though a stop says nothing about
                         #   where the car is
omega_min_speed_mps = 0.5  # below this the yaw-rate update is skipped (singular at standstill)
heading_min_speed_mps = 3.0  # the remembered heading (odometer direction near standstill) is taken from the
                         #   velocity only above this; below it follows the gyro (braking to a stop, the
                         #   velocity can reverse; without a gyro the car drove off 147 deg wrong)

[aekf]
tau_a_s = 20.0           # correlation time of the manoeuvre acceleration (seed 000)
a_max_mps2 = 1.0         # largest positive acceleration of the CS model (benchmark: 3 m/s^2 gave 22 m RMSE on
                         #   sample_logs/urban_drive vs 5.7 m with 1.0; open sky, urban, tunnels within 5 %)
a_min_mps2 = 1.0         # magnitude of the most negative acceleration
sigma_a_mps2 = 0.5       # fixed acceleration sigma (ekf), and sigma when a_hat ~ 0 (floor) in aekf
init_pos_sd_m = 10.0
init_vel_sd_mps = 5.0
init_acc_sd_mps2 = 1.0
check_spd = false        # Cholesky of P at every epoch, failures counted in info["spd_failures"] (tests)
drift_mean_decay = false # true: the gyro drift's mean decays as exp(-T/tau) (seed 000 literally); false: the
                         #   mean is held (a turn-on bias does not fade in an outage), covariance stays Gauss-Markov
drift_consider = "outage"  # never | outage | always: the yaw-rate and odometer updates do not correct the drift
                         #   (Schmidt consider state; Joseph keeps P exact) so sustained turns cannot leak into it
odo_consider = "outage"  # never | outage | always: the odometer row corrects neither k_s nor the position
                         #   (consider states; in an outage nothing else measures the speed: gyro + odometer
                         #   alone on comma2k19 walked k_s 1.00 -> 1.15 and the position 153 m off; 37 m now)
heading_consider = false # in outages the yaw-rate update does not correct the velocity either: removes the EKF's
                         #   spurious heading information (120 s tunnel: 260 -> 80 m) but cannot follow sharp turns
turn_propagation = true  # our choice: the prediction turns v and a by the gyro's heading increment
                         #   (-(yaw_rate) - eps) T, in mean and covariance (heading driven by the gyro); false:
                         #   seed 000 exactly (benchmark: tunnels aekf 59.6 -> 16.0 m forward, RTS 57.5 -> 3.1 m)
turn_omega_row = "lateral"  # with turn_propagation, the seed 000 yaw-rate row: skip | lateral (what is left of
                         #   it: the residual acceleration has no lateral part; benchmark: skip let the Newton step
                         #   reverse v while braking to a stop, 79 m open sky)
gyro_hold_s = 0.5        # with turn_propagation, a gyro rate turns the epochs up to this long after it
max_gap_s = 600.0        # a step longer than this is not propagated: position held, its variance grown by
                         #   (60 m/s x step)^2 (a fix dated 22 years later made the mean and lat/lon infinite)
odo_along_track = true   # the odometer corrects position, velocity and acceleration along the velocity only
                         #   (gains projected; Joseph keeps P exact): a speed carries no heading information, and
                         #   with the full gain a misalignment of P and v turned its updates into heading jumps
                         #   (0.5 deg each in DR) and erased the heading variance (10 min outage 6.4 sigma).
                         #   Benchmark (seeds 1-3, with the two keys below): tunnels forward 16.4 -> 20.9 m (RTS
                         #   3.4 -> 3.6 m) is the cost; one_hour 4.7 -> 4.0 m, urban 5.1 -> 4.7 m
lateral_acc_only = "outage"  # never | outage | always: with turn_omega_row = "lateral", that row corrects the
                         #   acceleration only (the rest consider states): "no lateral residual acceleration" holds
                         #   for any heading, but through P's correlations it moved v and the position and shrank
                         #   their heading variance (with a braking car, by up to 2 deg per update)
innovation_whitening = false  # aekf only (after Mehra 1970): the lag-one and lag-two autocovariances of the
                         #   normalised GNSS innovations give a white + Gauss-Markov split (correlation r, share
                         #   s) and R is scaled by the variance factor of an average of such errors, (1 - s) +
                         #   s (1 + r)/(1 - r); at a stop the m-th fix gets R x m.  Time-correlated multipath
                         #   carries less information than the receiver's sigma claims.  Benchmark (seeds 1-3,
                         #   with gnss_velocity): NEES (1 = honest) open sky 11 -> 2.4, stop_and_go 114 -> 2,
                         #   tunnels 3.9 -> 1.0, urban 46 -> 15; RMSE one_hour 2.03 -> 1.50 m, stop_and_go
                         #   1.21 -> 0.86 m, tunnels RTS 2.95 -> 2.13 m, urban 3.19 -> 3.52 m (RTS 2.66 -> 2.15)
                         #   Off since gnss_err_states (issue #4): the error states model the same correlation,
                         #   and R x (up to 10) on top of them slowed the corrections (seeds 1-3 aekf urban
                         #   2.21 -> 2.65 m forward, 1.09 -> 1.14 m RTS; the other scenarios within 1 %)
whitening_b = 0.99       # forgetting factor per fix of the innovation correlation estimate
whitening_max = 10.0     # largest R factor (25: urban forward 3.5 -> 4.1 m; the drive's multipath changes its
                         #   correlation time with the speed, one estimate serves all)
whitening_gap_s = 2.0    # fixes farther apart than this are not paired
whitening_nis_prob = 0.95  # only fixes whose NIS is under this chi-square(2) quantile enter the estimate
gnss_velocity = true     # ekf/aekf: the receiver's speed and course (RMC/VTG: Doppler, not differenced
                         #   positions, so multipath barely touches it) update v_e, v_n with each accepted fix.
                         #   Benchmark (seeds 1-3): urban 4.73 -> 3.19 m (RTS 3.14 -> 2.66), one_hour 4.03 ->
                         #   2.03 m, tunnels 20.9 -> 17.1 m (RTS 3.55 -> 2.95), open sky 0.74 -> 0.64 m
gnss_velocity_sd_mps = 0.2  # its sigma per axis (m/s)
gnss_velocity_min_mps = 1.0  # below this speed the course is noise: not used
heading_floor = true     # our choice: a consider heading variance (gyro noise + drift, reset from P at GNSS
                         #   fixes while moving) floors P's cross-track velocity variance at speed^2 x it: the
                         #   model has no heading state, and a stop (ZUPT) or the speed/lateral rows erased the
                         #   heading uncertainty (10 min outage: end error 6.4 / 4.4 sigma for ekf / aekf)
gnss_err_states = true   # ekf/aekf (issue #4): the fix error is white noise + a first-order Gauss-Markov bias
                         #   per axis (multipath), estimated as two more states (kernels_aekf GE_*): a white-noise
                         #   model fed time-correlated errors converged in seconds to a 1 m sigma with a 5-6 m error
                         #   and then, with whitening's large R, kept that offset for minutes.  Benchmark (seeds
                         #   1-3, forward / RTS, aekf; ekf): urban 3.35/2.07 -> 2.20/1.08 m; 3.27/2.29 -> 2.11/1.11,
                         #   one_hour 1.48/0.98 -> 1.31/0.86; 2.40/1.82 -> 1.31/0.86, open sky, tunnels, stop_and_go
                         #   better too; cost ~12 % of the forward speed and ~1.5-2 s of cold compile (off: none)
gnss_err_sd_m = 2.0      # stationary sigma of the bias per axis (m; 3: urban -1 %, open sky and stop_and_go +7 %)
gnss_err_tau_s = 180.0   # its correlation time when parked (s): the antenna does not move, the multipath changes
                         #   with the satellites only (60 s: a 30-min stop with GNSS drifted 1.2 m, tests/test_faults)
gnss_err_dist_m = 50.0   # ... and its decorrelation distance: 1/tau = 1/gnss_err_tau_s + speed/gnss_err_dist_m
                         #   (the reflection geometry changes as the antenna moves; 0: time only)
gnss_err_min_velocity_share = 0.5  # the error states only when at least this share of the fixes carry the
                         #   receiver's velocity (RMC/VTG speed): with positions only (GGA without RMC, a ROS
                         #   NavSatFix) the fix and its bias are told apart by dead reckoning alone, and a 2-m bias
                         #   that decorrelates in 2.5 s at 20 m/s let the smoother move the track metres (it
                         #   drifted 3-5 m off at stops).  Positions-only seeds 1 (ekf forward / RTS, m; on ->
                         #   off): open sky 0.86/2.28 -> 0.83/0.67, urban 6.65/4.99 -> 4.93/3.58 (seeds 2, 3:
                         #   5.61/4.50 -> 4.69/2.90, 4.37/5.14 -> 4.59/2.62), one_hour 3.60/4.34 -> 3.42/2.25,
                         #   stop_and_go 2.81/5.79 -> 1.24/0.99, tunnels 13.0/2.25 -> 10.3/3.19 (0: always on)
coast_acc_psd = 1.0      # no odometer, GNSS outage: zero-acceleration rows with r = this / T (m^2/s^3; 0: off),
                         #   as [fkf] coast_acc_psd: the CS model's mean carried the last acceleration through the
                         #   outage (one_hour seed 2, 60 s: 12 -> 106 m/s, 3 km off)
drive_off_speed_sd_mps = 0.5  # sigma added to v_e, v_n (m/s) and a_e, a_n (m/s^2, next key) where a
drive_off_acc_sd_mps2 = 1.0   #   standstill ends (0: not); see aekf.drive_off_var

[adaptive]
innovation_factor = false  # seed 001 adaptive factor on P(k|k-1)
innovation_c = 0.9
fading = false           # fading memory P(k|k-1) = lambda Phi P Phi^T + Q
fading_lambda = 1.01     # per second: each step multiplies Phi P Phi^T by lambda**T
sage_husa = false        # Sage-Husa estimation of the GNSS R
sage_husa_b = 0.98       # forgetting factor of Sage-Husa
sage_husa_r_min = 0.25   # divergence guard: the estimated R scale (x the nominal R) stays within
sage_husa_r_max = 100.0  #   [r_min, r_max]; each innovation sample is clamped to the same range

[fkf]
mode = "fr"              # fr: fusion-reset (Carlson 1990; default: NR lets the DR position drift) | nr: no reset (seed 002)
beta_gnss = 0.5          # fkf, FR mode: information share of the GNSS local filter (the DR filter gets 1 - this)
jerk_psd_m2ps5 = 1.0     # white-jerk spectral density per axis of the shared model's Q (m^2/s^5)
gnss_err_tau_s = 60.0    # correlation time of the GNSS position error states eps_e, eps_n
gnss_err_sd_m = 1.0      # steady-state sigma of eps_e, eps_n
gnss_err_dist_m = 0.0    # eps_e, eps_n also decorrelate over this distance driven (m; 0: time only, seed 002).
                         #   Clear sky: off -- comma2k19 (PDOP 1.8) at the README offset 0.486 m with 0, 0.506 m
                         #   with 300, 0.530 m with 50 (its error drifts in time); multipath: gnss_err_obstructed_*
gnss_err_pdop = 2.0      # fixes with PDOP >= this are obstructed: eps follows the gnss_err_obstructed_* keys
                         #   (multipath), else the three keys above (clear sky); fkf.multipath_regime.  Benchmark
                         #   (seeds 1-3, fkf forward / RTS m): urban 2.69/1.75 -> 2.13/1.23, one_hour 1.62/1.17 ->
                         #   1.16/0.79, stop_and_go 0.87/0.65 -> 0.63/0.37; open sky, tunnels, comma2k19 unchanged
                         #   (PDOP 1.5 / 1.8 there; 2.5: stop_and_go 0.75/0.48, its PDOP is 2.2; inf: one regime)
gnss_err_sigma_m = 2.2   # a fix without PDOP is obstructed when its base sigma (m, per axis) >= this: PDOP 2 at
                         #   HDOP = 0.62 PDOP with the UERE fallback, 2 x 0.62 x 2.5/sqrt(2); ROS NavSatFix has no DOP
gnss_err_window_s = 120.0  # the regime of a fix: the share of obstructed fixes in a centred window this long (0: its
                         #   own -- open sky 0.46/0.34 -> 0.53/0.36 m, stop_and_go 0.62/0.38 -> 0.68/0.49 m; 60: within 3 %)
gnss_err_obstructed_sd_m = 3.0     # steady-state sigma of eps under obstruction (m; seeds 1-6: 2: urban 2.12/1.63 m
                                   #   against 2.03/1.49 m, one_hour 1.37/0.97 against 1.28/0.88, stop_and_go equal)
gnss_err_obstructed_tau_s = 60.0   # its correlation time when parked (s; 180: within 1 %, stop_and_go RTS +3 %)
gnss_err_obstructed_dist_m = 50.0  # ... and its decorrelation distance: 1/tau = 1/tau_s + speed/dist (m; 75: urban
                                   #   RTS +3 %, stop_and_go +10 %; 0: time only)
gnss_velocity = true     # the GNSS local filter also takes the receiver's velocity (speed and course from
                         #   RMC/VTG: Doppler, barely touched by multipath) with each accepted fix (our choice)
gnss_velocity_sd_mps = 0.2  # its sigma per axis (m/s)
gnss_velocity_min_mps = 1.0  # below this speed the course is noise: not used
gnss_standstill_speed_mps = 0.5  # no odometer: stopped while every receiver (Doppler) speed over
                         #   gnss_standstill_window_s is below this (fkf.gnss_standstill; 0: off)
gnss_standstill_window_s = 1.0
coast_acc_psd = 1.0      # no odometer, GNSS outage: zero-acceleration rows with r = this / T (m^2/s^3; 0: off):
                         #   the constant-acceleration model otherwise carried a drive-off's acceleration through
                         #   a 10-s outage (urban seed 2: 26 m/s instead of 12, 128 m off)
no_odo_gate_reset_s = 3.0  # no odometer: [gnss] gate_reset_s shortened to this (0: not) -- with nothing else
                         #   measuring the speed, fixes gated for seconds mean the state ran off (positions only,
                         #   urban seeds 1-3 fkf forward 13.2/23.6/23.2 -> 7.1/8.9/12.4 m; with Doppler: same)
fix_standstill_speed_mps = 1.0  # ... stopped while every such speed over gnss_standstill_window_s is below this
fix_standstill_window_s = 6.0  # positions only and no odometer: the speed for that from the median positions of
                         #   the fixes in each half of a centred window this long (fkf.fix_speeds; 0: off)
heading_sd_rad = 0.03    # sigma of the gyro-integrated heading measurement (0.01: a clipped gyro dragged the
                         #   track, fault gyro_saturation 6.3 m; 0.03: fafkf urban 7.2 -> 5.8 m, one_hour 5.8 -> 5.1 m)
heading_err_rw_sd = 0.005  # random walk of q_w, rad per sqrt(s) (the course steering removes the gyro bias;
                         #   0.01 let the velocity direction wander in outages: tunnels fkf 27.5 -> 15.6 m, RTS 6.7 -> 3.4 m)
dist_err_rw_sd = 0.01     # random walk of q_s, m per sqrt(s) (q_s is metres per distance row: 0.2 m/s per sqrt(s) at
                         #   distance_interval_s = 0.05, as 0.002 was at the 100-Hz record rate)
heading_interval_s = 0.1 # heading measurements from the integrated gyro at most this often
distance_interval_s = 0.05  # odometer distance rows S on this grid and at every heading epoch, each the
                         #   distance since the previous row (0: every record, seed 002: 1-mm rows at 100 Hz,
                         #   and heading rows in outages moved the position metres each -- fkf.distance_rows).
                         #   Seeds 1-3 forward fkf (fafkf): one_hour 3.77 (3.68) -> 1.62 (1.51) m, max 68.8 ->
                         #   7.9 m, 60-s drift 5.8 -> 0.71 (0.65) %; urban 3.08 -> 2.69 m; open 0.49 -> 0.46;
                         #   tunnels 7.13 -> 7.18 (max 45 -> 38); comma2k19 0.50 -> 0.49 m at the README offset,
                         #   0.52 -> 0.55 m at the estimated 0.135 s, 1.90 -> 1.87 m as logged
heading_course_window_s = 10.0  # gyro heading steered to the GNSS course averaged over this window (30: a gyro
                         #   clipped at 0.05 rad/s gave 6.3 m with good GNSS; tunnels fkf 15.1 -> 10.8 m)
                         #   (removes the integrated gyro bias; 0: aligned once at the start, seed 002)
course_min_speed_mps = 3.0  # GNSS course used for that only at this speed or more
fix_course_velocity_share = 0.5  # positions only: when fewer than this share of the fixes carry the receiver's
                         #   speed (GGA without RMC/VTG, a ROS NavSatFix), the course steering and the odometer
                         #   scale come from chords between fixes against the dead-reckoned chords (fkf.fix_chords;
                         #   never velocity rows).  Without: fkf seeds 1-3 forward/RTS, open sky 2.1-12.2/1.9-10.7 m,
                         #   urban 8.7-13.4/5.2-11.2, tunnels 81-287 m (GNSS alone 1.4 / 7.6)
fix_chord_course_sd_rad = 0.05  # ... each chord at least sqrt(2 (sigma_fix^2 + sigma_eps^2)) / this long (open sky
                         #   ~40 m, urban ~110 m).  Positions-only fkf, means of seeds 1-3 fwd/RTS m (one_hour: seed
                         #   1) at the defaults below: 0.04: open 0.81/0.75, urban 4.03/2.34; 0.05: 0.77/0.71,
                         #   4.07/2.59; 0.06: 0.78/0.71, 4.22/2.57, stop_and_go 1.45/1.31 (0.05: 1.38/1.20).
                         #   Fixed-time chords, seed 1: 2 s urban 18.5/16.5 (multipath), 5 s 4.6/4.0
fix_chord_max_s = 15.0   # ... and at most this long in time (window 60 s: 5: urban 10.7/7.8, stop_and_go 31.8/30.9;
                         #   8: one_hour 4.46/2.66; 10: urban 4.30/2.75, one_hour 3.09/1.99; 15: 4.22/2.48, 2.87/1.91;
                         #   30: 4.31/2.62, 3.02/2.02; 60: 4.28/2.83, tunnels RTS 1.71 -> 2.86)
fix_course_window_s = 90.0  # ... their heading errors fitted by a line (weights |dr|^2/var) over this centred window
                         #   (60: urban 4.22/2.48, one_hour 2.87/1.91, tunnels 9.28/1.71, stop_and_go 1.35/1.22; 90:
                         #   4.08/2.55, 2.59/1.73, 9.19/1.66, 1.39/1.22; 120: 3.96/2.48, 2.61/1.68, 9.82/1.74,
                         #   1.39/1.22; a mean instead of a line lagged the gyro-bias ramp at tunnel edges: 50 m)
fix_odo_scale_window_s = 900.0  # ... and the odometer scale from them by weighted least squares over a centred
                         #   window this long (a chord's length is far noisier than a Doppler speed; stop_and_go,
                         #   max 30 s, window 60 s: 300: 1.62/1.59; 900: 1.48/1.32; whole drive: 1.44/1.27; at the
                         #   defaults 600: 1.37/1.26, 900: 1.38/1.20, 1800: 1.35/1.16 but tunnels RTS 1.65 -> 1.79)
odo_scale_window_s = 300.0  # odometer speeds times sum(GNSS speed) / sum(odometer speed) over the fixes
                         #   (>= course_min_speed_mps) in a centred window this long: removes the
                         #   wheel-scale error that q_s cannot hold (0: off, as in seed 002)
gyro_spike_radps = 1.0   # a yaw rate this far from its 5-sample median is a glitch: replaced (0: off)
odo_spike_mps = 5.0      # an odometer speed this far from its 5-sample median: replaced (0: off)
v_lin_mps = 0.1          # below this speed the distance row is linearised along the heading
dr_stale_s = 1.0         # a DR filter without any update for longer is left out of the fusion
                         #   (the GNSS filter: after the epochs' outage gap without an accepted fix)
init_pos_sd_m = 10.0     # initial sigmas of the shared state
init_vel_sd_mps = 5.0
init_acc_sd_mps2 = 1.0
init_heading_err_sd_rad = 0.1  # initial sigma of q_w (alignment of the gyro heading)
init_dist_err_sd_m = 0.05      # initial sigma of q_s
check_spd = false        # fkf and fafkf: Cholesky of every P at every epoch, failures in info["spd_failures"] (tests)
smooth_segment_epochs = 4096  # fkf/fafkf RTS: the forward pass keeps a checkpoint every this many epochs and
                         #   the smoother re-runs each segment from it (same floats), so it stores 65 floats
                         #   x this many epochs instead of x every epoch (0: store every epoch, 187 MB/hour)

[fafkf]
window = 20              # M residuals in the covariance-matching window
r_min_factor = 1.0       # R_jj clamped to [r_min_factor, r_max_factor] x its initial value; 1: nominal R is a
                         #   floor (Te is dominated by H P H^T, so matching drove R to any lower clamp:
                         #   0.1 tripled the DR-only error)
r_max_factor = 100.0
delta_max = 0.2          # largest |Delta| of one fuzzy R step (R_jj *= 1 + Delta)
residual_clip = 9.0      # a squared residual enters the window clipped to this x Te_jj (outlier guard)
weights = "shares"       # shares: covariance-weighted fusion, the fuzzy reliability W_1/(W_1 + W_2) the FR
                         #   information share (default: the paper's convex x = b x1 + (1-b) x2 scales each
                         #   local filter's update by its weight in FR mode, so neither is used in full; seeds
                         #   1-3 forward: urban 4.32 -> 3.00 m (fkf 3.08), stop_and_go 1.30 -> 0.86, tunnels
                         #   7.43 -> 7.14, one_hour 3.65 -> 3.68 m) | scalar (seed 002: one fuzzy beta; block
                         #   drifted 128 m in a 60-s outage) | block (per-state-block fuzzy weights)
normalisation = "share"  # share: value / sum over both filters | log
"""


def _parse_defaults() -> Params:
    # tomllib does read nan; keep them as floats.
    return tomllib.loads(DEFAULTS_TOML)


DEFAULTS: Params = _parse_defaults()


def defaults() -> Params:
    """A fresh copy of the defaults."""
    return copy.deepcopy(DEFAULTS)


def merge(base: Params, overrides: dict[str, Any], source: str = "parameters") -> Params:
    """Return ``base`` updated by ``overrides``, checking sections, keys and types."""
    out = copy.deepcopy(base)
    for section, values in overrides.items():
        if section not in out:
            raise ConfigError(f"{source}: unknown section [{section}]; "
                              f"known: {', '.join(sorted(out))}")
        if not isinstance(values, dict):
            raise ConfigError(f"{source}: [{section}] must be a table of key = value")
        for key, value in values.items():
            if key not in out[section]:
                raise ConfigError(f"{source}: unknown parameter {section}.{key}; "
                                  f"known in [{section}]: {', '.join(sorted(out[section]))}")
            out[section][key] = _coerce(out[section][key], value, f"{source}: {section}.{key}")
    return out


def _coerce(default: Any, value: Any, where: str) -> Any:
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
    elif isinstance(default, int):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif isinstance(default, float):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    elif isinstance(default, str) and isinstance(value, str):
        return value
    raise ConfigError(f"{where} = {value!r}: expected {type(default).__name__}")


def load(path: str | Path | None, base: Params | None = None) -> Params:
    """Defaults (or ``base``) overridden by a TOML file."""
    params = defaults() if base is None else base
    if path is None:
        return params
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the parameter file: {err.strerror}") from err
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not UTF-8 text: {err}") from err
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: invalid TOML: {err}") from err
    return merge(params, data, str(path))


def set_value(params: Params, dotted: str, value: Any) -> Params:
    """Set ``section.key`` (from a command-line option) with the same checks."""
    section, _, key = dotted.partition(".")
    return merge(params, {section: {key: value}}, "option")


def _fmt(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return repr(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return str(value)


def to_toml(params: Params) -> str:
    """The effective parameters as TOML (``--print-config``); loads back to the same values."""
    lines: list[str] = []
    for section, values in params.items():
        lines.append(f"[{section}]")
        lines.extend(f"{key} = {_fmt(v)}" for key, v in values.items())
        lines.append("")
    return "\n".join(lines)


def flat(params: Params) -> dict[str, str]:
    """``section.key -> value`` strings, for Parquet file metadata."""
    return {f"{s}.{k}": _fmt(v) for s, vals in params.items() for k, v in vals.items()}
