"""Plain numpy reference of the ekf/aekf (one Python iteration per epoch, dense matrices).

Readable on purpose: textbook letters x, P, F, Q, H, R, K, S, y, dense 8x8
products, ``np.linalg.solve`` for the smoother.  It shares only the input
preparation with the package (``aekf.gnss_noise``, ``aekf.initial_state``,
``aekf.kernel_params``: R/K_a per epoch, x0/P0 and the parameter vector) and
the model's dense matrices (``cs_model.phi_matrix``, ``newton_matrix``,
``q_matrix``, ``cs_sigma_a2``); the per-epoch cycle, measurement rows,
Joseph updates, gating, adaptive options and RTS are written out again here, so
that the tests comparing it with the compiled kernel check the kernel's block
arithmetic, packing and bookkeeping.

With ``aekf.gnss_err_states`` the state is 10-long, ``[x (8), b_e, b_n]``: the GNSS
error states of a first-order Gauss-Markov bias, ``z = (e, n) + b + v``, carried in
the same dense x, P, F, Q (the kernel keeps them as a separate block).
"""

from __future__ import annotations

import math

import numpy as np

from gpsdr_cli.filters import kernels_aekf as kn
from gpsdr_cli.filters.aekf import (
    coast_psd,
    drive_off_var,
    gnss_err_states_on,
    gnss_noise,
    gnss_velocity,
    initial_heading_var,
    initial_state,
    kernel_params,
    odometer_inputs,
    sensor_masks,
    unknown_rate_var,
)
from gpsdr_cli.models.cs_model import cs_sigma_a2, newton_matrix, phi_matrix, q_matrix


def joseph(x: np.ndarray, P: np.ndarray, H: np.ndarray, y: float, R: float,
           consider: tuple[int, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """Scalar Kalman update x, P with row H, innovation y, variance R (Joseph form).

    ``consider``: indices of states whose gain is forced to zero (Schmidt consider states).
    """
    S = float(H @ P @ H) + R
    K = P @ H / S
    if consider:
        K[list(consider)] = 0.0
    x = x + K * y
    A = np.eye(len(x)) - np.outer(K, H)
    P = A @ P @ A.T + R * np.outer(K, K)
    return x, 0.5 * (P + P.T)


def turn(x: np.ndarray, T: float, w: float, r_w: float) -> tuple[np.ndarray, np.ndarray,
                                                                 np.ndarray]:
    """aekf.turn_propagation: (x', J, Q_w) of turning v and a clockwise by (w - eps) T (any length >= 8),
    the position moved along the chord: p' = p + (T/2) (v' - v)."""
    dpsi = (w - x[6]) * T
    c, s = math.cos(dpsi), math.sin(dpsi)
    h = 0.5 * T
    Rm = np.array([[c, s], [-s, c]])  # acts on (east, north), clockwise by dpsi
    xr = x.copy()
    xr[[1, 4]] = Rm @ x[[1, 4]]
    xr[[2, 5]] = Rm @ x[[2, 5]]
    xr[[0, 3]] = x[[0, 3]] + h * (xr[[1, 4]] - x[[1, 4]])
    m = len(x)
    g = np.zeros(m)  # d x'/d dpsi
    g[1], g[4] = xr[4], -xr[1]
    g[2], g[5] = xr[5], -xr[2]
    g[0], g[3] = h * g[1], h * g[4]
    J = np.eye(m)
    J[np.ix_([1, 4], [1, 4])] = Rm
    J[np.ix_([2, 5], [2, 5])] = Rm
    J[np.ix_([0, 3], [1, 4])] += h * (Rm - np.eye(2))
    J[:, 6] += -T * g  # d dpsi / d eps = -T
    return xr, J, r_w * T * T * np.outer(g, g)


def along_joseph(x: np.ndarray, P: np.ndarray, H: np.ndarray, y: float, R: float,
                 consider: tuple[int, ...], d: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
    """:func:`joseph` with the gains of the (e, n), (v_e, v_n), (a_e, a_n) pairs projected on d."""
    S = float(H @ P @ H) + R
    K = P @ H / S
    if consider:
        K[list(consider)] = 0.0
    dv = np.array(d)
    for o in range(3):
        K[[o, o + 3]] = dv * float(dv @ K[[o, o + 3]])
    x = x + K * y
    A = np.eye(len(x)) - np.outer(K, H)
    P = A @ P @ A.T + R * np.outer(K, K)
    return x, 0.5 * (P + P.T)


def unit(i: int, m: int = 8) -> np.ndarray:
    H = np.zeros(m)
    H[i] = 1.0
    return H


def embed(A: np.ndarray, m: int, b_diag: float = 0.0) -> np.ndarray:
    """The 8x8 matrix A as the kinematic block of an m x m one, b_diag on the rest of the diagonal."""
    out = np.zeros((m, m))
    out[:8, :8] = A
    for i in range(8, m):
        out[i, i] = b_diag
    return out


def reference_filter(epochs, params, adaptive: bool) -> dict[str, np.ndarray]:
    """Forward pass (and RTS when params["filter"]["smooth"]); returns per-epoch arrays."""
    n = len(epochs)
    smooth = bool(params["filter"]["smooth"])
    r_e, r_n, ka, _ = gnss_noise(epochs, params, adaptive)
    has_gyro, has_odo = sensor_masks(epochs, params)  # plausible readings only
    has_odo, odo_speed, _ = odometer_inputs(epochs, params, has_odo)  # ... or the GNSS's standstill
    gv_e, gv_n = gnss_velocity(epochs, params)  # receiver speed/course as (v_e, v_n), or NaN
    x, P, psi_mem, heading_known = initial_state(epochs, params)
    a_p = params["aekf"]
    ge = gnss_err_states_on(epochs, params)  # GNSS error states b_e, b_n: x and P 10-long
    m = 10 if ge else 8
    var_b = a_p["gnss_err_sd_m"] ** 2
    if ge:
        x = np.concatenate([x, [0.0, 0.0]])
        P = embed(P, m, var_b)
    prm, _ = kernel_params(params, adaptive, smooth)
    coast = coast_psd(epochs, params)
    var_w = unknown_rate_var(params)
    fix_t = -math.inf  # the latest used fix (s)
    off_v, off_a = drive_off_var(params)
    alpha, tau_eps = prm[kn.PAR_ALPHA], prm[kn.PAR_TAU_EPS]
    sigma_a = prm[kn.PAR_SIGMA_A]
    st = params["standstill"]
    standstill = bool(st["enabled"])
    omega_min = st["omega_min_speed_mps"]
    ad = params["adaptive"]
    gate = bool(params["gnss"]["gate"])
    sa_py = cs_sigma_a2.py_func
    mode = params["aekf"]["drift_consider"]
    turn_on = bool(params["aekf"]["turn_propagation"])
    turn_row = params["aekf"]["turn_omega_row"]
    r_w = params["gyro"]["noise_sd_radps"] ** 2
    w_held, w_t = 0.0, -math.inf
    hfloor = bool(params["aekf"]["heading_floor"])
    vpsi, cpe = initial_heading_var(x, P, heading_known, params), 0.0  # heading floor (kernels_aekf)
    heading_min = max(st["heading_min_speed_mps"], omega_min)
    lat_mode = params["aekf"]["lateral_acc_only"]
    whiten = adaptive and bool(a_p["innovation_whitening"])  # Mehra: correlated innovations
    wh_c0 = wh_c1 = wh_c2 = 0.0
    wh_prev, wh_t, wh_m = np.zeros(2), -math.inf, 0
    wh_prev2, wh_t2, wh_static = np.zeros(2), -math.inf, 0
    b_since = -1.0  # bias gate timer
    n_fix = 0
    is_static = False
    t = 0.0
    odo_t = -math.inf  # the latest odometer record (s)
    rej_since = -1.0
    sh_r, sh_m = 1.0, 0
    xs = np.zeros((n, m))
    Ps = np.zeros((n, m, m))
    Ps_prior = np.zeros((n, m, m))
    xs_prior = np.zeros((n, m))
    Fs = np.zeros((n, m, m))
    nis = np.full(n, np.nan)
    used = np.zeros(n, bool)
    rejected = np.zeros(n, bool)
    static = np.zeros(n, bool)
    for k in range(n):
        T = epochs.dt_s[k]
        gap = T > params["aekf"]["max_gap_s"]
        if is_static and t + T - odo_t > kn.STALE_ODO_S:  # a silent odometer's stop expires
            is_static = False
        hold = (standstill and is_static) or gap
        F = np.eye(m)
        if k > 0 and T > 0:
            if adaptive:  # Fang et al. eqs. (14)-(15)
                s2e = sa_py(x[2], prm[kn.PAR_AMAX], prm[kn.PAR_AMIN], ka[k], sigma_a)
                s2n = sa_py(x[5], prm[kn.PAR_AMAX], prm[kn.PAR_AMIN], ka[k], sigma_a)
            else:
                s2e = s2n = sigma_a ** 2
            lam = prm[kn.PAR_FADING] ** T if ad["fading"] and prm[kn.PAR_FADING] > 1 else 1.0
            p66 = P[6, 6]
            w = math.nan
            F = phi_matrix(T, alpha, tau_eps, hold)
            Q = q_matrix(T, alpha, 2 * alpha * s2e, 2 * alpha * s2n, prm[kn.PAR_Q_EPS],
                         prm[kn.PAR_Q_KS], hold)
            Fm = newton_matrix(T, tau_eps, hold, params["aekf"]["drift_mean_decay"])
            if ge:  # b: Gauss-Markov, 1/tau_b = 1/tau + speed/distance (speed after the prediction)
                v_pred = 0.0 if hold else math.hypot(*(Fm @ x[:8])[[1, 4]])
                dist = a_p["gnss_err_dist_m"]
                f_b = math.exp(-T * (1.0 / a_p["gnss_err_tau_s"]
                                     + (v_pred / dist if dist > 0 else 0.0)))
                F, Q, Fm = embed(F, m, f_b), embed(Q, m, var_b * (1 - f_b ** 2)), embed(Fm, m, f_b)
            x = Fm @ x
            P = lam * F @ P @ F.T + Q
            P = 0.5 * (P + P.T)
            t += T
            if gap:  # not propagated; position variance grown by (60 m/s x T)^2
                P = P + np.diag([(60.0 * T) ** 2, 0, 0, (60.0 * T) ** 2] + [0] * (m - 4))
            if turn_on and not hold:
                if has_gyro[k] and math.isfinite(epochs.yaw_rate_radps[k]):
                    w = -epochs.yaw_rate_radps[k]
                elif t - w_t <= params["aekf"]["gyro_hold_s"]:
                    w = w_held
                if math.isfinite(w):  # gyro noise + scale error (random walk per radian turned)
                    x, J, Qw = turn(x, T, w, r_w + params["gyro"]["scale_sd"] ** 2 * abs(w) / T)
                    F = J @ F
                    P = J @ P @ J.T + Qw
                    P = 0.5 * (P + P.T)
            if hfloor:  # consider heading error: dpsi' = dpsi - T d_eps + T n_w
                if math.isfinite(w) or (hold and has_gyro[k]):
                    r_h = r_w + (params["gyro"]["scale_sd"] ** 2 * abs(w) / T if math.isfinite(w)
                                 else 0.0)
                    vpsi = min(vpsi + T * T * (p66 + r_h) - 2 * T * cpe, kn.VPSI_MAX)
                    cpe = math.exp(-T / tau_eps) * (cpe - T * p66)
                elif not hold and epochs.gnss_outage[k] and var_w > 0 and max(w_t, fix_t) > -math.inf:
                    tg = t - max(w_t, fix_t)  # no gyro reading in an outage: an unknown turn
                    tg0 = max(tg - T, 0.0)
                    vpsi = min(vpsi + var_w * (tg * tg - tg0 * tg0), kn.VPSI_MAX)
                elif not hold:
                    vpsi = cpe = 0.0
                v = math.hypot(x[1], x[4])
                if not hold and v >= omega_min:  # prior cross-track velocity var >= v^2 vpsi
                    ce, cn = x[4] / v, -x[1] / v  # summed as the kernel does (cancellation)
                    d = v * v * vpsi - (ce * ce * P[1, 1] + 2.0 * ce * cn * P[1, 4]
                                        + cn * cn * P[4, 4])
                    if d > 0.0:
                        P[np.ix_([1, 4], [1, 4])] += d * np.outer([ce, cn], [ce, cn])
        xs_prior[k], Ps_prior[k], Fs[k] = x, P, F  # the smoother's prior (P updated below)
        if epochs.has_gnss[k]:
            z = np.array([epochs.gnss_e[k], epochs.gnss_n[k]])
            if ge and params["gnss"]["gate"] and n_fix >= params["gnss"]["gate_warmup_fixes"]:
                # bias gate: b outside its stationary gate for gate_reset_s while moving -> position
                if x[8] ** 2 + x[9] ** 2 > prm[kn.PAR_GATE_THR] * var_b and not is_static:
                    if b_since < 0:
                        b_since = t
                    if t - b_since >= prm[kn.PAR_GATE_RESET]:
                        x = x.copy()
                        x[0] += x[8]
                        x[3] += x[9]
                        P = P + np.diag([x[8] ** 2, 0, 0, x[9] ** 2] + [0] * (m - 4))
                        x[8] = x[9] = 0.0
                        b_since = -1.0
                        Ps_prior[k] = P  # part of P(k|k-1), as the gate reset
                        xs_prior[k] = x  # ... and the mean's move, of x(k|k-1)
                elif not is_static:
                    b_since = -1.0
            Hg = np.zeros((2, m))
            Hg[0, 0] = Hg[1, 3] = 1.0
            if ge:  # z = position + b + v
                Hg[0, 8] = Hg[1, 9] = 1.0
            y = z - Hg @ x
            f_wh = 1.0
            if whiten and wh_c0 > 0.0 and wh_c1 > 0.0:  # white + Gauss-Markov innovations:
                r_c = min(max(wh_c2 / wh_c1, 0.0), 0.999)  # c1 = s r, c2 = s r^2
                s_c = min(wh_c1 / max(r_c, 1e-3), wh_c0)
                f_wh = min(((wh_c0 - s_c) + s_c * (1 + r_c) / (1 - r_c)) / wh_c0,
                           a_p["whitening_max"])
            if whiten and is_static:  # the m-th fix of a stop: R x m
                wh_static += 1
                f_wh = max(f_wh, wh_static)
            R = np.diag([r_e[k], r_n[k]]) * sh_r  # nominal: NIS, gate, innovation adaptive factor
            S = Hg @ P @ Hg.T + R
            nis[k] = float(y @ np.linalg.solve(S, y))
            accept, reset, r_fac = True, False, 1.0
            thr = prm[kn.PAR_GATE_THR]
            gn = params["gnss"]
            if gate and n_fix >= gn["gate_warmup_fixes"]:
                if nis[k] > thr:
                    if rej_since < 0:
                        rej_since = t
                    if t - rej_since >= prm[kn.PAR_GATE_RESET]:  # no lock-out, first
                        reset, rej_since = True, -1.0
                    elif (gn["gate_mode"] == "inflate" and nis[k] <= thr * gn["gate_inflate_max"]
                            and t - rej_since >= gn["gate_inflate_after_s"]):
                        r_fac = nis[k] / thr
                    else:
                        accept = False
                        rejected[k] = True
                else:
                    rej_since = -1.0
            if accept:
                if ad["innovation_factor"] and r_fac == 1.0 and not gap:  # the innovation-factor paper
                    beta = math.sqrt(float(y @ y) / np.trace(S))
                    a_f = 1.0 if beta <= ad["innovation_c"] else ad["innovation_c"] / beta
                    if a_f < 1.0:  # on the kinematic block only (see kernels_aekf)
                        D = np.diag([math.sqrt(1.0 / a_f)] * 6 + [1.0] * (m - 6))
                        P = D @ P @ D
                if reset:  # no lock-out: accept and inflate the position variance
                    P = P + np.diag([y[0] ** 2, 0, 0, y[1] ** 2] + [0] * (m - 4))
                Ps_prior[k] = P  # innovation adaptive factor and reset inflation are part of P(k|k-1)
                if ad["sage_husa"]:
                    b = ad["sage_husa_b"]
                    d = (1 - b) / (1 - b ** (sh_m + 1))
                    lo, hi = ad["sage_husa_r_min"], ad["sage_husa_r_max"]
                    sample = (y @ y - P[0, 0] - P[3, 3]) / (r_e[k] + r_n[k])
                    sh_r = min(max((1 - d) * sh_r + d * min(max(sample, lo), hi), lo), hi)
                    sh_m += 1
                re, rn = r_e[k] * sh_r * f_wh, r_n[k] * sh_r * f_wh
                if (whiten and not reset and r_fac == 1.0 and not is_static
                        and nis[k] <= -2.0 * math.log1p(-a_p["whitening_nis_prob"])
                        and P[0, 0] + P[3, 3] < (r_e[k] + r_n[k]) * sh_r):  # converged
                    u = y / np.sqrt([P[0, 0] + r_e[k] * sh_r, P[3, 3] + r_n[k] * sh_r])
                    b = a_p["whitening_b"]
                    d = (1 - b) / (1 - b ** (wh_m + 1))
                    wh_c0 = (1 - d) * wh_c0 + d * 0.5 * float(u @ u)
                    if t - wh_t <= a_p["whitening_gap_s"]:
                        wh_c1 = (1 - d) * wh_c1 + d * 0.5 * float(u @ wh_prev)
                    if t - wh_t2 <= 2 * a_p["whitening_gap_s"]:
                        wh_c2 = (1 - d) * wh_c2 + d * 0.5 * float(u @ wh_prev2)
                    wh_prev2, wh_t2 = wh_prev, wh_t
                    wh_prev, wh_t, wh_m = u, t, wh_m + 1
                # b is estimated only with a receiver velocity or at a standstill, else a
                # consider state
                has_v = is_static or (a_p["gnss_velocity"] and np.isfinite(gv_e[k])
                                      and np.isfinite(gv_n[k]))
                cons_b = (8, 9) if ge and not has_v else ()
                x, P = joseph(x, P, Hg[0], z[0] - Hg[0] @ x, re * r_fac, cons_b)
                x, P = joseph(x, P, Hg[1], z[1] - Hg[1] @ x, rn * r_fac, cons_b)
                used[k] = True
                fix_t = t
                n_fix += 1
                if a_p["gnss_velocity"] and np.isfinite(gv_e[k]) and np.isfinite(gv_n[k]):
                    r_v = a_p["gnss_velocity_sd_mps"] ** 2
                    x, P = joseph(x, P, unit(1, m), gv_e[k] - x[1], r_v)
                    x, P = joseph(x, P, unit(4, m), gv_n[k] - x[4], r_v)
        cons = (6,) if mode == "always" or (mode == "outage" and epochs.gnss_outage[k]) else ()
        o_mode = params["aekf"]["odo_consider"]  # k_s and the position
        cons_o = cons + ((0, 3, 7) if o_mode == "always" or (o_mode == "outage" and epochs.gnss_outage[k])
                         else ())
        cons_w = cons + ((1, 4) if params["aekf"]["heading_consider"] and epochs.gnss_outage[k]
                         else ())
        if turn_on and (lat_mode == "always" or (lat_mode == "outage" and epochs.gnss_outage[k])):
            cons_w = (0, 1, 3, 4, 6, 7)  # the lateral row corrects the acceleration only
        if has_odo[k]:
            u = odo_speed[k]
            odo_t = t
            was_static = is_static
            is_static = standstill and u < st["speed_mps"]
            if was_static and not is_static and heading_known:  # drive-off (aekf.drive_off_*),
                u_h = np.zeros(m)                                # along the remembered heading
                u_a = np.zeros(m)
                u_h[1], u_h[4] = math.sin(psi_mem), math.cos(psi_mem)
                u_a[2], u_a[5] = u_h[1], u_h[4]
                P = P + off_v * np.outer(u_h, u_h) + off_a * np.outer(u_a, u_a)
            if not is_static:
                wh_static = 0
            if is_static:  # zero-velocity update (Zeng et al.)
                zk = st["zupt_keeps_position"]  # position as consider states
                keep = (0, 3) if zk == "always" or (zk == "outage" and epochs.gnss_outage[k]) else ()
                for i in (1, 4, 2, 5):
                    x, P = joseph(x, P, unit(i, m), -x[i], st["zupt_sd_mps"] ** 2, keep)
            else:
                v = math.hypot(x[1], x[4])
                if v >= omega_min:
                    d_e, d_n, use = x[1] / v, x[4] / v, True
                else:
                    d_e, d_n, use = math.sin(psi_mem), math.cos(psi_mem), heading_known
                # u = k_s * |v| (Fang et al.'s s = k_s T v divided by T); a NaN record (the end of
                # a standstill from the GNSS, aekf.odometer_inputs) only ends the standstill
                if use and math.isfinite(u):
                    H = np.zeros(m)
                    H[1], H[4], H[7] = x[7] * d_e, x[7] * d_n, x[1] * d_e + x[4] * d_n
                    h = x[7] * (x[1] * d_e + x[4] * d_n)
                    if params["aekf"]["odo_along_track"]:
                        x, P = along_joseph(x, P, H, u - h, params["odo"]["noise_sd_mps"] ** 2, cons_o,
                                            (d_e, d_n))
                    else:
                        x, P = joseph(x, P, H, u - h, params["odo"]["noise_sd_mps"] ** 2, cons_o)
        if (coast > 0.0 and epochs.gnss_outage[k] and not is_static and T > 0.0
                and t - odo_t > kn.STALE_ODO_S):
            for i in (2, 5):  # coasting while no odometer record is fresh: a = 0 rows
                x, P = joseph(x, P, unit(i, m), -x[i], coast / T)
        static[k] = is_static
        if has_gyro[k]:
            w = -epochs.yaw_rate_radps[k]  # d(psi)/dt = -yaw_rate
            r_w = params["gyro"]["noise_sd_radps"] ** 2
            if is_static:
                x, P = joseph(x, P, unit(6, m), w - x[6], r_w)
            elif turn_on and turn_row == "skip":
                pass
            elif math.hypot(x[1], x[4]) >= omega_min:
                ve, ae, vn, an = x[1], x[2], x[4], x[5]
                v2 = ve ** 2 + vn ** 2
                c = vn * ae - ve * an
                H = np.zeros(m)  # Fang et al. Jacobian of omega
                H[1] = (-an * v2 - 2 * ve * c) / v2 ** 2
                H[4] = (ae * v2 - 2 * vn * c) / v2 ** 2
                H[2], H[5], H[6] = vn / v2, -ve / v2, 1.0
                if turn_on:  # "lateral": 0 = c / v2, the turn itself is in the prediction
                    H[6] = 0.0
                    x, P = joseph(x, P, H, -c / v2, r_w, cons_w)
                else:
                    x, P = joseph(x, P, H, w - (c / v2 + x[6]), r_w, cons_w)
        v = math.hypot(x[1], x[4])
        if hfloor and used[k] and v >= heading_min:  # the heading floor restarts from P
            c = np.array([x[4], -x[1]]) / v
            vpsi = min(float(c @ P[np.ix_([1, 4], [1, 4])] @ c) / v ** 2, kn.VPSI_MAX)
            cpe = float(c @ P[[1, 4], 6]) / v
        if v >= heading_min:
            psi_mem, heading_known = math.atan2(x[1], x[4]), True
        elif has_gyro[k] and k > 0:
            psi_mem += (-epochs.yaw_rate_radps[k] - x[6]) * T
        if has_gyro[k] and math.isfinite(epochs.yaw_rate_radps[k]):
            w_held, w_t = -epochs.yaw_rate_radps[k], t
        xs[k], Ps[k] = x, P
    if smooth and n > 1:
        xs, Ps = _rts(xs, Ps, xs_prior, Ps_prior, Fs)
    return {"x": xs, "P": Ps, "nis": nis, "gnss_used": used, "gnss_rejected": rejected,
            "static": static}


def _rts(xs: np.ndarray, Ps: np.ndarray, xs_prior: np.ndarray, Ps_prior: np.ndarray,
         Fs: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Textbook RTS: C = P(k|k) F^T P(k+1|k)^-1 (a solve), x_s = x + C (x_s' - x_prior')."""
    x_s, P_s = xs.copy(), Ps.copy()
    for k in range(len(xs) - 2, -1, -1):
        C = np.linalg.solve(Ps_prior[k + 1], Fs[k + 1] @ Ps[k]).T
        x_s[k] = xs[k] + C @ (x_s[k + 1] - xs_prior[k + 1])
        P = Ps[k] + C @ (P_s[k + 1] - Ps_prior[k + 1]) @ C.T
        P_s[k] = 0.5 * (P + P.T)
    return x_s, P_s
