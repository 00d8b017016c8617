/* The exact projection's per-pixel inverse blocks (eta I + M)^-1 of docs/model.md, M = H Hᵀ's K×K
 * block of one pixel. Needs common.cl and cl_khr_fp64; the host defines NCH (channels, K) and
 * INV_REAL double (the type the decomposition runs in, which also enables cl_khr_fp64).
 *
 *   block_inverse (one work item per pixel and set)
 *       A = M with the rows and columns of the set's left-out snapshot pixels zeroed
 *       A = V diag(d) Vᵀ           (cyclic Jacobi rotations, in double)
 *       lambda_j = max(d_j, 0) + eta_set
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
typedef INV_REAL inv_t;

/* Sweeps of the cyclic Jacobi method at most: it converges quadratically, within 10 sweeps for the
 * blocks of a rig; the bound only ends a loop that rounding keeps from meeting the test. */
#define JACOBI_SWEEPS 64
/* double's machine epsilon */
#define INV_EPS 2.220446049250313e-16

/* One rotation in the plane (p, q) that zeroes a[p][q] (Rutishauser's form), applied to a and to the
 * eigenvector columns v. a and v are NCH x NCH, row-major. */
inline void jacobi_rotate(inv_t *a, inv_t *v, int p, int q)
{
    inv_t apq = a[p * NCH + q];
    if (apq == (inv_t)0) return;
    inv_t theta = (a[q * NCH + q] - a[p * NCH + p]) / ((inv_t)2 * apq);
    /* tangent of the smaller rotation angle; for a huge theta, 1 / (2 theta) without squaring it */
    inv_t t = fabs(theta) > (inv_t)1e150 ? (inv_t)0.5 / theta
                                          : copysign((inv_t)1, theta) / (fabs(theta) + sqrt(theta * theta + (inv_t)1));
    inv_t c = (inv_t)1 / sqrt(t * t + (inv_t)1), s = t * c;
    for (int r = 0; r < NCH; ++r) {
        if (r == p || r == q) continue;
        inv_t arp = a[r * NCH + p], arq = a[r * NCH + q];
        a[r * NCH + p] = a[p * NCH + r] = c * arp - s * arq;
        a[r * NCH + q] = a[q * NCH + r] = s * arp + c * arq;
    }
    a[p * NCH + p] -= t * apq;
    a[q * NCH + q] += t * apq;
    a[p * NCH + q] = a[q * NCH + p] = (inv_t)0;
    for (int r = 0; r < NCH; ++r) {
        inv_t vrp = v[r * NCH + p], vrq = v[r * NCH + q];
        v[r * NCH + p] = c * vrp - s * vrq;
        v[r * NCH + q] = s * vrp + c * vrq;
    }
}

__kernel void block_inverse(__global const real *gram, __global const real *valid, int has_valid,
                            int valid_stride, __global const inv_t *etas, inv_t rcond, __global real *out,
                            int mn_)
{
    size_t mn = (size_t)mn_, gid = get_global_id(0);
    size_t set = gid / mn, p = gid - set * mn;
    inv_t a[NCH * NCH], v[NCH * NCH], keep[NCH], inv[NCH];
    for (int k = 0; k < NCH; ++k)
        keep[k] = has_valid ? (inv_t)(valid[(set * (size_t)valid_stride + (size_t)k) * mn + p] != (real)0) : (inv_t)1;
    for (int k = 0; k < NCH; ++k)
        for (int l = 0; l < NCH; ++l) {
            a[k * NCH + l] = (inv_t)gram[((size_t)k * NCH + l) * mn + p] * keep[k] * keep[l];
            v[k * NCH + l] = k == l ? (inv_t)1 : (inv_t)0;
        }
    for (int sweep = 0; sweep < JACOBI_SWEEPS; ++sweep) {
        inv_t off = (inv_t)0, diag = (inv_t)0;
        for (int k = 0; k < NCH; ++k) {
            diag += a[k * NCH + k] * a[k * NCH + k];
            for (int l = k + 1; l < NCH; ++l) off += a[k * NCH + l] * a[k * NCH + l];
        }
        /* off-diagonal mass at the rounding of the diagonal: the eigenvalues are as exact as the block */
        if (off <= (inv_t)INV_EPS * (inv_t)INV_EPS * diag) break;
        for (int q = 1; q < NCH; ++q)
            for (int r = 0; r < q; ++r) jacobi_rotate(a, v, r, q);
    }
    inv_t eta = etas[set], top = (inv_t)0;
    for (int j = 0; j < NCH; ++j) {
        inv_t lambda = fmax(a[j * NCH + j], (inv_t)0) + eta;
        a[j * NCH + j] = lambda;
        top = fmax(top, lambda);
    }
    for (int j = 0; j < NCH; ++j) {
        inv_t lambda = a[j * NCH + j];
        inv[j] = lambda > rcond * top ? (inv_t)1 / lambda : (inv_t)0;
    }
    __global real *block = out + set * (size_t)NCH * NCH * mn;
    for (int k = 0; k < NCH; ++k)
        for (int l = 0; l < NCH; ++l) {
            inv_t acc = (inv_t)0;
            for (int j = 0; j < NCH; ++j) acc += v[k * NCH + j] * inv[j] * v[l * NCH + j];
            block[((size_t)k * NCH + l) * mn + p] = (real)(acc * keep[k] * keep[l]);
        }
}
