/* The ADMM data step of MODEL.md in three launches. Needs common.cl; the host
 * defines NCH (channels) and PROJECTION_EXACT 0|1.
 *
 *   admm_dual      (one work item per voxel)  b <- b - (f - theta)  [skipped in GAP]
 *                                             f  = v = theta + b
 *   admm_project   (one work item per block   r = g - H v,  z = (eta I + M)^-1 r  (exact)
 *                   of TILE_R x TILE_W px)                   | r / (eta + psi)    (paper, Eq. 15)
 *                                             f += Hᵀ z     (window loops only)
 *   admm_difference (one work item per voxel) u = f - b     (input of the denoiser)
 *
 * Voxel-parallel passes keep neighbouring work items on neighbouring addresses, which
 * CPU vectorisers need (a per-pixel loop over the whole column takes 5x the time on PoCL).
 */
#ifndef PROJECTION_EXACT
#define PROJECTION_EXACT 1
#endif

/* admm_dual and admm_difference: one work item per voxel on an exact grid
 * (rsocl.device.launch.element_launches), so no bounds test (it costs masked stores on PoCL). */
__kernel void admm_dual(__global const real *theta, __global real *b, __global real *f, int update_dual)
{
    size_t i = get_global_id(0);
    real th = theta[i];
    real bn = update_dual ? b[i] - (f[i] - th) : b[i];
    b[i] = bn;
    f[i] = th + bn;
}

/* The projection of one pixel p (scalar path: the last, partial tile). */
inline void project_pixel(__global real *f, __global const real *g,
                          __global const int *first, __global const real *frac,
                          __global const real *len, __global const real *gain,
                          __global const real *inverse, real eta, int T, int L, size_t mn, size_t p)
{
    real r[NCH];
    for (int k = 0; k < NCH; ++k) {
        size_t q = (size_t)k * mn + p;
        r[k] = g[q] - gain[k] * window_dot(f, first[q], frac[q], len[k], T, L, mn, p);
    }
    for (int k = 0; k < NCH; ++k) {
        size_t q = (size_t)k * mn + p;
#if PROJECTION_EXACT
        real z = (real)0;
        for (int l = 0; l < NCH; ++l) z += inverse[((size_t)k * NCH + l) * mn + p] * r[l];
#else
        real d = eta + inverse[q];          /* inverse holds psi here */
        real z = d > (real)0 ? r[k] / d : (real)0;
#endif
        window_scatter(f, first[q], frac[q], len[k], T, L, mn, p, gain[k] * z);
    }
}

/* global size (>= ceil(n / TILE_W), >= ceil(m / TILE_R)): one work item per block of
 * TILE_R x TILE_W pixels (common.cl); blocks cut by the ROI's edge take project_pixel. */
__kernel void admm_project(__global real *f, __global const real *g,
                           __global const int *first, __global const real *frac,
                           __global const real *len, __global const real *gain,
                           __global const real *inverse, real eta, int T, int L, int m_, int n_)
{
    size_t m = (size_t)m_, n = (size_t)n_, mn = m * n;
    size_t x0 = get_global_id(0) * (size_t)TILE_W, y0 = get_global_id(1) * (size_t)TILE_R;
    if (x0 >= n || y0 >= m) return;
    if (x0 + TILE_W > n || y0 + TILE_R > m) {
        for (size_t y = y0; y < y0 + TILE_R && y < m; ++y)
            for (size_t x = x0; x < x0 + TILE_W && x < n; ++x)
                project_pixel(f, g, first, frac, len, gain, inverse, eta, T, L, mn, y * n + x);
        return;
    }
    size_t p0 = y0 * n + x0;
    realw res[NCH][TILE_R];            /* r = g - H v, per channel and row of the block */
    for (int k = 0; k < NCH; ++k) {
        size_t q0 = (size_t)k * mn + p0;
        realw hv[TILE_R];
        block_dot(f, first, frac, len[k], q0, T, L, mn, n, p0, hv);
        for (int r = 0; r < TILE_R; ++r) res[k][r] = load_w(g + q0 + (size_t)r * n) - gain[k] * hv[r];
    }
    for (int k = 0; k < NCH; ++k) {
        size_t q0 = (size_t)k * mn + p0;
        realw scale[TILE_R];
        for (int r = 0; r < TILE_R; ++r) {
            size_t pr = p0 + (size_t)r * n;
#if PROJECTION_EXACT
            realw z = (realw)(real)0;
            for (int l = 0; l < NCH; ++l) z += load_w(inverse + ((size_t)k * NCH + l) * mn + pr) * res[l][r];
#else
            realw d = eta + load_w(inverse + (size_t)k * mn + pr);     /* inverse holds psi here */
            realw z = d > (realw)(real)0 ? res[k][r] / d : (realw)(real)0;
#endif
            scale[r] = gain[k] * z;
        }
        block_scatter(f, first, frac, len[k], q0, T, L, mn, n, p0, scale);
    }
}

__kernel void admm_difference(__global const real *f, __global const real *b, __global real *u)
{
    size_t i = get_global_id(0);
    u[i] = f[i] - b[i];
}
