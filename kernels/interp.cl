/* interp3d on the device: each voxel the linear interpolation in time of its pixel's samples
 * (rsocl.model.interpolation.evaluate is the reference). Needs common.cl; the host defines NCH
 * (samples per pixel, the channels).
 *
 * Per set, the host sorts each pixel's samples by time, those at one time merged into their mean
 * (rsocl.model.interpolation.samples): values [NCH][m][n] and the distinct times split into a whole
 * sub-frame and a fraction, whole (int) and part (real) [NCH][m][n] (the time is whole + part, part in
 * [0, 1); entries beyond a pixel's count are not read), count[m][n] the distinct times a pixel keeps,
 * fallback the value of a pixel that keeps none, and per pair of neighbouring samples j, j + 1 the
 * inverse of their distance in time, inverse[NCH - 1][m][n], worked out in double precision (> 0
 * between kept samples, however close their times are in float). A batch of sets lies end to end;
 * the set is grid dimension 1.
 *
 * The distance of the sub-frame's centre first + s + 1/2 to a sample is (first + s - whole) +
 * (1/2 - part): an exact integer plus a fraction, so a float sample late in a long capture (T in the
 * millions) is as close to the reference as one at its start; a time held as one float would carry
 * its absolute rounding (1e-3 of a sub-frame at T = 1e4) into every weight.
 *
 * global size (solved sub-frames x m x n, sets) on an exact grid (rsocl.device.launch.batch_launches):
 * no bounds test. Work item i is sub-frame first + i / mn, pixel i % mn; neighbouring work items
 * take neighbouring pixels of one sub-frame, so reads and the write are contiguous.
 */
/* how far the centre of sub-frame q lies after the time whole + part, in sub-frames */
#define AFTER(q, whole, part) ((real)((q) - (whole)) + ((real)0.5 - (part)))

__kernel void interp3d(__global const int *whole, __global const real *part, __global const real *values,
                       __global const real *inverse, __global const int *count, __global const real *fallback,
                       __global real *out, int first, long per_set, long mn)
{
    size_t set = get_global_id(1), i = get_global_id(0);
    size_t s = i / (size_t)mn, p = i - s * (size_t)mn;
    size_t base = set * (size_t)NCH * (size_t)mn + p;
    __global const int *tw = whole + base;
    __global const real *tp = part + base, *v = values + base;
    int c = count[set * (size_t)mn + p], q = first + (int)s;   /* the sub-frame's centre: q + 1/2 */
    real value;
    if (c == 0) {
        value = fallback[set];
    } else if (c == 1) {
        value = v[0];
    } else {
        int hi = 0;                                      /* kept samples at or before the centre */
        for (int k = 0; k < c; ++k) hi += AFTER(q, tw[(size_t)k * mn], tp[(size_t)k * mn]) >= (real)0 ? 1 : 0;
        hi = clamp(hi, 1, c - 1);                        /* before the first two / after the last two: theirs */
        size_t h = (size_t)hi * mn, l = h - (size_t)mn;
        real inv = inverse[set * (size_t)(NCH > 1 ? NCH - 1 : 1) * (size_t)mn + l + p];
        real w = clamp(AFTER(q, tw[l], tp[l]) * inv, (real)0, (real)1);
        value = v[l] + w * (v[h] - v[l]);
    }
    out[set * (size_t)per_set + i] = value;
}
