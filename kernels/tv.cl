/* Chambolle's isotropic total-variation denoiser (the algorithm of
 * skimage.restoration.denoise_tv_chambolle), 2-D per sub-frame or 3-D with a
 * temporal weight. Layout x[T][m][n]; the dual p holds NP = 2 (+1 if TEMPORAL)
 * planes of T*m*n values: p[0] along y, p[1] along x, p[2] along t.
 * The host defines TEMPORAL 0|1. One work item per voxel. Needs common.cl. */
#ifndef TEMPORAL
#define TEMPORAL 1
#endif

/* x + d(p) at voxel (s, y, x), with d the (negative) divergence of p. */
inline real tv_primal(__global const real *img, __global const real *p, int s, int y, int x,
                      int m, int n, size_t N, real wt)
{
    size_t i = ((size_t)s * m + y) * n + x;
    real d = -(p[i] + p[N + i]);
    if (y > 0) d += p[i - n];
    if (x > 0) d += p[N + i - 1];
#if TEMPORAL
    d -= wt * p[2 * N + i];
    if (s > 0) d += wt * p[2 * N + i - (size_t)m * n];
#endif
    return img[i] + d;
}

/* One Chambolle iteration: p_out from p_in.  global size (n, m, T) */
__kernel void tv_step(__global const real *img, __global const real *p_in, __global real *p_out,
                      real tau, real tau_over_weight, real wt, int T, int m, int n)
{
    int x = get_global_id(0), y = get_global_id(1), s = get_global_id(2);
    if (x >= n || y >= m || s >= T) return;
    size_t N = (size_t)T * m * n;
    size_t i = ((size_t)s * m + y) * n + x;
    real o = tv_primal(img, p_in, s, y, x, m, n, N, wt);
    real gy = (y < m - 1) ? tv_primal(img, p_in, s, y + 1, x, m, n, N, wt) - o : (real)0;
    real gx = (x < n - 1) ? tv_primal(img, p_in, s, y, x + 1, m, n, N, wt) - o : (real)0;
    real norm2 = gy * gy + gx * gx;
#if TEMPORAL
    real gt = (s < T - 1) ? wt * (tv_primal(img, p_in, s + 1, y, x, m, n, N, wt) - o) : (real)0;
    norm2 += gt * gt;
#endif
    real denom = (real)1 + sqrt(norm2) * tau_over_weight;
    p_out[i] = (p_in[i] - tau * gy) / denom;
    p_out[N + i] = (p_in[N + i] - tau * gx) / denom;
#if TEMPORAL
    p_out[2 * N + i] = (p_in[2 * N + i] - tau * gt) / denom;
#endif
}

/* out = img + d(p): the denoised result.  global size (n, m, T) */
__kernel void tv_primal_out(__global const real *img, __global const real *p, __global real *out,
                            real wt, int T, int m, int n)
{
    int x = get_global_id(0), y = get_global_id(1), s = get_global_id(2);
    if (x >= n || y >= m || s >= T) return;
    size_t N = (size_t)T * m * n;
    out[((size_t)s * m + y) * n + x] = tv_primal(img, p, s, y, x, m, n, N, wt);
}
