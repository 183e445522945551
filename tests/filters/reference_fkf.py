"""Plain numpy, per-epoch reference of fkf and fafkf (Tang et al.), in textbook letters.

Written to be obviously right rather than fast: dense ``Phi``, ``Q``, ``H``;
``K = P H^T S^-1``; the Joseph form as a matrix product; the fusion with
``np.linalg.solve``; the RTS smoother as ``C = P Phi^T P_prior^-1``.  The
compiled kernels (:mod:`gpsdr_cli.filters.kernels_fkf`) must reproduce its
tracks to 1e-9 relative.  It takes the same prepared inputs
(:func:`gpsdr_cli.filters.fkf.prepare`: the heading integration, odometer
distances and standstill flags are vectorised numpy there already) and the
same fuzzy control tables (:mod:`gpsdr_cli.filters.fuzzy`).

Also here: :func:`tiny_drive`, a small drive generator with known truth for
the closed-form tests (straight lines and circles), independent of
:mod:`gpsdr_cli.simulate`.
"""

from __future__ import annotations

import math

import numpy as np

from gpsdr_cli.filters import fuzzy
from gpsdr_cli.filters import kernels_fkf as kf
from gpsdr_cli.filters.fkf import Prepared

NX = 10
POS_BLOCK = [kf.IE, kf.IN]
VEL_BLOCK = [kf.IVE, kf.IAE, kf.IVN, kf.IAN]


def eps_factor(T: float, par: np.ndarray, x: np.ndarray) -> float:
    """Gauss-Markov factor of eps over T: time constant tau, and the distance |v| T driven
    over the decorrelation distance D (when D > 0)."""
    rate = 1.0 / par[kf.PAR_TAU_EPS]
    if par[kf.PAR_EPS_DIST] > 0:
        rate += math.hypot(x[1], x[4]) / par[kf.PAR_EPS_DIST]
    return math.exp(-T * rate)


def regime_par(par: np.ndarray, w: float) -> np.ndarray:
    """``par`` with the eps model of a step into regime ``w`` (0 clear sky, 1 obstructed,
    between: 1/tau, 1/D and sd^2 interpolated linearly; a distance <= 0 adds no rate)."""
    out = par.copy()
    c = (par[kf.PAR_TAU_EPS_C], par[kf.PAR_EPS_SD_C], par[kf.PAR_EPS_DIST_C])
    o = (par[kf.PAR_TAU_EPS_O], par[kf.PAR_EPS_SD_O], par[kf.PAR_EPS_DIST_O])
    if w <= 0 or w >= 1:
        tau, sd, dist = c if w <= 0 else o
    else:
        tau = 1 / ((1 - w) / c[0] + w / o[0])
        sd = math.sqrt((1 - w) * c[1] ** 2 + w * o[1] ** 2)
        inv = (1 - w) * (1 / c[2] if c[2] > 0 else 0) + w * (1 / o[2] if o[2] > 0 else 0)
        dist = 1 / inv if inv > 0 else 0.0
    out[kf.PAR_TAU_EPS], out[kf.PAR_EPS_SD], out[kf.PAR_EPS_DIST] = tau, sd, dist
    return out


def Phi_of(T: float, static: bool, par: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Tang et al. eqs. (2)-(3) with the T^2/2 erratum; kinematics held at standstill."""
    Phi = np.eye(NX)
    if not static:
        axis = np.array([[1.0, T, 0.5 * T * T], [0.0, 1.0, T], [0.0, 0.0, 1.0]])
        Phi[0:3, 0:3] = axis
        Phi[3:6, 3:6] = axis
    Phi[6, 6] = Phi[7, 7] = eps_factor(T, par, x)
    return Phi


def Q_of(T: float, static: bool, par: np.ndarray, x: np.ndarray) -> np.ndarray:
    """White-jerk kinematics, stationary Gauss-Markov eps, random-walk q_w, q_s."""
    Q = np.zeros((NX, NX))
    if not static:
        q = par[kf.PAR_JERK_PSD]
        axis = q * np.array([[T**5 / 20, T**4 / 8, T**3 / 6],
                             [T**4 / 8, T**3 / 3, T**2 / 2],
                             [T**3 / 6, T**2 / 2, T]])
        Q[0:3, 0:3] = axis
        Q[3:6, 3:6] = axis
    f = eps_factor(T, par, x)
    Q[6, 6] = Q[7, 7] = par[kf.PAR_EPS_SD] ** 2 * (1 - f * f)
    Q[8, 8] = par[kf.PAR_QW_RW] ** 2 * T
    Q[9, 9] = par[kf.PAR_QS_RW] ** 2 * T
    return Q


def cap(P: np.ndarray) -> np.ndarray:
    """Sigma ceiling after a prediction (kernels_fkf.SD_CEILING, cap_variance): a capped
    state's variance and covariances scaled by its factor f = (ceiling / sigma)^2."""
    sd = np.sqrt(np.diag(P))
    if np.all(sd <= kf.SD_CEILING):
        return P
    f = np.minimum(1.0, (kf.SD_CEILING / sd) ** 2)
    out = P * np.outer(f, f)
    np.fill_diagonal(out, np.diag(P) * f)
    return out


def kf_update(x: np.ndarray, P: np.ndarray, H: np.ndarray, y: float, R: float,
              consider: tuple[int, ...] = ()) -> tuple[np.ndarray, np.ndarray]:
    """One scalar row: K = P H^T / S (zero for the ``consider`` states), Joseph form."""
    S = float(H @ P @ H) + R
    K = P @ H / S
    K[list(consider)] = 0.0
    x = x + K * y
    IKH = np.eye(NX) - np.outer(K, H)
    P = IKH @ P @ IKH.T + R * np.outer(K, K)
    return x, 0.5 * (P + P.T)


def wrap(a: float) -> float:
    return a - 2 * math.pi * math.ceil((a - math.pi) / (2 * math.pi))


def row(name: str, x: np.ndarray, t_m: float = 0.0, v_lin: float = 0.0,
        psi_hint: float = 0.0, heading: bool = False) -> tuple[np.ndarray, float]:
    """Measurement row H and prediction h(x) (Tang et al. eqs. (6), (8), (10)-(14) with errata)."""
    H = np.zeros(NX)
    ve, vn = x[1], x[4]
    if name == "e":
        H[0] = H[6] = 1
        return H, x[0] + x[6]
    if name == "n":
        H[3] = H[7] = 1
        return H, x[3] + x[7]
    if name == "heading":
        v2 = ve * ve + vn * vn
        H[1], H[4], H[8] = vn / v2, -ve / v2, 1
        return H, math.atan2(ve, vn) + x[8]
    v = math.hypot(ve, vn)
    H[9] = 1
    ue, un = math.sin(psi_hint), math.cos(psi_hint)
    if v >= v_lin and not (heading and ue * ve + un * vn < 0):   # not reversed against it
        H[1], H[4] = t_m * ve / v, t_m * vn / v
        return H, t_m * v + x[9]
    H[1], H[4] = t_m * ue, t_m * un
    return H, t_m * (ue * ve + un * vn) + x[9]


class Window:
    """Covariance matching for one component (Tang et al. eqs. (15)-(18)) + fuzzy R step."""

    def __init__(self, M: int) -> None:
        self.buf = [0.0] * M
        self.pos = 0
        self.count = 0
        self.factor = 1.0
        self.u = 0.0

    def push(self, y: float, Te: float, par: np.ndarray) -> None:
        M = len(self.buf)
        lim = math.sqrt(par[kf.PAR_RES_CLIP] * Te)
        self.buf[self.pos] = min(max(y, -lim), lim)
        self.pos = (self.pos + 1) % M
        self.count += 1
        if self.count < M:
            return
        Ra = sum(v * v for v in self.buf) / M
        if par[kf.PAR_RES_DEMEAN]:                  # the scatter about the window's mean
            Ra -= (sum(self.buf) / M) ** 2
        u = min(max((Te - Ra) / Te, -1.0), 1.0)
        self.u = u
        delta = par[kf.PAR_DELTA_MAX] * np.interp(u, np.linspace(-1, 1, len(fuzzy.R_TABLE)),
                                                fuzzy.R_TABLE)
        self.factor = min(max(self.factor * (1 + delta), par[kf.PAR_R_MIN]), par[kf.PAR_R_MAX])


def bilinear(table: np.ndarray, a: float, b: float) -> float:
    n = table.shape[0]
    a = min(max(a, 0.0), 1.0) * (n - 1)
    b = min(max(b, 0.0), 1.0) * (n - 1)
    i, j = min(int(a), n - 2), min(int(b), n - 2)
    wa, wb = a - i, b - j
    t0 = table[i, j] + wb * (table[i, j + 1] - table[i, j])
    t1 = table[i + 1, j] + wb * (table[i + 1, j + 1] - table[i + 1, j])
    return t0 + wa * (t1 - t0)


def normalise(a: float, b: float, log: bool) -> tuple[float, float]:
    if log:
        la = min(max(0.5 + 0.25 * math.log10((a + 1e-300) / (b + 1e-300)), 0.0), 1.0)
        return la, 1 - la
    return (a / (a + b), b / (a + b)) if a + b > 0 else (0.0, 0.0)


def beta(P1: np.ndarray, P2: np.ndarray, d1: np.ndarray, d2: np.ndarray, idx: list[int],
         de: tuple[float, float], log: bool) -> float:
    """Tang et al. eq. (20) with PE = tr(M M^T), M = D^-1 P D^-1 over the block."""
    M1 = (P1 / np.outer(d1, d1))[np.ix_(idx, idx)]
    M2 = (P2 / np.outer(d2, d2))[np.ix_(idx, idx)]
    p1, p2 = normalise(float(np.trace(M1 @ M1.T)), float(np.trace(M2 @ M2.T)), log)
    W1 = bilinear(fuzzy.W_TABLE, p1, de[0])
    W2 = bilinear(fuzzy.W_TABLE, p2, de[1])
    return W1 / (W1 + W2)


def run_reference(prep: Prepared, kind: str, smooth: bool = False) -> dict[str, np.ndarray]:
    """Forward pass (and RTS when ``smooth``) of fkf or fafkf; returns the fused track."""
    par, flags = prep.par, prep.flags
    fr = bool(flags[kf.FLG_MODE_FR])
    adaptive = kind == "fafkf"
    fusion = kf.FUSE_COV if kind == "fkf" else (
        flags[kf.FLG_FUSION] if flags[kf.FLG_FUSION] != kf.FUSE_COV else kf.FUSE_BLOCK)
    log = bool(flags[kf.FLG_NORM])
    gnss_on, dr_on = bool(flags[kf.FLG_GNSS_ON]), bool(flags[kf.FLG_DR_ON])
    both = gnss_on and dr_on
    n = len(prep.dt)
    d1, d2 = np.ones(NX), np.ones(NX)
    if fr and both:
        c0 = min(max(par[kf.PAR_BETA_GNSS], 0.05), 0.95) if fusion == kf.FUSE_COV else 0.5
        d1[:], d2[:] = 1 / math.sqrt(c0), 1 / math.sqrt(1 - c0)
    x1, x2 = prep.x0.copy(), prep.x0.copy()
    P1, P2 = prep.P0 * np.outer(d1, d1), prep.P0 * np.outer(d2, d2)
    xg, Pg = prep.x0.copy(), prep.P0.copy()
    own1 = list(range(NX)) if fr else [0, 1, 2, 3, 4, 5, 6, 7]
    own2 = list(range(NX)) if fr else [0, 1, 2, 3, 4, 5, 8, 9]
    win = [Window(int(flags[kf.FLG_WINDOW])) for _ in range(4)]
    zupt_R = par[kf.PAR_ZUPT_SD] ** 2
    t, t_acc, t_dr, t_head, psi_hint = 0.0, 0.0, 0.0, 0.0, prep.psi0
    t_dist = 0.0
    n_acc, share, t_fix = 0, 0.0, 0.0
    xs, Ps = np.zeros((n, NX)), np.zeros((n, NX, NX))
    beta_out = np.full((n, 2), np.nan)
    used = np.zeros(n, bool)

    def zupt(x, P, consider):
        for i in (1, 4, 2, 5):
            H = np.zeros(NX)
            H[i] = 1
            x, P = kf_update(x, P, H, -x[i], zupt_R, consider)
        return x, P

    for k in range(n):
        T = prep.dt[k] if k > 0 else 0.0
        t += T
        st = bool(prep.static[k])
        # without a fresh fix a stop corrects the velocity only (kernels_fkf.ZUPT_CONSIDER),
        # and never the heading's alignment error q_w (kernels_fkf.ZUPT_KEEP_HEADING)
        zc = (0, 3, 6, 7, 8) if t - t_acc > par[kf.PAR_GNSS_STALE_S] else (8,)
        if T > 0:
            pk = regime_par(par, prep.eps_w[k])           # the eps model of this step
            Phi1, Q1 = Phi_of(T, st, pk, x1), Q_of(T, st, pk, x1)
            Phi2, Q2 = Phi_of(T, st, pk, x2), Q_of(T, st, pk, x2)
            x1, x2 = Phi1 @ x1, Phi2 @ x2
            P1 = cap(Phi1 @ P1 @ Phi1.T + np.outer(d1, d1) * Q1)
            P2 = cap(Phi2 @ P2 @ Phi2.T + np.outer(d2, d2) * Q2)
        if gnss_on:
            if st:
                x1, P1 = zupt(x1, P1, zc)
            if prep.has_gnss[k]:
                z = np.array([prep.gnss_e[k], prep.gnss_n[k]])
                H1 = np.array([row("e", x1)[0], row("n", x1)[0]])
                y = z - H1 @ x1                           # Tang et al. eq. (15)
                HPH = H1 @ P1 @ H1.T
                R0 = np.array([prep.gnss_var_e[k], prep.gnss_var_n[k]])
                if adaptive:
                    for j in range(2):
                        win[j].push(y[j], HPH[j, j] + win[j].factor * R0[j], par)
                R = np.diag([win[0].factor * R0[0], win[1].factor * R0[1]])
                S = HPH + R
                nis = float(y @ np.linalg.solve(S, y))
                chi2 = par[kf.PAR_GATE_CHI2]
                tau = par[kf.PAR_GATE_RESET_S] / math.log(2.0)
                a = math.exp(-(t - t_fix) / tau) if tau > 0 else 0.0
                t_fix = t
                accept = not (chi2 > 0 and nis > chi2 and n_acc >= par[kf.PAR_GATE_WARMUP]
                              and t - t_acc <= par[kf.PAR_GATE_RESET_S]
                              and a * share + (1 - a) <= 0.5)
                share = a * share + (1 - a) * (not accept)
                if accept:
                    for j, name in enumerate(("e", "n")):
                        H, h = row(name, x1)
                        x1, P1 = kf_update(x1, P1, H, z[j] - h, R[j, j])
                    gv = (prep.gnss_ve[k], prep.gnss_vn[k])
                    if par[kf.PAR_GVEL_VAR] > 0 and not np.isnan(gv).any():
                        for j, i in enumerate((1, 4)):            # receiver velocity v_e, v_n
                            H = np.zeros(NX)
                            H[i] = 1
                            x1, P1 = kf_update(x1, P1, H, gv[j] - x1[i], par[kf.PAR_GVEL_VAR])
                    used[k] = True
                    n_acc += 1
                    t_acc = t
        else:
            t_acc = t
        if dr_on:
            if st:
                x2, P2 = zupt(x2, P2, zc)
                t_dr = t_dist = t
            else:
                if (par[kf.PAR_COAST_Q] > 0 and T > 0 and t - t_dist > par[kf.PAR_DR_STALE_S]
                        and t - t_acc > par[kf.PAR_GNSS_STALE_S]):    # no speed measured: a = 0 rows
                    for i in (2, 5):
                        H = np.zeros(NX)
                        H[i] = 1
                        x2, P2 = kf_update(x2, P2, H, -x2[i], par[kf.PAR_COAST_Q] / T)
                th, dist, t_m = prep.theta[k], prep.dist[k], prep.t_m[k]
                do_head = do_dist = False
                if not math.isnan(th):
                    psi_hint = th - x2[8]
                    v2 = x2[1] ** 2 + x2[4] ** 2
                    speed_known = t - t_dist <= par[kf.PAR_DR_STALE_S]
                    do_head = (v2 >= par[kf.PAR_OMEGA_MIN] ** 2 and speed_known) or (
                        v2 >= par[kf.PAR_OMEGA_MIN] ** 2
                        and v2 * v2 >= kf.HEAD_SPEED_SNR2 * (x2[[1, 4]] @ P2[np.ix_([1, 4], [1, 4])]
                                                                @ x2[[1, 4]]))
                if not math.isnan(dist) and t_m > 0:
                    do_dist = True
                R_head = par[kf.PAR_HEAD_SD] ** 2
                R_dist = (par[kf.PAR_ODO_SD] * t_m) ** 2
                if adaptive:
                    if do_head:
                        H, h = row("heading", x2)
                        win[2].push(wrap(th - h), H @ P2 @ H + win[2].factor * R_head, par)
                    if do_dist:
                        H, h = row("dist", x2, t_m, par[kf.PAR_V_LIN], psi_hint, not math.isnan(th))
                        win[3].push(dist - h, H @ P2 @ H + win[3].factor * R_dist, par)
                if do_head:
                    H, h = row("heading", x2)
                    y, R = wrap(th - h), win[2].factor * R_head
                    chi2 = par[kf.PAR_HEAD_CHI2]
                    if chi2 > 0 and y * y > chi2 * (H @ P2 @ H + R):
                        if t - t_head > par[kf.PAR_GATE_RESET_S]:     # re-align q_w
                            x2 = x2.copy()
                            x2[8] += y
                            P2 = P2.copy()
                            P2[8, 8] += y * y
                            t_head = t
                    else:
                        x2, P2 = kf_update(x2, P2, H, y, R)
                        t_head = t_dr = t
                if do_dist:
                    H, h = row("dist", x2, t_m, par[kf.PAR_V_LIN], psi_hint, not math.isnan(th))
                    y, R = dist - h, win[3].factor * R_dist
                    chi2 = par[kf.PAR_HEAD_CHI2]
                    if not (chi2 > 0 and y * y > chi2 * (H @ P2 @ H + R)):
                        x2, P2 = kf_update(x2, P2, H, y, R)
                        t_dr = t_dist = t
        g_fresh = t - t_acc <= par[kf.PAR_GNSS_STALE_S]
        d_fresh = t - t_dr <= par[kf.PAR_DR_STALE_S]
        if both and not fr and g_fresh != d_fresh:        # NR: a stale filter is left out
            if g_fresh:
                xg, Pg = x1.copy(), P1.copy()
                beta_out[k] = 1.0
            else:
                xg, Pg = x2.copy(), P2.copy()
                beta_out[k] = 0.0
        elif both:
            if fusion in (kf.FUSE_COV, kf.FUSE_SHARES):
                if fusion == kf.FUSE_SHARES:              # fuzzy information share
                    de = normalise(win[0].u ** 2 + win[1].u ** 2,
                                   win[2].u ** 2 + win[3].u ** 2, log)
                    bp = beta(P1, P2, d1, d2, list(range(NX)), de, log)
                Y, yv = np.zeros((NX, NX)), np.zeros(NX)
                for x, P, own in ((x1, P1, own1), (x2, P2, own2)):
                    ix = np.ix_(own, own)
                    Y[ix] += np.linalg.solve(P[ix], np.eye(len(own)))
                    yv[own] += np.linalg.solve(P[ix], x[own])
                Pg = np.linalg.solve(Y, np.eye(NX))
                Pg = 0.5 * (Pg + Pg.T)
                xg = np.linalg.solve(Y, yv)
                if fusion == kf.FUSE_SHARES:
                    w = np.full(NX, bp)
                    beta_out[k] = [bp, bp]
                else:
                    w = np.full(NX, par[kf.PAR_BETA_GNSS])
                    beta_out[k] = [0.5 * (Pg[0, 0] / P1[0, 0] + Pg[3, 3] / P1[3, 3]),
                                   0.5 * (Pg[1, 1] / P1[1, 1] + Pg[4, 4] / P1[4, 4])]
            else:
                de = normalise(win[0].u ** 2 + win[1].u ** 2, win[2].u ** 2 + win[3].u ** 2, log)
                if fusion == kf.FUSE_BLOCK:
                    bp = beta(P1, P2, d1, d2, POS_BLOCK, de, log)
                    bv = beta(P1, P2, d1, d2, VEL_BLOCK, de, log)
                else:
                    bp = bv = beta(P1, P2, d1, d2, list(range(NX)), de, log)
                w = np.array([bp, bv, bv, bp, bv, bv, 1, 1, 0, 0], float)
                if fr:
                    w[6:8], w[8:10] = bp, bv
                W1, W2 = np.diag(w), np.eye(NX) - np.diag(w)
                xg = W1 @ x1 + W2 @ x2                    # Tang et al. eq. (19)
                Pg = W1 @ P1 @ W1 + W2 @ P2 @ W2
                beta_out[k] = [bp, bv]
            if fr:                                        # Carlson fusion-reset
                c = np.clip(w, 0.05, 0.95)
                d1, d2 = 1 / np.sqrt(c), 1 / np.sqrt(1 - c)
                x1, x2 = xg.copy(), xg.copy()
                P1, P2 = Pg * np.outer(d1, d1), Pg * np.outer(d2, d2)
        elif gnss_on:
            xg, Pg = x1.copy(), P1.copy()
        else:
            xg, Pg = x2.copy(), P2.copy()
        xs[k], Ps[k] = xg, Pg

    if smooth:
        x_s, P_s = xs[-1].copy(), Ps[-1].copy()
        out_x, out_P = xs.copy(), Ps.copy()
        for k in range(n - 2, -1, -1):
            T, st = prep.dt[k + 1], bool(prep.static[k + 1])
            pk = regime_par(par, prep.eps_w[k + 1])
            Phi = Phi_of(T, st, pk, xs[k])
            x_prior = Phi @ xs[k]
            P_prior = cap(Phi @ Ps[k] @ Phi.T + Q_of(T, st, pk, xs[k]))
            C = np.linalg.solve(P_prior, Phi @ Ps[k]).T   # P Phi^T P_prior^-1
            x_s = xs[k] + C @ (x_s - x_prior)
            P_s = Ps[k] + C @ (P_s - P_prior) @ C.T
            dpos = x_s[[0, 3]] - xs[k][[0, 3]]          # guard: restart from the forward
            nees = float(dpos @ np.linalg.solve(Ps[k][np.ix_([0, 3], [0, 3])], dpos))
            if not nees <= kf.SMOOTH_RESTART_NEES:
                x_s, P_s = xs[k].copy(), Ps[k].copy()
            out_x[k], out_P[k] = x_s, P_s
        xs, Ps = out_x, out_P
    return {"e": xs[:, 0], "n": xs[:, 3], "v_e": xs[:, 1], "v_n": xs[:, 4],
            "var_e": Ps[:, 0, 0], "var_n": Ps[:, 3, 3], "cov_en": Ps[:, 0, 3],
            "beta": beta_out, "gnss_used": used, "q_w": xs[:, 8]}


def two_filter(fwd: dict[str, np.ndarray], bwd: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """fafkf's smoother: forward and (time-reversed, already flipped back) backward tracks
    fused per epoch by their 2x2 position covariances; velocities by the trace weights."""
    n = len(fwd["e"])
    out = {k: np.zeros(n) for k in ("e", "n", "v_e", "v_n", "var_e", "var_n", "cov_en")}
    for k in range(n):
        Pf = np.array([[fwd["var_e"][k], fwd["cov_en"][k]], [fwd["cov_en"][k], fwd["var_n"][k]]])
        Pb = np.array([[bwd["var_e"][k], bwd["cov_en"][k]], [bwd["cov_en"][k], bwd["var_n"][k]]])
        Yf, Yb = np.linalg.inv(Pf), np.linalg.inv(Pb)
        Ps = np.linalg.inv(Yf + Yb)
        xs = Ps @ (Yf @ [fwd["e"][k], fwd["n"][k]] + Yb @ [bwd["e"][k], bwd["n"][k]])
        wf = np.trace(Pb) / (np.trace(Pf) + np.trace(Pb))
        out["e"][k], out["n"][k] = xs
        out["var_e"][k], out["var_n"][k], out["cov_en"][k] = Ps[0, 0], Ps[1, 1], Ps[0, 1]
        out["v_e"][k] = wf * fwd["v_e"][k] + (1 - wf) * bwd["v_e"][k]
        out["v_n"][k] = wf * fwd["v_n"][k] + (1 - wf) * bwd["v_n"][k]
    return out


# ----------------------------------------------------------------------------------------
# A tiny drive generator with known truth (closed-form paths), for the tests.


def tiny_drive(duration_s: float = 120.0, *, speed_mps: float = 10.0, turn_radps: float = 0.0,
               gnss_sd_m: float = 1.0, gnss_hz: float = 5.0, dr_hz: float = 50.0,
               gyro_bias_radps: float = 0.0, odo_scale: float = 1.0, stop: tuple[float, float] | None = None,
               gnss_gap: tuple[float, float] | None = None, gnss_sd_jump: tuple[float, float] | None = None,
               seed: int = 0, lat0: float = 48.0, lon0: float = 11.0):
    """A drive at constant speed on a line (``turn_radps = 0``) or circle, with truth.

    ``stop = (t0, t1)``: standing still in that interval (speed ramps 2 s each side);
    ``gnss_gap``: no fixes in (t0, t1); ``gnss_sd_jump = (t0, factor)``: true GNSS
    noise times ``factor`` from t0 on (the reported sigma stays ``gnss_sd_m``).
    Returns (Drive, LocalFrame, truth dict of arrays t_ns, e, n, v_e, v_n).
    """
    from gpsdr_cli.geodesy import LocalFrame
    from gpsdr_cli.io.drive import Drive, GnssFixes, Odometry, YawRates

    rng = np.random.default_rng(seed)
    t0_ns = 1_700_000_000 * 1_000_000_000
    dt = 1.0 / dr_hz
    t = np.arange(0.0, duration_s + 1e-9, dt)
    speed = np.full(len(t), speed_mps)
    if stop is not None:
        a, b = stop
        ramp_down = np.clip((a - t) / 2.0, 0.0, 1.0)
        ramp_up = np.clip((t - b) / 2.0, 0.0, 1.0)
        speed = speed_mps * np.where(t < a, ramp_down, np.where(t > b, ramp_up, 0.0))
        speed[t < a - 2.0] = speed_mps
    psi_rate = np.where(speed > 0.0, turn_radps, 0.0)
    psi = np.concatenate(([0.7], 0.7 + np.cumsum(0.5 * (psi_rate[1:] + psi_rate[:-1]) * dt)))
    v_e, v_n = speed * np.sin(psi), speed * np.cos(psi)
    e = np.concatenate(([0.0], np.cumsum(0.5 * (v_e[1:] + v_e[:-1]) * dt)))
    n = np.concatenate(([0.0], np.cumsum(0.5 * (v_n[1:] + v_n[:-1]) * dt)))
    frame = LocalFrame.centred_on(lat0, lon0)
    t_ns = t0_ns + np.round(t * 1e9).astype(np.int64)

    step = round(dr_hz / gnss_hz)
    gi = np.arange(0, len(t), step)
    sd = np.full(len(gi), gnss_sd_m)
    if gnss_sd_jump is not None:
        sd = np.where(t[gi] >= gnss_sd_jump[0], gnss_sd_m * gnss_sd_jump[1], sd)
    ge = e[gi] + rng.normal(0.0, 1.0, len(gi)) * sd
    gn = n[gi] + rng.normal(0.0, 1.0, len(gi)) * sd
    keep = np.ones(len(gi), bool)
    if gnss_gap is not None:
        keep = ~((t[gi] > gnss_gap[0]) & (t[gi] < gnss_gap[1]))
    gi, ge, gn = gi[keep], ge[keep], gn[keep]
    lat, lon = frame.inverse(ge, gn)
    g = GnssFixes.empty(len(gi))
    g.t_ns[:] = t_ns[gi]
    g.lat_deg[:] = lat
    g.lon_deg[:] = lon
    g.alt_m[:] = 0.0
    g.fix_quality[:] = 1
    g.sigma_e_m[:] = gnss_sd_m
    g.sigma_n_m[:] = gnss_sd_m
    g.speed_mps[:] = speed[gi]
    g.course_deg[:] = np.degrees(psi[gi]) % 360.0
    yaw = -(psi_rate + gyro_bias_radps) + rng.normal(0.0, 0.002, len(t))   # CCW-positive
    odo = odo_scale * speed + np.where(speed > 0, rng.normal(0.0, 0.05, len(t)), 0.0)
    drive = Drive(gnss=g, gyro=YawRates(t_ns=t_ns.copy(), yaw_rate_radps=yaw),
                  odo=Odometry(t_ns=t_ns.copy(), speed_mps=np.maximum(odo, 0.0)))
    truth = {"t_ns": t_ns, "e": e, "n": n, "v_e": v_e, "v_n": v_n}
    return drive, frame, truth
