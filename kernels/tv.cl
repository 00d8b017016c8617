/* Chambolle's isotropic total-variation denoiser (the algorithm of
 * skimage.restoration.denoise_tv_chambolle), 2-D per sub-frame or 3-D with a
 * temporal weight. Layout x[T][m][n]; the dual p holds NP = 2 (+1 if TEMPORAL)
 * planes of T*m*n values: p[0] along y, p[1] along x, p[2] along t.
 * The host defines TEMPORAL 0|1. One work item per voxel, two kernels per
 * iteration (primal then dual), each reading its neighbours once; the first iteration,
 * from p = 0, is one kernel (tv_dual_first). Needs common.cl. */
#ifndef TEMPORAL
#define TEMPORAL 1
#endif

/* Launch with an exact grid (rsocl.device.launch.voxel_launches): there is no bounds test, and
 * neighbours across an edge are read at a clamped index and discarded with a select,
 * because PoCL turns a per-work-item `if` into masked loads and stores (2x the time).
 * Selects on y and s are uniform in a work group (a row); along x, where a per-lane
 * select costs PoCL a vector of 64-bit indices per row of 8 voxels, the kernels use:
 *  - xnext[x] = 1 for x < n - 1, else 0 (n values): the dual multiplies the x difference
 *    by it, a plain vector load and a multiply (10 % of the TV time, measured);
 *  - the invariant p[1] = 0 at x = n - 1 (the x difference there is 0 from p = 0 on, so
 *    every step keeps it 0): the primal reads p[1] at i - 1 with no select at x = 0. */

/* out = img + d(p), d the (negative) divergence of p.  global size (n, m, T) */
__kernel void tv_primal(__global const real *img, __global const real *p, __global real *out,
                        real wt, int T, int m, int n)
{
    int x = get_global_id(0), y = get_global_id(1), s = get_global_id(2);
    size_t N = (size_t)T * m * n, mn = (size_t)m * n;
    size_t i = ((size_t)s * m + y) * n + x;
    real d = -(p[i] + p[N + i]);
    /* The x - 1 neighbour is read at i - 1 always: at x = 0 that is p[1] at x = n - 1 of the
     * row before, which is 0 (see above), or p[0] at the very last voxel (y = m - 1: 0 too)
     * when i = 0. */
    real py = p[y > 0 ? i - n : i];
    d += y > 0 ? py : (real)0;
    d += p[N + i - 1];
#if TEMPORAL
    real pt = p[2 * N + (s > 0 ? i - mn : i)];
    d -= wt * p[2 * N + i];
    d += s > 0 ? wt * pt : (real)0;
#endif
    out[i] = img[i] + d;
}

/* p <- (p - tau grad(out)) / (1 + tau/weight |grad(out)|) at voxel (x, y, s); with
 * from_zero, p is taken as 0 and not read (the first iteration, where out = img).
 * At the far edges the clamped neighbour is the voxel itself: the difference is 0. */
inline void dual_update(__global const real *out, __global real *p, __global const real *xnext,
                        real tau, real tau_over_weight, real wt, int T, int m, int n, int from_zero)
{
    int x = get_global_id(0), y = get_global_id(1), s = get_global_id(2);
    size_t N = (size_t)T * m * n, mn = (size_t)m * n;
    size_t i = ((size_t)s * m + y) * n + x;
    real o = out[i];
    real gy = out[y < m - 1 ? i + n : i] - o;
    /* out[i + 1] is in the buffer except for the last voxel: read it plainly (a vector
     * load) in every row but the last one, where the row is uniform. */
    real right = (y < m - 1 || s < T - 1) ? out[i + 1] : out[x < n - 1 ? i + 1 : i];
    real gx = (right - o) * xnext[x];            /* exactly 0 at x = n - 1 */
    real norm2 = gy * gy + gx * gx;
#if TEMPORAL
    real gt = wt * (out[s < T - 1 ? i + mn : i] - o);
    norm2 += gt * gt;
#endif
    real scale = (real)1 / ((real)1 + vector_friendly_sqrt(norm2) * tau_over_weight);
    p[i] = ((from_zero ? (real)0 : p[i]) - tau * gy) * scale;
    p[N + i] = ((from_zero ? (real)0 : p[N + i]) - tau * gx) * scale;
#if TEMPORAL
    p[2 * N + i] = ((from_zero ? (real)0 : p[2 * N + i]) - tau * gt) * scale;
#endif
}

/* The dual step, in place.  global size (n, m, T) */
__kernel void tv_dual(__global const real *out, __global real *p, __global const real *xnext,
                      real tau, real tau_over_weight, real wt, int T, int m, int n)
{
    dual_update(out, p, xnext, tau, tau_over_weight, wt, T, m, n, 0);
}

/* The first dual step from p = 0, where out = img + d(0) = img: it reads img and only
 * writes p (no fill of p, no first primal step).  global size (n, m, T) */
__kernel void tv_dual_first(__global const real *img, __global real *p, __global const real *xnext,
                            real tau, real tau_over_weight, real wt, int T, int m, int n)
{
    dual_update(img, p, xnext, tau, tau_over_weight, wt, T, m, n, 1);
}
