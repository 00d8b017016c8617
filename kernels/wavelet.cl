/* Orthonormal discrete wavelet transform with periodization (PyWavelets'
 * mode="periodization"), one level along one axis of a sub-box, and the soft
 * threshold of the detail coefficients. Needs common.cl.
 *
 * The host defines the filter as compile-time constants:
 *   #define FLEN <F>                      filter length (even)
 *   #define DEC_LO {c0, c1, ..., c(F-1)}  decomposition low-pass (pywt's dec_lo)
 *   #define DEC_HI {...}                  decomposition high-pass (pywt's dec_hi)
 * The reconstruction filters are the reversed decomposition filters, so the
 * synthesis kernel is the transpose (= inverse, the transform is orthonormal)
 * of the analysis kernel and uses DEC_LO/DEC_HI too.
 *
 * Layout: the full array is a[T][m][n] (strides st = m*n, sy = n, 1). A pass
 * works on the sub-box [t0, t0 + ct) x [0, cy) x [0, cx) (the current
 * approximation band of a block of frames starting at t0, in the in-place
 * Mallat layout) along `axis` (0: t, 1: y, 2: x), whose sub-box length
 * N = (ct, cy, cx)[axis] is even and >= FLEN (the host plans the levels so).
 * Outside the sub-box nothing is read or written. Global size: the sub-box as
 * (cx, cy, ct), padded; kernels check bounds.
 *
 * Analysis (pywt's periodized dwt), for k in [0, N/2):
 *   approx[k] = sum_j DEC_LO[j] in[(2k + F/2 - j) mod N]   stored at k
 *   detail[k] = sum_j DEC_HI[j] in[(2k + F/2 - j) mod N]   stored at N/2 + k
 */
#ifndef FLEN
#error "FLEN, DEC_LO and DEC_HI must be defined by the host"
#endif

__constant real dec_lo[FLEN] = DEC_LO;
__constant real dec_hi[FLEN] = DEC_HI;

/* Index of the sub-box item (s, y, x) and its coordinate along `axis`. */
#define SUBBOX_ITEM                                                            \
    int x = get_global_id(0), y = get_global_id(1), s = get_global_id(2);      \
    if (x >= cx || y >= cy || s >= ct) return;                                 \
    size_t st = (size_t)m * n;                                                 \
    size_t stride = axis == 0 ? st : (axis == 1 ? (size_t)n : (size_t)1);      \
    int N = axis == 0 ? ct : (axis == 1 ? cy : cx);                            \
    int k = axis == 0 ? s : (axis == 1 ? y : x);                               \
    size_t line = (size_t)(t0 + s) * st + (size_t)y * n + x - (size_t)k * stride;

/* One analysis level along `axis`: dst = W src on the sub-box, one work item per
 * output coefficient. src and dst are different buffers. */
__kernel void dwt_analysis(__global const real *src, __global real *dst, int axis,
                           int m, int n, int t0, int ct, int cy, int cx)
{
    SUBBOX_ITEM
    int h = N >> 1;
    int detail = k >= h;
    int kk = detail ? k - h : k;
    /* i = (2 kk + F/2 - j) mod N, starting at j = 0 and stepping down */
    int i = 2 * kk + FLEN / 2;
    if (i >= N) i -= N;
    real acc = (real)0;
    if (detail) {
        for (int j = 0; j < FLEN; ++j) {
            acc += dec_hi[j] * src[line + (size_t)i * stride];
            i = (i == 0) ? N - 1 : i - 1;
        }
    } else {
        for (int j = 0; j < FLEN; ++j) {
            acc += dec_lo[j] * src[line + (size_t)i * stride];
            i = (i == 0) ? N - 1 : i - 1;
        }
    }
    dst[line + (size_t)k * stride] = acc;
}

/* One synthesis level along `axis` (the transpose of dwt_analysis): dst = W^T src
 * on the sub-box, one work item per output sample:
 *   out[p] = sum over j with (p + j - F/2) even of
 *            DEC_LO[j] approx[q] + DEC_HI[j] detail[q],  q = (p + j - F/2) / 2 mod N/2. */
__kernel void dwt_synthesis(__global const real *src, __global real *dst, int axis,
                            int m, int n, int t0, int ct, int cy, int cx)
{
    SUBBOX_ITEM
    int h = N >> 1;
    int j0 = (k + FLEN / 2) & 1;
    /* q for j = j0; N is even, so adding N keeps the parity and makes it non-negative */
    int q = ((k + j0 - FLEN / 2 + N) >> 1) % h;
    real acc = (real)0;
    for (int j = j0; j < FLEN; j += 2) {
        acc += dec_lo[j] * src[line + (size_t)q * stride] + dec_hi[j] * src[line + (size_t)(q + h) * stride];
        q = (q + 1 == h) ? 0 : q + 1;
    }
    dst[line + (size_t)k * stride] = acc;
}

/* Soft threshold, in place, of the coefficients of the block of frames
 * [t0, t0 + ct) outside its coarsest approximation box [t0, t0 + at) x [0, ay) x [0, ax):
 * c <- sign(c) max(|c| - thr, 0), written branch-free as c - clamp(c, -thr, thr)
 * (threshold 0 inside the box).  global size (n, m, ct) */
__kernel void soft_threshold(__global real *c, real thr, int m, int n, int t0, int ct, int at, int ay, int ax)
{
    int x = get_global_id(0), y = get_global_id(1), s = get_global_id(2);
    if (x >= n || y >= m || s >= ct) return;
    size_t i = ((size_t)(t0 + s) * m + y) * n + x;
    real t = (x < ax && y < ay && s < at) ? (real)0 : thr;
    real v = c[i];
    c[i] = v - clamp(v, -t, t);
}
