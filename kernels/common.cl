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

/* Weight of sub-frame j (counted from the window's first sub-frame, floor(start/dt))
 * for an exposure that starts `frac` sub-frames after that sub-frame's start and
 * lasts `len` sub-frames. All quantities are small numbers, so fp32 is accurate. */
inline real shutter_weight(int j, real frac, real len)
{
#if MASK_BINARY
    real jj = (real)j;
    return (jj >= frac && jj <= frac + len) ? (real)1 : (real)0;
#else
    /* plain comparisons: fmin/fmax are library calls that PoCL does not vectorise */
    real jj = (real)j, end = frac + len;
    real lo = jj > frac ? jj : frac;
    real hi = jj + (real)1 < end ? jj + (real)1 : end;
    return hi > lo ? hi - lo : (real)0;
#endif
}

/* sum_s w(s) f[s, p] over one channel's window: the forward model of one pixel.
 * Branch-free (clamped index, zero weight outside [0, T)) so CPU compilers keep
 * neighbouring work items in SIMD lanes. */
inline real window_dot(__global const real *f, int first, real frac, real len,
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
inline void window_scatter(__global real *f, int first, real frac, real len,
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

/* sqrt(v) for v >= 0 from the classic bit-level estimate of 1/sqrt refined by
 * Newton steps: plain arithmetic that CPU vectorisers (PoCL) keep in SIMD lanes,
 * where the library sqrt is called one lane at a time (measured 3-5x slower per
 * voxel in the TV kernel on PoCL 3.0). Accurate to a few ulp in float and double. */
inline real vector_friendly_sqrt(real v)
{
    float vf = (float)v;
    float y = as_float(0x5f375a86 - (as_int(vf) >> 1));
    float h = 0.5f * vf;
    y = y * (1.5f - h * y * y);
    y = y * (1.5f - h * y * y);
    y = y * (1.5f - h * y * y);
    real r = (real)y;
#if REAL_IS_DOUBLE
    real hd = (real)0.5 * v;
    r = r * ((real)1.5 - hd * r * r);
    r = r * ((real)1.5 - hd * r * r);
#endif
    return v * r;
}
