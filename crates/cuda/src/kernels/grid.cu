// The dense 3-D grid field (trilinear lookup, channels last) and the density/colour activation,
// forward and backward, one thread per position (or per row); compiled at run time by NVRTC
// (see `src/kernel.rs`), so it includes no header.
//
// The conventions and numerics are those of the CPU ops in `fogray-ops` (crates/ops/src/grid
// and crates/ops/src/activation):
// - Nodes are aligned with the box corners; a position outside the closed box reads 0 and gets
//   no gradient; one on an inner face belongs to the cell above it, one on the max face to the
//   last cell; a NaN coordinate is an error (reported through `invalid`).
// - Each position's cell and weights are computed in f64 and rounded once to the data's type;
//   the forward's sum runs in the data's precision, corner by corner in the CPU op's corner
//   order, with products and sums rounded separately (`__fmul_rn`, `__fadd_rn`: never
//   contracted into a fused multiply-add, which the CPU op does not use), so that the forward
//   has the CPU op's bits.
// - The grid gradient sums each node's terms `w_k g_c` (w unrounded, in f64) in f64 and rounds
//   once; on the GPU the terms meet by f64 atomic addition, in no fixed order, so its bits may
//   differ from the CPU op's in the last place of the f64 sum, not more.
// - The position gradient, `(du/dp) sum_k dw_k/dt (g . v_k)`, is summed in f64 in the CPU op's
//   order.

typedef unsigned long long u64;
typedef long long i64;

// The box and the lattice: `scale = (n - 1) / (max - min)`, `end = n - 1`, `last = n - 2` per
// axis, node strides of the channels-last storage (in nodes), and each corner's node offset
// (corner k takes the upper node along axis a when bit 2 - a of k is set).
struct Geometry {
    double min[3];
    double max[3];
    double scale[3];
    double end[3];
    i64 last[3];
    u64 strides[3];
    u64 corners[8];
};

// The cell of `p`: false outside the closed box (or for NaN), else its first node and its
// fractions.
__device__ __forceinline__ bool locate(const Geometry& g, const double p[3], u64& node, double t[3]) {
    bool inside = true;
#pragma unroll
    for (int a = 0; a < 3; ++a) inside &= (p[a] >= g.min[a]) & (p[a] <= g.max[a]);
    if (!inside) return false;
    node = 0;
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        // u in [0, n - 1]: rounding may carry the max face a hair past n - 1, hence the clamp
        // (fmin returns the other operand for a NaN, as the CPU op's f64::min).
        double u = fmin(__dmul_rn(p[a] - g.min[a], g.scale[a]), g.end[a]);
        i64 i = (i64)u;
        if (i > g.last[a]) i = g.last[a];
        node += (u64)i * g.strides[a];
        t[a] = u - (double)i;
    }
    return true;
}

// The 8 trilinear weights in the corner order, built axis by axis as the CPU op builds them.
__device__ __forceinline__ void weights(const double t[3], double w[8]) {
    w[0] = 1.0;
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        int m = 1 << a;
#pragma unroll
        for (int k = m - 1; k >= 0; --k) {
            w[2 * k + 1] = __dmul_rn(w[k], t[a]);
            w[2 * k] = __dmul_rn(w[k], 1.0 - t[a]);
        }
    }
}

template <typename T>
__device__ __forceinline__ T mul_rn(T a, T b);
template <>
__device__ __forceinline__ float mul_rn(float a, float b) { return __fmul_rn(a, b); }
template <>
__device__ __forceinline__ double mul_rn(double a, double b) { return __dmul_rn(a, b); }
template <typename T>
__device__ __forceinline__ T add_rn(T a, T b);
template <>
__device__ __forceinline__ float add_rn(float a, float b) { return __fadd_rn(a, b); }
template <>
__device__ __forceinline__ double add_rn(double a, double b) { return __dadd_rn(a, b); }

template <typename T>
__device__ __forceinline__ bool position_of(const T* __restrict__ positions, u64 s, double p[3], unsigned* invalid) {
    bool nan = false;
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        p[a] = (double)positions[3 * s + a];
        nan |= p[a] != p[a];
    }
    if (nan) atomicOr(invalid, 1u);
    return !nan;
}

// The cell of position s, for the backwards: false outside the box or for a NaN coordinate
// (which the forward has reported).
template <typename T>
__device__ __forceinline__ bool cell_of(const Geometry& g, const T* __restrict__ positions, u64 s, u64& node,
                                        double t[3]) {
    double p[3];
    bool nan = false;
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        p[a] = (double)positions[3 * s + a];
        nan |= p[a] != p[a];
    }
    return !nan && locate(g, p, node, t);
}

template <typename T>
__device__ __forceinline__ void grid_forward(Geometry g, const T* __restrict__ grid, const T* __restrict__ positions,
                                             u64 n, u64 ch, T* __restrict__ out, unsigned* __restrict__ invalid) {
    u64 s = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (s >= n) return;
    double p[3], t[3];
    u64 node = 0;
    T* o = out + s * ch;
    if (!position_of(positions, s, p, invalid) || !locate(g, p, node, t)) {
        for (u64 c = 0; c < ch; ++c) o[c] = (T)0;
        return;
    }
    double w[8];
    weights(t, w);
    T wt[8];
#pragma unroll
    for (int k = 0; k < 8; ++k) wt[k] = (T)w[k];
    for (u64 c = 0; c < ch; ++c) {
        // The first product starts the sum (0 + w v would turn -0 into +0).
        T acc = mul_rn(wt[0], grid[(node + g.corners[0]) * ch + c]);
#pragma unroll
        for (int k = 1; k < 8; ++k) acc = add_rn(acc, mul_rn(wt[k], grid[(node + g.corners[k]) * ch + c]));
        o[c] = acc;
    }
}

// Adds every position's terms w_k g_c into the f64 accumulator of the grid gradient (zeroed
// by the host).
template <typename T>
__device__ __forceinline__ void grid_scatter(Geometry g, const T* __restrict__ positions, const T* __restrict__ upstream,
                                             u64 n, u64 ch, double* __restrict__ acc) {
    u64 s = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (s >= n) return;
    double t[3];
    u64 node = 0;
    if (!cell_of(g, positions, s, node, t)) return;
    double w[8];
    weights(t, w);
    for (u64 c = 0; c < ch; ++c) {
        double gc = (double)upstream[s * ch + c];
        if (gc == 0.0) continue;
#pragma unroll
        for (int k = 0; k < 8; ++k) atomicAdd(&acc[(node + g.corners[k]) * ch + c], __dmul_rn(w[k], gc));
    }
}

template <typename T>
__device__ __forceinline__ void round_into(const double* __restrict__ acc, u64 len, T* __restrict__ out) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i < len) out[i] = (T)acc[i];
}

template <typename T>
__device__ __forceinline__ void grid_position_gradient(Geometry g, const T* __restrict__ grid,
                                                       const T* __restrict__ positions,
                                                       const T* __restrict__ upstream, u64 n, u64 ch,
                                                       T* __restrict__ out) {
    u64 s = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (s >= n) return;
    T* o = out + 3 * s;
    o[0] = o[1] = o[2] = (T)0;
    const T* gs = upstream + s * ch;
    bool any = false;
    for (u64 c = 0; c < ch; ++c) any |= gs[c] != (T)0;
    if (!any) return;
    double t[3];
    u64 node = 0;
    if (!cell_of(g, positions, s, node, t)) return;
    // g . v_k for each corner, then each axis's derivative weights.
    double gv[8];
#pragma unroll
    for (int k = 0; k < 8; ++k) {
        double sum = 0.0;
        const T* row = grid + (node + g.corners[k]) * ch;
        for (u64 c = 0; c < ch; ++c) sum = __dadd_rn(sum, __dmul_rn((double)row[c], (double)gs[c]));
        gv[k] = sum;
    }
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        // dw_k/dt_a: the weight with axis a's factor replaced by +1 or -1, the weight at
        // t_a = 1 minus the weight at t_a = 0.
        double s1[3] = {t[0], t[1], t[2]}, hi[8], lo[8];
        s1[a] = 1.0;
        weights(s1, hi);
        s1[a] = 0.0;
        weights(s1, lo);
        double d = 0.0;
#pragma unroll
        for (int k = 0; k < 8; ++k) d = __dadd_rn(d, __dmul_rn(hi[k] - lo[k], gv[k]));
        o[a] = (T)__dmul_rn(d, g.scale[a]);
    }
}

// softplus(x) = max(x, 0) + ln(1 + e), sigmoid(x) = exp(min(x, 0)) / (1 + e), with
// e = exp(-|x|) in [0, 1]: nothing overflows and the tails keep their relative accuracy.
__device__ __forceinline__ double softplus(double x) { return fmax(x, 0.0) + log1p(exp(-fabs(x))); }
__device__ __forceinline__ double sigmoid(double x) { return exp(fmin(x, 0.0)) / (1.0 + exp(-fabs(x))); }
// sigmoid'(x) = e / (1 + e)^2, never y (1 - y), which is 0 once y rounds to 1.
__device__ __forceinline__ double sigmoid_slope(double x) {
    double e = exp(-fabs(x));
    return e / ((1.0 + e) * (1.0 + e));
}

template <typename T>
__device__ __forceinline__ void density_color_forward(const T* __restrict__ raw, u64 n, u64 k, double shift,
                                                      T* __restrict__ sigma, T* __restrict__ color,
                                                      unsigned* __restrict__ invalid) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    const T* row = raw + i * k;
    bool nan = false;
    double x = (double)row[0];
    nan |= x != x;
    sigma[i] = (T)softplus(x + shift);
    for (u64 c = 1; c < k; ++c) {
        double v = (double)row[c];
        nan |= v != v;
        color[i * (k - 1) + c - 1] = (T)sigmoid(v);
    }
    if (nan) atomicOr(invalid, 1u);
}

template <typename T>
__device__ __forceinline__ void density_color_backward(const T* __restrict__ raw, u64 n, u64 k, double shift,
                                                       const T* __restrict__ d_sigma, int has_d_sigma,
                                                       const T* __restrict__ d_color, int has_d_color,
                                                       T* __restrict__ d_raw) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    const T* row = raw + i * k;
    T* o = d_raw + i * k;
    // softplus' = sigmoid.
    o[0] = has_d_sigma ? (T)((double)d_sigma[i] * sigmoid((double)row[0] + shift)) : (T)0;
    for (u64 c = 1; c < k; ++c) {
        o[c] = has_d_color ? (T)((double)d_color[i * (k - 1) + c - 1] * sigmoid_slope((double)row[c])) : (T)0;
    }
}

// The real spherical-harmonics basis of degree 0 to 3 at unit direction (x, y, z), in the
// order, normalisation and signs of `fogray_ops::sh::basis` (Plenoxels' and 3D Gaussian
// splatting's); a lower degree uses a prefix.
__device__ __forceinline__ void sh_basis(double x, double y, double z, double Y[16]) {
    const double C0 = 0.28209479177387814, C1 = 0.4886025119029199;
    const double C2[5] = {1.0925484305920792, -1.0925484305920792, 0.31539156525252005, -1.0925484305920792,
                          0.5462742152960396};
    const double C3[7] = {-0.5900435899266435, 2.890611442640554,  -0.4570457994644658, 0.3731763325901154,
                          -0.4570457994644658, 1.445305721320277, -0.5900435899266435};
    double xx = x * x, yy = y * y, zz = z * z;
    Y[0] = C0;
    Y[1] = -C1 * y;
    Y[2] = C1 * z;
    Y[3] = -C1 * x;
    Y[4] = C2[0] * (x * y);
    Y[5] = C2[1] * (y * z);
    Y[6] = C2[2] * (2.0 * zz - xx - yy);
    Y[7] = C2[3] * (x * z);
    Y[8] = C2[4] * (xx - yy);
    Y[9] = C3[0] * y * (3.0 * xx - yy);
    Y[10] = C3[1] * (x * y) * z;
    Y[11] = C3[2] * y * (4.0 * zz - xx - yy);
    Y[12] = C3[3] * z * (2.0 * zz - 3.0 * xx - 3.0 * yy);
    Y[13] = C3[4] * x * (4.0 * zz - xx - yy);
    Y[14] = C3[5] * z * (xx - yy);
    Y[15] = C3[6] * x * (xx - 3.0 * yy);
}

// The activation of a row of `1 + 3 B` raw values seen along direction `dir` (`[n, 3]`, one
// per row): the density `softplus(raw_0 + shift)` of `density_color_forward`, and the colour
// `sigmoid(sum_b raw[1 + c B + b] Y_b(d))` of `fogray_ops::ShColor` (channel-major
// coefficients); in f64, each value rounded once.
template <typename T>
__device__ __forceinline__ void sh_density_color_forward(const T* __restrict__ raw, const T* __restrict__ dirs,
                                                         u64 n, u64 basis, double shift, T* __restrict__ sigma,
                                                         T* __restrict__ color, unsigned* __restrict__ invalid) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    const T* row = raw + i * (1 + 3 * basis);
    double Y[16];
    double x = (double)dirs[3 * i], y = (double)dirs[3 * i + 1], z = (double)dirs[3 * i + 2];
    sh_basis(x, y, z, Y);
    bool nan = (x != x) | (y != y) | (z != z);
    double d0 = (double)row[0];
    nan |= d0 != d0;
    sigma[i] = (T)softplus(d0 + shift);
#pragma unroll
    for (int c = 0; c < 3; ++c) {
        double sum = 0.0;
        for (u64 b = 0; b < basis; ++b) sum += (double)row[1 + c * basis + b] * Y[b];
        nan |= sum != sum;
        color[3 * i + c] = (T)sigmoid(sum);
    }
    if (nan) atomicOr(invalid, 1u);
}

// Its backward: `d_raw_0 = d_sigma sigmoid(raw_0 + shift)`, and
// `d_raw[1 + c B + b] = d_color_c sigmoid'(x_c) Y_b(d)` with `x_c` recomputed from the inputs.
template <typename T>
__device__ __forceinline__ void sh_density_color_backward(const T* __restrict__ raw, const T* __restrict__ dirs,
                                                          u64 n, u64 basis, double shift,
                                                          const T* __restrict__ d_sigma,
                                                          const T* __restrict__ d_color, T* __restrict__ d_raw) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    u64 k = 1 + 3 * basis;
    const T* row = raw + i * k;
    T* o = d_raw + i * k;
    double Y[16];
    sh_basis((double)dirs[3 * i], (double)dirs[3 * i + 1], (double)dirs[3 * i + 2], Y);
    o[0] = (T)((double)d_sigma[i] * sigmoid((double)row[0] + shift));
#pragma unroll
    for (int c = 0; c < 3; ++c) {
        double sum = 0.0;
        for (u64 b = 0; b < basis; ++b) sum += (double)row[1 + c * basis + b] * Y[b];
        double s = (double)d_color[3 * i + c] * sigmoid_slope(sum);
        for (u64 b = 0; b < basis; ++b) o[1 + c * basis + b] = (T)(s * Y[b]);
    }
}

#define INSTANTIATE(T, SUFFIX)                                                                                      \
    extern "C" __global__ void grid_forward_##SUFFIX(Geometry g, const T* grid, const T* positions, u64 n, u64 ch,   \
                                                     T* out, unsigned* invalid) {                                   \
        grid_forward<T>(g, grid, positions, n, ch, out, invalid);                                                   \
    }                                                                                                               \
    extern "C" __global__ void grid_scatter_##SUFFIX(Geometry g, const T* positions, const T* upstream, u64 n,      \
                                                     u64 ch, double* acc) {                                         \
        grid_scatter<T>(g, positions, upstream, n, ch, acc);                                                        \
    }                                                                                                               \
    extern "C" __global__ void grid_round_##SUFFIX(const double* acc, u64 len, T* out) {                            \
        round_into<T>(acc, len, out);                                                                               \
    }                                                                                                               \
    extern "C" __global__ void grid_position_gradient_##SUFFIX(Geometry g, const T* grid, const T* positions,       \
                                                               const T* upstream, u64 n, u64 ch, T* out) {          \
        grid_position_gradient<T>(g, grid, positions, upstream, n, ch, out);                                        \
    }                                                                                                               \
    extern "C" __global__ void density_color_forward_##SUFFIX(const T* raw, u64 n, u64 k, double shift, T* sigma,   \
                                                              T* color, unsigned* invalid) {                        \
        density_color_forward<T>(raw, n, k, shift, sigma, color, invalid);                                          \
    }                                                                                                               \
    extern "C" __global__ void density_color_backward_##SUFFIX(const T* raw, u64 n, u64 k, double shift,            \
                                                               const T* d_sigma, int has_d_sigma, const T* d_color, \
                                                               int has_d_color, T* d_raw) {                         \
        density_color_backward<T>(raw, n, k, shift, d_sigma, has_d_sigma, d_color, has_d_color, d_raw);             \
    }                                                                                                               \
    extern "C" __global__ void sh_density_color_forward_##SUFFIX(const T* raw, const T* dirs, u64 n, u64 basis,    \
                                                                 double shift, T* sigma, T* color,                  \
                                                                 unsigned* invalid) {                               \
        sh_density_color_forward<T>(raw, dirs, n, basis, shift, sigma, color, invalid);                             \
    }                                                                                                               \
    extern "C" __global__ void sh_density_color_backward_##SUFFIX(const T* raw, const T* dirs, u64 n, u64 basis,   \
                                                                  double shift, const T* d_sigma, const T* d_color, \
                                                                  T* d_raw) {                                       \
        sh_density_color_backward<T>(raw, dirs, n, basis, shift, d_sigma, d_color, d_raw);                          \
    }

INSTANTIATE(float, f32)
INSTANTIATE(double, f64)
