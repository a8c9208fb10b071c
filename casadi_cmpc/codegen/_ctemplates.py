"""C text of the exported controllers (header, logic, example, Makefile)."""

from __future__ import annotations

import textwrap
from typing import Any

import numpy as np

from ..interval._cgen import PRELUDE

_COMMON = r"""
#define NX CMPC_NX
#define NU CMPC_NU
#define NW CMPC_NW

/* work arrays of the generated functions (C99 has no empty arrays: +1) */
#define WORK(fn) \
    static const casadi_real *fn##_arg[fn##_SZ_ARG + 1]; \
    static casadi_real *fn##_res[fn##_SZ_RES + 1]; \
    static casadi_int fn##_iw[fn##_SZ_IW + 1]; \
    static casadi_real fn##_w[fn##_SZ_W + 1];

WORK(cmpc_f)
static const double cmpc_no_w[1] = {0.0};

void cmpc_model(const double *x, const double *u, const double *w, double *x_next) {
    cmpc_f_arg[0] = x;
    cmpc_f_arg[1] = u;
    cmpc_f_arg[2] = NW > 0 ? w : cmpc_no_w;
    cmpc_f_res[0] = x_next;
    cmpc_f(cmpc_f_arg, cmpc_f_res, cmpc_f_iw, cmpc_f_w, 0);
}

/* The natural interval inclusion of f at the point (x, u, w), outward rounded (generated
 * from the model's instruction list above): the exact real value of every component of
 * f(x, u, w) lies in [lo[i], hi[i]]; [-inf, inf] where f may be undefined. */
void cmpc_model_iv(const double *x, const double *u, const double *w, double *lo,
                   double *hi) {
    const double *in[3];
    double *ol[1], *oh[1];
    int i;
    in[0] = x;
    in[1] = u;
    in[2] = NW > 0 ? w : cmpc_no_w;
    ol[0] = lo;
    oh[0] = hi;
    cmpc_f_iv(in, in, ol, oh);
    for (i = 0; i < NX; ++i)
        if (lo[i] != lo[i] || hi[i] != hi[i]) {
            lo[i] = -INFINITY;
            hi[i] = INFINITY;
        }
}

static int all_finite(const double *v, int k) {
    int i;
    for (i = 0; i < k; ++i)
        if (!isfinite(v[i])) return 0;
    return 1;
}

/* a.x <= b for one row a (NX entries), decided from a compensated dot product (Ogita, Rump
 * and Oishi's Dot2 with error-free products through fma): the sum a.x - b is evaluated as in
 * twice the working precision, so a point of a facet and a point 1e-16 outside it are told
 * apart, whatever the rounding of a plain sum would say. */
static int row_le(const double *a, double b, const double *x) {
    double p = -b, s = 0.0;
    int i;
    for (i = 0; i < NX; ++i) {
        double h = a[i] * x[i], r = fma(a[i], x[i], -h), t = p + h, z = t - p;
        s += ((p - (t - z)) + (h - z)) + r;
        p = t;
    }
    return p + s <= 0.0;
}

static int solver_mem = -1;

#ifdef CMPC_PROFILE
/* build with -DCMPC_PROFILE -D_POSIX_C_SOURCE=199309L: time spent in the solver alone */
#include <time.h>
double cmpc_profile_solver_seconds = 0.0;
long cmpc_profile_solver_calls = 0;
static double profile_t0;
static double profile_now(void) {
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}
#define PROFILE_BEGIN() (profile_t0 = profile_now())
#define PROFILE_END() (cmpc_profile_solver_seconds += profile_now() - profile_t0, \
                       cmpc_profile_solver_calls++)
#else
#define PROFILE_BEGIN() ((void)0)
#define PROFILE_END() ((void)0)
#endif

static int solver_ready(void) {
    if (solver_mem < 0) {
        cmpc_solver_incref();
        solver_mem = cmpc_solver_checkout();
    }
    return solver_mem >= 0;
}
"""

_ROW_UPPER = r"""
/* An upper bound of a.y over the box [lo, hi] (NX entries), each product and sum rounded
 * upward: a.y <= row_upper(a, lo, hi) for every real y in the box. */
static double row_upper(const double *a, const double *lo, const double *hi) {
    double s = 0.0;
    int i;
    for (i = 0; i < NX; ++i)
        if (a[i] != 0.0) s = civ_up(s + civ_up(a[i] * (a[i] > 0.0 ? hi[i] : lo[i])));
    return s;
}
"""

_SEQUENCE = r"""
#define NZ (NU + 1)
#define NP (NX + CMPC_R * NX + CMPC_R + 1)
#define NG (CMPC_NV * (1 + CMPC_R))

WORK(cmpc_law)
WORK(cmpc_start)
WORK(cmpc_solver)

/* ---------------------------------------------------------------- level look-up */
/* Index of the last edge <= v (-1 if none): numpy's searchsorted(e, v, "right") - 1. */
static int last_le(const double *e, int E, double v) {
    int lo = 0, hi = E;
    while (lo < hi) {
        int mid = lo + (hi - lo) / 2;
        if (e[mid] <= v) lo = mid + 1; else hi = mid;
    }
    return lo - 1;
}

/* Index of the last edge < v (-1 if none). */
static int last_lt(const double *e, int E, double v) {
    int lo = 0, hi = E;
    while (lo < hi) {
        int mid = lo + (hi - lo) / 2;
        if (e[mid] < v) lo = mid + 1; else hi = mid;
    }
    return lo - 1;
}

static int clampi(int i, int a, int b) { return i < a ? a : (i > b ? b : i); }

/* Smallest step whose boxes hold x (-1: none) and the witness row of that box. The grid
 * has one cell per product of consecutive box bounds; a point on a cell face takes the
 * smallest level of the (up to 2^n) cells meeting there. O(n log E + 2^n). */
static int grid_level(const double *x, long *row) {
    int d, bits, cand[NX][2];
    int best = -1;
    *row = -1;
    for (d = 0; d < NX; ++d) {
        const double *e = cmpc_edges + cmpc_edge_off[d];
        int E = cmpc_n_edges[d], i, hi_i, lo_i;
        int top = E > 1 ? E - 2 : 0; /* last cell (one cell if all boxes are flat here) */
        if (!(x[d] >= e[0] && x[d] <= e[E - 1])) return -1;
        i = last_le(e, E, x[d]);
        hi_i = clampi(i, 0, top);
        lo_i = (i >= 0 && e[clampi(i, 0, E - 1)] == x[d]) ? clampi(i - 1, 0, top) : hi_i;
        cand[d][0] = lo_i;
        cand[d][1] = hi_i;
    }
    for (bits = 0; bits < (1 << NX); ++bits) {
        long idx = 0;
        int lv;
        for (d = 0; d < NX; ++d) idx += cand[d][(bits >> (NX - 1 - d)) & 1] * cmpc_cell_stride[d];
        lv = cmpc_cell_level[idx];
        if (lv > 0 && (best < 0 || lv < best)) {
            best = lv;
            *row = cmpc_cell_box[idx];
        }
    }
    return best;
}

static int in_poly(const double *A, const double *b, int rows, const double *x) {
    int k;
    for (k = 0; k < rows; ++k)
        if (!row_le(A + k * NX, b[k], x)) return 0;
    return 1;
}

static int poly_level(const double *x) {
    int p, best = -1;
    for (p = 0; p < CMPC_NPOLY; ++p) {
        int lv = cmpc_poly_level[p];
        if ((best < 0 || lv < best) &&
            in_poly(cmpc_poly_A + cmpc_poly_off[p] * NX, cmpc_poly_b + cmpc_poly_off[p],
                    cmpc_poly_rows[p], x))
            best = lv;
    }
    return best;
}

/* level of x and the (level, witness row) of its box */
static int locate(const double *x, int *wit_level, long *wit_row) {
    int lv = grid_level(x, wit_row);
    *wit_level = lv;
    if (in_poly(cmpc_T_A, cmpc_T_b, CMPC_T_ROWS, x)) return 0;
    if (CMPC_POLYTOPIC) return poly_level(x);
    return lv;
}

int cmpc_level(const double *x) {
    int wl;
    long wr;
    if (!all_finite(x, NX)) return CMPC_BAD_INPUT;
    return locate(x, &wl, &wr);
}

/* ---------------------------------------------------------------- successor check */
""" + _ROW_UPPER + r"""
/* every image box [lo[v], hi[v]] inside the polytope {y : A y <= b} */
static int images_in_poly(const double *A, const double *b, int rows, double lo[][NX],
                          double hi[][NX]) {
    int k, v;
    for (k = 0; k < rows; ++k)
        for (v = 0; v < CMPC_NV; ++v)
            if (!(row_upper(A + k * NX, lo[v], hi[v]) <= b[k])) return 0;
    return 1;
}

/* the box [lo, hi] covered by the boxes of steps 1..j (every grid cell meeting it) */
static int box_covered(const double *lo, const double *hi, int j) {
    int d, a[NX], b[NX], c[NX];
    for (d = 0; d < NX; ++d) {
        const double *e = cmpc_edges + cmpc_edge_off[d];
        int E = cmpc_n_edges[d], top = E > 1 ? E - 2 : 0;
        if (!(lo[d] >= e[0] && hi[d] <= e[E - 1] && lo[d] <= hi[d])) return 0;
        a[d] = clampi(last_le(e, E, lo[d]), 0, top);
        b[d] = clampi(last_lt(e, E, hi[d]), 0, top);
        if (b[d] < a[d]) b[d] = a[d]; /* a point on an edge: the cell starting there */
        c[d] = a[d];
    }
    for (;;) {
        long idx = 0;
        int lv;
        for (d = 0; d < NX; ++d) idx += c[d] * cmpc_cell_stride[d];
        lv = cmpc_cell_level[idx];
        if (lv < 1 || lv > j) return 0;
        for (d = NX - 1; d >= 0; --d) {
            if (c[d] < b[d]) { c[d]++; break; }
            c[d] = a[d];
        }
        if (d < 0) return 1;
    }
}

/* Proves f(x, u, w) in K_j for every w in W (the nominal w when not robust): u in U, and
 * the interval enclosure of f at each vertex w_v of W (cmpc_model_iv) inside T, or inside
 * one polytope of level <= j (all vertex boxes: the polytope is convex and, f being affine
 * in w, f(x, u, W) is the convex hull of the vertex images), or the hull of the vertex boxes
 * covered by the boxes of steps 1..j. */
static int successor_in(const double *x, const double *u, int j) {
    double lo[CMPC_NV][NX], hi[CMPC_NV][NX];
    int v, i, p;
    for (i = 0; i < NU; ++i)
        if (!(u[i] >= cmpc_u_lo[i] && u[i] <= cmpc_u_hi[i])) return 0;
    for (v = 0; v < CMPC_NV; ++v) {
        cmpc_model_iv(x, u, cmpc_wv + v * NW, lo[v], hi[v]);
        if (!all_finite(lo[v], NX) || !all_finite(hi[v], NX)) return 0;
    }
    if (images_in_poly(cmpc_T_A, cmpc_T_b, CMPC_T_ROWS, lo, hi)) return 1;
    if (CMPC_POLYTOPIC) {
        for (p = 0; p < CMPC_NPOLY; ++p)
            if (cmpc_poly_level[p] <= j &&
                images_in_poly(cmpc_poly_A + cmpc_poly_off[p] * NX,
                               cmpc_poly_b + cmpc_poly_off[p], cmpc_poly_rows[p], lo, hi))
                return 1;
        return 0;
    } else {
        double l[NX], h[NX];
        for (i = 0; i < NX; ++i) {
            l[i] = lo[0][i];
            h[i] = hi[0][i];
            for (v = 1; v < CMPC_NV; ++v) {
                if (lo[v][i] < l[i]) l[i] = lo[v][i];
                if (hi[v][i] > h[i]) h[i] = hi[v][i];
            }
        }
        return box_covered(l, h, j);
    }
}

/* ---------------------------------------------------------------- the step */
/* The solver's start (as SetSequenceMPC._initial): u0 from the generated cmpc_start (one
 * Newton step on the mean vertex cost from the guess) as the scaled v0 = (u0 - mid) / half,
 * the epigraph variable at the first largest finite vertex cost c_k and multiplier 1 on
 * that row; the cost scale cs = 1 / c_k (1 when c_k is 0 or not finite) is returned. */
static double solver_start(const double *x, const double *guess, double *z0, double *lam) {
    double c[CMPC_NV], u0[NU], cs;
    int v, k = 0;
    double best = -INFINITY;
    cmpc_start_arg[0] = x;
    cmpc_start_arg[1] = guess;
    cmpc_start_res[0] = u0;
    cmpc_start_res[1] = c;
    cmpc_start(cmpc_start_arg, cmpc_start_res, cmpc_start_iw, cmpc_start_w, 0);
    for (v = 0; v < CMPC_NV; ++v)
        if (isfinite(c[v]) && c[v] > best) { best = c[v]; k = v; }
    cs = isfinite(c[k]) && c[k] > 0 ? 1.0 / c[k] : 1.0;
    for (v = 0; v < NU; ++v) z0[v] = (u0[v] - cmpc_u_mid[v]) / cmpc_u_half[v];
    z0[NU] = cs * c[k];
    for (v = 0; v < NG; ++v) lam[v] = 0.0;
    lam[k * (1 + CMPC_R)] = 1.0;
    return cs;
}

void cmpc_reset(void) { /* the one-step controller keeps nothing between calls */ }

int cmpc_step(const double *x, double *u) {
    int lvl, wl, i, k, nc = 0, flags = 0, have_opt = 0, chosen = -1, flag;
    long wr;
    double cand[5][NU + 1];
    const double *uw = 0;
    static double z0[NZ], p[NP], lbx[NZ], ubx[NZ], lbg[NG + 1], ubg[NG + 1], lam_x0[NZ],
        lam_g0[NG + 1];
    static double zs[NZ], fval;
    static const double ts[3] = {0.75, 0.5, 0.25};
    for (i = 0; i < NU; ++i) u[i] = NAN;
    if (!all_finite(x, NX)) return CMPC_BAD_INPUT;
    lvl = locate(x, &wl, &wr);
    if (lvl < 0) return CMPC_NOT_CONTROLLABLE;
    if (lvl == 0) {
        cmpc_law_arg[0] = x;
        cmpc_law_res[0] = u;
        cmpc_law(cmpc_law_arg, cmpc_law_res, cmpc_law_iw, cmpc_law_w, 0);
        return 0;
    }
    if (!solver_ready()) return CMPC_INTERNAL_ERROR;
    if (wl >= 1 && wr >= 0) uw = cmpc_witness + wr * NU;
    /* one-step problem into K_{lvl-1}, started from the stored control (see solver_start) */
    p[NP - 1] = solver_start(x, uw ? uw : cmpc_u_mid, z0, lam_g0);
    for (i = 0; i < NX; ++i) p[i] = x[i];
    for (i = 0; i < CMPC_R * NX; ++i) p[NX + i] = cmpc_nlp_H[(lvl - 1) * CMPC_R * NX + i];
    for (i = 0; i < CMPC_R; ++i) p[NX + CMPC_R * NX + i] = cmpc_nlp_h[(lvl - 1) * CMPC_R + i];
    for (i = 0; i < NU; ++i) { lbx[i] = cmpc_v_lo[i]; ubx[i] = cmpc_v_hi[i]; }
    lbx[NU] = -INFINITY;
    ubx[NU] = INFINITY;
    for (i = 0; i < NG; ++i) { lbg[i] = -INFINITY; ubg[i] = 0.0; }
    for (i = 0; i < NZ; ++i) lam_x0[i] = 0.0;
    cmpc_solver_arg[0] = z0; cmpc_solver_arg[1] = p;
    cmpc_solver_arg[2] = lbx; cmpc_solver_arg[3] = ubx;
    cmpc_solver_arg[4] = lbg; cmpc_solver_arg[5] = ubg;
    cmpc_solver_arg[6] = lam_x0; cmpc_solver_arg[7] = lam_g0;
    cmpc_solver_res[0] = zs; cmpc_solver_res[1] = &fval;
    for (i = 2; i < 6; ++i) cmpc_solver_res[i] = 0;
    PROFILE_BEGIN();
    flag = cmpc_solver(cmpc_solver_arg, cmpc_solver_res, cmpc_solver_iw, cmpc_solver_w,
                       solver_mem);
    PROFILE_END();
    if (all_finite(zs, NU)) { /* u = mid + half v, inside U */
        for (i = 0; i < NU; ++i) {
            double ui = cmpc_u_mid[i] + cmpc_u_half[i] * zs[i];
            if (ui < cmpc_u_lo[i]) ui = cmpc_u_lo[i];
            if (ui > cmpc_u_hi[i]) ui = cmpc_u_hi[i];
            cand[nc][i] = ui;
        }
        nc++;
        have_opt = 1;
    }
    if (flag != 0 || !have_opt) flags |= CMPC_FLAG_SOLVER_FAILED;
    if (uw) {
        if (have_opt)
            for (k = 0; k < 3; ++k, ++nc)
                for (i = 0; i < NU; ++i) cand[nc][i] = uw[i] + ts[k] * (cand[0][i] - uw[i]);
        for (i = 0; i < NU; ++i) cand[nc][i] = uw[i];
        nc++;
    }
    if (nc == 0) return CMPC_INTERNAL_ERROR | flags;
    for (k = 0; k < nc && chosen < 0; ++k)
        if (successor_in(x, cand[k], lvl - 1)) chosen = k;
    if (chosen < 0 && uw && wl <= lvl && successor_in(x, cand[nc - 1], wl - 1))
        chosen = nc - 1;
    if (chosen < 0) {
        k = uw ? nc - 1 : 0;
        for (i = 0; i < NU; ++i) u[i] = cand[k][i];
        return lvl | flags | CMPC_FLAG_UNVERIFIED | (uw ? CMPC_FLAG_WITNESS : 0);
    }
    for (i = 0; i < NU; ++i) u[i] = cand[chosen][i];
    if (have_opt && chosen == 0) return lvl | flags;
    if (uw && chosen == nc - 1) return lvl | flags | CMPC_FLAG_WITNESS;
    return lvl | flags | CMPC_FLAG_BLEND;
}
"""
_QUASI = r"""
#define NS CMPC_STEPS
#define NZ (NS * NU)
#define NP (NX + CMPC_R * NX + CMPC_R)

WORK(cmpc_solver)
#if CMPC_HAS_LAW
WORK(cmpc_law)
#endif
""" + _ROW_UPPER + r"""
/* the plan in progress: the controls still to apply, the level it started at and its
 * target level; stored = 1 when it is the stored sequence of a box (proven offline) */
static double plan_rest[NZ + 1];
static int plan_n = 0, plan_level = -1, plan_target = -1, plan_stored = 0;

void cmpc_reset(void) { plan_n = 0; plan_stored = 0; }

static int in_poly(int k, const double *x) {
    int r;
    for (r = cmpc_poly_off[k]; r < cmpc_poly_off[k + 1]; ++r)
        if (!row_le(cmpc_poly_A + r * NX, cmpc_poly_b[r], x)) return 0;
    return 1;
}

/* first stored box of level m (1..M) holding x (-1: none) */
static long box_of_level(int m, const double *x) {
    long k;
    int d;
    for (k = cmpc_box_off[m - 1]; k < cmpc_box_off[m]; ++k) {
        for (d = 0; d < NX; ++d)
            if (!(x[d] >= cmpc_box_lo[k * NX + d] && x[d] <= cmpc_box_hi[k * NX + d])) break;
        if (d == NX) return k;
    }
    return -1;
}

/* smallest m with x in P_m or in a stored box of level m (-1: none) */
static int find_level(const double *x) {
    int m;
    for (m = 0; m < CMPC_NSETS; ++m) {
        if (in_poly(m, x)) return m;
        if (m >= 1 && box_of_level(m, x) >= 0) return m;
    }
    return -1;
}

int cmpc_level(const double *x) {
    if (!all_finite(x, NX)) return CMPC_BAD_INPUT;
    return find_level(x);
}

/* Interval evolution of the point x under useq (L controls, in U): X(k+1) = f(X(k), u(k),
 * W) by the outward-rounded natural inclusion (cmpc_f_iv) over the box X(k) and the box W.
 * Returns the first a in 1..L with X(a) inside P_j (every row bounded above by row_upper),
 * the boxes X(1..a-1) inside the box X; 0 when not proven. Exact real arithmetic holds in
 * the claim: every trajectory from x under useq and any w(k) in W obeys it. */
static int prove(const double *x, const double *useq, int L, int j) {
    double lo[NX], hi[NX], nl[NX], nh[NX];
    const double *il[3], *ih[3];
    double *ol[1], *oh[1];
    int k, i, r;
    for (k = 0; k < L * NU; ++k)
        if (!(useq[k] >= cmpc_u_lo[k % NU] && useq[k] <= cmpc_u_hi[k % NU])) return 0;
    for (i = 0; i < NX; ++i) lo[i] = hi[i] = x[i];
    for (k = 0; k < L; ++k) {
        int in = 1;
        if (k > 0)
            for (i = 0; i < NX; ++i)
                if (!(lo[i] >= cmpc_x_lo[i] && hi[i] <= cmpc_x_hi[i])) return 0;
        il[0] = lo; ih[0] = hi;
        il[1] = useq + k * NU; ih[1] = useq + k * NU;
        il[2] = NW > 0 ? cmpc_w_lo : cmpc_no_w; ih[2] = NW > 0 ? cmpc_w_hi : cmpc_no_w;
        ol[0] = nl; oh[0] = nh;
        cmpc_f_iv(il, ih, ol, oh);
        if (!all_finite(nl, NX) || !all_finite(nh, NX)) return 0;
        for (r = cmpc_poly_off[j]; r < cmpc_poly_off[j + 1] && in; ++r)
            if (!(row_upper(cmpc_poly_A + r * NX, nl, nh) <= cmpc_poly_b[r])) in = 0;
        if (in) return k + 1;
        for (i = 0; i < NX; ++i) { lo[i] = nl[i]; hi[i] = nh[i]; }
    }
    return 0;
}

static void start_plan(const double *useq, int a, int level, int target, int stored,
                       double *u) {
    int i;
    for (i = 0; i < NU; ++i) u[i] = useq[i];
    for (i = 0; i < (a - 1) * NU; ++i) plan_rest[i] = useq[NU + i];
    plan_n = a - 1;
    plan_level = level;
    plan_target = target;
    plan_stored = stored;
}

int cmpc_step(const double *x, double *u) {
    int i, k, lvl, j, a, flag, have_opt = 0, flags = 0;
    long bx;
    static double z0[NZ], p[NP], zs[NZ], fval, lam_x0[NZ], lam_g0[CMPC_NG + 1], cand[NZ];
    static const double ts[3] = {0.75, 0.5, 0.25};
    int in_T;
    for (i = 0; i < NU; ++i) u[i] = NAN;
    if (!all_finite(x, NX)) return CMPC_BAD_INPUT;
    in_T = in_poly(0, x);
#if CMPC_HAS_LAW
    if (in_T) {
        double ul[NU];
        cmpc_law_arg[0] = x;
        cmpc_law_res[0] = ul;
        cmpc_law(cmpc_law_arg, cmpc_law_res, cmpc_law_iw, cmpc_law_w, 0);
        if (prove(x, ul, 1, 0)) {
            plan_n = 0;
            for (i = 0; i < NU; ++i) u[i] = ul[i];
            return 0;
        }
    }
#endif
    /* a plan in progress: proven again from the measured state */
    if (plan_n > 0) {
        a = prove(x, plan_rest, plan_n, plan_target);
        if (a || plan_stored) {
            int n = a ? a : plan_n;
            for (i = 0; i < NU; ++i) u[i] = plan_rest[i];
            for (i = 0; i < (n - 1) * NU; ++i) plan_rest[i] = plan_rest[NU + i];
            plan_n = n - 1;
            return plan_level | CMPC_FLAG_FALLBACK | (a ? 0 : CMPC_FLAG_WITNESS);
        }
    }
    plan_n = 0;
    if (in_T) {
#if CMPC_HAS_LAW
        cmpc_law_arg[0] = x;
        cmpc_law_res[0] = u;
        cmpc_law(cmpc_law_arg, cmpc_law_res, cmpc_law_iw, cmpc_law_w, 0);
        return 0 | CMPC_FLAG_UNVERIFIED;
#else
        for (i = 0; i < NU; ++i) u[i] = 0.5 * (cmpc_u_lo[i] + cmpc_u_hi[i]);
        return 0 | CMPC_FLAG_UNVERIFIED;
#endif
    }
    lvl = find_level(x);
    if (lvl < 0) return CMPC_NOT_CONTROLLABLE;
    j = lvl - 1;
    bx = box_of_level(lvl, x);
    if (!solver_ready()) return CMPC_INTERNAL_ERROR;
    /* (6.22)-(6.23) into P_j, started from the stored sequence when it is complete */
    for (i = 0; i < NZ; ++i) {
        double v = bx >= 0 ? cmpc_box_u[bx * NZ + i] : NAN;
        z0[i] = v == v ? v : 0.5 * (cmpc_u_lo[i % NU] + cmpc_u_hi[i % NU]);
        lam_x0[i] = 0.0;
    }
    for (i = 0; i < CMPC_NG; ++i) lam_g0[i] = 0.0;
    for (i = 0; i < NX; ++i) p[i] = x[i];
    for (i = 0; i < CMPC_R * NX; ++i) p[NX + i] = cmpc_nlp_H[j * CMPC_R * NX + i];
    for (i = 0; i < CMPC_R; ++i) p[NX + CMPC_R * NX + i] = cmpc_nlp_h[j * CMPC_R + i];
    cmpc_solver_arg[0] = z0; cmpc_solver_arg[1] = p;
    cmpc_solver_arg[2] = cmpc_lbx; cmpc_solver_arg[3] = cmpc_ubx;
    cmpc_solver_arg[4] = cmpc_lbg; cmpc_solver_arg[5] = cmpc_ubg;
    cmpc_solver_arg[6] = lam_x0; cmpc_solver_arg[7] = lam_g0;
    cmpc_solver_res[0] = zs; cmpc_solver_res[1] = &fval;
    for (i = 2; i < 6; ++i) cmpc_solver_res[i] = 0;
    PROFILE_BEGIN();
    flag = cmpc_solver(cmpc_solver_arg, cmpc_solver_res, cmpc_solver_iw, cmpc_solver_w,
                       solver_mem);
    PROFILE_END();
    if (all_finite(zs, NZ)) {
        for (i = 0; i < NZ; ++i) {
            double v = zs[i];
            if (v < cmpc_u_lo[i % NU]) v = cmpc_u_lo[i % NU];
            if (v > cmpc_u_hi[i % NU]) v = cmpc_u_hi[i % NU];
            zs[i] = v;
        }
        have_opt = 1;
    }
    if (flag != 0 || !have_opt) flags |= CMPC_FLAG_SOLVER_FAILED;
    if (have_opt && (a = prove(x, zs, NS, j))) {
        start_plan(zs, a, lvl, j, 0, u);
        return lvl | flags;
    }
    if (bx >= 0) {
        const double *us = cmpc_box_u + bx * NZ;
        int L = cmpc_box_arrival[bx];
        if (have_opt)
            for (k = 0; k < 3; ++k) {
                for (i = 0; i < L * NU; ++i) cand[i] = us[i] + ts[k] * (zs[i] - us[i]);
                if ((a = prove(x, cand, L, j))) {
                    start_plan(cand, a, lvl, j, 0, u);
                    return lvl | flags | CMPC_FLAG_BLEND;
                }
            }
        a = prove(x, us, L, j);
        /* not proven here: the stored sequence is proven offline for the whole box */
        start_plan(us, a ? a : L, lvl, j, a ? 0 : 1, u);
        return lvl | flags | CMPC_FLAG_WITNESS;
    }
    for (i = 0; i < NU; ++i) u[i] = have_opt ? zs[i] : 0.5 * (cmpc_u_lo[i] + cmpc_u_hi[i]);
    return lvl | flags | CMPC_FLAG_UNVERIFIED;
}
"""


_CONTRACTIVE = r"""
#define NZ CMPC_NZ
#define NG CMPC_NG
#define NN (CMPC_N * NU)

WORK(cmpc_solver)
WORK(cmpc_pred)
#if CMPC_HAS_LAW
WORK(cmpc_law)
#endif

static double warm[NN];
static int have_warm = 0;
static double lam_x[NZ], lam_g[NG + 1];
static int have_lam = 0;

void cmpc_reset(void) {
    have_warm = 0;
    have_lam = 0;
}

static int in_local_set(const double *x) {
    int k;
    if (!CMPC_HAS_LAW) return 0;
    for (k = 0; k < CMPC_S_ROWS; ++k)
        if (!row_le(cmpc_S_A + k * NX, cmpc_S_b[k], x)) return 0;
    return 1;
}

int cmpc_level(const double *x) {
    if (!all_finite(x, NX)) return CMPC_BAD_INPUT;
    return in_local_set(x) ? 0 : 1;
}

static double clip(double v, double a, double b) { return v < a ? a : (v > b ? b : v); }

/* Proves the sequence useq from x: the interval enclosure (cmpc_check_iv, generated from the
 * instruction list of the exact check graph: u and x thin, the constants of the model and
 * the controller as the intervals cmpc_par_lo/hi) of every row (predicted states in X, path
 * and terminal rows, contraction) lies within [cmpc_check_lo, cmpc_check_hi]. */
static int check_rows(const double *useq, const double *x) {
    static double zl[CMPC_NCHECK_IN], zh[CMPC_NCHECK_IN], rl[CMPC_NCHECK], rh[CMPC_NCHECK];
    const double *il[1], *ih[1];
    double *ol[1], *oh[1];
    int i;
    for (i = 0; i < NN; ++i) zl[i] = zh[i] = useq[i];
    for (i = 0; i < NX; ++i) zl[NN + i] = zh[NN + i] = x[i];
    for (i = NN + NX; i < CMPC_NCHECK_IN; ++i) {
        zl[i] = cmpc_par_lo[i - NN - NX];
        zh[i] = cmpc_par_hi[i - NN - NX];
    }
    il[0] = zl;
    ih[0] = zh;
    ol[0] = rl;
    oh[0] = rh;
    cmpc_check_iv(il, ih, ol, oh);
    for (i = 0; i < CMPC_NCHECK; ++i) /* NaN (possibly undefined) fails */
        if (!(rl[i] - cmpc_check_lo[i] >= 0.0 && cmpc_check_hi[i] - rh[i] >= 0.0)) return 0;
    return 1;
}

int cmpc_step(const double *x, double *u) {
    static double z0[NZ], p[NX + 1], zs[NZ], fval, lx[NZ], lg[NG + 1];
    static double useq[NN];
    double e[CMPC_NC], r0 = 0.0;
    int i, k, same = 1, flag, ok;
    for (i = 0; i < NU; ++i) u[i] = NAN;
    if (!all_finite(x, NX)) return CMPC_BAD_INPUT;
    for (i = 0; i < NX; ++i) same &= x[i] == cmpc_x_ref[i];
    for (k = 0; k < CMPC_NC; ++k) {
        e[k] = 0.0;
        for (i = 0; i < NX; ++i) e[k] += cmpc_C[k * NX + i] * (x[i] - cmpc_x_ref[i]);
    }
    for (k = 0; k < CMPC_NC; ++k) {
        double a = fabs(e[k]);
        if (CMPC_NORM == 2) r0 += a * a;
        else if (CMPC_NORM == 1) r0 += a;
        else if (a > r0) r0 = a;
    }
    if (CMPC_NORM == 2) r0 = sqrt(r0);
    if (same || !(r0 >= 1e-250)) {
        for (i = 0; i < NU; ++i) u[i] = cmpc_u_ref[i];
        return 0;
    }
#if CMPC_HAS_LAW
    if (in_local_set(x)) {
        cmpc_law_arg[0] = x;
        cmpc_law_res[0] = u;
        cmpc_law(cmpc_law_arg, cmpc_law_res, cmpc_law_iw, cmpc_law_w, 0);
        return 0;
    }
#endif
    if (!solver_ready()) return CMPC_INTERNAL_ERROR;
    for (i = 0; i < NZ; ++i) z0[i] = 0.0;
    for (k = 0; k < CMPC_N; ++k)
        for (i = 0; i < NU; ++i)
            z0[k * NU + i] = have_warm
                ? warm[(k + 1 < CMPC_N ? k + 1 : CMPC_N - 1) * NU + i]
                : clip(cmpc_u_ref[i], cmpc_u_lo[i], cmpc_u_hi[i]);
    if (CMPC_NZX > 0 || CMPC_NT > 0) { /* the states predicted from that sequence */
        static double xp[CMPC_N * NX];
        cmpc_pred_arg[0] = z0;
        cmpc_pred_arg[1] = x;
        cmpc_pred_res[0] = xp;
        cmpc_pred(cmpc_pred_arg, cmpc_pred_res, cmpc_pred_iw, cmpc_pred_w, 0);
        for (k = 0; k < CMPC_NT; ++k) { /* 1-norm slacks: |C (x(N) - x_ref)| / r0 + 1e-3 */
            double eN = 0.0;
            for (i = 0; i < NX; ++i)
                eN += cmpc_C[k * NX + i] * (xp[(CMPC_N - 1) * NX + i] - cmpc_x_ref[i]);
            z0[NN + k] = fabs(eN) / r0 + 1e-3;
        }
        for (i = 0; i < CMPC_NZX; ++i) z0[NN + CMPC_NT + i] = xp[i]; /* multiple shooting */
    }
    for (i = 0; i < NX; ++i) p[i] = x[i];
    p[NX] = 1.0 / r0;
    cmpc_solver_arg[0] = z0; cmpc_solver_arg[1] = p;
    cmpc_solver_arg[2] = cmpc_lbz; cmpc_solver_arg[3] = cmpc_ubz;
    cmpc_solver_arg[4] = cmpc_lbg; cmpc_solver_arg[5] = cmpc_ubg;
    cmpc_solver_arg[6] = have_lam ? lam_x : 0;
    cmpc_solver_arg[7] = have_lam ? lam_g : 0;
    cmpc_solver_res[0] = zs; cmpc_solver_res[1] = &fval; cmpc_solver_res[2] = 0;
    cmpc_solver_res[3] = lx; cmpc_solver_res[4] = lg; cmpc_solver_res[5] = 0;
    PROFILE_BEGIN();
    flag = cmpc_solver(cmpc_solver_arg, cmpc_solver_res, cmpc_solver_iw, cmpc_solver_w,
                       solver_mem);
    PROFILE_END();
    ok = all_finite(zs, NZ);
    if (ok) {
        for (i = 0; i < NZ; ++i) lam_x[i] = lx[i];
        for (i = 0; i < NG; ++i) lam_g[i] = lg[i];
        have_lam = 1;
        for (k = 0; k < CMPC_N; ++k)
            for (i = 0; i < NU; ++i)
                useq[k * NU + i] = clip(zs[k * NU + i], cmpc_u_lo[i], cmpc_u_hi[i]);
        ok = check_rows(useq, x);
        if (ok) {
            for (i = 0; i < NN; ++i) warm[i] = useq[i];
            have_warm = 1;
            for (i = 0; i < NU; ++i) u[i] = useq[i];
            return 1 | (flag != 0 ? CMPC_FLAG_SOLVER_FAILED : 0);
        }
    } else {
        have_lam = 0;
    }
    /* fallback: the next move of the last checked sequence, else u_ref (clipped) */
    if (have_warm) {
        for (k = 0; k + 1 < CMPC_N; ++k)
            for (i = 0; i < NU; ++i) warm[k * NU + i] = warm[(k + 1) * NU + i];
        for (i = 0; i < NU; ++i) u[i] = warm[i];
    } else {
        for (i = 0; i < NU; ++i) u[i] = clip(cmpc_u_ref[i], cmpc_u_lo[i], cmpc_u_hi[i]);
    }
    return 1 | CMPC_FLAG_FALLBACK | CMPC_FLAG_UNVERIFIED |
           (flag != 0 || !all_finite(zs, NZ) ? CMPC_FLAG_SOLVER_FAILED : 0);
}
"""


_SEQUENCE_CHECK = (
    "A level i >= 1 without CMPC_FLAG_UNVERIFIED is proved: u lies in U and f(x, u, w) lies "
    "in K_{i-1} for every w in W (the nominal w when the controller is nominal), in exact "
    "real arithmetic. The check encloses f at x, u and each vertex of W by outward-rounded "
    "interval arithmetic generated from the model's expression graph (cmpc_model_iv); the "
    "images of W, convex hulls of the vertex images for a model affine in w, must lie in a "
    "polytope of the sequence (row sums rounded upward) or their interval hull in the boxes "
    "of steps 1..i-1. With CMPC_FLAG_UNVERIFIED nothing is claimed about the applied control.")
_QUASI_CHECK = (
    "A level i >= 1 without CMPC_FLAG_UNVERIFIED or CMPC_FLAG_WITNESS is proved: u is the "
    "first control of a sequence (in U) under which every state stays in X and enters "
    "P_{i-1} within CMPC_STEPS steps, for every disturbance sequence in W, in exact real "
    "arithmetic (interval evolution by the outward-rounded natural inclusion generated from "
    "the model's expression graph, rows of P_{i-1} bounded upward). CMPC_FLAG_FALLBACK: the "
    "next control of the plan in progress, proven again from x. CMPC_FLAG_WITNESS: the "
    "stored sequence of the box that held the state where the plan began, proven offline "
    "(zonotope evolution) for every state of that box and every w in W, so valid when the "
    "states since then came from the model with w in W (cmpc_reset() drops the plan). "
    "Level 0 without flags: the local law, its step proven to stay in T = P_0; with "
    "CMPC_FLAG_UNVERIFIED nothing is claimed.")
_CONTRACTIVE_CHECK = (
    "A code 1 without CMPC_FLAG_UNVERIFIED is proved for the nominal model: the applied move "
    "is the first of a sequence whose predicted states, path and terminal rows and "
    "contraction were enclosed by outward-rounded interval arithmetic (generated from the "
    "check's expression graph, the same rows as the Python certificate) and found within "
    "their bounds. With CMPC_FLAG_UNVERIFIED (the fallback) nothing is claimed.")


def header(model: Any, kind: str, solver: str, sizes: dict) -> str:
    from .export import (
        BAD_INPUT,
        FLAG_BLEND,
        FLAG_FALLBACK,
        FLAG_SOLVER_FAILED,
        FLAG_UNVERIFIED,
        FLAG_WITNESS,
        INTERNAL_ERROR,
        NOT_CONTROLLABLE,
    )
    what = {"set_sequence": "one-step MPC along a sequence of controllable sets",
            "quasi": f"MPC along quasi {sizes.get('steps')}-step robust controllable sets "
                     "(Alg 6.8)"}.get(kind, f"contractive MPC, horizon {sizes.get('horizon')}")
    levels = {"set_sequence": "the level i of x: 0 = x in the terminal set (local law "
                              "applied), i >= 1 = x in K_i \\ K_{i-1} (one-step problem into "
                              "K_{i-1})",
              "quasi": "the level i of the plan: 0 = x in T = P_0 (local law applied), "
                       "i >= 1 = a plan from P_i (or a stored box of level i) into P_{i-1}"
              }.get(kind, "0 = local law (or x at the reference), 1 = the MPC problem was "
                          "solved")
    levels = textwrap.fill("bits (CMPC_LEVEL(code)) are " + levels, 88,
                           initial_indent=" *       ", subsequent_indent=" *       ")
    check = textwrap.fill({"set_sequence": _SEQUENCE_CHECK, "quasi": _QUASI_CHECK}.get(
        kind, _CONTRACTIVE_CHECK), 88, initial_indent=" * ", subsequent_indent=" * ")
    return f"""/* Controller exported from casadi_cmpc: {what}.
 * Model '{model.name}': n = {model.n} states, m = {model.m} inputs, l = {model.l} disturbances.
 * Solver: {solver}{' (standalone C, libc and libm only)' if solver == 'sqp' else
                   ' (links the IPOPT library shipped with casadi)'}.
 *
 *   int cmpc_step(const double *x, double *u);
 *       x: state (CMPC_NX), u: control written (CMPC_NU). Returns a code >= 0 whose low 16
{levels};
 *       flags above them say how u was obtained (see below). Negative codes: no control
 *       (u is NaN): CMPC_NOT_CONTROLLABLE (x in no set), CMPC_BAD_INPUT (x not finite),
 *       CMPC_INTERNAL_ERROR (solver memory).
 *   int cmpc_level(const double *x);   the level look-up alone (CMPC_NOT_CONTROLLABLE:
 *                                      in no set; CMPC_BAD_INPUT: x not finite)
 *   void cmpc_reset(void);             forget warm starts
 *   void cmpc_model(const double *x, const double *u, const double *w, double *x_next);
 *                                      the model f(x, u, w) in floating point (simulation)
 *   void cmpc_model_iv(const double *x, const double *u, const double *w, double *lo,
 *                      double *hi);    an interval [lo, hi] holding the exact f(x, u, w)
 *
{check}
 */
#ifndef CMPC_CONTROLLER_H
#define CMPC_CONTROLLER_H

#define CMPC_KIND "{kind}"
#define CMPC_NX {model.n}
#define CMPC_NU {model.m}
#define CMPC_NW {model.l}

#define CMPC_NOT_CONTROLLABLE ({NOT_CONTROLLABLE})
#define CMPC_BAD_INPUT ({BAD_INPUT})
#define CMPC_INTERNAL_ERROR ({INTERNAL_ERROR})
#define CMPC_LEVEL(code) ((code) & 0xFFFF)
/* the solver's control failed the check; a blend with the stored control passed it */
#define CMPC_FLAG_BLEND {FLAG_BLEND}
/* the stored proving control of x's box was applied */
#define CMPC_FLAG_WITNESS {FLAG_WITNESS}
/* the solver reported a failure or returned a non-finite control */
#define CMPC_FLAG_SOLVER_FAILED {FLAG_SOLVER_FAILED}
/* no candidate passed the check (the stored control, or u_ref, is applied unchecked) */
#define CMPC_FLAG_UNVERIFIED {FLAG_UNVERIFIED}
/* contractive MPC: the next move of the last checked sequence (or u_ref) was applied */
#define CMPC_FLAG_FALLBACK {FLAG_FALLBACK}

int cmpc_step(const double *x, double *u);
int cmpc_level(const double *x);
void cmpc_reset(void);
void cmpc_model(const double *x, const double *u, const double *w, double *x_next);
void cmpc_model_iv(const double *x, const double *u, const double *w, double *lo, double *hi);

#endif
"""


_STEP = "int cmpc_step(const double *x, double *u) {"
# the step runs in the default floating-point environment (see CIV_ENV_ENTER in PRELUDE)
_STEP_IN_DEFAULT_ENV = """
/* The interval rules hold in the default floating-point environment (round to nearest,
 * subnormals kept): a caller's directed rounding mode or flush-to-zero is set aside for the
 * step (the solver's iterations included) and given back on return. */
int cmpc_step(const double *x, double *u) {
    int r;
    CIV_ENV_ENTER;
    r = cmpc_step_in_default_env(x, u);
    CIV_ENV_LEAVE;
    return r;
}
"""


def _source(body: str, intervals: str) -> str:
    """cmpc_controller.c: includes, the interval helpers and the generated interval
    evaluations (``intervals``), the common part, then ``body`` (its ``cmpc_step`` runs
    in the default floating-point environment)."""
    if body.count(_STEP) != 1:
        raise AssertionError("a controller body defines cmpc_step once")
    body = body.replace(_STEP, "static int cmpc_step_in_default_env(const double *x, "
                        "double *u) {") + _STEP_IN_DEFAULT_ENV
    return ("/* Exported controller logic (generated by casadi_cmpc; do not edit). */\n"
            "#include <float.h>\n#include <math.h>\n"
            "#include \"cmpc_controller.h\"\n#include \"cmpc_casadi.h\"\n"
            "#include \"cmpc_tables.h\"\n" + PRELUDE + "\n" + intervals + _COMMON + body)


def sequence_source(intervals: str) -> str:
    """The logic of a set-sequence controller; ``intervals`` defines ``cmpc_f_iv``."""
    return _source(_SEQUENCE, intervals)


def quasi_source(intervals: str) -> str:
    """The logic of a quasi multi-step controller; ``intervals`` defines ``cmpc_f_iv``."""
    return _source(_QUASI, intervals)


def contractive_source(intervals: str) -> str:
    """The logic of a contractive MPC; ``intervals`` defines ``cmpc_f_iv`` and
    ``cmpc_check_iv``."""
    return _source(_CONTRACTIVE, intervals)


def example(model: Any, x0: np.ndarray, steps: int, seed: int) -> str:
    W = model.W.as_array() if model.l else np.zeros((0, 2))
    x0s = ", ".join(repr(float(v)) for v in x0)
    wlo = ", ".join(repr(float(v)) for v in W[:, 0]) or "0.0"
    whi = ", ".join(repr(float(v)) for v in W[:, 1]) or "0.0"
    return f"""/* Closed loop of the exported controller on the generated model: x+ = f(x, u, w),
 * w drawn uniformly in W. Prints one line per step. Build with `make`, run ./example. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include "cmpc_controller.h"

static const double x_init[CMPC_NX] = {{{x0s}}};
static const double w_lo[CMPC_NW > 0 ? CMPC_NW : 1] = {{{wlo}}};
static const double w_hi[CMPC_NW > 0 ? CMPC_NW : 1] = {{{whi}}};

static unsigned long long rng_state = {int(seed) * 2654435761 + 88172645463325252};

static double uniform(void) {{
    rng_state = rng_state * 6364136223846793005ULL + 1442695040888963407ULL;
    return (double)(rng_state >> 11) / 9007199254740992.0;
}}

int main(int argc, char **argv) {{
    double x[CMPC_NX], u[CMPC_NU], w[CMPC_NW > 0 ? CMPC_NW : 1], xn[CMPC_NX];
    int k, i, steps = argc > 1 ? atoi(argv[1]) : {int(steps)};
    for (i = 0; i < CMPC_NX; ++i) x[i] = x_init[i];
    printf("step level flags x u\\n");
    for (k = 0; k < steps; ++k) {{
        int code = cmpc_step(x, u);
        if (code < 0) {{
            printf("%d stop: code %d (%s)\\n", k, code,
                   code == CMPC_NOT_CONTROLLABLE ? "not controllable" : "error");
            return 1;
        }}
        printf("%d %d 0x%x", k, CMPC_LEVEL(code), (unsigned)code >> 16);
        for (i = 0; i < CMPC_NX; ++i) printf(" %.9g", x[i]);
        for (i = 0; i < CMPC_NU; ++i) printf(" %.9g", u[i]);
        printf("\\n");
        for (i = 0; i < CMPC_NW; ++i) w[i] = w_lo[i] + (w_hi[i] - w_lo[i]) * uniform();
        cmpc_model(x, u, w, xn);
        for (i = 0; i < CMPC_NX; ++i) x[i] = xn[i];
    }}
    return 0;
}}
"""


def makefile(solver: str, inc: str, lib: str) -> str:
    ipopt = solver == "ipopt"
    return f"""# Builds the exported controller with the C compiler $(CC) (C99): by default cc,
# make's built-in value; another one with e.g. `make CC=gcc` or `make CC=clang`.
#   make            libcmpc.so and the example program
#   ./example [N]   closed loop of N steps on the generated model
CC ?= cc
CFLAGS ?= -std=c99 -Wall -Wextra -Werror -O2
SOFLAGS = -shared -fPIC
{'IPOPT_CFLAGS = ' + inc if ipopt else '# standalone: no external library'}
{'IPOPT_LIBS = ' + lib if ipopt else 'IPOPT_LIBS ='}
{'' if ipopt else 'IPOPT_CFLAGS ='}
SRC = cmpc_controller.c cmpc_casadi.c

all: libcmpc.so example

libcmpc.so: $(SRC) cmpc_controller.h cmpc_tables.h cmpc_casadi.h
\t$(CC) $(CFLAGS) $(IPOPT_CFLAGS) $(SOFLAGS) $(SRC) -o $@ $(IPOPT_LIBS) -lm

example: example.c $(SRC) cmpc_controller.h cmpc_tables.h cmpc_casadi.h
\t$(CC) $(CFLAGS) $(IPOPT_CFLAGS) example.c $(SRC) -o $@ $(IPOPT_LIBS) -lm

clean:
\trm -f libcmpc.so example

.PHONY: all clean
"""


def readme(kind: str, solver: str, model: Any) -> str:
    return f"""Controller exported from casadi_cmpc ({kind}, solver {solver})
for model '{model.name}'.

  make          builds libcmpc.so and ./example with $(CC) (default cc; make CC=gcc
                picks another compiler), -std=c99 -Wall -Wextra -Werror -O2
  ./example 40  runs 40 closed-loop steps on the generated model and prints them

API: see cmpc_controller.h (int cmpc_step(const double *x, double *u)).
Files: cmpc_casadi.c/.h (CasADi-generated solver and functions), cmpc_tables.h (set tables),
cmpc_controller.c (look-up, local law, solver call, successor check, fallback).
"""
