/* The row-timed shutter operator H (forward), its adjoint, and the diagonal and
 * per-pixel blocks of H Hᵀ. Layouts: f[T][m][n], g[K][m][n] (a batch: f[B][T][m][n], g[B][K][m][n]),
 * first/frac[K][m][n], len[K][2] (whole sub-frames, then the rest: WINDOW_LENGTH), gain[K]. Each
 * work item handles one pixel (psi, gram) or one block of TILE_R x TILE_W
 * pixels (forward, adjoint; see common.cl) and loops over the exposure window only: cost
 * ~ K*m*n*L, never K*T*m*n. `first` counts from the first sub-frame solved for, so it may
 * be negative; T is the number of sub-frames solved for. Needs common.cl. */

/* g[k, p] = gain[k] * sum_s w(k, s, p) f[s, p];   global size (>= ceil(n / TILE_W),
 * >= ceil(m / TILE_R), sets * K): one work item per block of TILE_R x TILE_W pixels of one channel
 * of one set (common.cl); blocks cut by the ROI's edge take the scalar loop per pixel. A batch of
 * sets lies end to end: f[set][T][m][n], g[set][K][m][n]; the geometry is every set's. */
__kernel void forward(__global const real *f_all, __global real *g_all,
                      __global const int *first, __global const real *frac,
                      __global const real *len, __global const real *gain,
                      int K, int T, int L, int m_, int n_)
{
    size_t m = (size_t)m_, n = (size_t)n_, mn = m * n;
    size_t kk = get_global_id(2), set = kk / (size_t)K, k = kk - set * (size_t)K;
    size_t x0 = get_global_id(0) * (size_t)TILE_W, y0 = get_global_id(1) * (size_t)TILE_R;
    if (x0 >= n || y0 >= m) return;
    __global const real *f = f_all + set * (size_t)T * mn;
    __global real *g = g_all + set * (size_t)K * mn;
    if (x0 + TILE_W <= n && y0 + TILE_R <= m) {
        size_t p0 = y0 * n + x0, q0 = k * mn + p0;
        realw acc[TILE_R];
        block_dot(f, first, frac, WINDOW_LENGTH(len, k), q0, T, L, mn, n, p0, acc);
        for (int r = 0; r < TILE_R; ++r) store_w(gain[k] * acc[r], g + q0 + (size_t)r * n);
        return;
    }
    for (size_t y = y0; y < y0 + TILE_R && y < m; ++y)
        for (size_t x = x0; x < x0 + TILE_W && x < n; ++x) {
            size_t p = y * n + x, q = k * mn + p;
            g[q] = gain[k] * window_dot(f, first[q], frac[q], WINDOW_LENGTH(len, k), T, L, mn, p);
        }
}

/* x = 0, one work item per element on an exact grid (rsocl.device.launch.element_launches): the
 * start of Hᵀ g, faster than clEnqueueFillBuffer on PoCL (docs/implementation_notes.md). */
__kernel void zero(__global real *x)
{
    x[get_global_id(0)] = (real)0;
}

/* f[s, p] += sum_k gain[k] w(k, s, p) g[k, p], over each channel's window only;
 * global size (>= ceil(n / TILE_W), >= ceil(m / TILE_R), sets): one work item per block of
 * TILE_R x TILE_W pixels of one set, all channels (blocks are disjoint, so there are no races). The
 * host first sets f to 0 (Hᵀ g, kernel zero) or to a base (base + Hᵀ g) with a copy: a per-pixel
 * loop over the whole column is slower on CPU devices (docs/implementation_notes.md). Batches as in forward. */
__kernel void adjoint_scatter(__global const real *g_all, __global real *f_all,
                              __global const int *first, __global const real *frac,
                              __global const real *len, __global const real *gain,
                              int K, int T, int L, int m_, int n_)
{
    size_t m = (size_t)m_, n = (size_t)n_, mn = m * n, set = get_global_id(2);
    size_t x0 = get_global_id(0) * (size_t)TILE_W, y0 = get_global_id(1) * (size_t)TILE_R;
    if (x0 >= n || y0 >= m) return;
    __global const real *g = g_all + set * (size_t)K * mn;
    __global real *f = f_all + set * (size_t)T * mn;
    if (x0 + TILE_W <= n && y0 + TILE_R <= m) {
        size_t p0 = y0 * n + x0;
        for (int k = 0; k < K; ++k) {
            size_t q0 = (size_t)k * mn + p0;
            realw scale[TILE_R];
            for (int r = 0; r < TILE_R; ++r) scale[r] = gain[k] * load_w(g + q0 + (size_t)r * n);
            block_scatter(f, first, frac, WINDOW_LENGTH(len, k), q0, T, L, mn, n, p0, scale);
        }
        return;
    }
    for (size_t y = y0; y < y0 + TILE_R && y < m; ++y)
        for (size_t x = x0; x < x0 + TILE_W && x < n; ++x) {
            size_t p = y * n + x;
            for (int k = 0; k < K; ++k) {
                size_t q = (size_t)k * mn + p;
                window_scatter(f, first[q], frac[q], WINDOW_LENGTH(len, k), T, L, mn, p, gain[k] * g[q]);
            }
        }
}

/* psi[k, p] = gain[k]^2 sum_s w(k, s, p)^2;   global size (m*n, K) */
__kernel void psi(__global real *out, __global const int *first, __global const real *frac,
                  __global const real *len, __global const real *gain, int T, int L, int mn_)
{
    size_t p = get_global_id(0), k = get_global_id(1);
    size_t mn = (size_t)mn_;
    if (p >= mn) return;
    size_t q = k * mn + p;
    real acc = (real)0;
    for (int j = 0; j < L; ++j) {
        if (first[q] + j >= T) break;
        if (first[q] + j < 0) continue;
        real w = shutter_weight(j, frac[q], WINDOW_LENGTH(len, k));
        acc += w * w;
    }
    out[q] = gain[k] * gain[k] * acc;
}

/* Per-pixel block M[k][l] = gain[k] gain[l] sum_s w(k, s) w(l, s), stored out[(k*K + l)*mn + p].
 * global size (m*n) */
__kernel void gram(__global real *out, __global const int *first, __global const real *frac,
                   __global const real *len, __global const real *gain, int K, int T, int L, int mn_)
{
    size_t p = get_global_id(0);
    size_t mn = (size_t)mn_;
    if (p >= mn) return;
    for (int k = 0; k < K; ++k) {
        size_t qk = (size_t)k * mn + p;
        for (int l = 0; l <= k; ++l) {
            size_t ql = (size_t)l * mn + p;
            real acc = (real)0;
            for (int j = 0; j < L; ++j) {
                int s = first[qk] + j;
                if (s >= T) break;
                if (s < 0) continue;
                int jl = s - first[ql];
                if (jl < 0 || jl >= L) continue;
                acc += shutter_weight(j, frac[qk], WINDOW_LENGTH(len, k)) * shutter_weight(jl, frac[ql], WINDOW_LENGTH(len, l));
            }
            acc *= gain[k] * gain[l];
            out[((size_t)k * K + l) * mn + p] = acc;
            out[((size_t)l * K + k) * mn + p] = acc;
        }
    }
}
