// The fused emission-absorption composite on packed rays, forward and backward, one thread per
// ray; compiled at run time by NVRTC (see `src/kernel.rs`), so it includes no header.
//
// The numerics are those of the CPU op in `fogray-ops` (crates/ops/src/composite, and
// docs/volume-rendering.md), for f32 and f64 data alike: every value of the computation is a
// double (tau = sigma delta is exact in f64 for f32 inputs), alpha = -expm1(-tau), the
// transmittance T_k = exp(-running optical depth) (never a product of 1 - alpha), the opacity
// -expm1(-total depth) (never 1 - T_end), and the backward is the back-to-front recurrence
//   R_k = R_{k+1} + alpha_k (v_k - R_{k+1}),   R_end = gC.c_bg,   v_k = gC.c_k + gO
//   dL/dtau_k = T_{k+1} (v_k - R_{k+1})
// with no division and no subtraction from a total.
//
// The backward walks each ray back to front but needs T_{k+1} = exp(-prefix depth), a
// front-to-back sum; subtracting taus from the total would lose T behind a huge tau (1e30 + 1
// - 1e30 = 0). So the forward stores the exact running depth at the start of every chunk of
// CHUNK samples (one double per CHUNK samples, the op's only residual), and the backward
// recomputes each chunk's prefix depths front to back in registers, then walks the chunk back
// to front. Both sums run in the same order (the CPU op's, see `forward`), so they give the
// same bits.

typedef unsigned long long u64;

#define CHUNK 8
#define BLOCK 128
#define F32_MAX 3.402823466e38f
#define F64_MAX 1.7976931348623157e308

// Finite and non-negative (NaN fails both comparisons).
__device__ __forceinline__ bool in_domain(float v) { return v >= 0.0f && v <= F32_MAX; }
__device__ __forceinline__ bool in_domain(double v) { return v >= 0.0 && v <= F64_MAX; }
__device__ __forceinline__ bool is_finite(float v) { return fabsf(v) <= F32_MAX; }
__device__ __forceinline__ bool is_finite(double v) { return fabs(v) <= F64_MAX; }

// Where ray r's chunk depths start in the residual: ray r has at most len/CHUNK + 1 chunks,
// so start/CHUNK + r leaves room for every ray before it (the buffer holds n/CHUNK + R + 1).
__device__ __forceinline__ u64 chunk_base(u64 start, u64 r) { return start / CHUNK + r; }

// Sample k's optical depth, and whether its density and length are in their domain.
template <typename T>
__device__ __forceinline__ double tau_of(const T* __restrict__ sigma, const T* __restrict__ delta, u64 k, bool& ok) {
    T s = sigma[k], d = delta[k];
    ok &= in_domain(s) & in_domain(d);
    return (double)s * (double)d;
}

// Adds sample k, whose optical depth is tau and which lies behind an optical depth `depth`,
// to the colour; checks its colour.
template <typename T>
__device__ __forceinline__ void add_sample(const T* __restrict__ color, u64 k, double depth, double tau, double& c0,
                                           double& c1, double& c2, bool& ok) {
    T r0 = color[3 * k], r1 = color[3 * k + 1], r2 = color[3 * k + 2];
    ok &= is_finite(r0) & is_finite(r1) & is_finite(r2);
    double w = exp(-depth) * -expm1(-tau);
    c0 = fma(w, (double)r0, c0);
    c1 = fma(w, (double)r1, c1);
    c2 = fma(w, (double)r2, c2);
}

// The running optical depth is summed as the CPU op sums it (attenuation.rs,
// `exclusive_prefix_sums`): in groups of 4 from the ray's first sample, the depth before each
// sample of a group being the group's start plus the partial sum of the group (one addition
// per group on the running total, not one per sample: on a 1e5-sample ray this is what keeps
// T within 1e-12 of the CPU op's), and the last len % 4 samples one at a time. Every depth
// then has the CPU op's bits. CHUNK is a multiple of 4, so chunks start at group starts.
template <typename T>
__device__ __forceinline__ void forward(const u64* __restrict__ offsets, u64 rays, const T* __restrict__ sigma,
                                        const T* __restrict__ delta, const T* __restrict__ color,
                                        const T* __restrict__ background, T* __restrict__ out_color,
                                        T* __restrict__ out_opacity, double* __restrict__ chunk_depth,
                                        unsigned* __restrict__ invalid) {
    u64 r = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (r >= rays) return;
    u64 start = offsets[r], end = offsets[r + 1];
    u64 base = chunk_base(start, r);
    double running = 0.0, c0 = 0.0, c1 = 0.0, c2 = 0.0;
    bool ok = true;
    u64 k = start;
    for (; k + 4 <= end; k += 4) {
        if ((k - start) % CHUNK == 0) chunk_depth[base + (k - start) / CHUNK] = running;
        double t0 = tau_of(sigma, delta, k, ok), t1 = tau_of(sigma, delta, k + 1, ok);
        double t2 = tau_of(sigma, delta, k + 2, ok), t3 = tau_of(sigma, delta, k + 3, ok);
        double p1 = t0 + t1, p2 = p1 + t2, p3 = p2 + t3;
        add_sample(color, k, running, t0, c0, c1, c2, ok);
        add_sample(color, k + 1, running + t0, t1, c0, c1, c2, ok);
        add_sample(color, k + 2, running + p1, t2, c0, c1, c2, ok);
        add_sample(color, k + 3, running + p2, t3, c0, c1, c2, ok);
        running += p3;
    }
    for (; k < end; ++k) {
        if ((k - start) % CHUNK == 0) chunk_depth[base + (k - start) / CHUNK] = running;
        double t = tau_of(sigma, delta, k, ok);
        add_sample(color, k, running, t, c0, c1, c2, ok);
        running += t;
    }
    double t_end = exp(-running);
    out_color[3 * r] = (T)fma(t_end, (double)background[0], c0);
    out_color[3 * r + 1] = (T)fma(t_end, (double)background[1], c1);
    out_color[3 * r + 2] = (T)fma(t_end, (double)background[2], c2);
    // Not 1 - T_end, which is 0 for a faint ray.
    out_opacity[r] = (T)(-expm1(-running));
    if (!ok) atomicOr(invalid, 1u);
}

// The backward's global loads and stores are staged through shared memory, a warp at a time,
// so that they are coalesced: in step j every lane of a warp takes its ray's j-th chunk from
// the back (each a contiguous span of at most CHUNK samples), the warp copies the 32 spans'
// densities, lengths and colours into shared memory with consecutive lanes on consecutive
// elements of a span, each lane then runs its ray's recurrence on its own span exactly as
// before (same operations, same order, same bits), writing its gradients over the span in
// shared memory, and the warp copies the 32 spans' gradients out the same way. A lane's span
// is padded to an odd stride (CHUNK + 1, 3 CHUNK + 1 elements) so that the lanes' reads of
// their spans do not conflict on banks.
#define WARPS (BLOCK / 32)
#define SPAN (CHUNK + 1)
#define CSPAN (3 * CHUNK + 1)

template <typename T>
__device__ __forceinline__ void backward(const u64* __restrict__ offsets, u64 rays, const T* __restrict__ sigma,
                                         const T* __restrict__ delta, const T* __restrict__ color,
                                         const T* __restrict__ background, const T* __restrict__ d_color,
                                         const T* __restrict__ d_opacity, int has_d_opacity,
                                         const double* __restrict__ chunk_depth, T* __restrict__ g_sigma,
                                         T* __restrict__ g_delta, T* __restrict__ g_color,
                                         double* __restrict__ bg_partial) {
    __shared__ double red[3][BLOCK];
    __shared__ T st_sigma[WARPS][32 * SPAN];
    __shared__ T st_delta[WARPS][32 * SPAN];
    __shared__ T st_color[WARPS][32 * CSPAN];
    __shared__ u64 st_s0[WARPS][32];
    __shared__ int st_m[WARPS][32];
    unsigned lane = threadIdx.x & 31u, wid = threadIdx.x >> 5;
    u64 r = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    bool active = r < rays;
    u64 start = 0, end = 0, base = 0, chunks = 0;
    double g0 = 0.0, g1 = 0.0, g2 = 0.0, go = 0.0, behind = 0.0;
    if (active) {
        start = offsets[r];
        end = offsets[r + 1];
        base = chunk_base(start, r);
        chunks = (end - start + CHUNK - 1) / CHUNK;
        g0 = (double)d_color[3 * r];
        g1 = (double)d_color[3 * r + 1];
        g2 = (double)d_color[3 * r + 2];
        go = has_d_opacity ? (double)d_opacity[r] : 0.0;
        behind = g0 * (double)background[0] + g1 * (double)background[1] + g2 * (double)background[2];
    }
    // The warp's steps: its longest ray's chunk count.
    u64 steps = chunks;
#pragma unroll
    for (int o = 16; o > 0; o >>= 1) {
        u64 other = __shfl_xor_sync(0xffffffffu, steps, o);
        steps = other > steps ? other : steps;
    }
    T* my_sigma = &st_sigma[wid][lane * SPAN];
    T* my_delta = &st_delta[wid][lane * SPAN];
    T* my_color = &st_color[wid][lane * CSPAN];
    double t_end = 1.0, t_next = 1.0;
    for (u64 j = 0; j < steps; ++j) {
        // This lane's chunk: the j-th from the back, or none (m = 0).
        bool has = j < chunks;
        u64 c = has ? chunks - 1 - j : 0;
        u64 s0 = start + c * CHUNK;
        int m = has ? ((end - s0 < CHUNK) ? (int)(end - s0) : CHUNK) : 0;
        st_s0[wid][lane] = s0;
        st_m[wid][lane] = m;
        __syncwarp();
        // Coalesced loads of the warp's spans.
#pragma unroll
        for (int t = 0; t < CHUNK; ++t) {
            unsigned idx = t * 32 + lane, src = idx / CHUNK, i = idx % CHUNK;
            if ((int)i < st_m[wid][src]) {
                u64 k = st_s0[wid][src] + i;
                st_sigma[wid][src * SPAN + i] = sigma[k];
                st_delta[wid][src * SPAN + i] = delta[k];
            }
        }
#pragma unroll
        for (int t = 0; t < 3 * CHUNK; ++t) {
            unsigned idx = t * 32 + lane, src = idx / (3 * CHUNK), i = idx % (3 * CHUNK);
            if ((int)i < 3 * st_m[wid][src]) st_color[wid][src * CSPAN + i] = color[3 * st_s0[wid][src] + i];
        }
        __syncwarp();
        if (has) {
            // Depths before each sample of the chunk, front to back in registers (unrolled:
            // constant indices), grouped as in the forward so that they have its bits.
            double dep[CHUNK];
            double running = chunk_depth[base + c];
            bool unused = true;
#pragma unroll
            for (int g = 0; g < CHUNK; g += 4) {
                if (g + 4 <= m) {
                    double t0 = tau_of(my_sigma, my_delta, g, unused), t1 = tau_of(my_sigma, my_delta, g + 1, unused);
                    double t2 = tau_of(my_sigma, my_delta, g + 2, unused), t3 = tau_of(my_sigma, my_delta, g + 3, unused);
                    double p1 = t0 + t1, p2 = p1 + t2, p3 = p2 + t3;
                    dep[g] = running;
                    dep[g + 1] = running + t0;
                    dep[g + 2] = running + p1;
                    dep[g + 3] = running + p2;
                    running += p3;
                } else {
                    // The ray's last len % 4 samples, one at a time.
#pragma unroll
                    for (int i = g; i < g + 4; ++i) {
                        if (i < m) {
                            dep[i] = running;
                            running += tau_of(my_sigma, my_delta, i, unused);
                        }
                    }
                }
            }
            if (j == 0) {
                // `running` is now the whole ray's optical depth.
                t_end = exp(-running);
                t_next = t_end;
            }
#pragma unroll
            for (int i = CHUNK - 1; i >= 0; --i) {
                if (i < m) {
                    T s = my_sigma[i], d = my_delta[i];
                    double tau = (double)s * (double)d;
                    double alpha = -expm1(-tau);
                    double t_k = exp(-dep[i]);
                    double c0 = (double)my_color[3 * i], c1 = (double)my_color[3 * i + 1];
                    double c2 = (double)my_color[3 * i + 2];
                    double v = g0 * c0 + g1 * c1 + g2 * c2 + go;
                    double diff = v - behind;
                    // What the sample adds minus what it hides.
                    double g_tau = t_next * diff;
                    // The gradients over the sample's inputs, which it no longer needs.
                    my_sigma[i] = (T)((double)d * g_tau);
                    my_delta[i] = (T)((double)s * g_tau);
                    double w = t_k * alpha;
                    my_color[3 * i] = (T)(w * g0);
                    my_color[3 * i + 1] = (T)(w * g1);
                    my_color[3 * i + 2] = (T)(w * g2);
                    behind = fma(alpha, diff, behind);
                    t_next = t_k;
                }
            }
        }
        __syncwarp();
        // Coalesced stores of the warp's gradients.
#pragma unroll
        for (int t = 0; t < CHUNK; ++t) {
            unsigned idx = t * 32 + lane, src = idx / CHUNK, i = idx % CHUNK;
            if ((int)i < st_m[wid][src]) {
                u64 k = st_s0[wid][src] + i;
                g_sigma[k] = st_sigma[wid][src * SPAN + i];
                g_delta[k] = st_delta[wid][src * SPAN + i];
            }
        }
#pragma unroll
        for (int t = 0; t < 3 * CHUNK; ++t) {
            unsigned idx = t * 32 + lane, src = idx / (3 * CHUNK), i = idx % (3 * CHUNK);
            if ((int)i < 3 * st_m[wid][src]) g_color[3 * st_s0[wid][src] + i] = st_color[wid][src * CSPAN + i];
        }
        // Before the next step overwrites the spans and the lanes' chunk bounds.
        __syncwarp();
    }
    double gb0 = 0.0, gb1 = 0.0, gb2 = 0.0;
    if (active) {
        gb0 = t_end * g0;
        gb1 = t_end * g1;
        gb2 = t_end * g2;
    }
    // The shared background's gradient: a fixed-order tree sum per block (deterministic), the
    // blocks' sums added by `reduce_background`.
    unsigned tid = threadIdx.x;
    red[0][tid] = gb0;
    red[1][tid] = gb1;
    red[2][tid] = gb2;
    __syncthreads();
    for (unsigned half = BLOCK / 2; half > 0; half >>= 1) {
        if (tid < half) {
            red[0][tid] += red[0][tid + half];
            red[1][tid] += red[1][tid + half];
            red[2][tid] += red[2][tid + half];
        }
        __syncthreads();
    }
    if (tid == 0) {
        bg_partial[3 * (u64)blockIdx.x] = red[0][0];
        bg_partial[3 * (u64)blockIdx.x + 1] = red[1][0];
        bg_partial[3 * (u64)blockIdx.x + 2] = red[2][0];
    }
}

#define REDUCE 256

template <typename T>
__device__ __forceinline__ void reduce_background(const double* __restrict__ bg_partial, u64 blocks,
                                                  T* __restrict__ g_background) {
    __shared__ double red[3][REDUCE];
    unsigned tid = threadIdx.x;
    double a0 = 0.0, a1 = 0.0, a2 = 0.0;
    for (u64 b = tid; b < blocks; b += REDUCE) {
        a0 += bg_partial[3 * b];
        a1 += bg_partial[3 * b + 1];
        a2 += bg_partial[3 * b + 2];
    }
    red[0][tid] = a0;
    red[1][tid] = a1;
    red[2][tid] = a2;
    __syncthreads();
    for (unsigned half = REDUCE / 2; half > 0; half >>= 1) {
        if (tid < half) {
            red[0][tid] += red[0][tid + half];
            red[1][tid] += red[1][tid + half];
            red[2][tid] += red[2][tid + half];
        }
        __syncthreads();
    }
    if (tid == 0) {
        g_background[0] = (T)red[0][0];
        g_background[1] = (T)red[1][0];
        g_background[2] = (T)red[2][0];
    }
}

#define INSTANTIATE(T, SUFFIX)                                                                                      \
    extern "C" __global__ void __launch_bounds__(BLOCK) composite_forward_##SUFFIX(                                  \
        const u64* offsets, u64 rays, const T* sigma, const T* delta, const T* color, const T* background,          \
        T* out_color, T* out_opacity, double* chunk_depth, unsigned* invalid) {                                     \
        forward<T>(offsets, rays, sigma, delta, color, background, out_color, out_opacity, chunk_depth, invalid);   \
    }                                                                                                               \
    extern "C" __global__ void __launch_bounds__(BLOCK) composite_backward_##SUFFIX(                                 \
        const u64* offsets, u64 rays, const T* sigma, const T* delta, const T* color, const T* background,          \
        const T* d_color, const T* d_opacity, int has_d_opacity, const double* chunk_depth, T* g_sigma,             \
        T* g_delta, T* g_color, double* bg_partial) {                                                               \
        backward<T>(offsets, rays, sigma, delta, color, background, d_color, d_opacity, has_d_opacity, chunk_depth, \
                    g_sigma, g_delta, g_color, bg_partial);                                                         \
    }                                                                                                               \
    extern "C" __global__ void __launch_bounds__(REDUCE)                                                            \
        composite_reduce_background_##SUFFIX(const double* bg_partial, u64 blocks, T* g_background) {               \
        reduce_background<T>(bg_partial, blocks, g_background);                                                     \
    }

INSTANTIATE(float, f32)
INSTANTIATE(double, f64)
