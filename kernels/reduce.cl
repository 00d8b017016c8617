/* Reductions and the bandwidth reference kernel. Needs common.cl. */

/* Partial sums of w (a - b)^2 (b may be 0: then of a^2; w may be 0: no weights), one per work group, with a
 * compensated per-item sum and a tree in local memory. The host adds the partials
 * in double precision. Launch with a power-of-two local size. A batch of sets is the second grid
 * dimension: set get_global_id(1) sums its own n_ elements (at set * n_) into its own row of
 * get_num_groups(0) partials. */
__kernel void sum_sq_diff(__global const real *a, __global const real *b, __global const real *w,
                          __global acc_t *partials, __local acc_t *scratch, int n_)
{
    size_t n = (size_t)n_, base = get_global_id(1) * n;
    size_t gid = get_global_id(0), lid = get_local_id(0), stride = get_global_size(0);
    acc_t sum = 0, comp = 0;
    for (size_t i = gid; i < n; i += stride) {
        size_t j = base + i;
        acc_t d = (acc_t)a[j] - (b ? (acc_t)b[j] : (acc_t)0);
        acc_t y = (w ? (acc_t)w[j] : (acc_t)1) * d * d - comp;
        acc_t t = sum + y;
        comp = (t - sum) - y;
        sum = t;
    }
    scratch[lid] = sum;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (size_t width = get_local_size(0) / 2; width > 0; width /= 2) {
        if (lid < width) scratch[lid] += scratch[lid + width];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    if (lid == 0) partials[get_global_id(1) * get_num_groups(0) + get_group_id(0)] = scratch[0];
}

/* dst = src, one work item per element on an exact grid (rsocl.device.launch.element_launches,
 * no bounds test): the bandwidth reference of the benchmarks. */
__kernel void copy(__global const real *src, __global real *dst)
{
    dst[get_global_id(0)] = src[get_global_id(0)];
}
