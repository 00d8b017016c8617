/* The exact projection's per-pixel inverse blocks (eta I + M)^-1 of docs/model.md, M = H Hᵀ's K×K
 * block of one pixel. Needs common.cl, jacobi.cl and cl_khr_fp64; the host defines NCH (channels, K)
 * and INV_REAL double (the type the decomposition runs in, which also enables cl_khr_fp64).
 *
 *   block_inverse (one work item per pixel and set)
 *       A = M with the rows and columns of the set's left-out snapshot pixels zeroed
 *       A = V diag(d) Vᵀ           (jacobi_eigen, in double)
 *       lambda_j = max(d_j, 0) + eta_set   (pinv_scales)
 *       out = V diag(keep_j / lambda_j) Vᵀ, keep_j = lambda_j > rcond max_j lambda_j,
 *             rows and columns of the left-out pixels zeroed
 *
 * The same pseudo-inverse as the host's rsocl.solver.inverse.block_inverse (NumPy's eigh): the
 * directions below rcond of the largest are dropped, so unsampled pixels and GAP (eta = 0) give a zero
 * or least-norm update, never a division by zero. Layouts: gram [K][K][mn]; valid [sets][K][mn] (1 where
 * the pixel enters the data term; valid_stride: K, or 0 when every set shares set 0's (or no valid at all
 * with has_valid = 0); out [count][K][K][mn]. Global size: count * mn on an exact grid.
 */
#ifndef INV_REAL
#error "INV_REAL must be defined by the host (double)"
#endif

__kernel void block_inverse(__global const real *gram, __global const real *valid, int has_valid,
                            int valid_stride, __global const jac_t *etas, jac_t rcond, __global real *out,
                            int mn_)
{
    size_t mn = (size_t)mn_, gid = get_global_id(0);
    size_t set = gid / mn, p = gid - set * mn;
    jac_t a[NCH * NCH], v[NCH * NCH], keep[NCH], inv[NCH];
    for (int k = 0; k < NCH; ++k)
        keep[k] = has_valid ? (jac_t)(valid[(set * (size_t)valid_stride + (size_t)k) * mn + p] != (real)0) : (jac_t)1;
    for (int k = 0; k < NCH; ++k)
        for (int l = 0; l < NCH; ++l) a[k * NCH + l] = (jac_t)gram[((size_t)k * NCH + l) * mn + p] * keep[k] * keep[l];
    jacobi_eigen(a, v);
    pinv_scales(a, etas[set], rcond, inv);
    __global real *block = out + set * (size_t)NCH * NCH * mn;
    for (int k = 0; k < NCH; ++k)
        for (int l = 0; l < NCH; ++l) {
            jac_t acc = (jac_t)0;
            for (int j = 0; j < NCH; ++j) acc += v[k * NCH + j] * inv[j] * v[l * NCH + j];
            block[((size_t)k * NCH + l) * mn + p] = (real)(acc * keep[k] * keep[l]);
        }
}
