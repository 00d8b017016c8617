/* The ADMM data step of docs/model.md. Needs common.cl and residual.cl (and jacobi.cl with
 * GAP_ONE_SIDED); the host defines NCH (channels), ACC, PROJECTION_EXACT 0|1, SATURATED 0|1 (samples
 * of residual weight 0 one-sided: one_sided_step) and GAP_ONE_SIDED 0|1 with GAP_RCOND (a set at
 * eta = 0 among them: gap_one_sided_step).
 *
 *   admm_dual      (one work item per voxel)  b <- b - (f - theta)  [sets with eta > 0]
 *                                             f  = v = theta + b
 *   admm_project   (one work item per block   r = g - H v,  z = (eta I + M)^-1 r  (exact)
 *                                             [SATURATED: samples with w = 0 one-sided, one_sided_step;
 *                                              at eta = 0 with GAP_ONE_SIDED, gap_one_sided_step]
 *                   of TILE_R x TILE_W px)                   | r / (eta + psi)    (paper, Eq. 15)
 *                                             f += Hᵀ z     (window loops only)
 *                                             [difference = 1: then u = f - b over the block's column]
 *                                             [slot >= 0 (global offset): first the residual of theta]
 *   admm_difference (one work item per voxel) u = f - b     (input of the denoiser)
 *   admm_blend      (one work item per voxel) theta = x0 + alpha (theta - x0)  (after the last iteration)
 *   admm_pull       (one work item per voxel) theta += w (x0 - theta), w per set and pixel  (the static fix)
 *
 * A batch of sets lies end to end (theta, b, f, u: [B][T][m][n]; g: [B][K][m][n]); every kernel
 * takes the whole batch in one launch, the set as the last grid dimension. Per set: eta, and
 * whether the dual is updated (eta > 0); the inverse blocks are shared, or one per set.
 * Voxel-parallel passes keep neighbouring work items on neighbouring addresses, which
 * CPU vectorisers need (a per-pixel loop over the whole column is slower: docs/implementation_notes.md).
 * The host may define PROJECT_LANES (default 1): admm_project's work items per block, which share the
 * loops over a block's whole column (the deferred primal step and u = f - b) and leave the window loops
 * to the first; every voxel's arithmetic is the same for any number of lanes.
 */
#ifndef PROJECTION_EXACT
#define PROJECTION_EXACT 1
#endif
#ifndef PROJECT_LANES
#define PROJECT_LANES 1
#endif
#ifndef DEFER_PRIMAL
#define DEFER_PRIMAL 0
#endif
#ifndef SATURATED
#define SATURATED 0
#endif
#ifndef GAP_ONE_SIDED
#define GAP_ONE_SIDED 0
#endif

/* admm_dual: global size (per-set voxels, sets) on an exact grid (rsocl.device.launch.batch_launches),
 * so no bounds test (it costs masked stores on PoCL). dual[set] = 1 where that set's eta > 0;
 * update_dual = 0 at the first iteration. */
__kernel void admm_dual(__global const real *theta, __global real *b, __global real *f,
                        __global const int *dual, int update_dual, int per_set)
{
    size_t set = get_global_id(1), i = set * (size_t)per_set + get_global_id(0);
    real th = theta[i];
    real bn = (update_dual && dual[set]) ? b[i] - (f[i] - th) : b[i];
    b[i] = bn;
    f[i] = th + bn;
}

#if SATURATED && PROJECTION_EXACT
/* Whether sample k of pixel p enters one-sided: weight 0 (saturated) in a row the blocks hold (B_kk != 0; a
 * row left out of them has weight 0 too). */
inline int one_sided_sample(__global const real *w, __global const real *inverse, size_t mn, size_t p, int k)
{
    return w[(size_t)k * mn + p] == (real)0 && inverse[((size_t)k * NCH + k) * mn + p] != (real)0;
}

/* The one-sided exact data step of one pixel p (docs/model.md, saturated pixels): z, where f += Hᵀ z, from
 * the residuals r = g - H v of its NCH samples; w[q] = 0 marks a saturated sample (its g a lower bound).
 * The per-pixel minimiser of the two-sided terms, the one-sided ones and eta |f - v|^2, by an active set
 * over the saturated samples: act[k] = 1 where sample k's term counts. A trial of act computes z for it and
 * switches the saturated samples that break the optimality tests; SEARCH_ACTIVE_SET runs trials until one
 * switches none: the switching first (at most 2 NCH + 2 rounds), then, where it cycles, every active set in
 * turn, the most active first (as the NumPy reference). (The paper's diagonal step needs none of this: its
 * terms separate, and the clamp r = max(r, 0) of project_pixel is its exact one-sided step.) */
#define SEARCH_ACTIVE_SET(TRIAL)                                                        \
    do {                                                                                \
        int done_ = 0, idx_[NCH], ns_ = 0;                                              \
        for (int round_ = 0; round_ < 2 * NCH + 2 && !done_; ++round_) done_ = !(TRIAL); \
        for (int k_ = 0; k_ < NCH; ++k_)                                                \
            if (sat[k_]) idx_[ns_++] = k_;                                              \
        for (int count_ = ns_; count_ >= 0 && !done_; --count_)                         \
            for (uint set_ = 0; set_ < (1u << ns_) && !done_; ++set_) {                 \
                if (popcount(set_) != (uint)count_) continue;                           \
                for (int i_ = 0; i_ < ns_; ++i_) act[idx_[i_]] = (int)((set_ >> i_) & 1u); \
                done_ = !(TRIAL);                                                       \
            }                                                                           \
    } while (0)

/* A trial with the blocks B = (eta I + M)^-1 alone (eta > 0): an inactive sample's pseudo-residual r'
 * makes its z zero (B_DD r'_D = -B_DA r_A, Gaussian elimination with partial pivoting), z = B r', and
 * (M z)_k = r'_k - eta z_k gives the tests: an active saturated sample needs z_k >= 0, an inactive one
 * r'_k >= r_k. Rows left out of the blocks (B_kk = 0) take no part. Returns 1 where it switched samples. */
inline int one_sided_trial(const real *r, const int *sat, int *act, __global const real *inverse, size_t mn,
                           size_t p, real *z)
{
#define BLOCK(k, l) inverse[((size_t)(k) * NCH + (size_t)(l)) * mn + p]
    int idx[NCH], nd = 0;
    real rp[NCH];
    for (int k = 0; k < NCH; ++k) {
        rp[k] = r[k];
        if (!act[k]) idx[nd++] = k;
    }
    if (nd > 0) {
        real a[NCH][NCH + 1];
        for (int i = 0; i < nd; ++i) {
            real s = (real)0;
            for (int l = 0; l < NCH; ++l)
                if (act[l]) s += BLOCK(idx[i], l) * r[l];
            for (int j = 0; j < nd; ++j) a[i][j] = BLOCK(idx[i], idx[j]);
            a[i][nd] = -s;
        }
        for (int c = 0; c < nd; ++c) {      /* forward elimination, partial pivoting */
            int piv = c;
            for (int i = c + 1; i < nd; ++i)
                if (fabs(a[i][c]) > fabs(a[piv][c])) piv = i;
            for (int j = 0; j <= nd; ++j) {
                real t = a[c][j];
                a[c][j] = a[piv][j];
                a[piv][j] = t;
            }
            if (a[c][c] == (real)0) continue;
            for (int i = c + 1; i < nd; ++i) {
                real factor = a[i][c] / a[c][c];
                for (int j = c; j <= nd; ++j) a[i][j] -= factor * a[c][j];
            }
        }
        for (int c = nd - 1; c >= 0; --c) { /* back substitution; a zero pivot leaves its unknown 0 */
            real s = a[c][nd];
            for (int j = c + 1; j < nd; ++j) s -= a[c][j] * a[j][nd];
            a[c][nd] = a[c][c] != (real)0 ? s / a[c][c] : (real)0;
        }
        for (int i = 0; i < nd; ++i) rp[idx[i]] = a[i][nd];
    }
    for (int k = 0; k < NCH; ++k) {
        real s = (real)0;
        for (int l = 0; l < NCH; ++l) s += BLOCK(k, l) * rp[l];
        z[k] = act[k] ? s : (real)0;
    }
    int changed = 0;
    for (int k = 0; k < NCH; ++k) {
        if (!sat[k]) continue;
        if (act[k] && z[k] < (real)0) {
            act[k] = 0;
            changed = 1;
        } else if (!act[k] && rp[k] < r[k]) {
            act[k] = 1;
            changed = 1;
        }
    }
    return changed;
#undef BLOCK
}

inline void one_sided_step(const real *r, __global const real *w, __global const real *inverse, size_t mn,
                           size_t p, real *z)
{
    int sat[NCH], act[NCH];
    for (int k = 0; k < NCH; ++k) {
        sat[k] = one_sided_sample(w, inverse, mn, p, k);
        act[k] = !sat[k] || r[k] > (real)0;
    }
    SEARCH_ACTIVE_SET(one_sided_trial(r, sat, act, inverse, mn, p, z));
}
#endif

#if SATURATED && PROJECTION_EXACT && GAP_ONE_SIDED
/* The one-sided exact data step of one pixel p at eta = 0 (GAP), the limit eta -> 0+ of one_sided_step
 * (docs/model.md, saturated pixels). There an active set's sub-block M_AA may be singular (cameras whose
 * windows weight only the same sub-frames), and the pseudo-inverse blocks no longer give M z = r' - eta z.
 * So each trial solves z_A = M_AA⁺ r_A from M itself (its block, from the windows as H uses them, in
 * pixel_gram; jacobi.cl's decomposition, GAP_RCOND of the run's dtype) and tests every sample's
 * residual after the step, s = r - M z: an active saturated sample needs s_k > 0, or s_k = 0 and z_k >= 0;
 * an inactive one s_k <= 0. "0" is within GAP_TOL of the largest |r| and the terms of (M z)_k (a nearly
 * singular sub-block's large z leaves its rounding in s), and that over M's largest diagonal for z_k.
 * Rows left out of the blocks (B_kk = 0) take no part. */
#if REAL_IS_DOUBLE
#define GAP_TOL 1e-9
#else
#define GAP_TOL 1e-4f
#endif

/* M's block of pixel p, gain_k gain_l sum_s w_k(s) w_l(s), rows and columns with keep = 0 zeroed. */
inline void pixel_gram(__global const int *first, __global const real *frac, __global const real *len,
                       __global const real *gain, const int *keep, int T, int L, size_t mn, size_t p, jac_t *m)
{
    for (int k = 0; k < NCH; ++k)
        for (int l = k; l < NCH; ++l) {
            size_t qk = (size_t)k * mn + p, ql = (size_t)l * mn + p;
            jac_t acc = (jac_t)0;
            for (int j = 0; j < L && keep[k] && keep[l]; ++j) {
                int s = first[qk] + j, jl = s - first[ql];
                if (s < 0 || jl < 0 || jl >= L) continue;
                if (s >= T) break;
                acc += (jac_t)shutter_weight(j, frac[qk], WINDOW_LENGTH(len, k)) *
                       (jac_t)shutter_weight(jl, frac[ql], WINDOW_LENGTH(len, l));
            }
            m[k * NCH + l] = m[l * NCH + k] = (jac_t)gain[k] * (jac_t)gain[l] * acc;
        }
}

/* A trial of act at eta = 0 (z in jac_t); returns 1 where it switched samples. */
inline int gap_trial(const real *r, const int *sat, int *act, const jac_t *m, jac_t top_r, jac_t top_m, jac_t *z)
{
    jac_t a[NCH * NCH], v[NCH * NCH], inv[NCH], y[NCH];
    for (int k = 0; k < NCH; ++k)
        for (int l = 0; l < NCH; ++l) a[k * NCH + l] = act[k] && act[l] ? m[k * NCH + l] : (jac_t)0;
    jacobi_eigen(a, v);
    pinv_scales(a, (jac_t)0, (jac_t)GAP_RCOND, inv);
    for (int j = 0; j < NCH; ++j) {
        jac_t s = (jac_t)0;
        for (int l = 0; l < NCH; ++l) s += act[l] ? v[l * NCH + j] * (jac_t)r[l] : (jac_t)0;
        y[j] = inv[j] * s;
    }
    for (int k = 0; k < NCH; ++k) {
        jac_t s = (jac_t)0;
        for (int j = 0; j < NCH; ++j) s += v[k * NCH + j] * y[j];
        z[k] = act[k] ? s : (jac_t)0;
    }
    int changed = 0;
    for (int k = 0; k < NCH; ++k) {
        if (!sat[k]) continue;
        jac_t after = (jac_t)r[k], size = (jac_t)0;
        for (int l = 0; l < NCH; ++l) {
            after -= m[k * NCH + l] * z[l];
            size += fabs(m[k * NCH + l] * z[l]);
        }
        jac_t tol = (jac_t)GAP_TOL * (top_r + size), tol_z = tol / top_m;
        if (act[k] && !(after > tol || (after >= -tol && z[k] >= -tol_z))) {
            act[k] = 0;
            changed = 1;
        } else if (!act[k] && after > tol) {
            act[k] = 1;
            changed = 1;
        }
    }
    return changed;
}

inline void gap_one_sided_step(const real *r, __global const real *w, __global const real *inverse,
                               __global const int *first, __global const real *frac, __global const real *len,
                               __global const real *gain, int T, int L, size_t mn, size_t p, real *z)
{
    int sat[NCH], act[NCH], keep[NCH];
    jac_t m[NCH * NCH], zz[NCH], top_r = (jac_t)0, top_m = (jac_t)JAC_TINY;
    for (int k = 0; k < NCH; ++k) {
        keep[k] = inverse[((size_t)k * NCH + k) * mn + p] != (real)0;
        sat[k] = one_sided_sample(w, inverse, mn, p, k);
        act[k] = keep[k] && (!sat[k] || r[k] > (real)0);
        top_r = fmax(top_r, fabs((jac_t)r[k]));
    }
    pixel_gram(first, frac, len, gain, keep, T, L, mn, p, m);
    for (int k = 0; k < NCH; ++k) top_m = fmax(top_m, m[k * NCH + k]);
    SEARCH_ACTIVE_SET(gap_trial(r, sat, act, m, top_r, top_m, zz));
    for (int k = 0; k < NCH; ++k) z[k] = (real)zz[k];
}
#endif

/* The projection of one pixel p (scalar path: the last, partial tile; with SATURATED, every pixel of a
 * block that holds a saturated sample). */
inline void project_pixel(__global real *f, __global const real *g, __global const real *w,
                          __global const int *first, __global const real *frac,
                          __global const real *len, __global const real *gain,
                          __global const real *inverse, real eta, int T, int L, size_t mn, size_t p)
{
    real r[NCH], z[NCH];
    for (int k = 0; k < NCH; ++k) {
        size_t q = (size_t)k * mn + p;
        r[k] = g[q] - gain[k] * window_dot(f, first[q], frac[q], WINDOW_LENGTH(len, k), T, L, mn, p);
#if SATURATED && !PROJECTION_EXACT
        if (w && w[q] == (real)0) r[k] = fmax(r[k], (real)0);     /* one-sided: the diagonal step's clamp */
#endif
    }
#if SATURATED && PROJECTION_EXACT
    if (w) {
#if GAP_ONE_SIDED
        int saturated = 0;                 /* a pixel without one takes the plain step, as in a run without any */
        for (int k = 0; k < NCH; ++k)
            saturated |= one_sided_sample(w, inverse, mn, p, k);
        if (eta == (real)0 && saturated)
            gap_one_sided_step(r, w, inverse, first, frac, len, gain, T, L, mn, p, z);
        else
#endif
            one_sided_step(r, w, inverse, mn, p, z);
    } else
#endif
    {
        for (int k = 0; k < NCH; ++k) {
            size_t q = (size_t)k * mn + p;
#if PROJECTION_EXACT
            real s = (real)0;
            for (int l = 0; l < NCH; ++l) s += inverse[((size_t)k * NCH + l) * mn + p] * r[l];
            z[k] = s;
#else
            real d = eta + inverse[q];          /* inverse holds psi here */
            z[k] = d > (real)0 ? r[k] / d : (real)0;
#endif
        }
    }
    for (int k = 0; k < NCH; ++k) {
        size_t q = (size_t)k * mn + p;
        window_scatter(f, first[q], frac[q], WINDOW_LENGTH(len, k), T, L, mn, p, gain[k] * z[k]);
    }
}

/* u = f - b over sub-frames lane, lane + PROJECT_LANES, ... < T of `rows` rows of `width` pixels from p0
 * (row length n). */
inline void column_difference(__global const real *f, __global const real *b, __global real *u,
                              int T, size_t mn, size_t n, size_t p0, size_t rows, size_t width, int lane)
{
    for (int s = lane; s < T; s += PROJECT_LANES)
        for (size_t r = 0; r < rows; ++r) {
            size_t i = (size_t)s * mn + p0 + r * n;
            if (width == TILE_W) {
                store_w(load_w(f + i) - load_w(b + i), u + i);
            } else {
                for (size_t x = 0; x < width; ++x) u[i + x] = f[i + x] - b[i + x];
            }
        }
}

/* u = f - b over the whole column of the block at (x0, y0) (the part inside the ROI for a block cut by
 * its edge), the sub-frames of lane `lane`: the admm_difference pass, while the block is in cache. */
static inline void block_difference(__global const real *f, __global const real *b, __global real *u, int T,
                                    size_t m, size_t n, size_t x0, size_t y0, int lane)
{
    size_t rows = m - y0 < TILE_R ? m - y0 : TILE_R, width = n - x0 < TILE_W ? n - x0 : TILE_W;
    column_difference(f, b, u, T, m * n, n, y0 * n + x0, rows, width, lane);
}

/* The projection of the block of TILE_R x TILE_W pixels at (x0, y0) inside the ROI of one set (f, g,
 * inverse: that set's); a block cut by the ROI's edge takes project_pixel. */
static inline void project_block(__global real *f, __global const real *g, __global const real *w,
                                 __global const int *first, __global const real *frac, __global const real *len,
                                 __global const real *gain, __global const real *inverse, real eta, int T, int L,
                                 size_t m, size_t n, size_t x0, size_t y0)
{
    size_t mn = m * n;
    if (x0 + TILE_W > n || y0 + TILE_R > m) {
        for (size_t y = y0; y < y0 + TILE_R && y < m; ++y)
            for (size_t x = x0; x < x0 + TILE_W && x < n; ++x)
                project_pixel(f, g, w, first, frac, len, gain, inverse, eta, T, L, mn, y * n + x);
        return;
    }
    size_t p0 = y0 * n + x0;
#if SATURATED
    if (w) {                           /* a block with a saturated sample: pixel by pixel, one-sided */
        int any = 0;
        for (int k = 0; k < NCH && !any; ++k)
            for (int r = 0; r < TILE_R; ++r)
                for (int x = 0; x < TILE_W; ++x) any |= w[(size_t)k * mn + p0 + (size_t)r * n + x] == (real)0;
        if (any) {
            for (int r = 0; r < TILE_R; ++r)
                for (int x = 0; x < TILE_W; ++x)
                    project_pixel(f, g, w, first, frac, len, gain, inverse, eta, T, L, mn, p0 + (size_t)r * n + x);
            return;
        }
    }
#endif
    realw res[NCH][TILE_R];            /* r = g - H v, per channel and row of the block */
    for (int k = 0; k < NCH; ++k) {
        size_t q0 = (size_t)k * mn + p0;
        realw hv[TILE_R];
        block_dot(f, first, frac, WINDOW_LENGTH(len, k), q0, T, L, mn, n, p0, hv);
        for (int r = 0; r < TILE_R; ++r) res[k][r] = load_w(g + q0 + (size_t)r * n) - gain[k] * hv[r];
    }
    for (int k = 0; k < NCH; ++k) {
        size_t q0 = (size_t)k * mn + p0;
        realw scale[TILE_R];
        for (int r = 0; r < TILE_R; ++r) {
            size_t pr = p0 + (size_t)r * n;
#if PROJECTION_EXACT
            realw z = (realw)(real)0;
            for (int l = 0; l < NCH; ++l) z += load_w(inverse + ((size_t)k * NCH + l) * mn + pr) * res[l][r];
#else
            realw d = eta + load_w(inverse + (size_t)k * mn + pr);     /* inverse holds psi here */
            realw z = d > (realw)(real)0 ? res[k][r] / d : (realw)(real)0;
#endif
            scale[r] = gain[k] * z;
        }
        block_scatter(f, first, frac, WINDOW_LENGTH(len, k), q0, T, L, mn, n, p0, scale);
    }
}

#if DEFER_PRIMAL
/* The plain TV's last primal step and the ADMM's dual update of the iteration before, for the pixels
 * of the block at (x0, y0) of set `set` (of `sets`) at the sub-frames of lane `lane`: what
 * tv_primal_update (tv.cl, in this program) computes at these voxels, from the denoiser's input u and
 * its dual p (tv.cl's layout): theta = u + d(p), then b = theta - u and f = theta + b where dual[set],
 * else f = theta. Each work item reads u and writes theta, b and f at its own voxels only; p is
 * read-only here. */
static void deferred_primal(__global const real *u_all, __global const real *p, __global const real *steps,
                            __global const int *dual, __global real *theta_all, __global real *b_all,
                            __global real *f_all, int T, size_t m, size_t n, size_t set, size_t sets,
                            size_t x0, size_t y0, int lane)
{
    size_t mn = m * n, N = sets * (size_t)T * mn;
    real wt = steps[3 * set + 2];
    int on = dual[set];
    for (size_t y = y0; y < y0 + TILE_R && y < m; ++y)
        for (size_t x = x0; x < x0 + TILE_W && x < n; ++x)
            for (int s = lane; s < T; s += PROJECT_LANES) {
                size_t i = ((set * (size_t)T + (size_t)s) * m + y) * n + x;
                real u = u_all[i], th = primal_at(u_all, p, wt, N, mn, n, i, (int)y, s);
                theta_all[i] = th;
                if (on) {
                    real bn = th - u;
                    b_all[i] = bn;
                    f_all[i] = th + bn;
                } else {
                    f_all[i] = th;
                }
            }
}
#endif

/* global size (>= ceil(n / TILE_W), >= ceil(m / TILE_R) x PROJECT_LANES, sets), local size (LX,
 * LY x PROJECT_LANES, 1): one work item per block of TILE_R x TILE_W pixels of one set (common.cl) and
 * lane; lane l of a group holds its rows l*LY .. (l+1)*LY - 1 along dimension 1, on the blocks of lane 0.
 * eta[set]; the inverse of set s starts at s * own_inverse * (its size per set). The residual slot is
 * the global offset along the sets, less one: the host enqueues with offset (0, 0, slot + 1), so no
 * argument changes from one iteration to the next. With slot >= 0 the launch first adds the residual
 * of the estimate theta (weights w, which may be 0) into that slot of the partials, as
 * residual_partials (residual.cl) on the same blocks and work groups (LX x LY) would (scratch: NCH x
 * LX x LY): the residual of the previous iteration's estimate, without a launch of its own. Compiled
 * with DEFER_PRIMAL (and tv.cl), it takes four more arguments, and with deferred = 1 first makes the
 * denoiser's last primal step and the dual update of the iteration before at its pixels
 * (deferred_primal): the TV's last launch. Where a block's lanes share a loop (PROJECT_LANES > 1), a
 * barrier orders the passes over its column: the lanes' deferred step before the first lane's window
 * loops, those before the lanes' u = f - b. */
__kernel void admm_project(__global real *f_all, __global const real *g_all,
                           __global const int *first, __global const real *frac,
                           __global const real *len, __global const real *gain,
                           __global const real *inverse_all, __global const real *etas, int own_inverse,
                           __global real *b_all, __global real *u_all, int difference,
                           __global real *theta_all, __global const real *w_all,
                           __global acc_t *partials, __local acc_t *scratch,
                           int T, int L, int m_, int n_
#if DEFER_PRIMAL
                           , __global const real *p_last, __global const real *tv_steps,
                           __global const int *dual_on, int deferred
#endif
                           )
{
    int slot = (int)get_global_offset(2) - 1;
    size_t rows = get_local_size(1) / PROJECT_LANES, lane = get_local_id(1) / rows;
    size_t m = (size_t)m_, n = (size_t)n_, mn = m * n, set = get_global_id(2) - get_global_offset(2);
    size_t x0 = get_global_id(0) * (size_t)TILE_W;
    size_t y0 = (get_group_id(1) * rows + get_local_id(1) % rows) * (size_t)TILE_R;
    size_t cube = (size_t)T * mn;
    int inside = x0 < n && y0 < m;
    __global const real *g = g_all + set * (size_t)NCH * mn;
    acc_t sums[NCH];
    for (int k = 0; k < NCH; ++k) sums[k] = (acc_t)0;
#if DEFER_PRIMAL
    if (inside && deferred)
        deferred_primal(u_all, p_last, tv_steps, dual_on, theta_all, b_all, f_all, T, m, n, set,
                        get_global_size(2), x0, y0, (int)lane);
#endif
#if PROJECT_LANES > 1
    barrier(CLK_GLOBAL_MEM_FENCE);
#endif
    if (inside && lane == 0) {
        if (slot >= 0) {
            __global const real *w = w_all ? w_all + set * (size_t)NCH * mn : 0;
            for (int k = 0; k < NCH; ++k)
                sums[k] = block_residual(theta_all + set * cube, g, w, first, frac, WINDOW_LENGTH(len, k), gain[k], (size_t)k, T,
                                         L, m, n, x0, y0);
        }
#if PROJECTION_EXACT
        __global const real *inverse = inverse_all + set * (size_t)own_inverse * NCH * NCH * mn;
#else
        __global const real *inverse = inverse_all + set * (size_t)own_inverse * NCH * mn;
#endif
        __global const real *w_set = w_all ? w_all + set * (size_t)NCH * mn : 0;
        project_block(f_all + set * cube, g, w_set, first, frac, len, gain, inverse, etas[set], T, L, m, n, x0, y0);
    }
#if PROJECT_LANES > 1
    barrier(CLK_GLOBAL_MEM_FENCE);
#endif
    if (inside && difference)
        block_difference(f_all + set * cube, b_all + set * cube, u_all + set * cube, T, m, n, x0, y0, (int)lane);
    group_partials(sums, NCH, set * NCH, get_global_size(2) * NCH, slot, rows, scratch, partials);
}

__kernel void admm_difference(__global const real *f, __global const real *b, __global real *u)
{
    size_t i = get_global_id(0);
    u[i] = f[i] - b[i];
}

/* The returned estimate moved back towards the start x0: theta = x0 + alpha (theta - x0). */
__kernel void admm_blend(__global real *theta, __global const real *x0, real alpha)
{
    size_t i = get_global_id(0);
    real start = x0[i];
    theta[i] = start + alpha * (theta[i] - start);
}

/* The estimate pulled towards the start x0 pixel by pixel (rsocl.solver.static): theta += w (x0 - theta),
 * w per set and pixel, [B][m][n]; mn pixels per sub-frame, per_set voxels per set. */
__kernel void admm_pull(__global real *theta, __global const real *x0, __global const real *w, long per_set, long mn)
{
    size_t i = get_global_id(0);
    real weight = w[(i / (size_t)per_set) * (size_t)mn + i % (size_t)mn];
    real now = theta[i];
    theta[i] = now + weight * (x0[i] - now);
}
