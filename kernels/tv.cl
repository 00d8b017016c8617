/* Chambolle's isotropic total-variation denoiser (the algorithm of
 * skimage.restoration.denoise_tv_chambolle), 2-D per sub-frame or 3-D with a
 * temporal weight. Layout x[B][T][m][n]: a batch of B sets end to end (B = 1: one set), each
 * denoised on its own (no temporal difference across a set boundary), with its own step
 * lengths steps[3 set] = tau, steps[3 set + 1] = tau / weight (both 0 for weight 0: p stays 0,
 * the output is the input) and its own temporal weight wt = steps[3 set + 2] (sets of one batch
 * may differ). The dual p holds NP = 2 (+1 if TEMPORAL) planes of N = B*T*m*n values: p[0] along
 * y, p[1] along x, p[2] along t.
 * The host defines TEMPORAL 0|1. One work item per voxel, two kernels per
 * iteration (primal then dual), each reading its neighbours once; the first iteration,
 * from p = 0, is one kernel (tv_dual_first). Or one kernel per iteration (tv_step) from one
 * copy of p into another, each work item computing the primal of its voxel and of the three
 * next ones itself; or one per two iterations (tv_step2), each work item also stepping the dual
 * of the voxels around it; with these two, the first two iterations from p = 0 may be one kernel
 * (tv_first2). Needs common.cl. */
#ifndef TEMPORAL
#define TEMPORAL 1
#endif

/* Launch with an exact grid (rsocl.device.launch.voxel_launches over (B*T, m, n): the set and its
 * sub-frame are get_global_id(2) / T and % T, uniform in a work group): there is no bounds test, and
 * neighbours across an edge are read at a clamped index and discarded with a select,
 * because PoCL turns a per-work-item `if` into masked loads and stores (docs/implementation_notes.md).
 * Selects on y and s are uniform in a work group (a row); along x, where a per-lane
 * select costs PoCL a vector of 64-bit indices per row of 8 voxels, the kernels use:
 *  - xnext[x] = 1 for x < n - 1, else 0 (n values): the dual multiplies the x difference
 *    by it, a plain vector load and a multiply (docs/implementation_notes.md);
 *  - the invariant p[1] = 0 at x = n - 1 (the x difference there is 0 from p = 0 on, so
 *    every step keeps it 0): the primal reads p[1] at i - 1 with no select at x = 0. */

typedef struct { real y, x, t; } dual3;   /* the three components of p at one voxel (t: 0 in 2-D) */

/* out = img + d(p) at voxel i (row y, sub-frame s of its set), d the (negative) divergence of p, from
 * the components d reads: q = p at i, qy = p[0] at i - n (used where y > 0), qx = p[1] at i - 1,
 * qt = p[2] at i - mn (used where s > 0). */
static inline real primal_of(__global const real *img, size_t i, dual3 q, real qy, real qx, real qt, real wt,
                             int y, int s)
{
    real d = -(q.y + q.x);
    d += y > 0 ? qy : (real)0;
    d += qx;
#if TEMPORAL
    d -= wt * q.t;
    d += s > 0 ? wt * qt : (real)0;
#endif
    return img[i] + d;
}

/* primal_of with the components read from p. The x - 1 neighbour is read at i - 1 always: at x = 0
 * that is p[1] at x = n - 1 of the row before, which is 0 (see above), or p[0] at the very last voxel
 * (y = m - 1: 0 too) when i = 0. */
static inline real primal_at(__global const real *img, __global const real *p, real wt, size_t N, size_t mn,
                             size_t n, size_t i, int y, int s)
{
    dual3 q;                                    /* read in primal_of's order */
    q.y = p[i];
    q.x = p[N + i];
    real qy = p[y > 0 ? i - n : i], qx = p[N + i - 1];
#if TEMPORAL
    real qt = p[2 * N + (s > 0 ? i - mn : i)];
    q.t = p[2 * N + i];
#else
    real qt = (real)0;
    q.t = (real)0;
#endif
    return primal_of(img, i, q, qy, qx, qt, wt, y, s);
}

/* out = img + d(p).  global size (n, m, B*T) */
__kernel void tv_primal(__global const real *img, __global const real *p, __global real *out,
                        __global const real *steps, int T, int m, int n, int sets)
{
    int x = get_global_id(0), y = get_global_id(1), st = get_global_id(2);
    int set = st / T;
    size_t N = (size_t)sets * T * m * n, mn = (size_t)m * n;
    size_t i = ((size_t)st * m + y) * n + x;
    out[i] = primal_at(img, p, steps[3 * set + 2], N, mn, (size_t)n, i, y, st - set * T);
}

/* tv_primal, and then the ADMM's next dual update from the denoiser's input img = u and output
 * theta = out: b = theta - u and f = theta + b in the sets where dual[set], else f = theta (the last
 * primal step of a call made inside the ADMM).  global size (n, m, B*T) */
__kernel void tv_primal_update(__global const real *img, __global const real *p, __global real *out,
                               __global const real *steps, int T, int m, int n, int sets,
                               __global real *bvar, __global real *fvar, __global const int *dual)
{
    int x = get_global_id(0), y = get_global_id(1), st = get_global_id(2);
    int set = st / T, s = st - set * T;
    size_t N = (size_t)sets * T * m * n, mn = (size_t)m * n;
    size_t i = ((size_t)st * m + y) * n + x;
    real u = img[i], th = primal_at(img, p, steps[3 * set + 2], N, mn, (size_t)n, i, y, s);
    out[i] = th;
    if (dual[set]) {                        /* uniform in a work group (one sub-frame of one set) */
        real bn = th - u;
        bvar[i] = bn;
        fvar[i] = th + bn;
    } else {
        fvar[i] = th;
    }
}

/* p <- (p - tau grad(out)) / (1 + tau/weight |grad(out)|) at voxel (x, y, s) of its set; with
 * from_zero, p is taken as 0 and not read (the first iteration, where out = img).
 * At the far edges the clamped neighbour is the voxel itself: the difference is 0. */
static inline void dual_update(__global const real *out, __global real *p, __global const real *xnext,
                               __global const real *steps, int T, int m, int n, int sets, int from_zero)
{
    int x = get_global_id(0), y = get_global_id(1), st = get_global_id(2);
    int set = st / T, s = st - set * T;
    size_t N = (size_t)sets * T * m * n, mn = (size_t)m * n;
    size_t i = ((size_t)st * m + y) * n + x;
    real tau = steps[3 * set], tau_over_weight = steps[3 * set + 1];
    real o = out[i];
    real gy = out[y < m - 1 ? i + n : i] - o;
    /* out[i + 1] is in the buffer except for the last voxel: read it plainly (a vector
     * load) in every row but the last one, where the row is uniform. */
    real right = (y < m - 1 || st < sets * T - 1) ? out[i + 1] : out[x < n - 1 ? i + 1 : i];
    real gx = (right - o) * xnext[x];            /* exactly 0 at x = n - 1 */
    real norm2 = gy * gy + gx * gx;
#if TEMPORAL
    real gt = steps[3 * set + 2] * (out[s < T - 1 ? i + mn : i] - o);
    norm2 += gt * gt;
#endif
    real scale = (real)1 / ((real)1 + vector_friendly_sqrt(norm2) * tau_over_weight);
    p[i] = ((from_zero ? (real)0 : p[i]) - tau * gy) * scale;
    p[N + i] = ((from_zero ? (real)0 : p[N + i]) - tau * gx) * scale;
#if TEMPORAL
    p[2 * N + i] = ((from_zero ? (real)0 : p[2 * N + i]) - tau * gt) * scale;
#endif
}

/* The dual step, in place.  global size (n, m, B*T) */
__kernel void tv_dual(__global const real *out, __global real *p, __global const real *xnext,
                      __global const real *steps, int T, int m, int n, int sets)
{
    dual_update(out, p, xnext, steps, T, m, n, sets, 0);
}

/* The first dual step from p = 0, where out = img + d(0) = img: it reads img and only
 * writes p (no fill of p, no first primal step).  global size (n, m, B*T) */
__kernel void tv_dual_first(__global const real *img, __global real *p, __global const real *xnext,
                            __global const real *steps, int T, int m, int n, int sets)
{
    dual_update(img, p, xnext, steps, T, m, n, sets, 1);
}

/* STEP_AT(q, X, Y, ST, S): q (a dual3) = the dual step of one Chambolle iteration at voxel (X, Y) of
 * sub-frame S of its set (ST = set * T + S the global sub-frame): the primal out = img + d(p_in) at
 * this voxel and at its next ones along y, x and t (computed here, not read), then the three
 * components of p_in stepped from the gradient of out. At the far edges the next voxel is this one
 * (the difference is 0); along x the next voxel is read in the next row and its difference
 * multiplied by xnext, as tv_dual does, and the primal at i + 1 reads p[1] at i, which is 0 at
 * x = n - 1. The arithmetic of tv_primal and tv_dual, in their order (in 2-D the t terms add 0).
 * It reads the caller's img, p_in, xnext, tau, tow (tau / weight), wt, T, m, n, sets, N, mn and nn.
 * A macro, not a function, so that every compiler inlines it: PoCL 3.0 left a function of this
 * size a call where tv_step2 takes it thirteen times, and tv_step2 ran 1.8 times slower. */
#define STEP_AT(q, X, Y, ST, S)                                                                           \
    do {                                                                                                  \
        int sx_ = (X), sy_ = (Y), sst_ = (ST), ss_ = (S);                                                 \
        size_t si_ = ((size_t)sst_ * m + sy_) * nn + sx_;                                                  \
        real so_ = primal_at(img, p_in, wt, N, mn, nn, si_, sy_, ss_);                                    \
        int syn_ = sy_ < m - 1 ? sy_ + 1 : sy_;                          /* uniform in a row */           \
        real sgy_ = primal_at(img, p_in, wt, N, mn, nn, si_ + (size_t)(syn_ - sy_) * nn, syn_, ss_) - so_; \
        size_t six_ = (sy_ < m - 1 || sst_ < sets * T - 1) ? si_ + 1 : (sx_ < n - 1 ? si_ + 1 : si_);     \
        real sgx_ = (primal_at(img, p_in, wt, N, mn, nn, six_, sy_, ss_) - so_) * xnext[sx_];             \
        int ssn_ = ss_ < T - 1 ? ss_ + 1 : ss_;                          /* uniform in a work group */    \
        real sgt_ = TEMPORAL                                                                              \
            ? wt * (primal_at(img, p_in, wt, N, mn, nn, si_ + (size_t)(ssn_ - ss_) * mn, sy_, ssn_) - so_) \
            : (real)0;                                                                                    \
        real snorm2_ = sgy_ * sgy_ + sgx_ * sgx_;                                                         \
        snorm2_ += sgt_ * sgt_;                                                                           \
        real sscale_ = (real)1 / ((real)1 + vector_friendly_sqrt(snorm2_) * tow);                         \
        (q).y = (p_in[si_] - tau * sgy_) * sscale_;                                                       \
        (q).x = (p_in[N + si_] - tau * sgx_) * sscale_;                                                   \
        (q).t = TEMPORAL ? (p_in[2 * N + si_] - tau * sgt_) * sscale_ : (real)0;                          \
    } while (0)

/* One whole Chambolle iteration per launch: STEP_AT from one copy of p into another (ping-pong): no
 * work item reads what another writes, so one launch per iteration where tv_primal and tv_dual take
 * two.  global size (n, m, B*T) */
__kernel void tv_step(__global const real *img, __global const real *p_in, __global real *p_out,
                      __global const real *xnext, __global const real *steps, int T, int m, int n, int sets)
{
    int x = get_global_id(0), y = get_global_id(1), st = get_global_id(2);
    int set = st / T, s = st - set * T;
    size_t N = (size_t)sets * T * m * n, mn = (size_t)m * n, nn = (size_t)n;
    size_t i = ((size_t)st * m + y) * n + x;
    real tau = steps[3 * set], tow = steps[3 * set + 1], wt = steps[3 * set + 2];
    dual3 q;
    STEP_AT(q, x, y, st, s);
    p_out[i] = q.y;
    p_out[N + i] = q.x;
#if TEMPORAL
    p_out[2 * N + i] = q.t;
#endif
}

/* FIRST_AT(q, X, Y, ST, S): q (a dual3) = the first dual step from p = 0 at voxel (X, Y) of sub-frame S
 * of its set (ST = set * T + S): tv_dual_first's arithmetic at that voxel, where the primal is the input
 * img itself. It reads the caller's img, xnext, tau, tow, wt, T, m, n, sets, mn and nn. */
#define FIRST_AT(q, X, Y, ST, S)                                                                          \
    do {                                                                                                  \
        int fx_ = (X), fy_ = (Y), fst_ = (ST), fs_ = (S);                                                 \
        size_t fi_ = ((size_t)fst_ * m + fy_) * nn + fx_;                                                  \
        real fo_ = img[fi_];                                                                              \
        real fgy_ = img[fy_ < m - 1 ? fi_ + nn : fi_] - fo_;                                              \
        real fright_ = (fy_ < m - 1 || fst_ < sets * T - 1) ? img[fi_ + 1] : img[fx_ < n - 1 ? fi_ + 1 : fi_]; \
        real fgx_ = (fright_ - fo_) * xnext[fx_];                                                         \
        real fgt_ = TEMPORAL ? wt * (img[fs_ < T - 1 ? fi_ + mn : fi_] - fo_) : (real)0;                   \
        real fnorm2_ = fgy_ * fgy_ + fgx_ * fgx_;                                                         \
        fnorm2_ += fgt_ * fgt_;                                                                           \
        real fscale_ = (real)1 / ((real)1 + vector_friendly_sqrt(fnorm2_) * tow);                         \
        (q).y = ((real)0 - tau * fgy_) * fscale_;                                                         \
        (q).x = ((real)0 - tau * fgx_) * fscale_;                                                         \
        (q).t = TEMPORAL ? ((real)0 - tau * fgt_) * fscale_ : (real)0;                                    \
    } while (0)

/* TWO_STEPS(FIRST): the body of a launch that makes two whole Chambolle iterations: FIRST (STEP_AT, or
 * FIRST_AT from p = 0) at this work item's voxel and at the twelve around it that the second
 * iteration's primals read (at an edge the neighbour is clamped to a voxel of the set and its value
 * discarded by a select, so every work item does the same work), then the second step at its voxel,
 * written to p_out. Declares the work item's indices itself; reads the kernel's arguments. */
#if TEMPORAL
#define TWO_STEPS_T(FIRST)                                                                                \
    int sp = s > 0 ? s - 1 : s, sn = s < T - 1 ? s + 1 : s; /* and at the next one along t (f) */         \
    dual3 ct, ut, rt, f, fy, fx;                                                                          \
    FIRST(ct, x, y, st + sp - s, sp);                                                                     \
    FIRST(ut, x, yn, st + sp - s, sp);                                                                    \
    FIRST(rt, xn, y, st + sp - s, sp);                                                                    \
    FIRST(f, x, y, st + sn - s, sn);                                                                      \
    FIRST(fy, x, yp, st + sn - s, sn);                                                                    \
    FIRST(fx, xp, y, st + sn - s, sn);
#define TWO_STEPS_GT                                                                                      \
    real gt = s < T - 1 ? wt * (primal_of(img, i + mn, f, fy.y, x > 0 ? fx.x : zero, c.t, wt, y, s + 1) - o) : zero; \
    norm2 += gt * gt;
#define TWO_STEPS_PT p_out[2 * N + i] = (c.t - tau * gt) * scale;
#else
#define TWO_STEPS_T(FIRST) dual3 ct = c, ut = c, rt = c; /* not read in 2-D */
#define TWO_STEPS_GT
#define TWO_STEPS_PT
#endif
#define TWO_STEPS(FIRST)                                                                                  \
    int x = get_global_id(0), y = get_global_id(1), st = get_global_id(2);                                \
    int set = st / T, s = st - set * T;                                                                   \
    size_t N = (size_t)sets * T * m * n, mn = (size_t)m * n, nn = (size_t)n;                              \
    size_t i = ((size_t)st * m + y) * n + x;                                                              \
    real tau = steps[3 * set], tow = steps[3 * set + 1], wt = steps[3 * set + 2], zero = (real)0;         \
    int yp = y > 0 ? y - 1 : y, yn = y < m - 1 ? y + 1 : y; /* clamped neighbours */                      \
    int xp = x > 0 ? x - 1 : x, xn = x < n - 1 ? x + 1 : x;                                               \
    /* the first step at this voxel (c), at the next ones along y (u) and x (r), and at the previous      \
     * ones each of these reads (suffix: along which axis) */                                             \
    dual3 c, cy, cx, u, ux, r, ry;                                                                        \
    FIRST(c, x, y, st, s);                                                                                \
    FIRST(cy, x, yp, st, s);                                                                              \
    FIRST(cx, xp, y, st, s);                                                                              \
    FIRST(u, x, yn, st, s);                                                                               \
    FIRST(ux, xp, yn, st, s);                                                                             \
    FIRST(r, xn, y, st, s);                                                                               \
    FIRST(ry, xn, yp, st, s);                                                                             \
    TWO_STEPS_T(FIRST)                                                                                    \
    /* the primals of the stepped dual at this voxel and at its next ones (at x = 0 the p[1] of the row   \
     * before, which primal_at reads, is 0: passed as zero) */                                            \
    real o = primal_of(img, i, c, cy.y, x > 0 ? cx.x : zero, ct.t, wt, y, s);                             \
    real gy = y < m - 1 ? primal_of(img, i + nn, u, c.y, x > 0 ? ux.x : zero, ut.t, wt, y + 1, s) - o : zero; \
    real gx = x < n - 1 ? (primal_of(img, i + 1, r, ry.y, c.x, rt.t, wt, y, s) - o) * xnext[x] : zero;    \
    real norm2 = gy * gy + gx * gx;                                                                       \
    TWO_STEPS_GT                                                                                          \
    real scale = (real)1 / ((real)1 + vector_friendly_sqrt(norm2) * tow);                                 \
    p_out[i] = (c.y - tau * gy) * scale;                                                                  \
    p_out[N + i] = (c.x - tau * gx) * scale;                                                              \
    TWO_STEPS_PT

/* Two whole Chambolle iterations per launch, from one copy of p into another (TWO_STEPS(STEP_AT)). The
 * same arithmetic as two tv_step launches (values equal; a zero's sign may differ). About 13 times
 * tv_step's arithmetic for half its launches: for devices where a launch costs more than that.
 * global size (n, m, B*T) */
__kernel void tv_step2(__global const real *img, __global const real *p_in, __global real *p_out,
                       __global const real *xnext, __global const real *steps, int T, int m, int n, int sets)
{
    TWO_STEPS(STEP_AT)
}

/* The first two Chambolle iterations from p = 0 in one launch (TWO_STEPS(FIRST_AT)): what tv_dual_first
 * and then tv_step compute (values equal; a zero's sign may differ), reading only img and writing only
 * p_out: the bytes of tv_dual_first, one launch less.  global size (n, m, B*T) */
__kernel void tv_first2(__global const real *img, __global real *p_out, __global const real *xnext,
                        __global const real *steps, int T, int m, int n, int sets)
{
    TWO_STEPS(FIRST_AT)
}
