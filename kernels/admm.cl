/* The ADMM data step of MODEL.md, fused per pixel, and the reductions the solver
 * needs. Needs common.cl; the host defines NCH (channels) and PROJECTION_EXACT 0|1.
 *
 * admm_data_step, per pixel p, over its column of T sub-frames:
 *   b   <- b - (f - theta)            (dual update of the previous iteration; skipped in GAP)
 *   v    = theta + b
 *   r    = g - H v                    (window loops only)
 *   z    = (eta I + M)^-1 r           (exact: precomputed K×K block per pixel)
 *        | r / (eta + psi)            (paper's Eq. 15)
 *   f    = v + Hᵀ z
 *   u    = f - b                      (input of the denoiser)
 */
#ifndef PROJECTION_EXACT
#define PROJECTION_EXACT 1
#endif

__kernel void admm_data_step(__global const real *theta, __global real *b, __global real *f,
                             __global real *u, __global const real *g,
                             __global const int *first, __global const real *frac,
                             __global const real *len, __global const real *gain,
                             __global const real *inverse, real eta,
                             int T, int L, int mn_, int update_dual)
{
    size_t p = get_global_id(0);
    size_t mn = (size_t)mn_;
    if (p >= mn) return;
    for (int s = 0; s < T; ++s) {
        size_t i = (size_t)s * mn + p;
        real th = theta[i];
        real bn = update_dual ? b[i] - (f[i] - th) : b[i];
        b[i] = bn;
        f[i] = th + bn;
    }
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
    for (int s = 0; s < T; ++s) {
        size_t i = (size_t)s * mn + p;
        u[i] = f[i] - b[i];
    }
}

/* Partial sums of (a - b)^2 (b may be 0: then of a^2), one per work group, with a
 * compensated per-item sum and a tree in local memory. The host adds the partials
 * in double precision. Launch with a power-of-two local size. */
__kernel void sum_sq_diff(__global const real *a, __global const real *b, __global acc_t *partials,
                          __local acc_t *scratch, int n_)
{
    size_t n = (size_t)n_;
    size_t gid = get_global_id(0), lid = get_local_id(0), stride = get_global_size(0);
    acc_t sum = 0, comp = 0;
    for (size_t i = gid; i < n; i += stride) {
        acc_t d = (acc_t)a[i] - (b ? (acc_t)b[i] : (acc_t)0);
        acc_t y = d * d - comp;
        acc_t t = sum + y;
        comp = (t - sum) - y;
        sum = t;
    }
    scratch[lid] = sum;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (size_t half = get_local_size(0) / 2; half > 0; half /= 2) {
        if (lid < half) scratch[lid] += scratch[lid + half];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) partials[get_group_id(0)] = scratch[0];
}

/* dst = src, one work item per element: the bandwidth reference of the benchmarks. */
__kernel void copy(__global const real *src, __global real *dst, int n)
{
    size_t i = get_global_id(0);
    if (i < (size_t)n) dst[i] = src[i];
}
