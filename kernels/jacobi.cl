/* The eigen-decomposition of a small symmetric NCH x NCH matrix by cyclic Jacobi rotations, and the
 * scales of the pseudo-inverse built from it: for inverse.cl (the exact projection's blocks, in double)
 * and admm.cl (the GAP step with saturated samples, in real). Needs common.cl and NCH; the type is
 * jac_t: INV_REAL where the host defines it (double), else real (JAC_EPS, JAC_TINY: its epsilon and
 * smallest normal number). Matrices are row-major, a[k * NCH + l].
 */
#ifdef INV_REAL
typedef INV_REAL jac_t;
#define JAC_EPS 2.220446049250313e-16
#define JAC_TINY 2.2250738585072014e-308
#elif REAL_IS_DOUBLE
typedef real jac_t;
#define JAC_EPS 2.220446049250313e-16
#define JAC_TINY 2.2250738585072014e-308
#else
typedef real jac_t;
#define JAC_EPS 1.1920928955078125e-7f
#define JAC_TINY 1.17549435e-38f
#endif

/* Sweeps of the cyclic Jacobi method at most: it converges quadratically, within 10 sweeps for the
 * blocks of a rig; the bound only ends a loop that rounding keeps from meeting the test. */
#define JACOBI_SWEEPS 64

/* One rotation in the plane (p, q) that zeroes a[p][q] (Rutishauser's form), applied to a and to the
 * eigenvector columns v. */
inline void jacobi_rotate(jac_t *a, jac_t *v, int p, int q)
{
    jac_t apq = a[p * NCH + q];
    if (apq == (jac_t)0) return;
    jac_t theta = (a[q * NCH + q] - a[p * NCH + p]) / ((jac_t)2 * apq);
    /* tangent of the smaller rotation angle; for a huge theta, 1 / (2 theta) without squaring it */
    jac_t t = fabs(theta) > (jac_t)1e18 ? (jac_t)0.5 / theta
                                         : copysign((jac_t)1, theta) / (fabs(theta) + sqrt(theta * theta + (jac_t)1));
    jac_t c = (jac_t)1 / sqrt(t * t + (jac_t)1), s = t * c;
    for (int r = 0; r < NCH; ++r) {
        if (r == p || r == q) continue;
        jac_t arp = a[r * NCH + p], arq = a[r * NCH + q];
        a[r * NCH + p] = a[p * NCH + r] = c * arp - s * arq;
        a[r * NCH + q] = a[q * NCH + r] = s * arp + c * arq;
    }
    a[p * NCH + p] -= t * apq;
    a[q * NCH + q] += t * apq;
    a[p * NCH + q] = a[q * NCH + p] = (jac_t)0;
    for (int r = 0; r < NCH; ++r) {
        jac_t vrp = v[r * NCH + p], vrq = v[r * NCH + q];
        v[r * NCH + p] = c * vrp - s * vrq;
        v[r * NCH + q] = s * vrp + c * vrq;
    }
}

/* a = V diag(d) Vᵀ: on return a is diagonal (d on its diagonal, to the rounding of the matrix) and v
 * holds the eigenvectors as columns. A row and column of zeros stays one, with its unit vector in v. */
inline void jacobi_eigen(jac_t *a, jac_t *v)
{
    for (int k = 0; k < NCH; ++k)
        for (int l = 0; l < NCH; ++l) v[k * NCH + l] = k == l ? (jac_t)1 : (jac_t)0;
    for (int sweep = 0; sweep < JACOBI_SWEEPS; ++sweep) {
        jac_t off = (jac_t)0, diag = (jac_t)0;
        for (int k = 0; k < NCH; ++k) {
            diag += a[k * NCH + k] * a[k * NCH + k];
            for (int l = k + 1; l < NCH; ++l) off += a[k * NCH + l] * a[k * NCH + l];
        }
        /* off-diagonal mass at the rounding of the diagonal: the eigenvalues are as exact as the block */
        if (off <= (jac_t)JAC_EPS * (jac_t)JAC_EPS * diag) break;
        for (int q = 1; q < NCH; ++q)
            for (int r = 0; r < q; ++r) jacobi_rotate(a, v, r, q);
    }
}

/* The pseudo-inverse's scales of (eta I + A) from jacobi_eigen's diagonal a: lambda_j = max(d_j, 0) + eta,
 * inv[j] = 1 / lambda_j where lambda_j > rcond max_j lambda_j, else 0 (rsocl.solver.inverse.RCOND).
 * a's diagonal is left holding lambda. */
inline void pinv_scales(jac_t *a, jac_t eta, jac_t rcond, jac_t *inv)
{
    jac_t top = (jac_t)0;
    for (int j = 0; j < NCH; ++j) {
        jac_t lambda = fmax(a[j * NCH + j], (jac_t)0) + eta;
        a[j * NCH + j] = lambda;
        top = fmax(top, lambda);
    }
    for (int j = 0; j < NCH; ++j) {
        jac_t lambda = a[j * NCH + j];
        inv[j] = lambda > rcond * top ? (jac_t)1 / lambda : (jac_t)0;
    }
}
