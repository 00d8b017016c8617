/* rsocl's plain TV iteration (kernels/tv.cl: tv_primal, tv_dual) written as C loops, for
 * benchmarks/tv_ceiling.py: what a C compiler makes of the same arithmetic and memory traffic on
 * this CPU, with OpenMP threads over the rows. float32, one set, temporal weight wt > 0.
 * Layout as tv.cl: out, img [T][m][n]; p = three planes of N = T m n values (y, x, t).
 * Each row is a function of its own with restrict pointers: inside an OpenMP region the compiler
 * no longer knows that the buffers do not overlap, and its run-time overlap test sent the
 * rows to scalar code (10x the time, measured with GCC 12). */
#include <stddef.h>
#ifdef _OPENMP
#include <omp.h>
#endif

void set_threads(int threads)
{
#ifdef _OPENMP
    omp_set_num_threads(threads);
#else
    (void)threads;
#endif
}

/* sqrt as tv.cl computes it (common.cl: vector_friendly_sqrt), so both give the same values */
static inline float friendly_sqrt(float v)
{
    union { float f; int i; } u;
    u.f = v;
    u.i = 0x5f375a86 - (u.i >> 1);
    float y = u.f, h = 0.5f * v;
    y = y * (1.5f - h * y * y);
    y = y * (1.5f - h * y * y);
    y = y * (1.5f - h * y * y);
    return v * y;
}

/* one row of out = img + d(p); ky, kt: 1 and wt where the row has a row and a sub-frame before it
 * (else 0), and py_before, pt_before point there (or at the row itself). As tv.cl, px[x - 1] is read
 * at x = 0 too: there it is the last column of the row before (0: no x difference there), or, for
 * the datacube's first row, the last value of py (its last row: 0 too). */
static __attribute__((noinline)) void primal_row(
    const float *restrict img, const float *restrict py, const float *restrict px, const float *restrict pt,
    const float *restrict py_before, const float *restrict pt_before, float *restrict out,
    float ky, float kt, float wt, int n)
{
    for (int x = 0; x < n; ++x)
        out[x] = img[x] - py[x] - px[x] + px[x - 1] + ky * py_before[x] - wt * pt[x] + kt * pt_before[x];
}

void tv_primal(const float *img, const float *p, float *out, float wt, int T, int m, int n)
{
    size_t mn = (size_t)m * n, N = (size_t)T * mn;
#pragma omp parallel for schedule(static)
    for (int r = 0; r < T * m; ++r) {
        int s = r / m, y = r - s * m;
        size_t i = (size_t)r * n, dy = y > 0 ? (size_t)n : 0, dt = s > 0 ? mn : 0;
        primal_row(img + i, p + i, p + N + i, p + 2 * N + i, p + i - dy, p + 2 * N + i - dt, out + i,
                   y > 0 ? 1.0f : 0.0f, s > 0 ? wt : 0.0f, wt, n);
    }
}

/* the dual update of pixel x of a row from its differences */
static inline void update(float *restrict py, float *restrict px, float *restrict pt, int x,
                          float gy, float gx, float gt, float tau, float tau_over_weight)
{
    float scale = 1.0f / (1.0f + friendly_sqrt(gy * gy + gx * gx + gt * gt) * tau_over_weight);
    py[x] = (py[x] - tau * gy) * scale;
    px[x] = (px[x] - tau * gx) * scale;
    pt[x] = (pt[x] - tau * gt) * scale;
}

/* one row of p <- (p - tau grad(out)) / (1 + tau_over_weight |grad(out)|), in place: o the row of
 * out, o_below and o_next the row below and the row of the next sub-frame (or the row itself where
 * there is none: difference 0). As tv.cl: the right neighbour is read at x + 1 in every pixel and
 * its difference multiplied by xnext[x] (1, or 0 in the last column), so the loop has no condition;
 * the datacube's last row, where o[n] is past the end, takes its last pixel apart. */
static __attribute__((noinline)) void dual_row(
    const float *restrict o, const float *restrict o_below, const float *restrict o_next,
    float *restrict py, float *restrict px, float *restrict pt, const float *restrict xnext,
    float tau, float tau_over_weight, float wt, int n, int last)
{
    int plain = last ? n - 1 : n;
    for (int x = 0; x < plain; ++x)
        update(py, px, pt, x, o_below[x] - o[x], (o[x + 1] - o[x]) * xnext[x], wt * (o_next[x] - o[x]),
               tau, tau_over_weight);
    if (last)
        update(py, px, pt, n - 1, o_below[n - 1] - o[n - 1], 0.0f, wt * (o_next[n - 1] - o[n - 1]),
               tau, tau_over_weight);
}

void tv_dual(const float *out, float *p, const float *xnext, float tau, float tau_over_weight, float wt,
             int T, int m, int n)
{
    size_t mn = (size_t)m * n, N = (size_t)T * mn;
#pragma omp parallel for schedule(static)
    for (int r = 0; r < T * m; ++r) {
        int s = r / m, y = r - s * m;
        size_t i = (size_t)r * n, dy = y < m - 1 ? (size_t)n : 0, dt = s < T - 1 ? mn : 0;
        dual_row(out + i, out + i + dy, out + i + dt, p + i, p + N + i, p + 2 * N + i, xnext, tau, tau_over_weight,
                 wt, n, r == T * m - 1);
    }
}
