/* Chambolle's TV (tv.cl's algorithm and arithmetic) with several iterations per launch: each work
 * group copies a tile of the input and of the dual p, with a halo, into local memory, runs
 * `updates` dual updates there (temporal blocking) and writes back only the tile's interior, so
 * the datacube crosses global memory once per launch instead of twice per iteration.
 *
 * One update is out = img + d(p) (the primal), then p <- (p - tau grad(out)) / (1 + tau/weight
 * |grad(out)|). out at a voxel needs p there and at its lower neighbours, p needs out there and
 * at its upper neighbours: every update leaves one layer less of the region correct on each side,
 * so the host gives the region `updates` layers of halo above and `updates` (+1 for the final
 * primal, -1 when p starts at 0) below, except along the domain's edges, where the algorithm's own
 * boundary rules apply. Layouts as tv.cl: x[B][T][m][n] (B sets end to end, no temporal
 * difference across a set boundary), p: NP planes of N = B*T*m*n values, steps[3 set] = tau,
 * steps[3 set + 1] = tau / weight and steps[3 set + 2] = the set's temporal weight. The host
 * defines TEMPORAL 0|1 (NP = 3|2). Needs common.cl.
 *
 * Grid: local size (LX, LY, 1); group (gx, gy, gz) takes the tile of AX x AY x AT voxels at
 * x = gx*AX, y = gy*AY, t = (gz % tiles_t)*AT of set gz / tiles_t. `local` holds 5 arrays (img,
 * p0, p1, p2, out; 4 without TEMPORAL) of `cap` values, one guard value before each and one after
 * the last, so that the read of a left (right) neighbour at the region's first (last) voxel stays
 * inside local memory (the value is discarded). Each work item takes the rows y = y0 + ly + k LY
 * of a phase (load, primal, dual step, write) and in them the voxels x = x0 + lx + k LX; one barrier
 * separates the phases. Rows are loops of their own over restrict pointers, with a unit-stride
 * version for LX = 1: a CPU device (one work item per group) runs them as vectorised loops.
 *
 * mode: bit 0 = p starts at 0 (pin is not read), bit 1 = final (write out = img + d(p), not p),
 * bit 2 = also the ADMM's next dual update from u = img and theta = out: b = theta - u and
 * f = theta + b where dual[set] (eta > 0), else f = theta (b stays 0).
 */
#ifndef TEMPORAL
#define TEMPORAL 1
#endif
#if TEMPORAL
#define TV_ARRAYS 5
#else
#define TV_ARRAYS 4
#endif

#define FUSED_P_ZERO 1
#define FUSED_FINAL 2
#define FUSED_DUAL 4

/* Bounds of a box [lo, hi) per axis, in the set's coordinates (x, y, t). */
typedef struct { int x0, x1, y0, y1, t0, t1; } box_t;

/* out = img + d(p) along one row of the region, voxels x0 + k * LX (k = 0, 1, ...) below x1; every
 * pointer is the row's start (local index of x = r.x0); up_p0 is P0's row above (y - 1, or the row
 * itself at y = 0), prev_p2 P2's row one sub-frame before (or the row itself). The same operations,
 * in the same order, as tv_primal. A unit stride is a loop of its own: a CPU compiler vectorises it. */
#define FUSED_PRIMAL_STEP(i, xx)                                                                        \
    {                                                                                              \
        real d = -(p0[i] + p1[i]);                                                                 \
        real py = up_p0[i];                                                                        \
        d += has_y ? py : (real)0;                                                                 \
        real px = p1[(i) - 1];                   /* the guard value when the region's first */    \
        d += (xx) > 0 ? px : (real)0;                                                              \
        FUSED_PRIMAL_T(i)                                                                          \
        o[i] = img[i] + d;                                                                         \
    }
#if TEMPORAL
#define FUSED_PRIMAL_T(i)                                                                          \
        real pt = prev_p2[i];                                                                      \
        d -= wt * p2[i];                                                                           \
        d += has_t ? wt * pt : (real)0;
#else
#define FUSED_PRIMAL_T(i)
#endif

/* STEP(i, x) over the row's voxels x = x0 + k * LX below x1 (i: the local index), with a loop of
 * its own for the unit stride, which a CPU compiler vectorises. */
#define FUSED_ROW_LOOP(STEP)                                                                       \
    if (LX == 1) {                                                                                 \
        for (int x = x0; x < x1; ++x) {                                                            \
            int i = x - rx0;                                                                       \
            STEP(i, x)                                                                             \
        }                                                                                          \
    } else {                                                                                       \
        for (int x = x0; x < x1; x += LX) {                                                        \
            int i = x - rx0;                                                                       \
            STEP(i, x)                                                                             \
        }                                                                                          \
    }

inline void fused_primal_row(__local real *restrict o, __local const real *restrict img,
                             __local const real *restrict p0, __local const real *restrict up_p0,
                             __local const real *restrict p1, __local const real *restrict p2,
                             __local const real *restrict prev_p2, int has_y, int has_t, real wt,
                             int rx0, int x0, int x1, int LX)
{
    FUSED_ROW_LOOP(FUSED_PRIMAL_STEP)
}

/* The dual step (as tv.cl's dual_update) along one row: src is the primal's row, src_up the row
 * below it in y (y + 1, or itself at the last row), src_next the row one sub-frame later (or
 * itself); n1 = n - 1 (no x difference there). */
#define FUSED_DUAL_STEP(i, xx)                                                                          \
    {                                                                                              \
        real v = src[i];                                                                           \
        real gy = src_up[i] - v;                                                                   \
        real right = src[(i) + 1];               /* past the row end: discarded below */          \
        real gx = (xx) < n1 ? right - v : (real)0;                                                 \
        real norm2 = gy * gy + gx * gx;                                                            \
        FUSED_DUAL_T(i)                                                                            \
        real scale = (real)1 / ((real)1 + vector_friendly_sqrt(norm2) * tau_over_weight);         \
        p0[i] = (p0[i] - tau * gy) * scale;                                                        \
        p1[i] = (p1[i] - tau * gx) * scale;                                                        \
        FUSED_DUAL_P2(i)                                                                           \
    }
#if TEMPORAL
#define FUSED_DUAL_T(i)                                                                            \
        real gt = wt * (src_next[i] - v);                                                          \
        norm2 += gt * gt;
#define FUSED_DUAL_P2(i) p2[i] = (p2[i] - tau * gt) * scale;
#else
#define FUSED_DUAL_T(i)
#define FUSED_DUAL_P2(i)
#endif

inline void fused_dual_row(__local real *restrict p0, __local real *restrict p1, __local real *restrict p2,
                           __local const real *restrict src, __local const real *restrict src_up,
                           __local const real *restrict src_next, real tau, real tau_over_weight, real wt,
                           int n1, int rx0, int x0, int x1, int LX)
{
    FUSED_ROW_LOOP(FUSED_DUAL_STEP)
}

/* Copies between global memory and the region, along one row: voxels k * LX (k = 0, 1, ...) below
 * len of row pointers that start at the first voxel; p is 0 where p_zero. */
inline void fused_load_row(__local real *restrict img, __local real *restrict p0, __local real *restrict p1,
                           __local real *restrict p2, __global const real *restrict gimg,
                           __global const real *restrict g0, __global const real *restrict g1,
                           __global const real *restrict g2, int p_zero, int len, int LX)
{
    if (p_zero) {
        for (int i = 0; i < len; i += LX) {
            img[i] = gimg[i]; p0[i] = (real)0; p1[i] = (real)0;
#if TEMPORAL
            p2[i] = (real)0;
#endif
        }
    } else if (LX == 1) {
        for (int i = 0; i < len; ++i) {
            img[i] = gimg[i]; p0[i] = g0[i]; p1[i] = g1[i];
#if TEMPORAL
            p2[i] = g2[i];
#endif
        }
    } else {
        for (int i = 0; i < len; i += LX) {
            img[i] = gimg[i]; p0[i] = g0[i]; p1[i] = g1[i];
#if TEMPORAL
            p2[i] = g2[i];
#endif
        }
    }
}

inline void fused_store_row(__global real *restrict g0, __global real *restrict g1, __global real *restrict g2,
                            __local const real *restrict p0, __local const real *restrict p1,
                            __local const real *restrict p2, int len, int LX)
{
    if (LX == 1) {
        for (int i = 0; i < len; ++i) {
            g0[i] = p0[i]; g1[i] = p1[i];
#if TEMPORAL
            g2[i] = p2[i];
#endif
        }
    } else {
        for (int i = 0; i < len; i += LX) {
            g0[i] = p0[i]; g1[i] = p1[i];
#if TEMPORAL
            g2[i] = p2[i];
#endif
        }
    }
}

/* out = img + d(p) at one voxel (local index li): the final write's primal. */
inline real fused_primal(__local const real *IMG, __local const real *P0, __local const real *P1,
                         __local const real *P2, int li, int x, int y, int t, int RX, int RXY, real wt)
{
    real d = -(P0[li] + P1[li]);
    real py = P0[y > 0 ? li - RX : li];
    d += y > 0 ? py : (real)0;
    real px = P1[li - 1];                        /* the guard value when li = 0 */
    d += x > 0 ? px : (real)0;
#if TEMPORAL
    real pt = P2[t > 0 ? li - RXY : li];
    d -= wt * P2[li];
    d += t > 0 ? wt * pt : (real)0;
#endif
    return IMG[li] + d;
}

__kernel void tv_fused(__global const real *img, __global const real *pin, __global real *pout,
                       __global real *out, __global real *bvar, __global real *fvar,
                       __global const int *dual, __global const real *steps,
                       int T, int m, int n, int sets, int tiles_t, int AX, int AY, int AT,
                       int halo_lo, int halo_hi, int halo_t_lo, int halo_t_hi,
                       int updates, int mode, int cap, __local real *local_mem)
{
    const int lx = get_local_id(0), ly = get_local_id(1);
    const int LX = get_local_size(0), LY = get_local_size(1);
    const int gz = get_group_id(2), set = gz / tiles_t, tz = gz - set * tiles_t;
    const size_t N = (size_t)sets * T * m * n, mn = (size_t)m * n, base = (size_t)set * T * mn;
    const real tau = steps[3 * set], tau_over_weight = steps[3 * set + 1], wt = steps[3 * set + 2];

    box_t in;                                    /* the tile's interior */
    in.x0 = get_group_id(0) * AX; in.x1 = min(in.x0 + AX, n);
    in.y0 = get_group_id(1) * AY; in.y1 = min(in.y0 + AY, m);
    in.t0 = tz * AT;              in.t1 = min(in.t0 + AT, T);
    box_t r;                                     /* the region in local memory */
    r.x0 = max(in.x0 - halo_lo, 0);   r.x1 = min(in.x1 + halo_hi, n);
    r.y0 = max(in.y0 - halo_lo, 0);   r.y1 = min(in.y1 + halo_hi, m);
    r.t0 = max(in.t0 - halo_t_lo, 0); r.t1 = min(in.t1 + halo_t_hi, T);
    const int RX = r.x1 - r.x0, RY = r.y1 - r.y0, RXY = RX * RY;

    __local real *IMG = local_mem + 1;
    __local real *P0 = IMG + (cap + 1);
    __local real *P1 = P0 + (cap + 1);
    __local real *P2 = P1 + (cap + 1);           /* unused without TEMPORAL */
    __local real *OUT = IMG + (TV_ARRAYS - 1) * (cap + 1);
    if (lx == 0 && ly == 0)                      /* the guards, and the value after the last array */
        for (int a = 0; a <= TV_ARRAYS; ++a) local_mem[a * (cap + 1)] = (real)0;

    const int p_zero = mode & FUSED_P_ZERO;
    /* ---- load the region ---- */
    for (int t = r.t0; t < r.t1; ++t)
        for (int y = r.y0 + ly; y < r.y1; y += LY) {
            int row = ((t - r.t0) * RY + (y - r.y0)) * RX + lx;
            size_t g = base + ((size_t)t * m + y) * n + r.x0 + lx;
            fused_load_row(IMG + row, P0 + row, P1 + row, P2 + row, img + g, pin + g, pin + N + g,
                           pin + (TV_ARRAYS - 3) * N + g, p_zero, RX - lx, LX);
        }
    barrier(CLK_LOCAL_MEM_FENCE);

    box_t v = r;                                 /* where p is correct */
    for (int j = 0; j < updates; ++j) {
        /* ---- out = img + d(p) where the lower neighbours' p is correct ---- */
        int from_img = p_zero && j == 0;         /* p = 0: out = img exactly */
        if (!from_img) {
            v.x0 += v.x0 > 0; v.y0 += v.y0 > 0;
#if TEMPORAL
            v.t0 += v.t0 > 0;
#endif
            for (int t = v.t0; t < v.t1; ++t)
                for (int y = v.y0 + ly; y < v.y1; y += LY) {
                    int row = ((t - r.t0) * RY + (y - r.y0)) * RX;
                    int up = y > 0 ? row - RX : row, prev = t > 0 ? row - RXY : row;
                    fused_primal_row(OUT + row, IMG + row, P0 + row, P0 + up, P1 + row, P2 + row, P2 + prev,
                                     y > 0, t > 0, wt, r.x0, v.x0 + lx, v.x1, LX);
                }
        }
        barrier(CLK_LOCAL_MEM_FENCE);
        __local const real *SRC = from_img ? IMG : OUT;
        /* ---- the dual step where the upper neighbours' out is correct ---- */
        v.x1 -= v.x1 < n; v.y1 -= v.y1 < m;
#if TEMPORAL
        v.t1 -= v.t1 < T;
#endif
        for (int t = v.t0; t < v.t1; ++t)
            for (int y = v.y0 + ly; y < v.y1; y += LY) {
                int row = ((t - r.t0) * RY + (y - r.y0)) * RX;
                int below = y < m - 1 ? row + RX : row, next = t < T - 1 ? row + RXY : row;
                fused_dual_row(P0 + row, P1 + row, P2 + row, SRC + row, SRC + below, SRC + next,
                               tau, tau_over_weight, wt, n - 1, r.x0, v.x0 + lx, v.x1, LX);
            }
        barrier(CLK_LOCAL_MEM_FENCE);
    }

    /* ---- write the interior: p, or the final out (and the ADMM's dual update) ---- */
    const int final_ = mode & FUSED_FINAL, update_dual = (mode & FUSED_DUAL) && dual[set];
    if (!final_) {
        for (int t = in.t0; t < in.t1; ++t)
            for (int y = in.y0 + ly; y < in.y1; y += LY) {
                int row = ((t - r.t0) * RY + (y - r.y0)) * RX + (in.x0 - r.x0) + lx;
                size_t g = base + ((size_t)t * m + y) * n + in.x0 + lx;
                fused_store_row(pout + g, pout + N + g, pout + (TV_ARRAYS - 3) * N + g, P0 + row, P1 + row,
                                P2 + row, in.x1 - in.x0 - lx, LX);
            }
        return;
    }
    for (int t = in.t0; t < in.t1; ++t)
        for (int y = in.y0 + ly; y < in.y1; y += LY)
            for (int x = in.x0 + lx; x < in.x1; x += LX) {
                int li = ((t - r.t0) * RY + (y - r.y0)) * RX + (x - r.x0);
                size_t gi = base + ((size_t)t * m + y) * n + x;
                if (final_) {
                    real th = fused_primal(IMG, P0, P1, P2, li, x, y, t, RX, RXY, wt);
                    out[gi] = th;
                    if (mode & FUSED_DUAL) {
                        if (update_dual) {
                            real bn = th - IMG[li];
                            bvar[gi] = bn;
                            fvar[gi] = th + bn;
                        } else {
                            fvar[gi] = th;
                        }
                    }
                } else {
                    pout[gi] = P0[li];
                    pout[N + gi] = P1[li];
#if TEMPORAL
                    pout[2 * N + gi] = P2[li];
#endif
                }
            }
}

/* The ADMM's dual update from the denoiser's input u and output theta, where the TV could not take
 * it into its last launch (no fused plan on this device): b = theta - u and f = theta + b where
 * dual[set], else f = theta. global size (per-set voxels, sets) on an exact grid. */
__kernel void dual_from_u(__global const real *theta, __global const real *u, __global real *bvar,
                          __global real *fvar, __global const int *dual, int per_set)
{
    size_t set = get_global_id(1), i = set * (size_t)per_set + get_global_id(0);
    real th = theta[i];
    if (dual[set]) {
        real bn = th - u[i];
        bvar[i] = bn;
        fvar[i] = th + bn;
    } else {
        fvar[i] = th;
    }
}
