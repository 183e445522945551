"""Compiled parts of the batch smoother (:mod:`gpsdr_cli.filters.graph`): residuals and
Jacobians of every factor assembled into the banded normal equations, the selected
inversion of the banded Cholesky factor, and the interpolation from keyframes to epochs.

Layout: keyframe ``i`` owns the ten unknowns ``10 i + (E, N, V, PSI, B, S, G, GE, GN, GC)``:
east and north (m, local frame), speed v (m/s), heading psi (rad, clockwise from north,
unwrapped), gyro bias b (rad/s) and gyro scale correction g (the yaw rate's sign:
``d(psi)/dt = -((1 + g) yaw_rate - b)``, so a gyro reading ``(1 + k)`` times the true rate
has g = 1 / (1 + k) - 1), odometer scale s (true speed = s x odometer speed; on a drive
without an odometer, the forward accelerometer's offset in m/s^2: dv/dt = reading - s) and
the GNSS error per axis (m: fix = position + error + white noise), and the bias of the
receiver's course (rad: course = heading + bias + noise; pinned at zero but in the NLOS
segment fit's last solve).  Every factor links keyframe i to i + 1 at most, and only the
displacement reaches past keyframe i + 1's own slot of an unknown (from keyframe i's east to
i + 1's speed), so in this order the information matrix is banded with ``BAND = 12``
sub-diagonals (the band of two whole keyframes, 19, carried seven that stay zero through
every factorisation), stored in LAPACK's lower form (``ab[r - c, c] = H[r, c]`` for
r >= c; Fortran order, so each column's band is contiguous) and factored here
(:func:`band_cholesky`): LAPACK's ``dpbtrf`` factors a band this narrow column by column
with two BLAS calls each, and took 22 ms on an NLOS hour's band where the compiled loop,
its update unrolled over the band's fixed width, takes 7-8 ms (one core of a 2-vCPU AMD
EPYC, OpenBLAS 0.3.30).

Per epoch step (epoch j-1 -> j, length dt): the speed is ``s_i x odo[j-1]`` where the
odometer is fresh (``odo_ok``), else the speed state interpolated linearly between the
keyframes; the heading turns by ``-((1 + g_i) yaw_rate[j-1] - b_i) dt`` where the gyro is fresh
(``gyro_ok``), else not at all (a heading random walk covers it).  Position uses the
heading at the middle of the step.  Written by hand (numba): the factors are specific to
our epoch layout, and a generic factor-graph library with Python-side custom factors costs
milliseconds per factor (see the module docstring of filters/graph.py).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

N_X = 10
E, N, V, PSI, B, S, G, GE, GN, GC = 0, 1, 2, 3, 4, 5, 6, 7, 8, 9
# the widest coupling: keyframe i's east with i + 1's speed, through the displacement
# (19 -> 12 super-diagonals)
BAND = N_X + V - E
N_2 = 2 * N_X

# kernel ids
K_GAUSS, K_HUBER, K_CAUCHY, K_GEMAN = 0, 1, 2, 3

# per-interval noise table columns (frozen between relinearisations of the noise): the
# displacement's whitening, L^-1 = [[w11, 0], [w21, w22]] with L L^T its covariance, and the
# heading change's sd (rad)
Q_W11, Q_W21, Q_W22, Q_SD_PSI = 0, 1, 2, 3
N_Q = 4

# parameter vector
P_SD_ODO, P_Q_DIST, P_POS_FLOOR, P_HEAD_RW, P_GYRO_SCALE, P_NOGYRO_RW, P_ACC_SD = range(7)
P_BIAS_RW, P_SCALE_RW, P_ZARU_SD, P_VTIE_SD, P_GSPEED_SD, P_GCOURSE_MIN, P_MAX_STEP = range(7, 14)
P_GYRO_SD, P_STOP_SPEED, P_ZUPT_SD = 14, 15, 16  # P_GYRO_SD: rad/s x sqrt(sample interval), per sqrt(s)
P_GSCALE_RW = 17  # the gyro scale correction's random walk, per sqrt(s)
N_P = 18


@njit(cache=True)
def wrap(a: float) -> float:
    """Angle to (-pi, pi]."""
    return a - 2.0 * math.pi * math.floor((a + math.pi) / (2.0 * math.pi))


@njit(cache=True)
def robust_weight(r2: float, kernel: int, c: float) -> float:
    """IRLS weight of a squared normalised residual r2 (rho'(r2) in the r2 form)."""
    if kernel == K_CAUCHY:
        return 1.0 / (1.0 + r2 / (c * c))
    if kernel == K_HUBER:
        r = math.sqrt(r2)
        return 1.0 if r <= c else c / r
    if kernel == K_GEMAN:
        d = 1.0 + r2 / (c * c)
        return 1.0 / (d * d)
    return 1.0


@njit(cache=True)
def robust_weights(r2: np.ndarray, kernel: int, c: float) -> np.ndarray:
    """:func:`robust_weight` of each element of ``r2``."""
    out = np.empty(len(r2))
    for i in range(len(r2)):
        out[i] = robust_weight(r2[i], kernel, c)
    return out


@njit(cache=True)
def robust_cost(r2: float, kernel: int, c: float) -> float:
    """rho(r2): 2 x the negative log-likelihood up to a constant (r2 for the Gaussian)."""
    if kernel == K_CAUCHY:
        return c * c * math.log1p(r2 / (c * c))
    if kernel == K_HUBER:
        r = math.sqrt(r2)
        return r2 if r <= c else 2.0 * c * r - c * c
    if kernel == K_GEMAN:
        return r2 / (1.0 + r2 / (c * c))
    return r2


@njit(cache=True)
def _add_block(ab, g, base, J, r, m, ncol, w, nz):
    """H += w J^T J and g += w J^T r for rows J[:m, :ncol] on unknowns base .. base+ncol-1,
    and those rows of ``J`` zeroed again (the next factor starts from a zero ``J``).

    Row by row over the row's non-zero columns (``nz``: scratch, ``ncol`` long): a
    factor's row touches 2-12 of the 16 unknowns."""
    for k in range(m):
        cnt = 0
        for a in range(ncol):
            if J[k, a] != 0.0:
                nz[cnt] = a
                cnt += 1
        if cnt and nz[cnt - 1] - nz[0] > BAND:  # the columns are ascending
            raise ValueError("a factor couples unknowns outside the band")
        wr = w * r[k]
        for ia in range(cnt):
            a = nz[ia]
            wa = w * J[k, a]
            ra = base + a
            g[ra] += J[k, a] * wr
            for ib in range(ia, cnt):
                bb = nz[ib]
                ab[bb - a, ra] += wa * J[k, bb]
        for ia in range(cnt):
            J[k, nz[ia]] = 0.0


@njit(cache=True)
def _add_row(ab, g, base, c0, v0, c1, v1, c2, v2, rk, w):
    """:func:`_add_block` of one row with at most three non-zeros, given directly: values
    ``v0 .. v2`` in the columns ``c0 < c1 < c2`` of unknowns ``base ..`` (a zero value is
    skipped, as there; an unused slot has value 0), residual ``rk``, weight ``w``.  The
    same products in the same order, so the same sums to the bit; a factor's short rows
    spent most of a linearisation scanning 20 columns of J for their two or three entries."""
    wr = w * rk
    cols = (c0, c1, c2)
    vals = (v0, v1, v2)
    for a in range(3):
        va = vals[a]
        if va == 0.0:
            continue
        wa = w * va
        ra = base + cols[a]
        g[ra] += va * wr
        ab[0, ra] += wa * va
        for b in range(a + 1, 3):
            if vals[b] != 0.0:
                ab[cols[b] - cols[a], ra] += wa * vals[b]


@njit(cache=True)
def _turn(yaw_k, bias, gsc, dt, gyro_ok_k, t_gyro):
    """One step's heading change (rad) with the gyro's reading (scale correction ``gsc``),
    0 without one, and the gyro time (s) to the step's middle and to its end, from
    ``t_gyro`` at its start."""
    if gyro_ok_k:
        return -((1.0 + gsc) * yaw_k - bias) * dt, t_gyro + 0.5 * dt, t_gyro + dt
    return 0.0, t_gyro, t_gyro


@njit(cache=True)
def _integrate(x, i, j0, j1, t_s, yaw, odo, gyro_ok, odo_ok, prm):
    """Dead reckoning over epochs j0+1 .. j1 from keyframe i's state.

    Returns (dE, dN, dpsi, d_psi_e, d_psi_n, d_b_e, d_b_n, d_s_e, d_s_n, d_v0_e, d_v0_n,
    d_v1_e, d_v1_n, t_gyro, dist, sum_var_speed_dt2, t_free, t_nogyro, turned)."""
    b0 = N_X * i
    psi0 = x[b0 + PSI]
    v0 = x[b0 + V]
    v1 = x[b0 + N_X + V]
    bias = x[b0 + B]
    gsc = x[b0 + G]
    scale = x[b0 + S]
    T = t_s[j1] - t_s[j0]
    de = dn = 0.0
    dpsi = 0.0
    jpe = jpn = jbe = jbn = jse = jsn = 0.0
    jv0e = jv0n = jv1e = jv1n = 0.0
    t_gyro = 0.0
    dist = 0.0
    var_sp = 0.0
    t_free = 0.0
    t_nogyro = 0.0
    turned = 0.0
    max_step = prm[P_MAX_STEP]
    for j in range(j0 + 1, j1 + 1):
        dt = t_s[j] - t_s[j - 1]
        if dt <= 0.0:
            continue
        if dt > max_step:  # no record for this long: nothing is known of the motion
            t_free += dt
            continue
        k = j - 1
        step, tg_mid, t_gyro = _turn(yaw[k], bias, gsc, dt, gyro_ok[k], t_gyro)
        if not gyro_ok[k]:
            t_nogyro += dt
        turned += abs(step)
        psi_mid = psi0 + dpsi + 0.5 * step
        sn = math.sin(psi_mid)
        cs = math.cos(psi_mid)
        if odo_ok[k]:
            u = scale * odo[k]
            jse += odo[k] * dt * sn
            jsn += odo[k] * dt * cs
            var_sp += (prm[P_SD_ODO] * dt) ** 2
        else:
            tau = (t_s[j - 1] + 0.5 * dt - t_s[j0]) / T if T > 0.0 else 0.0
            u = v0 + (v1 - v0) * tau
            jv0e += (1.0 - tau) * dt * sn
            jv0n += (1.0 - tau) * dt * cs
            jv1e += tau * dt * sn
            jv1n += tau * dt * cs
        de += u * dt * sn
        dn += u * dt * cs
        jpe += u * dt * cs
        jpn += -u * dt * sn
        jbe += u * dt * cs * tg_mid
        jbn += -u * dt * sn * tg_mid
        dist += abs(u) * dt
        dpsi += step
    return (de, dn, dpsi, jpe, jpn, jbe, jbn, jse, jsn, jv0e, jv0n, jv1e, jv1n, t_gyro, dist,
            var_sp, t_free, t_nogyro, turned)


# per-interval preintegrated sums (:func:`_preintegrate`): the bias and the scale correction
# they were taken at (rad/s; 1), the raw heading change (rad: -sum(yaw dt), bias and scale
# aside), the gyro time (s), the largest |raw heading| inside the interval (rad), then per
# speed source (odometer; speed state's start, end) the moments sum(w tau^n e^(i a)),
# n = 0..N_MOM-1, as (re, im) pairs, and after them the same with w x phi (phi: the raw
# heading to the step's middle), for the scale correction's first order
PRE_B, PRE_PHI, PRE_TG, PRE_G, PRE_PHIMAX = 0, 1, 2, 3, 4
N_MOM = 5
PRE_M = 5
PRE_F = PRE_M + 3 * 2 * N_MOM
N_PRE = PRE_F + 3 * 2 * N_MOM
#: largest bias change x gyro time (rad) the moments are expanded over before they are taken
#: again: the expansion's error is below (0.02)^4 / 24 (the bias Jacobian's sum, one order
#: short of the displacement's) relative
PRE_REFRESH_RAD = 0.02
#: largest scale change x raw heading (rad) taken to first order before the sums are taken
#: again: the displacement's error is below (0.003)^2 / 2 relative
PRE_REFRESH_G_RAD = 0.003


@njit(cache=True)
def _preintegrate(pre, i, j0, j1, bias, gsc, t_s, yaw, odo, gyro_ok, odo_ok, prm):
    """Fill ``pre[i]`` for the interval j0 -> j1 at the gyro bias ``bias`` (rad/s) and scale
    correction ``gsc``.

    The step from epoch j-1 heads at ``psi0 + a``, a = (1 + g) phi + b tau (phi: the raw yaw
    integral to the step's middle, tau: the gyro time to it), so every displacement sum of
    :func:`_integrate` is the keyframe's heading rotation of sum(w e^(i a)) with w the step's
    speed weight: odometer x dt, or the speed state's linear share (1 - tau', tau') x dt.
    Taken at one bias, the sums at another follow from the moments in tau (the bias only
    turns e^(i a) by e^(i db tau)), and at another scale, to first order, from the moments
    with w phi (e^(i dg phi) ~ 1 + i dg phi): :func:`_integrate_pre`."""
    T = t_s[j1] - t_s[j0]
    for c in range(N_PRE):
        pre[i, c] = 0.0
    dpsi = 0.0
    t_gyro = 0.0
    phi = 0.0
    phi_max = 0.0
    max_step = prm[P_MAX_STEP]
    for j in range(j0 + 1, j1 + 1):
        dt = t_s[j] - t_s[j - 1]
        if dt <= 0.0 or dt > max_step:
            continue
        k = j - 1
        step, tg_mid, t_gyro = _turn(yaw[k], bias, gsc, dt, gyro_ok[k], t_gyro)
        phi_mid = phi
        if gyro_ok[k]:
            phi_mid = phi - 0.5 * yaw[k] * dt
            phi -= yaw[k] * dt
        phi_max = max(phi_max, abs(phi))
        a = dpsi + 0.5 * step
        dpsi += step
        ca = math.cos(a)
        sa = math.sin(a)
        if odo_ok[k]:
            _moments(pre, i, PRE_M, odo[k] * dt, tg_mid, ca, sa)
            _moments(pre, i, PRE_F, odo[k] * dt * phi_mid, tg_mid, ca, sa)
        else:
            tau = (t_s[j - 1] + 0.5 * dt - t_s[j0]) / T if T > 0.0 else 0.0
            _moments(pre, i, PRE_M + 2 * N_MOM, (1.0 - tau) * dt, tg_mid, ca, sa)
            _moments(pre, i, PRE_M + 4 * N_MOM, tau * dt, tg_mid, ca, sa)
            _moments(pre, i, PRE_F + 2 * N_MOM, (1.0 - tau) * dt * phi_mid, tg_mid, ca, sa)
            _moments(pre, i, PRE_F + 4 * N_MOM, tau * dt * phi_mid, tg_mid, ca, sa)
    pre[i, PRE_B] = bias
    pre[i, PRE_G] = gsc
    pre[i, PRE_PHI] = phi
    pre[i, PRE_TG] = t_gyro
    pre[i, PRE_PHIMAX] = phi_max


@njit(cache=True)
def _moments(pre, i, col, w, tau, ca, sa):
    p = w
    for n in range(N_MOM):
        pre[i, col + 2 * n] += p * ca
        pre[i, col + 2 * n + 1] += p * sa
        p *= tau


@njit(cache=True)
def _expand(pre, i, col, d, first):
    """sum(w tau^first e^(i (a + d tau))) from the moments at ``col`` (d: bias change, rad/s):
    sum over n of (i d)^n / n! x moment(first + n)."""
    re = 0.0
    im = 0.0
    # (i d)^n / n!: real, imaginary parts
    fr = 1.0
    fi = 0.0
    for n in range(N_MOM - first):
        mr = pre[i, col + 2 * (first + n)]
        mi = pre[i, col + 2 * (first + n) + 1]
        re += fr * mr - fi * mi
        im += fr * mi + fi * mr
        fr, fi = -fi * d / (n + 1), fr * d / (n + 1)
    return re, im


@njit(cache=True)
def _integrate_pre(x, i, j0, j1, t_s, yaw, odo, gyro_ok, odo_ok, prm, pre, jac):
    """:func:`_integrate`'s first 14 results from the preintegrated sums ``pre`` (taken again
    for interval i when the bias or the scale correction has moved too far from the one they
    were taken at), then the displacement's Jacobian in the scale correction (east, north)
    and the raw heading change (rad).  Without ``jac`` the bias and scale Jacobians are left
    at zero: the cost alone needs the displacement, and its expansion is half the work."""
    b0 = N_X * i
    psi0 = x[b0 + PSI]
    bias = x[b0 + B]
    gsc = x[b0 + G]
    d = bias - pre[i, PRE_B]
    dg = gsc - pre[i, PRE_G]
    # (also NaN: not yet taken)
    if not (abs(d) * pre[i, PRE_TG] <= PRE_REFRESH_RAD
            and abs(dg) * pre[i, PRE_PHIMAX] <= PRE_REFRESH_G_RAD):
        _preintegrate(pre, i, j0, j1, bias, gsc, t_s, yaw, odo, gyro_ok, odo_ok, prm)
        d = 0.0
        dg = 0.0
    c0 = math.cos(psi0)
    s0 = math.sin(psi0)
    # per speed source (odometer x s, the speed state's start v0 and end v1): the sums of
    # w sin and w cos at the keyframe's heading, of w tau cos, w tau sin for the bias, and
    # of w phi cos, w phi sin for the scale (e^(i dg phi) to first order)
    de = dn = jbe = jbn = jge = jgn = 0.0
    fr = fi = 0.0
    se = sn_ = v0e = v0n = v1e = v1n = 0.0
    for f in range(3):
        col = PRE_M + 2 * N_MOM * f
        zr, zi = _expand(pre, i, col, d, 0)
        if dg != 0.0 or jac:
            fr, fi = _expand(pre, i, PRE_F + 2 * N_MOM * f, d, 0)
            zr -= dg * fi
            zi += dg * fr
        ws = s0 * zr + c0 * zi
        wc = c0 * zr - s0 * zi
        u = x[b0 + S] if f == 0 else (x[b0 + V] if f == 1 else x[b0 + N_X + V])
        de += u * ws
        dn += u * wc
        if jac:
            tr, ti = _expand(pre, i, col, d, 1)
            jbe += u * (c0 * tr - s0 * ti)
            jbn -= u * (s0 * tr + c0 * ti)
            jge += u * (c0 * fr - s0 * fi)
            jgn -= u * (s0 * fr + c0 * fi)
        if f == 0:
            se, sn_ = ws, wc
        elif f == 1:
            v0e, v0n = ws, wc
        else:
            v1e, v1n = ws, wc
    t_gyro = pre[i, PRE_TG]
    phi = pre[i, PRE_PHI]
    dpsi = (1.0 + gsc) * phi + bias * t_gyro
    return (de, dn, dpsi, dn, -de, jbe, jbn, se, sn_, v0e, v0n, v1e, v1n, t_gyro, jge, jgn, phi)


@njit(cache=True)
def interval_noise(x, key_ep, t_s, yaw, odo, gyro_ok, odo_ok, prm, v_psd, q_out):
    """The whitening of each interval's dead-reckoned displacement and the sd of its heading
    change (:data:`Q_W11` ...), from the sensors' noise at the state ``x`` (frozen while the
    state is solved; taken here once, not at each of the solve's many cost evaluations).
    ``v_psd``: per interval, the PSD of the speed state's unmodelled acceleration (m^2/s^3)."""
    n_key = len(key_ep)
    for i in range(n_key - 1):
        j0, j1 = key_ep[i], key_ep[i + 1]
        res = _integrate(x, i, j0, j1, t_s, yaw, odo, gyro_ok, odo_ok, prm)
        dpsi, t_gyro, dist, var_sp, t_free, t_nogyro, turned = (res[2], res[13], res[14],
                                                                  res[15], res[16], res[17],
                                                                  res[18])
        T = t_s[j1] - t_s[j0]
        # heading: gyro white noise per sample, the per-radian scale error, a random walk;
        # without a gyro the heading walks freely
        var_psi = prm[P_GYRO_SD] ** 2 * t_gyro + prm[P_GYRO_SCALE] ** 2 * turned \
            + prm[P_HEAD_RW] ** 2 * T + prm[P_NOGYRO_RW] ** 2 * t_nogyro + 1e-12
        var_a = var_sp + prm[P_Q_DIST] ** 2 * dist + prm[P_POS_FLOOR] ** 2
        # speed from the interpolated speed state: unmodelled acceleration inside the interval
        var_a += v_psd[i] * T ** 3 / 12.0 * _odo_free_share(j0, j1, t_s, odo_ok)
        var_c = dist * dist * var_psi / 3.0 + prm[P_Q_DIST] ** 2 * dist + prm[P_POS_FLOOR] ** 2
        free = (60.0 * t_free) ** 2  # 60 m/s through a stretch without any record
        var_a += free
        var_c += free
        psi_m = x[N_X * i + PSI] + 0.5 * dpsi
        sa, ca = math.sin(psi_m), math.cos(psi_m)
        # along = (sin, cos), cross = (cos, -sin)
        qee = var_a * sa * sa + var_c * ca * ca
        qen = var_a * sa * ca - var_c * ca * sa
        qnn = var_a * ca * ca + var_c * sa * sa
        l11 = math.sqrt(qee)
        l21 = qen / l11
        l22 = math.sqrt(max(qnn - l21 * l21, 1e-18))
        q_out[i, Q_W11] = 1.0 / l11
        q_out[i, Q_W21] = -l21 / (l11 * l22)
        q_out[i, Q_W22] = 1.0 / l22
        q_out[i, Q_SD_PSI] = math.sqrt(var_psi + (10.0 * t_free) ** 2)


@njit(cache=True)
def _odo_free_share(j0, j1, t_s, odo_ok):
    T = t_s[j1] - t_s[j0]
    if T <= 0.0:
        return 0.0
    free = 0.0
    for j in range(j0 + 1, j1 + 1):
        if not odo_ok[j - 1]:
            free += t_s[j] - t_s[j - 1]
    return free / T


@njit(cache=True)
def linearise(x, key_ep, t_s, yaw, odo, gyro_ok, odo_ok, stopped, q, prm,
              fix_e, fix_n, fix_sde, fix_sdn, gspd, gcrs, gvel_w, err_phi, err_wsd, crs_phi,
              crs_wsd, acc_dv, acc_t, v_sd, s_sd, prior_mean, prior_sd, kernel, c, ab, g, want,
              fix_kernel, seg_sd, seg_crs_sd, seg_vote, seg_kernel, seg_c, pre):
    """Cost of the state ``x`` and, with ``want``, the normal equations H (banded, ``ab``) and
    gradient ``g`` (J^T W r) of every factor at ``x`` (IRLS weights from ``x``).

    Fix arrays are per keyframe (NaN: no fix / no speed there); ``gvel_w``: the information
    of each receiver velocity (speed and course) as a multiple of ``P_GSPEED_SD``'s (> 0).
    The GNSS error states follow ``eps[i+1] = err_phi[i] eps[i] + w``, sd(w) = ``err_wsd[i]``
    (per interval, m); the course bias likewise with ``crs_phi``, ``crs_wsd`` (rad).
    The speed state follows ``v[i+1] = v[i] + acc_dv[i] - s[i] acc_t[i] + w``, sd(w) =
    ``v_sd[i]``: the forward accelerometer's integral over the interval (m/s) less the
    offset held in the S slot (m/s^2) over the ``acc_t[i]`` seconds it covers; a drive
    without an accelerometer has both at 0 (a random walk).  sd of S's random walk:
    ``s_sd[i]``.
    Fix positions are under ``fix_kernel``, the receiver's velocity under ``kernel``.
    ``seg_sd`` (per keyframe, NaN: none): a zero prior on the error state there, sd in m
    (with the course bias, sd ``seg_crs_sd`` in rad, in the same robust vote; 0: not in it),
    under ``seg_kernel`` at scale ``seg_c``, counted ``seg_vote`` times (one per segment
    of fixes that share one reflected-signal bias, whatever the number of its fixes).
    ``pre``: per interval, the dead reckoning's preintegrated sums (:func:`_preintegrate`;
    NaN rows are taken at the first call), kept from call to call.
    Returns the cost: the robust cost of the GNSS factors plus the squared whitened
    residuals of the others."""
    n_key = len(key_ep)
    if want:
        # column by column: ``ab`` is in LAPACK's (Fortran) order, and a row-major sweep
        # strode through it 16 times
        for col in range(ab.shape[1]):
            for row in range(ab.shape[0]):
                ab[row, col] = 0.0
        g[:] = 0.0
    cost = 0.0
    # the dead reckoning's rows (displacement east, north; heading change), whose entries
    # depend on the sensors; every other factor's rows go to :func:`_add_row` directly
    J = np.zeros((3, N_2))
    r = np.zeros(3)
    je = np.zeros(N_2)
    jn = np.zeros(N_2)
    nz = np.empty(N_2, np.int64)
    # ---- prior on keyframe 0 (and, through the random walks, on every b and s)
    for a in range(N_X):
        rr = (x[a] - prior_mean[a]) / prior_sd[a]
        if a == PSI:
            rr = wrap(x[a] - prior_mean[a]) / prior_sd[a]
        cost += rr * rr
        if want:
            _add_row(ab, g, 0, a, 1.0 / prior_sd[a], 0, 0.0, 0, 0.0, rr, 1.0)
    for i in range(n_key - 1):
        j0, j1 = key_ep[i], key_ep[i + 1]
        T = t_s[j1] - t_s[j0]
        b0 = N_X * i
        res = _integrate_pre(x, i, j0, j1, t_s, yaw, odo, gyro_ok, odo_ok, prm, pre, want)
        de, dn, dpsi = res[0], res[1], res[2]
        t_gyro = res[13]
        # ---- displacement: r = p1 - p0 - D, whitened by the inverse Cholesky factor of Q
        m11, m21, m22 = q[i, Q_W11], q[i, Q_W21], q[i, Q_W22]
        re = x[b0 + N_X + E] - x[b0 + E] - de
        rn = x[b0 + N_X + N] - x[b0 + N] - dn
        w0 = m11 * re
        w1 = m21 * re + m22 * rn
        cost += w0 * w0 + w1 * w1
        if want:
            # raw Jacobian rows (east, north) over the 12 unknowns of keyframes i, i+1
            je[:] = 0.0
            jn[:] = 0.0
            je[E] = -1.0
            jn[N] = -1.0
            je[N_X + E] = 1.0
            jn[N_X + N] = 1.0
            je[PSI] = -res[3]
            jn[PSI] = -res[4]
            je[B] = -res[5]
            jn[B] = -res[6]
            je[G] = -res[14]
            jn[G] = -res[15]
            je[S] = -res[7]
            jn[S] = -res[8]
            je[V] = -res[9]
            jn[V] = -res[10]
            je[N_X + V] = -res[11]
            jn[N_X + V] = -res[12]
            for cc in range(N_2):
                J[0, cc] = m11 * je[cc]
                J[1, cc] = m21 * je[cc] + m22 * jn[cc]
            r[0] = w0
            r[1] = w1
        # ---- heading change against the gyro
        sd_psi = q[i, Q_SD_PSI]
        rp = wrap(x[b0 + N_X + PSI] - x[b0 + PSI] - dpsi) / sd_psi
        cost += rp * rp
        if want:
            J[2, N_X + PSI] = 1.0 / sd_psi
            J[2, PSI] = -1.0 / sd_psi
            J[2, B] = -t_gyro / sd_psi
            J[2, G] = -res[16] / sd_psi
            r[2] = rp
            _add_block(ab, g, b0, J, r, 3, N_2, 1.0, nz)
        # ---- random walks of b and s; the speed state driven by the accelerometer
        sq = math.sqrt(max(T, 1e-6))
        sdb = prm[P_BIAS_RW] * sq
        sds = s_sd[i]
        sdv = v_sd[i]
        rb = (x[b0 + N_X + B] - x[b0 + B]) / sdb
        rs = (x[b0 + N_X + S] - x[b0 + S]) / sds
        rv = (x[b0 + N_X + V] - x[b0 + V] - acc_dv[i] + x[b0 + S] * acc_t[i]) / sdv
        cost += rb * rb + rs * rs + rv * rv
        if want:
            _add_row(ab, g, b0, B, -1.0 / sdb, N_X + B, 1.0 / sdb, 0, 0.0, rb, 1.0)
            _add_row(ab, g, b0, S, -1.0 / sds, N_X + S, 1.0 / sds, 0, 0.0, rs, 1.0)
            _add_row(ab, g, b0, V, -1.0 / sdv, S, acc_t[i] / sdv, N_X + V, 1.0 / sdv, rv, 1.0)
        # ... and of the gyro's scale correction
        sdg = prm[P_GSCALE_RW] * sq
        rgs = (x[b0 + N_X + G] - x[b0 + G]) / sdg
        cost += rgs * rgs
        if want:
            _add_row(ab, g, b0, G, -1.0 / sdg, N_X + G, 1.0 / sdg, 0, 0.0, rgs, 1.0)
        # ---- the speed state tied to the odometer at keyframe i+1
        k1 = key_ep[i + 1]
        if odo_ok[k1]:
            rt = (x[b0 + N_X + V] - x[b0 + N_X + S] * odo[k1]) / prm[P_VTIE_SD]
            cost += rt * rt
            if want:
                _add_row(ab, g, b0, N_X + V, 1.0 / prm[P_VTIE_SD], N_X + S,
                         -odo[k1] / prm[P_VTIE_SD], 0, 0.0, rt, 1.0)
        # ---- standstill: no heading change (the gyro's reading is then its bias); without
        # an odometer reading at the keyframe, zero speed at it
        if stopped[i]:
            rz = wrap(x[b0 + N_X + PSI] - x[b0 + PSI]) / prm[P_ZARU_SD]
            cost += rz * rz
            if want:
                _add_row(ab, g, b0, PSI, -1.0 / prm[P_ZARU_SD], N_X + PSI, 1.0 / prm[P_ZARU_SD],
                         0, 0.0, rz, 1.0)
            if not odo_ok[k1]:
                rz = x[b0 + N_X + V] / prm[P_ZUPT_SD]
                cost += rz * rz
                if want:
                    _add_row(ab, g, b0, N_X + V, 1.0 / prm[P_ZUPT_SD], 0, 0.0, 0, 0.0, rz, 1.0)
        # ---- the GNSS error states: first-order Gauss-Markov per axis; the course bias
        phi = err_phi[i]
        wsd = err_wsd[i]
        for ax in range(3):
            col = GE + ax
            if col == GC:
                phi = crs_phi[i]
                wsd = crs_wsd[i]
            rg = (x[b0 + N_X + col] - phi * x[b0 + col]) / wsd
            cost += rg * rg
            if want:
                _add_row(ab, g, b0, col, -phi / wsd, N_X + col, 1.0 / wsd, 0, 0.0, rg, 1.0)
    # ---- odometer tie at keyframe 0
    if odo_ok[key_ep[0]]:
        rt = (x[V] - x[S] * odo[key_ep[0]]) / prm[P_VTIE_SD]
        cost += rt * rt
        if want:
            _add_row(ab, g, 0, V, 1.0 / prm[P_VTIE_SD], S, -odo[key_ep[0]] / prm[P_VTIE_SD],
                     0, 0.0, rt, 1.0)
    # ---- GNSS factors (robust)
    for i in range(n_key):
        b0 = N_X * i
        if not math.isnan(fix_e[i]):
            re = (x[b0 + E] + x[b0 + GE] - fix_e[i]) / fix_sde[i]
            rn = (x[b0 + N] + x[b0 + GN] - fix_n[i]) / fix_sdn[i]
            r2 = re * re + rn * rn
            cost += robust_cost(r2, fix_kernel, c)
            if want:
                w = robust_weight(r2, fix_kernel, c)
                _add_row(ab, g, b0, E, 1.0 / fix_sde[i], GE, 1.0 / fix_sde[i], 0, 0.0, re, w)
                _add_row(ab, g, b0, N, 1.0 / fix_sdn[i], GN, 1.0 / fix_sdn[i], 0, 0.0, rn, w)
        if not math.isnan(gspd[i]):
            sd = prm[P_GSPEED_SD] / math.sqrt(gvel_w[i])
            rv = (x[b0 + V] - gspd[i]) / sd
            r2 = rv * rv
            with_course = not math.isnan(gcrs[i]) and gspd[i] >= prm[P_GCOURSE_MIN]
            if with_course:
                sdc = sd / gspd[i]
                rc = wrap(x[b0 + PSI] + x[b0 + GC] - gcrs[i]) / sdc
                r2 += rc * rc
            cost += robust_cost(r2, kernel, c)
            if want:
                w = robust_weight(r2, kernel, c)
                _add_row(ab, g, b0, V, 1.0 / sd, 0, 0.0, 0, 0.0, rv, w)
                if with_course:
                    _add_row(ab, g, b0, PSI, 1.0 / sdc, GC, 1.0 / sdc, 0, 0.0, rc, w)
        if not math.isnan(seg_sd[i]):
            re = x[b0 + GE] / seg_sd[i]
            rn = x[b0 + GN] / seg_sd[i]
            r2 = re * re + rn * rn
            if seg_crs_sd > 0.0:  # the course bias, where the caller frees it
                rcb = x[b0 + GC] / seg_crs_sd
                r2 += rcb * rcb
            cost += seg_vote[i] * robust_cost(r2, seg_kernel, seg_c)
            if want:
                w = seg_vote[i] * robust_weight(r2, seg_kernel, seg_c)
                _add_row(ab, g, b0, GE, 1.0 / seg_sd[i], 0, 0.0, 0, 0.0, re, w)
                _add_row(ab, g, b0, GN, 1.0 / seg_sd[i], 0, 0.0, 0, 0.0, rn, w)
                if seg_crs_sd > 0.0:
                    _add_row(ab, g, b0, GC, 1.0 / seg_crs_sd, 0, 0.0, 0, 0.0, rcb, w)
    return cost


@njit(cache=True)
def keyframe_epochs(t_s, mark, step_s):
    """Greedy keyframes: epoch 0, every ``mark``ed epoch, and the first epoch ``step_s`` (s)
    or more after the last keyframe (compiled: a Python loop over an hour at 100 Hz took
    0.3 s per solve)."""
    out = np.empty(len(t_s), np.int64)
    out[0] = 0
    m = 1
    last_t = t_s[0]
    for k in range(1, len(t_s)):
        if mark[k] or t_s[k] - last_t >= step_s - 1e-9:
            out[m] = k
            m += 1
            last_t = t_s[k]
    return out[:m].copy()


@njit(cache=True)
def fix_weights(x, fix_e, fix_n, fix_sde, fix_sdn, kernel, c, w_out, r2_out):
    """Robust weight and squared normalised residual of each keyframe's fix (NaN: none)."""
    for i in range(len(fix_e)):
        if math.isnan(fix_e[i]):
            w_out[i] = np.nan
            r2_out[i] = np.nan
            continue
        re = (x[N_X * i + E] + x[N_X * i + GE] - fix_e[i]) / fix_sde[i]
        rn = (x[N_X * i + N] + x[N_X * i + GN] - fix_n[i]) / fix_sdn[i]
        r2 = re * re + rn * rn
        r2_out[i] = r2
        w_out[i] = robust_weight(r2, kernel, c)


@njit(cache=True)
def band_cholesky(ab):
    """H = L L^T in place: ``ab`` holds H's lower band (``ab[r - c, c] = H[r, c]``) and
    leaves holding L's.  Column by column, each column's update of the next ``BAND``
    columns at once (right-looking).  Returns 0, or the 1-based column whose pivot is not
    positive (H not positive definite, or not finite), as LAPACK's ``info``.

    Away from the last ``BAND`` columns the column is copied to a scratch vector and every
    loop runs the full band width: with fixed bounds and no aliasing between the column
    read and the columns written the compiler unrolls the update, twice as fast on an
    hour's drive (13 -> 7 ms a factor) and the same to the bit."""
    n = ab.shape[1]
    col = np.empty(BAND + 1)
    n_full = max(n - BAND, 0)
    for j in range(n):
        d = ab[0, j]
        if not d > 0.0:  # also NaN
            return j + 1
        ljj = math.sqrt(d)
        ab[0, j] = ljj
        inv = 1.0 / ljj
        if j < n_full:
            for p in range(1, BAND + 1):
                v = ab[p, j] * inv
                ab[p, j] = v
                col[p] = v
            for p in range(1, BAND + 1):
                v = col[p]
                if v != 0.0:
                    for q in range(p, BAND + 1):
                        ab[q - p, j + p] -= col[q] * v
            continue
        m = n - 1 - j
        for p in range(1, m + 1):
            ab[p, j] *= inv
        for p in range(1, m + 1):
            v = ab[p, j]
            if v != 0.0:
                for q in range(p, m + 1):
                    ab[q - p, j + p] -= ab[q, j] * v
    return 0


@njit(cache=True)
def band_cholesky_damped(ab, lam, out):
    """:func:`band_cholesky` of H with its diagonal times (1 + ``lam``), plus 1e-12 (the
    Levenberg-Marquardt damping), into ``out``; ``ab`` is left as it is for a retry at
    another damping (``out`` may be ``ab`` itself when it is not needed again).  One pass
    over the columns: numpy's damping and restoring of ``ab``'s diagonal (a strided row)
    took longer than the factor on an hour's drive."""
    n = ab.shape[1]
    scale = 1.0 + lam
    for j in range(n):
        out[0, j] = ab[0, j] * scale + 1e-12
        for p in range(1, ab.shape[0]):
            out[p, j] = ab[p, j]
    return band_cholesky(out)


@njit(cache=True)
def band_solve(lb, rhs):
    """x with L L^T x = ``rhs``, ``lb`` the lower band of L (:func:`band_cholesky`)."""
    n = lb.shape[1]
    x = rhs.copy()
    for j in range(n):
        x[j] /= lb[0, j]
        v = x[j]
        for p in range(1, min(BAND, n - 1 - j) + 1):
            x[j + p] -= lb[p, j] * v
    for j in range(n - 1, -1, -1):
        s = x[j]
        for p in range(1, min(BAND, n - 1 - j) + 1):
            s -= lb[p, j] * x[j + p]
        x[j] = s / lb[0, j]
    return x


def upper_of_lower(lb: np.ndarray) -> np.ndarray:
    """The upper band of U = L^T (``cb[BAND + r - c, c] = U[r, c]``) from L's lower band."""
    n = lb.shape[1]
    cb = np.zeros_like(lb)
    for d in range(min(BAND + 1, n)):  # a drive of fewer unknowns than the band is wide
        cb[BAND - d, d:] = lb[d, :n - d]
    return cb


@njit(cache=True)
def banded_inverse_band(cb, n):
    """Entries of H^-1 inside the band from H's upper banded Cholesky factor ``cb``
    (H = U^T U, ``cb[BAND + r - c, c] = U[r, c]``), by the backward recursion of Takahashi,
    Fagan & Chin (1973): O(n BAND^2).  Returns the same banded layout."""
    u = BAND
    sb = np.zeros((u + 1, n))
    for i in range(n - 1, -1, -1):
        uii = cb[u, i]
        hi = min(i + u, n - 1)
        for j in range(hi, i - 1, -1):
            s = 0.0
            for k in range(i + 1, hi + 1):
                uik = cb[u + i - k, k]
                if uik == 0.0:
                    continue
                # Sigma[k, j], symmetric, inside the band
                if k <= j:
                    skj = sb[u + k - j, j]
                else:
                    skj = sb[u + j - k, k]
                s += uik * skj
            if j == i:
                sb[u, i] = (1.0 / uii - s) / uii
            else:
                sb[u + i - j, j] = -s / uii
    return sb


@njit(cache=True)
def to_epochs(x, key_ep, t_s, yaw, odo, gyro_ok, odo_ok, prm, n_ep,
              e_out, n_out, ve_out, vn_out, psi_out):
    """Every epoch's position, velocity and heading: the dead reckoning from the keyframe
    before it, its closure error at the next keyframe spread linearly in time."""
    n_key = len(key_ep)
    for i in range(n_key):
        k = key_ep[i]
        e_out[k] = x[N_X * i + E]
        n_out[k] = x[N_X * i + N]
        psi_out[k] = x[N_X * i + PSI]
    for i in range(n_key - 1):
        j0, j1 = key_ep[i], key_ep[i + 1]
        res = _integrate(x, i, j0, j1, t_s, yaw, odo, gyro_ok, odo_ok, prm)
        T = t_s[j1] - t_s[j0]
        ce = x[N_X * i + N_X + E] - x[N_X * i + E] - res[0]
        cn = x[N_X * i + N_X + N] - x[N_X * i + N] - res[1]
        cp = wrap(x[N_X * i + N_X + PSI] - x[N_X * i + PSI] - res[2])
        psi0 = x[N_X * i + PSI]
        bias = x[N_X * i + B]
        gsc = x[N_X * i + G]
        scale = x[N_X * i + S]
        v0 = x[N_X * i + V]
        v1 = x[N_X * i + N_X + V]
        pe = x[N_X * i + E]
        pn = x[N_X * i + N]
        dpsi = 0.0
        for j in range(j0 + 1, j1):
            dt = t_s[j] - t_s[j - 1]
            kk = j - 1
            if dt > 0.0 and dt <= prm[P_MAX_STEP]:
                step = -((1.0 + gsc) * yaw[kk] - bias) * dt if gyro_ok[kk] else 0.0
                psi_mid = psi0 + dpsi + 0.5 * step
                tau = (t_s[j - 1] + 0.5 * dt - t_s[j0]) / T if T > 0.0 else 0.0
                u = scale * odo[kk] if odo_ok[kk] else v0 + (v1 - v0) * tau
                pe += u * dt * math.sin(psi_mid)
                pn += u * dt * math.cos(psi_mid)
                dpsi += step
            f = (t_s[j] - t_s[j0]) / T if T > 0.0 else 0.0
            e_out[j] = pe + ce * f
            n_out[j] = pn + cn * f
            psi_out[j] = psi0 + dpsi + cp * f
    # velocity at every epoch from the speed at it and its heading
    for i in range(n_key - 1):
        j0, j1 = key_ep[i], key_ep[i + 1]
        T = t_s[j1] - t_s[j0]
        scale = x[N_X * i + S]
        v0 = x[N_X * i + V]
        v1 = x[N_X * i + N_X + V]
        for j in range(j0, j1 + 1 if i == n_key - 2 else j1):
            tau = (t_s[j] - t_s[j0]) / T if T > 0.0 else 0.0
            u = scale * odo[j] if odo_ok[j] else v0 + (v1 - v0) * tau
            ve_out[j] = u * math.sin(psi_out[j])
            vn_out[j] = u * math.cos(psi_out[j])
    if n_key == 1:
        k = key_ep[0]
        u = x[S] * odo[k] if odo_ok[k] else x[V]
        ve_out[k] = u * math.sin(x[PSI])
        vn_out[k] = u * math.cos(x[PSI])
