/* The ADMM data step of MODEL.md in three launches. Needs common.cl; the host
 * defines NCH (channels) and PROJECTION_EXACT 0|1.
 *
 *   admm_dual      (one work item per voxel)  b <- b - (f - theta)  [skipped in GAP]
 *                                             f  = v = theta + b
 *   admm_project   (one work item per pixel)  r = g - H v,  z = (eta I + M)^-1 r  (exact)
 *                                                            | r / (eta + psi)    (paper, Eq. 15)
 *                                             f += Hᵀ z     (window loops only)
 *   admm_difference (one work item per voxel) u = f - b     (input of the denoiser)
 *
 * Voxel-parallel passes keep neighbouring work items on neighbouring addresses, which
 * CPU vectorisers need (a per-pixel loop over the whole column ran 5x slower on PoCL).
 */
#ifndef PROJECTION_EXACT
#define PROJECTION_EXACT 1
#endif

__kernel void admm_dual(__global const real *theta, __global real *b, __global real *f, int update_dual, int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    real th = theta[i];
    real bn = update_dual ? b[i] - (f[i] - th) : b[i];
    b[i] = bn;
    f[i] = th + bn;
}

__kernel void admm_project(__global real *f, __global const real *g,
                           __global const int *first, __global const real *frac,
                           __global const real *len, __global const real *gain,
                           __global const real *inverse, real eta, int T, int L, int mn_)
{
    size_t p = get_global_id(0);
    size_t mn = (size_t)mn_;
    if (p >= mn) return;
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

__kernel void admm_difference(__global const real *f, __global const real *b, __global real *u, int n)
{
    int i = get_global_id(0);
    if (i < n) u[i] = f[i] - b[i];
}
