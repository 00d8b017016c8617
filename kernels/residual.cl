/* The ADMM's data residual in one launch: the forward H f of operator.cl and the weighted sum of
 * squares w (g - H f)^2 of reduce.cl, with no H f array in between. Needs common.cl; the host
 * defines TILE_W, TILE_R (the operator's blocks) and ACC.
 *
 * residual_partials: global size (>= ceil(n / TILE_W), >= ceil(m / TILE_R), sets * K), local size
 * (LX, LY, 1) (rsocl.device.launch.block_grid): one work item per block of TILE_R x TILE_W pixels
 * of one channel of one set. Each item adds its block's w (g - gain H f)^2 in acc_t (the difference
 * taken from H f rounded to real, as the forward kernel stores it), its work group adds the items'
 * sums in local memory in a fixed order, and one partial per work group goes to
 *   partials[slot * total + (kk * groups_y + group_y) * groups_x + group_x],  kk = set * K + k,
 * total = groups_x * groups_y * sets * K: the partials of set s are the s-th of sets equal runs of
 * each slot. Several slots hold the residuals of several iterations until the host reads them.
 * w may be 0 (no weights). Items outside the ROI add 0 and still reach the barrier. */
__kernel void residual_partials(__global const real *f_all, __global const real *g_all, __global const real *w_all,
                                __global const int *first, __global const real *frac,
                                __global const real *len, __global const real *gain,
                                __global acc_t *partials, __local acc_t *scratch, int slot,
                                int K, int T, int L, int m_, int n_)
{
    size_t m = (size_t)m_, n = (size_t)n_, mn = m * n;
    size_t kk = get_global_id(2), set = kk / (size_t)K, k = kk - set * (size_t)K;
    size_t x0 = get_global_id(0) * (size_t)TILE_W, y0 = get_global_id(1) * (size_t)TILE_R;
    acc_t sum = (acc_t)0;
    if (x0 < n && y0 < m) {
        __global const real *f = f_all + set * (size_t)T * mn;
        __global const real *g = g_all + set * (size_t)K * mn;
        __global const real *w = w_all ? w_all + set * (size_t)K * mn : 0;
        if (x0 + TILE_W <= n && y0 + TILE_R <= m) {
            size_t p0 = y0 * n + x0, q0 = k * mn + p0;
            realw acc[TILE_R];
            block_dot(f, first, frac, len[k], q0, T, L, mn, n, p0, acc);
            for (int r = 0; r < TILE_R; ++r) {
                real h[TILE_W];
                realw hr = gain[k] * acc[r];
                RSOCL_STORE(hr, h);
                size_t q = q0 + (size_t)r * n;
                for (int i = 0; i < TILE_W; ++i) {
                    acc_t d = (acc_t)g[q + i] - (acc_t)h[i];
                    sum += (w ? (acc_t)w[q + i] : (acc_t)1) * d * d;
                }
            }
        } else {
            for (size_t y = y0; y < y0 + TILE_R && y < m; ++y)
                for (size_t x = x0; x < x0 + TILE_W && x < n; ++x) {
                    size_t p = y * n + x, q = k * mn + p;
                    real h = gain[k] * window_dot(f, first[q], frac[q], len[k], T, L, mn, p);
                    acc_t d = (acc_t)g[q] - (acc_t)h;
                    sum += (w ? (acc_t)w[q] : (acc_t)1) * d * d;
                }
        }
    }
    size_t lx = get_local_size(0), lid = get_local_id(1) * lx + get_local_id(0);
    scratch[lid] = sum;
    barrier(CLK_LOCAL_MEM_FENCE);
    if (lid == 0) {
        size_t items = lx * get_local_size(1);
        acc_t total = (acc_t)0;
        for (size_t i = 0; i < items; ++i) total += scratch[i];
        size_t gx = get_num_groups(0), gy = get_num_groups(1);
        size_t per_slot = gx * gy * get_global_size(2);
        partials[(size_t)slot * per_slot + (kk * gy + get_group_id(1)) * gx + get_group_id(0)] = total;
    }
}
