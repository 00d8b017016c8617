/* Shared definitions for every rsocl program.
 *
 * The host prepends:
 *   #define REAL float|double     storage and arithmetic type of the datacube
 *   #define ACC  float|double     accumulator of reductions (double where the device has fp64)
 *   #define MASK_BINARY 0|1       shutter rule: exact overlap (0) or the paper's Eq. 4 (1)
 *   #define NCH <K>               number of channels (snapshots), when the program needs it
 * OpenCL C 1.2, no vendor extensions; cl_khr_fp64 only when REAL or ACC is double.
 */
#ifndef REAL
#error "REAL must be defined by the host"
#endif
#ifndef ACC
#define ACC REAL
#endif
#ifndef MASK_BINARY
#define MASK_BINARY 0
#endif
typedef REAL real;
typedef ACC acc_t;

#if REAL_IS_DOUBLE
typedef double2 real2;
#else
typedef float2 real2;
#endif

/* The window length of channel k from the operator's len buffer, (len[K][2]: whole sub-frames, then
 * the rest in [0, 1); rsocl.model.windows.kernel_windows). */
#define WINDOW_LENGTH(len, k) ((real2)((len)[2 * (k)], (len)[2 * (k) + 1]))

/* Weight of sub-frame j (counted from the window's first sub-frame, floor(start/dt)) for an exposure
 * that starts `frac` sub-frames after that sub-frame's start and lasts len.x + len.y sub-frames
 * (WINDOW_LENGTH). The end is taken relative to j as (len.x - j) + (frac + len.y): near the end both
 * terms are small, so a window of thousands of sub-frames keeps its last weight in fp32. Binary mask:
 * j in [frac, frac + len], with the frac that rsocl.model.windows.kernel_windows gives (the host's
 * first and last sub-frame, whatever the rounding). */
inline real shutter_weight(int j, real frac, real2 len)
{
    real jj = (real)j;
#if MASK_BINARY
    return (jj >= frac && jj - len.x <= frac + len.y) ? (real)1 : (real)0;
#else
    /* plain comparisons: fmin/fmax are library calls that PoCL does not vectorise */
    real lo = frac - jj > (real)0 ? frac - jj : (real)0;
    real to_end = (len.x - jj) + (frac + len.y);
    real hi = to_end < (real)1 ? to_end : (real)1;
    return hi > lo ? hi - lo : (real)0;
#endif
}

/* sum_s w(s) f[s, p] over one channel's window: the forward model of one pixel.
 * Branch-free (clamped index, zero weight outside [0, T)) so CPU compilers keep
 * neighbouring work items in SIMD lanes. */
inline real window_dot(__global const real *f, int first, real frac, real2 len,
                       int T, int L, size_t mn, size_t p)
{
    real acc = (real)0;
    for (int j = 0; j < L; ++j) {
        int s = first + j;
        int inside = (s >= 0) & (s < T);
        real w = inside ? shutter_weight(j, frac, len) : (real)0;
        acc += w * f[(size_t)clamp(s, 0, T - 1) * mn + p];
    }
    return acc;
}

/* f[s, p] += scale * w(s) over one channel's window: the adjoint of one pixel. */
inline void window_scatter(__global real *f, int first, real frac, real2 len,
                           int T, int L, size_t mn, size_t p, real scale)
{
    for (int j = 0; j < L; ++j) {
        int s = first + j;
        if (s >= T) break;
        if (s < 0) continue;
        real w = shutter_weight(j, frac, len);
        if (w != (real)0) f[(size_t)s * mn + p] += scale * w;
    }
}

/* ---- Tiles of TILE_W neighbouring pixels, in explicit vectors ----
 * A tile is TILE_W consecutive pixels p0 .. p0 + TILE_W - 1 (flat index) of one channel;
 * its loop runs over the union of their windows, [min first, max first + L) clipped to
 * [0, T): every load and store is one contiguous vector, where a pixel-per-work-item loop
 * makes per-lane gathers (docs/implementation_notes.md).
 * Lanes outside their own window get weight 0, so results equal the scalar loops above.
 * The host defines TILE_W (default: 32 bytes of reals; on devices that are not CPUs, one pixel:
 * rsocl.model.operator.GPU_BLOCK); pixels of blocks cut by the ROI's right or bottom edge take the
 * scalar loops. */
#ifndef TILE_W
#if REAL_IS_DOUBLE
#define TILE_W 4
#else
#define TILE_W 8
#endif
#endif
#define RSOCL_CAT_(a, b) a##b
#define RSOCL_CAT(a, b) RSOCL_CAT_(a, b)
#if TILE_W == 1
typedef real realw;                 /* one pixel per row of a block: scalars (GPUs) */
typedef int intw;
#define convert_realw RSOCL_CAT(convert_, REAL)
#else
typedef RSOCL_CAT(REAL, TILE_W) realw;
typedef RSOCL_CAT(int, TILE_W) intw;
#define convert_realw RSOCL_CAT(convert_, RSOCL_CAT(REAL, TILE_W))
#endif

/* Tile loads and stores at any alignment, written element by element: LLVM merges them
 * into one unaligned vector load or store. PoCL 3.0 calls vload8/vstore8 as library
 * functions (not inlined, with spills around each call), which slows the forward kernel
 * (docs/implementation_notes.md). */
#if TILE_W == 1
#define RSOCL_TILE(p) (p)[0]
#define RSOCL_STORE(v, p) ((p)[0] = (v))
#elif TILE_W == 2
#define RSOCL_TILE(p) (p)[0], (p)[1]
#define RSOCL_STORE(v, p) ((p)[0] = (v).s0, (p)[1] = (v).s1)
#elif TILE_W == 4
#define RSOCL_TILE(p) (p)[0], (p)[1], (p)[2], (p)[3]
#define RSOCL_STORE(v, p) ((p)[0] = (v).s0, (p)[1] = (v).s1, (p)[2] = (v).s2, (p)[3] = (v).s3)
#elif TILE_W == 8
#define RSOCL_TILE(p) (p)[0], (p)[1], (p)[2], (p)[3], (p)[4], (p)[5], (p)[6], (p)[7]
#define RSOCL_STORE(v, p) ((p)[0] = (v).s0, (p)[1] = (v).s1, (p)[2] = (v).s2, (p)[3] = (v).s3, \
                           (p)[4] = (v).s4, (p)[5] = (v).s5, (p)[6] = (v).s6, (p)[7] = (v).s7)
#elif TILE_W == 16
#define RSOCL_TILE(p) (p)[0], (p)[1], (p)[2], (p)[3], (p)[4], (p)[5], (p)[6], (p)[7], \
                      (p)[8], (p)[9], (p)[10], (p)[11], (p)[12], (p)[13], (p)[14], (p)[15]
#define RSOCL_STORE(v, p) ((p)[0] = (v).s0, (p)[1] = (v).s1, (p)[2] = (v).s2, (p)[3] = (v).s3, \
                           (p)[4] = (v).s4, (p)[5] = (v).s5, (p)[6] = (v).s6, (p)[7] = (v).s7, \
                           (p)[8] = (v).s8, (p)[9] = (v).s9, (p)[10] = (v).sa, (p)[11] = (v).sb, \
                           (p)[12] = (v).sc, (p)[13] = (v).sd, (p)[14] = (v).se, (p)[15] = (v).sf)
#else
#error "TILE_W must be 1, 2, 4, 8 or 16"
#endif
inline realw load_w(__global const real *p) { return (realw)(RSOCL_TILE(p)); }
inline intw load_iw(__global const int *p) { return (intw)(RSOCL_TILE(p)); }
inline void store_w(realw v, __global real *p) { RSOCL_STORE(v, p); }

/* Sub-frames [*lo, *hi) that cover the windows of the TILE_W pixels starting at first + q0. */
inline void tile_span(__global const int *first, size_t q0, int T, int L, int *lo, int *hi)
{
    int a = first[q0], b = a;
    for (int i = 1; i < TILE_W; ++i) {
        int v = first[q0 + i];
        a = v < a ? v : a;
        b = v > b ? v : b;
    }
    b += L;
    *lo = a > 0 ? a : 0;
    *hi = b < T ? b : T;
}

/* shutter_weight for TILE_W lanes at window positions j. It is 0 outside [0, L) with no
 * extra test: 0 <= frac <= 1, len.y < 1 and the end offset len.x + frac + len.y < L = ceil(max len) + 1
 * (rsocl.model.windows.kernel_windows). */
inline realw shutter_weight_v(realw j, realw frac, real2 len)
{
    realw zero = (realw)(real)0;
#if MASK_BINARY
    return ((j >= frac) & (j - len.x <= frac + len.y)) ? (realw)(real)1 : zero;
#else
    realw one = (realw)(real)1, lo = frac - j;
    lo = lo > zero ? lo : zero;
    realw to_end = ((realw)len.x - j) + (frac + len.y);
    realw hi = to_end < one ? to_end : one;
    return hi > lo ? hi - lo : zero;
#endif
}

/* ---- Blocks of TILE_R rows x TILE_W pixels ----
 * The forward, adjoint and ADMM projection kernels give a work item one block: the tiles
 * at flat pixel p0 + r*n, r = 0 .. TILE_R - 1 (n: row length), of the channel at q0 = k*mn + p0.
 * The sub-frame loop is outermost, so each step reads or writes TILE_R tiles of one plane,
 * neighbours in memory. TILE_R = 4 was the fastest of the row counts tried on PoCL
 * (docs/implementation_notes.md). Each row keeps its own window span, so it reads only its own tiles'
 * windows and sums in the same order as a tile alone. */
#ifndef TILE_R
#define TILE_R 4
#endif

/* The geometry of a block (channel at q0): per-row spans [los[r], his[r]) of its tiles' windows,
 * their union [*lo, *hi), and each row's window starts and fractions as vectors. */
inline void block_geometry(__global const int *first, __global const real *frac, size_t q0, size_t n,
                           int T, int L, int *los, int *his, int *lo, int *hi, realw *start, realw *fr)
{
    *lo = T;
    *hi = 0;
    for (int r = 0; r < TILE_R; ++r) {
        size_t q = q0 + (size_t)r * n;
        tile_span(first, q, T, L, &los[r], &his[r]);
        *lo = los[r] < *lo ? los[r] : *lo;
        *hi = his[r] > *hi ? his[r] : *hi;
        start[r] = convert_realw(load_iw(first + q));
        fr[r] = load_w(frac + q);
    }
}

/* acc[r] = sum_s w(s) f[s, p0 + r*n + i] over each lane's window: the forward of a block
 * (geometry of the channel at q0). */
inline void block_dot(__global const real *f, __global const int *first, __global const real *frac,
                      real2 len, size_t q0, int T, int L, size_t mn, size_t n, size_t p0, realw *acc)
{
    int los[TILE_R], his[TILE_R], lo, hi;
    realw start[TILE_R], fr[TILE_R];
    block_geometry(first, frac, q0, n, T, L, los, his, &lo, &hi, start, fr);
    for (int r = 0; r < TILE_R; ++r) acc[r] = (realw)(real)0;
    for (int s = lo; s < hi; ++s) {
        __global const real *fs = f + (size_t)s * mn + p0;
        for (int r = 0; r < TILE_R; ++r)
            if (s >= los[r] && s < his[r])
                acc[r] += shutter_weight_v((realw)(real)s - start[r], fr[r], len) * load_w(fs + (size_t)r * n);
    }
}

/* f[s, p0 + r*n + i] += scale[r].si * w(s) over each lane's window: the adjoint of a block. */
inline void block_scatter(__global real *f, __global const int *first, __global const real *frac,
                          real2 len, size_t q0, int T, int L, size_t mn, size_t n, size_t p0, const realw *scale)
{
    int los[TILE_R], his[TILE_R], lo, hi;
    realw start[TILE_R], fr[TILE_R];
    block_geometry(first, frac, q0, n, T, L, los, his, &lo, &hi, start, fr);
    for (int s = lo; s < hi; ++s) {
        __global real *fs = f + (size_t)s * mn + p0;
        for (int r = 0; r < TILE_R; ++r)
            if (s >= los[r] && s < his[r]) {
                __global real *dst = fs + (size_t)r * n;
                store_w(load_w(dst) + scale[r] * shutter_weight_v((realw)(real)s - start[r], fr[r], len), dst);
            }
    }
}

/* sqrt(v) for v >= 0 from the classic bit-level estimate of 1/sqrt refined by
 * Newton steps: plain arithmetic that CPU vectorisers (PoCL) keep in SIMD lanes,
 * where the library sqrt is called one lane at a time (docs/implementation_notes.md).
 * Accurate to a few ulp in float and double. In double the estimate is double's own
 * (64-bit constant), so it holds over double's whole range (data of 1e-18 or 1e19,
 * whose squares float cannot hold). */
inline real vector_friendly_sqrt(real v)
{
#if REAL_IS_DOUBLE
    real y = as_double(0x5fe6eb50c7b537a9L - (as_long(v) >> 1));
    real h = (real)0.5 * v;
    y = y * ((real)1.5 - h * y * y);
    y = y * ((real)1.5 - h * y * y);
    y = y * ((real)1.5 - h * y * y);
    y = y * ((real)1.5 - h * y * y);
    return v * y;
#else
    float y = as_float(0x5f375a86 - (as_int(v) >> 1));
    float h = 0.5f * v;
    y = y * (1.5f - h * y * y);
    y = y * (1.5f - h * y * y);
    y = y * (1.5f - h * y * y);
    return v * y;
#endif
}
