/* interp3d on the device: each voxel the linear interpolation in time of its pixel's samples
 * (rsocl.model.interpolation.evaluate is the reference). Needs common.cl; the host defines NCH
 * (samples per pixel, the channels).
 *
 * Per set, the host sorts each pixel's samples by time, those at one time merged into their mean
 * (rsocl.model.interpolation.samples): times and values [NCH][m][n] (the distinct times, the rest
 * at +inf), count[m][n] the distinct times a pixel keeps, fallback the value of a pixel that keeps
 * none, and per pair of neighbouring samples j, j + 1 the inverse of their distance in time,
 * inverse[NCH - 1][m][n], worked out in double precision (> 0 between kept samples, however close
 * their times are in float). A batch of sets lies end to end; the set is grid dimension 1.
 *
 * global size (solved sub-frames x m x n, sets) on an exact grid (rsocl.device.launch.batch_launches):
 * no bounds test. Work item i is sub-frame first + i / mn, pixel i % mn; neighbouring work items
 * take neighbouring pixels of one sub-frame, so reads and the write are contiguous.
 */
__kernel void interp3d(__global const real *times, __global const real *values, __global const real *inverse,
                       __global const int *count, __global const real *fallback, __global real *out, int first,
                       long per_set, long mn)
{
    size_t set = get_global_id(1), i = get_global_id(0);
    size_t s = i / (size_t)mn, p = i - s * (size_t)mn;
    size_t base = set * (size_t)NCH * (size_t)mn + p;
    __global const real *t = times + base, *v = values + base;
    int c = count[set * (size_t)mn + p];
    real q = (real)(first + (int)s) + (real)0.5;         /* the sub-frame's centre */
    real value;
    if (c == 0) {
        value = fallback[set];
    } else if (c == 1) {
        value = v[0];
    } else {
        int hi = 0;                                      /* kept samples at or before q */
        for (int k = 0; k < NCH; ++k) hi += t[(size_t)k * mn] <= q ? 1 : 0;
        hi = clamp(hi, 1, c - 1);                        /* before the first two / after the last two: theirs */
        size_t h = (size_t)hi * mn, l = h - (size_t)mn;
        real inv = inverse[set * (size_t)(NCH > 1 ? NCH - 1 : 1) * (size_t)mn + l + p];
        real w = clamp((q - t[l]) * inv, (real)0, (real)1);
        value = v[l] + w * (v[h] - v[l]);
    }
    out[set * (size_t)per_set + i] = value;
}
