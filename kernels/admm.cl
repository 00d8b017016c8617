/* The ADMM data step of MODEL.md, fused per pixel. Needs common.cl; the host defines NCH (channels) and PROJECTION_EXACT 0|1.
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
