/* Orthonormal DCT-II / DCT-III (its inverse) in blocks, one axis per launch,
 * and soft thresholding of all but the DC coefficient of each block.
 * Layout x[T][m][n]. Needs common.cl.
 *
 * Along an axis of length N with block size b (1 <= b <= N; b = N is the whole
 * axis), the blocks start at multiples of b; the last one has its own length
 * L = N - start < b when b does not divide N. The host uploads a table holding,
 * for every length L that occurs, two L x L matrices of the orthonormal basis
 * C[k][j] = s_k cos(pi (2j + 1) k / (2L)), s_0 = sqrt(1/L), s_k = sqrt(2/L):
 * one for the forward transform (X[k] = sum_j C[k][j] x[j]) and one for the
 * inverse (x[j] = sum_k C[k][j] X[k]), both stored as tab[i * L + o] with i the
 * summation index and o the output index, so one kernel serves both directions
 * and consecutive outputs read consecutive table entries.
 *
 * Why a table and explicit vectors: on PoCL 3 (CPU) cos() is called one lane at a
 * time, so computing the basis in the kernel costs more than the table lookup; and a
 * one-output-per-work-item loop is not vectorised across work items (its trip
 * count L varies; measured: docs/implementation_notes.md). Every work item
 * produces CH = 64 bytes of consecutive outputs (16 floats or 8 doubles) as NV
 * vectors of VW, so the inner loop is vector multiply-adds on whole cache lines. */

#define DCT_CAT_(a, b) a##b
#define DCT_CAT(a, b) DCT_CAT_(a, b)
#if REAL_IS_DOUBLE
#define VW 4
#else
#define VW 8
#endif
#define NV 2
#define CH (VW * NV)
typedef DCT_CAT(REAL, VW) realv;
/* common.cl's element-by-element tile access: one vector load or store, where PoCL 3.0
 * calls vload8/vstore8 out of line. Its tiles have the default TILE_W, which is VW. */
#if VW != TILE_W
#error "dct.cl needs TILE_W == VW (the host must not set TILE_W for this program)"
#endif
#define VLOADW(i, p) load_w((p) + (size_t)(i) * VW)
#define VSTOREW(v, i, p) store_w((v), (p) + (size_t)(i) * VW)

/* One pass along a strided axis (axis 1: y, stride n; axis 2: t, stride m*n) in
 * blocks of b: the coefficient o of row/sub-frame i for CH consecutive x.
 * off_full / off_part: table offsets of the length-b and of the partial-block
 * matrix (the latter unused when b divides the axis).
 * global size (ceil(n / CH), m, T) */
__kernel void dct_strided(__global const real *src, __global real *dst, __global const real *tab,
                          int axis, int b, int off_full, int off_part, int T, int m, int n)
{
    int x0 = get_global_id(0) * CH, y = get_global_id(1), s = get_global_id(2);
    if (x0 >= n || y >= m || s >= T) return;
    int i, N;
    size_t stride;
    if (axis == 1) { i = y; N = m; stride = (size_t)n; }
    else { i = s; N = T; stride = (size_t)m * n; }
    size_t idx = ((size_t)s * m + y) * n + x0;
    int start = (i / b) * b;
    int L = min(b, N - start);
    int o = i - start;
    __global const real *t = tab + ((L == b) ? off_full : off_part) + o;
    __global const real *p = src + (idx - (size_t)o * stride);
    int w = min(CH, n - x0);
    if (w == CH) {
        realv acc[NV];
        for (int v = 0; v < NV; ++v) acc[v] = (realv)0;
        for (int j = 0; j < L; ++j) {
            real c = t[(size_t)j * L];
            __global const real *pj = p + (size_t)j * stride;
            for (int v = 0; v < NV; ++v) acc[v] += c * VLOADW(v, pj);
        }
        for (int v = 0; v < NV; ++v) VSTOREW(acc[v], v, dst + idx);
        return;
    }
    int k = 0;  /* right edge of the frame: single vectors, then scalars */
    for (; k + VW <= w; k += VW) {
        realv acc = (realv)0;
        for (int j = 0; j < L; ++j) acc += t[(size_t)j * L] * VLOADW(0, p + (size_t)j * stride + k);
        VSTOREW(acc, 0, dst + idx + k);
    }
    for (; k < w; ++k) {
        real acc = (real)0;
        for (int j = 0; j < L; ++j) acc += t[(size_t)j * L] * p[(size_t)j * stride + k];
        dst[idx + k] = acc;
    }
}

/* One pass along x (contiguous) in blocks of b: CH consecutive coefficients
 * o0 .. o0 + CH - 1 of one block of one row (fewer at the end of a block).
 * With G = ceil(b / CH) work items per block: global size (ceil(n / b) * G, m, T) */
__kernel void dct_x(__global const real *src, __global real *dst, __global const real *tab,
                    int b, int off_full, int off_part, int T, int m, int n)
{
    int g = get_global_id(0), y = get_global_id(1), s = get_global_id(2);
    int G = (b + CH - 1) / CH;
    int start = (g / G) * b, o0 = (g % G) * CH;
    if (start >= n || y >= m || s >= T) return;
    int L = min(b, n - start);
    if (o0 >= L) return;
    size_t row = ((size_t)s * m + y) * n + start;
    __global const real *t = tab + ((L == b) ? off_full : off_part) + o0;
    __global const real *p = src + row;
    __global real *d = dst + row + o0;
    int w = min(CH, L - o0);
    if (w == CH) {
        realv acc[NV];
        for (int v = 0; v < NV; ++v) acc[v] = (realv)0;
        for (int j = 0; j < L; ++j) {
            real pj = p[j];
            for (int v = 0; v < NV; ++v) acc[v] += VLOADW(v, t + (size_t)j * L) * pj;
        }
        for (int v = 0; v < NV; ++v) VSTOREW(acc[v], v, d);
        return;
    }
    int k = 0;  /* end of a block: single vectors, then scalars */
    for (; k + VW <= w; k += VW) {
        realv acc = (realv)0;
        for (int j = 0; j < L; ++j) acc += VLOADW(0, t + (size_t)j * L + k) * p[j];
        VSTOREW(acc, 0, d + k);
    }
    for (; k < w; ++k) {
        real acc = (real)0;
        for (int j = 0; j < L; ++j) acc += t[(size_t)j * L + k] * p[j];
        d[k] = acc;
    }
}

/* c <- sign(c) max(|c| - thresh, 0), in place, except the DC coefficient of each
 * block (the first element of the block along every axis; bt = 1 makes every
 * sub-frame its own block in time).  global size (n, m, T) */
__kernel void dct_soft_threshold(__global real *c, real thresh, int bt, int by, int bx,
                                 int T, int m, int n)
{
    int x = get_global_id(0), y = get_global_id(1), s = get_global_id(2);
    if (x >= n || y >= m || s >= T) return;
    size_t idx = ((size_t)s * m + y) * n + x;
    real v = c[idx];
    int dc = (s % bt == 0) && (y % by == 0) && (x % bx == 0);
    real shrunk = (v > thresh) ? v - thresh : ((v < -thresh) ? v + thresh : (real)0);
    c[idx] = dc ? v : shrunk;
}
