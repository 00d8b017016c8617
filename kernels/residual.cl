/* The ADMM's data residual: the forward H f of operator.cl and the weighted sum of squares
 * w (g - H f)^2 of reduce.cl, with no H f array in between. Needs common.cl; the host defines
 * TILE_W, TILE_R (the operator's blocks) and ACC.
 *
 * Two helpers serve residual_partials below and admm_project (admm.cl), which adds the residual of
 * the estimate it is given to its own launch:
 *   block_residual  one work item's sum over its block of one channel
 *   group_partials  the work group's sums in a fixed order, one partial per group and channel, to
 *     partials[slot * total + (c * groups_y + group_y) * groups_x + group_x],
 *   c = set * K + k the channel, total = groups_x * groups_y * (all channels of all sets): the
 *   partials of set s are the s-th of sets equal runs of each slot. Several slots hold the
 *   residuals of several iterations until the host reads them. Both kernels on the same blocks and
 *   work groups give the same partials, bit for bit. */

/* w (g - gain H f)^2 in acc_t over the block of TILE_R x TILE_W pixels at (x0, y0) of channel k (the
 * part inside the ROI for a block cut by its edge), the difference taken from H f rounded to real,
 * as the forward kernel stores it. f, g, w: one set's estimate, snapshots and weights (w may be 0). */
static inline acc_t block_residual(__global const real *f, __global const real *g, __global const real *w,
                                   __global const int *first, __global const real *frac, real2 len, real gain,
                                   size_t k, int T, int L, size_t m, size_t n, size_t x0, size_t y0)
{
    size_t mn = m * n;
    acc_t sum = (acc_t)0;
    if (x0 + TILE_W <= n && y0 + TILE_R <= m) {
        size_t p0 = y0 * n + x0, q0 = k * mn + p0;
        realw acc[TILE_R];
        block_dot(f, first, frac, len, q0, T, L, mn, n, p0, acc);
        for (int r = 0; r < TILE_R; ++r) {
            real h[TILE_W];
            realw hr = gain * acc[r];
            RSOCL_STORE(hr, h);
            size_t q = q0 + (size_t)r * n;
            for (int i = 0; i < TILE_W; ++i) {
                acc_t d = (acc_t)g[q + i] - (acc_t)h[i];
                sum += (w ? (acc_t)w[q + i] : (acc_t)1) * d * d;
            }
        }
        return sum;
    }
    for (size_t y = y0; y < y0 + TILE_R && y < m; ++y)
        for (size_t x = x0; x < x0 + TILE_W && x < n; ++x) {
            size_t p = y * n + x, q = k * mn + p;
            real h = gain * window_dot(f, first[q], frac[q], len, T, L, mn, p);
            acc_t d = (acc_t)g[q] - (acc_t)h;
            sum += (w ? (acc_t)w[q] : (acc_t)1) * d * d;
        }
    return sum;
}

/* The work group adds its items' sums of `count` channels (channel c0 + c's in sums[c]) in local
 * memory (scratch: count x the summed items) in item order, and writes one partial per channel
 * (layout above; `channels` is the launch's total); where slot < 0 it touches neither scratch nor
 * partials. The summed items are the group's first `rows` rows along dimension 1 (the others' sums
 * are not read: admm_project's lanes). Every item of the group must call it: its barrier is not in a
 * branch (a barrier in a branch, though every item takes it, crashes PoCL 3.0). */
static inline void group_partials(const acc_t *sums, int count, size_t c0, size_t channels, int slot, size_t rows,
                                  __local acc_t *scratch, __global acc_t *partials)
{
    size_t lx = get_local_size(0), items = lx * rows, lid = get_local_id(1) * lx + get_local_id(0);
    if (slot >= 0 && lid < items)
        for (int c = 0; c < count; ++c) scratch[(size_t)c * items + lid] = sums[c];
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0 && slot >= 0) {
        size_t gx = get_num_groups(0), gy = get_num_groups(1);
        size_t per_slot = gx * gy * channels;
        for (int c = 0; c < count; ++c) {
            acc_t total = (acc_t)0;
            for (size_t i = 0; i < items; ++i) total += scratch[(size_t)c * items + i];
            partials[(size_t)slot * per_slot + ((c0 + (size_t)c) * gy + get_group_id(1)) * gx + get_group_id(0)] = total;
        }
    }
}

/* residual_partials: global size (>= ceil(n / TILE_W), >= ceil(m / TILE_R), sets * K), local size
 * (LX, LY, 1) (rsocl.device.launch.block_grid): one work item per block of TILE_R x TILE_W pixels
 * of one channel of one set. Items outside the ROI add 0 and still reach the barrier. */
__kernel void residual_partials(__global const real *f_all, __global const real *g_all, __global const real *w_all,
                                __global const int *first, __global const real *frac,
                                __global const real *len, __global const real *gain,
                                __global acc_t *partials, __local acc_t *scratch, int slot,
                                int K, int T, int L, int m_, int n_)
{
    size_t m = (size_t)m_, n = (size_t)n_, mn = m * n;
    size_t kk = get_global_id(2), set = kk / (size_t)K, k = kk - set * (size_t)K;
    size_t x0 = get_global_id(0) * (size_t)TILE_W, y0 = get_global_id(1) * (size_t)TILE_R;
    acc_t sum[1] = {(acc_t)0};
    if (x0 < n && y0 < m)
        sum[0] = block_residual(f_all + set * (size_t)T * mn, g_all + set * (size_t)K * mn,
                                w_all ? w_all + set * (size_t)K * mn : 0, first, frac, WINDOW_LENGTH(len, k), gain[k], k, T, L,
                                m, n, x0, y0);
    group_partials(sum, 1, kk, get_global_size(2), slot, get_local_size(1), scratch, partials);
}
