/* The ADMM data step of MODEL.md in three launches. Needs common.cl; the host
 * defines NCH (channels) and PROJECTION_EXACT 0|1.
 *
 *   admm_dual      (one work item per voxel)  b <- b - (f - theta)  [skipped in GAP]
 *                                             f  = v = theta + b
 *   admm_project   (one work item per tile    r = g - H v,  z = (eta I + M)^-1 r  (exact)
 *                   of TILE_W pixels)                        | r / (eta + psi)    (paper, Eq. 15)
 *                                             f += Hᵀ z     (window loops only)
 *   admm_difference (one work item per voxel) u = f - b     (input of the denoiser)
 *
 * Voxel-parallel passes keep neighbouring work items on neighbouring addresses, which
 * CPU vectorisers need (a per-pixel loop over the whole column ran 5x slower on PoCL).
 */
#ifndef PROJECTION_EXACT
#define PROJECTION_EXACT 1
#endif

/* admm_dual and admm_difference: one work item per voxel on an exact grid
 * (rsocl.launch.element_launches), so no bounds test (it costs masked stores on PoCL). */
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

/* global size ceil(m*n / TILE_W): one work item per tile of TILE_W pixels (common.cl). */
__kernel void admm_project(__global real *f, __global const real *g,
                           __global const int *first, __global const real *frac,
                           __global const real *len, __global const real *gain,
                           __global const real *inverse, real eta, int T, int L, int mn_)
{
    size_t mn = (size_t)mn_;
    size_t p0 = get_global_id(0) * (size_t)TILE_W;
    if (p0 >= mn) return;
    if (p0 + TILE_W > mn) {
        for (size_t p = p0; p < mn; ++p)
            project_pixel(f, g, first, frac, len, gain, inverse, eta, T, L, mn, p);
        return;
    }
    realw r[NCH];
    for (int k = 0; k < NCH; ++k) {
        size_t q0 = (size_t)k * mn + p0;
        r[k] = load_w(g + q0) - gain[k] * window_dot_v(f, first, frac, len[k], q0, T, L, mn, p0);
    }
    for (int k = 0; k < NCH; ++k) {
        size_t q0 = (size_t)k * mn + p0;
#if PROJECTION_EXACT
        realw z = (realw)(real)0;
        for (int l = 0; l < NCH; ++l) z += load_w(inverse + ((size_t)k * NCH + l) * mn + p0) * r[l];
#else
        realw d = eta + load_w(inverse + q0);     /* inverse holds psi here */
        realw z = d > (realw)(real)0 ? r[k] / d : (realw)(real)0;
#endif
        window_scatter_v(f, first, frac, len[k], q0, T, L, mn, p0, gain[k] * z);
    }
}

__kernel void admm_difference(__global const real *f, __global const real *b, __global real *u)
{
    size_t i = get_global_id(0);
    u[i] = f[i] - b[i];
}
