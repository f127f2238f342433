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
// same bits. The host compiles this file with --fmad=false: every fused multiply-add is an
// explicit `fma` below, none is the compiler's choice, which depends on the code around it.

typedef unsigned long long u64;

#define CHUNK 8
// Threads per block (`KernelTuning` on the host): 32, 64 or 128.
#ifndef BLOCK
#define BLOCK 128
#endif
#define F32_MAX 3.402823466e38f
#define F64_MAX 1.7976931348623157e308

// With F32_EXP 1 (`Exponentials::SplitSingle` on the host), the per-sample exp(-depth) and
// -expm1(-tau) of f32 data are taken with the single-precision functions, a fraction of the
// double ones' cost; every sum stays a double, and f64 data always takes the doubles. Rounding
// the depth d to f32 alone would cost up to d 2^-24 of T (1e-6 at d = 17), so T is split:
// d = hi + lo with hi = (float)d and lo = d - hi exact, T = expf(-hi) exp(-lo), and
// exp(-lo) = 1 - lo to within lo^2 / 2, below 2^-49 d^2 of T. What remains is expf's own
// error (2 ulp, 2.4e-7 of T). tau is exact in f64 for f32 data, and rounding it to f32 costs
// alpha at most 2^-24 of itself.
#ifndef F32_EXP
#define F32_EXP 0
#endif

// T = exp(-depth) and alpha = -expm1(-tau) of one sample of T-typed data.
template <typename T>
__device__ __forceinline__ double transmittance(double depth) { return exp(-depth); }
template <typename T>
__device__ __forceinline__ double absorbed(double tau) { return -expm1(-tau); }
#if F32_EXP
template <>
__device__ __forceinline__ double transmittance<float>(double depth) {
    float hi = (float)depth;
    double lo = depth - (double)hi;
    // expf(-hi) is 0 from hi = 104 on; past FLT_MAX hi is infinite and lo -infinite, whose
    // product would be NaN.
    return hi < 104.0f ? (double)expf(-hi) * (1.0 - lo) : 0.0;
}
template <>
__device__ __forceinline__ double absorbed<float>(double tau) { return (double)-expm1f(-(float)tau); }
#endif

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
    double w = transmittance<T>(depth) * absorbed<T>(tau);
    c0 = fma(w, (double)r0, c0);
    c1 = fma(w, (double)r1, c1);
    c2 = fma(w, (double)r2, c2);
}

// Both kernels run one thread per ray, and stage their global loads and stores through shared
// memory a warp at a time, so that they are coalesced: in step j every lane of a warp takes
// one span of its ray (SPAN_BYTES of densities, 64 by default, in whole residual chunks; the
// j-th span from the front in the forward, from the back in the backward), the warp copies the
// 32 spans' densities, lengths and colours into shared memory with consecutive lanes on
// consecutive elements of a span, and each lane then runs its ray's sums or recurrence on its
// own span, chunk by chunk. 64 bytes is what a DRAM access fetches: with spans of one 8-sample f32
// chunk (32 bytes) the other half came back for the next step and was often gone from L2 by
// then. A lane's span is padded to an odd stride (span + 1, 3 span + 1 elements) so that the
// lanes' reads of their spans do not conflict on banks. A span's start is kept as a 32-bit
// offset from the warp's first sample (the host refuses a batch whose 32 consecutive rays
// hold 2^32 / 3 samples or more), which keeps the kernels' registers few enough for several
// blocks per multiprocessor.
#define WARPS (BLOCK / 32)
// The staging layout (`KernelTuning` on the host): bytes of densities in a span, and loads in
// flight per lane.
#ifndef SPAN_BYTES
#define SPAN_BYTES 64
#endif
#ifndef LOADS
#define LOADS 8
#endif
// 1: the staging is pipelined. The warp copies the next step's spans into a second stage with
// asynchronous copies (cp.async: global to shared memory without registers, on compute
// capability 8.0 and newer) while it computes on this step's, so its loads are in flight while it
// computes, not only between steps. Two stages of shared memory a warp: the host builds it for
// blocks of 32 and 64 threads only (a block's static shared memory is at most 48 KB).
#ifndef PIPELINED
#define PIPELINED 0
#endif
// 1: one stage, filled with asynchronous copies that are all posted before the warp waits for
// any: every element of a step's spans is in flight at once without holding a register (the
// batched staging holds LOADS in registers), and the shared memory stays one stage.
#ifndef ASYNC_STAGE
#define ASYNC_STAGE 0
#endif
#define STAGES (PIPELINED ? 2 : 1)
#if (PIPELINED || ASYNC_STAGE) && defined(__CUDA_ARCH__) && __CUDA_ARCH__ >= 800
#define ASYNC_COPIES 1
#else
#define ASYNC_COPIES 0
#endif

// Chunks per span: SPAN_BYTES of densities, at least one chunk.
template <typename T>
struct Span {
    static constexpr int bytes_chunks = SPAN_BYTES / (CHUNK * (int)sizeof(T));
    static constexpr int chunks = bytes_chunks > 0 ? bytes_chunks : 1;
    static constexpr int len = chunks * CHUNK;
};

template <typename T>
struct Stage {
    static constexpr int SPAN = Span<T>::len;
    T sigma[32 * (SPAN + 1)];
    T delta[32 * (SPAN + 1)];
    T color[32 * (3 * SPAN + 1)];
    unsigned start[32];  // the lane's span, from the warp's first sample
    int len[32];         // its samples (0: this lane has no span in this step)
};

// Copies PER values per sample of the warp's 32 spans from `global` (offset to the warp's
// first sample) into `staged` (lane l's span at l * (PER span + 1)). The loads go out in
// batches of (up to) LOADS before any of them is stored, so that a warp has LOADS loads in flight
// (a load in the branch of its store waits for the one before). An element past its span
// loads the warp's first sample instead, which exists whenever the warp takes a step.
__host__ __device__ constexpr int gcd(int a, int b) { return b == 0 ? a : gcd(b, a % b); }

template <typename T, int PER>
__device__ __forceinline__ void gather(const T* __restrict__ global, T* staged, const Stage<T>& st, unsigned lane) {
    constexpr int W = PER * Span<T>::len;
    // Whole batches: LOADS, or the largest of its divisors that divides the span.
    constexpr int B = gcd(LOADS, W);
#pragma unroll 1
    for (int t0 = 0; t0 < W; t0 += B) {
        T v[B];
        unsigned to[B];
        bool in[B];
#pragma unroll
        for (int u = 0; u < B; ++u) {
            unsigned idx = (t0 + u) * 32 + lane, l = idx / W, i = idx % W;
            in[u] = (int)i < PER * st.len[l];
            to[u] = l * (W + 1) + i;
            v[u] = global[in[u] ? PER * st.start[l] + i : 0u];
        }
#pragma unroll
        for (int u = 0; u < B; ++u) {
            if (in[u]) staged[to[u]] = v[u];
        }
    }
}

// One element from global to shared memory, asynchronously where the device can (completed by
// `wait_copies`), else at once.
template <typename T>
__device__ __forceinline__ void copy_async(T* shared, const T* global) {
#if ASYNC_COPIES
    unsigned to = (unsigned)__cvta_generic_to_shared(shared);
    asm volatile("cp.async.ca.shared.global [%0], [%1], %2;\n" ::"r"(to), "l"(global), "n"((int)sizeof(T)) : "memory");
#else
    *shared = *global;
#endif
}

// Closes the group of copies this thread has issued since the last group.
__device__ __forceinline__ void commit_copies() {
#if ASYNC_COPIES
    asm volatile("cp.async.commit_group;\n" ::: "memory");
#endif
}

// Waits until at most PENDING of this thread's groups of copies are in flight (a `__syncwarp`
// after it makes the lanes' copies visible to each other).
template <int PENDING>
__device__ __forceinline__ void wait_copies() {
#if ASYNC_COPIES
    asm volatile("cp.async.wait_group %0;\n" ::"n"(PENDING) : "memory");
#endif
}

// `gather` with asynchronous copies: nothing waits for a load, so every element of the spans
// is in flight at once.
template <typename T, int PER>
__device__ __forceinline__ void gather_async(const T* __restrict__ global, T* staged, const Stage<T>& st,
                                             unsigned lane) {
    constexpr int W = PER * Span<T>::len;
#pragma unroll 4
    for (int t = 0; t < W; ++t) {
        unsigned idx = t * 32 + lane, l = idx / W, i = idx % W;
        if ((int)i < PER * st.len[l]) copy_async(&staged[l * (W + 1) + i], &global[PER * st.start[l] + i]);
    }
}

// The reverse of `gather`: the staged spans back out to `global`.
template <typename T, int PER>
__device__ __forceinline__ void scatter(T* __restrict__ global, const T* staged, const Stage<T>& st, unsigned lane) {
    constexpr int W = PER * Span<T>::len;
#pragma unroll 4
    for (int t = 0; t < W; ++t) {
        unsigned idx = t * 32 + lane, l = idx / W, i = idx % W;
        if ((int)i < PER * st.len[l]) global[PER * st.start[l] + i] = staged[l * (W + 1) + i];
    }
}

// Sets this lane's span for the step (`len` 0 for none) and stages the warp's spans: at once
// (`stage_in<false>`), or issued as asynchronous copies that nothing waits for here
// (`stage_in<true>`, for the pipeline and the asynchronous stage; completed by `wait_copies`).
template <bool ASYNC, typename T>
__device__ __forceinline__ void stage_in(const T* __restrict__ sigma, const T* __restrict__ delta,
                                         const T* __restrict__ color, u64 warp_start, u64 s0, int len,
                                         Stage<T>& st, unsigned lane) {
    st.start[lane] = (unsigned)(s0 - warp_start);
    st.len[lane] = len;
    __syncwarp();
    if constexpr (ASYNC) {
        gather_async<T, 1>(sigma + warp_start, st.sigma, st, lane);
        gather_async<T, 1>(delta + warp_start, st.delta, st, lane);
        gather_async<T, 3>(color + 3 * warp_start, st.color, st, lane);
    } else {
        gather<T, 1>(sigma + warp_start, st.sigma, st, lane);
        gather<T, 1>(delta + warp_start, st.delta, st, lane);
        gather<T, 3>(color + 3 * warp_start, st.color, st, lane);
        __syncwarp();
    }
}

// The staging of a step that is not pipelined: `stage_in` at once, or all of it posted as
// asynchronous copies and then waited for.
template <typename T>
__device__ __forceinline__ void stage_step(const T* __restrict__ sigma, const T* __restrict__ delta,
                                           const T* __restrict__ color, u64 warp_start, u64 s0, int len,
                                           Stage<T>& st, unsigned lane) {
#if ASYNC_STAGE
    stage_in<true>(sigma, delta, color, warp_start, s0, len, st, lane);
    commit_copies();
    wait_copies<0>();
    __syncwarp();
#else
    stage_in<false>(sigma, delta, color, warp_start, s0, len, st, lane);
#endif
}

// The warp's step count: its longest ray's span count.
__device__ __forceinline__ u64 warp_max(u64 v) {
#pragma unroll
    for (int o = 16; o > 0; o >>= 1) {
        u64 other = __shfl_xor_sync(0xffffffffu, v, o);
        v = other > v ? other : v;
    }
    return v;
}

// The running optical depth is summed as the CPU op sums it (attenuation.rs,
// `exclusive_prefix_sums`): in groups of 4 from the ray's first sample, the depth before each
// sample of a group being the group's start plus the partial sum of the group (one addition
// per group on the running total, not one per sample: on a 1e5-sample ray this is what keeps
// T within 1e-12 of the CPU op's), and the last len % 4 samples one at a time. Every depth
// then has the CPU op's bits. SPAN and CHUNK are multiples of 4, so spans and chunks start
// at group starts.
template <typename T>
__device__ __forceinline__ void forward(const u64* __restrict__ offsets, u64 rays, const T* __restrict__ sigma,
                                        const T* __restrict__ delta, const T* __restrict__ color,
                                        const T* __restrict__ background, T* __restrict__ out_color,
                                        T* __restrict__ out_opacity, double* __restrict__ chunk_depth,
                                        unsigned* __restrict__ invalid) {
    constexpr int SPAN = Span<T>::len, SPANS = Span<T>::chunks;
    __shared__ Stage<T> stage[WARPS][STAGES];
    unsigned lane = threadIdx.x & 31u, wid = threadIdx.x >> 5;
    u64 first = (u64)blockIdx.x * BLOCK + wid * 32;
    // No block-wide barrier below: a warp with no ray leaves.
    if (first >= rays) return;
    u64 r = first + lane;
    bool active = r < rays;
    u64 warp_start = offsets[first];
    u64 start = 0, end = 0, spans = 0;
    if (active) {
        start = offsets[r];
        end = offsets[r + 1];
        spans = (end - start + SPAN - 1) / SPAN;
    }
    u64 base = chunk_base(start, r);
    u64 steps = warp_max(spans);
    // This lane's span in step j (the j-th from the front): its first sample, and its length
    // (0: none).
    auto span = [&](u64 j, u64& s0) -> int {
        s0 = start + j * SPAN;
        return j < spans ? ((end - s0 < SPAN) ? (int)(end - s0) : SPAN) : 0;
    };
#if PIPELINED
    if (steps > 0) {
        u64 s0;
        int m = span(0, s0);
        stage_in<true>(sigma, delta, color, warp_start, s0, m, stage[wid][0], lane);
        commit_copies();
    }
#endif
    double running = 0.0, c0 = 0.0, c1 = 0.0, c2 = 0.0;
    bool ok = true;
    for (u64 j = 0; j < steps; ++j) {
        Stage<T>& st = stage[wid][j % STAGES];
        u64 s0;
        int m = span(j, s0);
#if PIPELINED
        // The next step's spans go out before this step's are waited for.
        if (j + 1 < steps) {
            u64 s1;
            int m1 = span(j + 1, s1);
            stage_in<true>(sigma, delta, color, warp_start, s1, m1, stage[wid][(j + 1) % STAGES], lane);
            commit_copies();
            wait_copies<1>();
        } else {
            wait_copies<0>();
        }
        __syncwarp();
#else
        stage_step(sigma, delta, color, warp_start, s0, m, st, lane);
#endif
        const T* my_sigma = &st.sigma[lane * (SPAN + 1)];
        const T* my_delta = &st.delta[lane * (SPAN + 1)];
        const T* my_color = &st.color[lane * (3 * SPAN + 1)];
#pragma unroll
        for (int g = 0; g < SPAN; g += 4) {
            if (g < m && g % CHUNK == 0) chunk_depth[base + j * SPANS + g / CHUNK] = running;
            if (g + 4 <= m) {
                double t0 = tau_of(my_sigma, my_delta, g, ok), t1 = tau_of(my_sigma, my_delta, g + 1, ok);
                double t2 = tau_of(my_sigma, my_delta, g + 2, ok), t3 = tau_of(my_sigma, my_delta, g + 3, ok);
                double p1 = t0 + t1, p2 = p1 + t2, p3 = p2 + t3;
                add_sample(my_color, g, running, t0, c0, c1, c2, ok);
                add_sample(my_color, g + 1, running + t0, t1, c0, c1, c2, ok);
                add_sample(my_color, g + 2, running + p1, t2, c0, c1, c2, ok);
                add_sample(my_color, g + 3, running + p2, t3, c0, c1, c2, ok);
                running += p3;
            } else {
                // The ray's last len % 4 samples, one at a time.
#pragma unroll
                for (int i = g; i < g + 4; ++i) {
                    if (i < m) {
                        double t = tau_of(my_sigma, my_delta, i, ok);
                        add_sample(my_color, i, running, t, c0, c1, c2, ok);
                        running += t;
                    }
                }
            }
        }
        // Before the next step overwrites the spans and the lanes' bounds.
        __syncwarp();
    }
    if (active) {
        double t_end = exp(-running);
        out_color[3 * r] = (T)fma(t_end, (double)background[0], c0);
        out_color[3 * r + 1] = (T)fma(t_end, (double)background[1], c1);
        out_color[3 * r + 2] = (T)fma(t_end, (double)background[2], c2);
        // Not 1 - T_end, which is 0 for a faint ray.
        out_opacity[r] = (T)(-expm1(-running));
    }
    if (!ok) atomicOr(invalid, 1u);
}

// The backward of one chunk of `m` samples (staged at `sigma`, `delta`, `color`), whose first
// sample lies behind the optical depth `running` (the forward's residual): its gradients
// replace the staged values. `behind` and `t_next` carry the recurrence from the chunk behind;
// `last` says this is the ray's last chunk, whose depth sum gives T_end.
template <typename T>
__device__ __forceinline__ void backward_chunk(T* sigma, T* delta, T* color, int m, double running, bool last,
                                               double g0, double g1, double g2, double go, double& behind,
                                               double& t_next, double& t_end) {
    // Depths before each sample of the chunk, front to back in registers (unrolled: constant
    // indices), grouped as in the forward so that they have its bits.
    double dep[CHUNK];
    bool unused = true;
#pragma unroll
    for (int g = 0; g < CHUNK; g += 4) {
        if (g + 4 <= m) {
            double t0 = tau_of(sigma, delta, g, unused), t1 = tau_of(sigma, delta, g + 1, unused);
            double t2 = tau_of(sigma, delta, g + 2, unused), t3 = tau_of(sigma, delta, g + 3, unused);
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
                    running += tau_of(sigma, delta, i, unused);
                }
            }
        }
    }
    if (last) {
        // `running` is now the whole ray's optical depth.
        t_end = exp(-running);
        t_next = t_end;
    }
#pragma unroll
    for (int i = CHUNK - 1; i >= 0; --i) {
        if (i < m) {
            T s = sigma[i], d = delta[i];
            double tau = (double)s * (double)d;
            double alpha = absorbed<T>(tau);
            double t_k = transmittance<T>(dep[i]);
            double c0 = (double)color[3 * i], c1 = (double)color[3 * i + 1], c2 = (double)color[3 * i + 2];
            double v = g0 * c0 + g1 * c1 + g2 * c2 + go;
            double diff = v - behind;
            // What the sample adds minus what it hides.
            double g_tau = t_next * diff;
            // The gradients over the sample's inputs, which it no longer needs.
            sigma[i] = (T)((double)d * g_tau);
            delta[i] = (T)((double)s * g_tau);
            double w = t_k * alpha;
            color[3 * i] = (T)(w * g0);
            color[3 * i + 1] = (T)(w * g1);
            color[3 * i + 2] = (T)(w * g2);
            behind = fma(alpha, diff, behind);
            t_next = t_k;
        }
    }
}

template <typename T>
__device__ __forceinline__ void backward(const u64* __restrict__ offsets, u64 rays, const T* __restrict__ sigma,
                                         const T* __restrict__ delta, const T* __restrict__ color,
                                         const T* __restrict__ background, const T* __restrict__ d_color,
                                         const T* __restrict__ d_opacity, int has_d_opacity,
                                         const double* __restrict__ chunk_depth, T* __restrict__ g_sigma,
                                         T* __restrict__ g_delta, T* __restrict__ g_color,
                                         double* __restrict__ bg_partial, u64 partials) {
    constexpr int SPAN = Span<T>::len, SPANS = Span<T>::chunks;
    __shared__ Stage<T> stage[WARPS][STAGES];
    unsigned lane = threadIdx.x & 31u, wid = threadIdx.x >> 5;
    u64 first = (u64)blockIdx.x * BLOCK + wid * 32;
    // No block-wide barrier: a warp past the partial sums leaves; one past the rays but not
    // the partial sums (no ray at all) takes no step and writes zeros.
    if (first / 32 >= partials) return;
    u64 r = first + lane;
    bool active = r < rays;
    u64 warp_start = first < rays ? offsets[first] : 0;
    u64 start = 0, end = 0, spans = 0;
    double g0 = 0.0, g1 = 0.0, g2 = 0.0, go = 0.0, behind = 0.0;
    if (active) {
        start = offsets[r];
        end = offsets[r + 1];
        spans = (end - start + SPAN - 1) / SPAN;
        g0 = (double)d_color[3 * r];
        g1 = (double)d_color[3 * r + 1];
        g2 = (double)d_color[3 * r + 2];
        go = has_d_opacity ? (double)d_opacity[r] : 0.0;
        behind = g0 * (double)background[0] + g1 * (double)background[1] + g2 * (double)background[2];
    }
    u64 base = chunk_base(start, r);
    u64 steps = warp_max(spans);
    // This lane's span in step j (the j-th from the back): its index, first sample and length
    // (0: none).
    auto span = [&](u64 j, u64& c, u64& s0) -> int {
        bool has = j < spans;
        c = has ? spans - 1 - j : 0;
        s0 = start + c * SPAN;
        return has ? ((end - s0 < SPAN) ? (int)(end - s0) : SPAN) : 0;
    };
#if PIPELINED
    // The depths before the span's chunks (the forward's residual) travel with the span.
    __shared__ double depths[WARPS][STAGES][32 * SPANS];
    auto post_step = [&](u64 j) {
        u64 c, s0;
        int m = span(j, c, s0);
        int k = (int)(j % STAGES);
        stage_in<true>(sigma, delta, color, warp_start, s0, m, stage[wid][k], lane);
#pragma unroll
        for (int h = 0; h < SPANS; ++h) {
            if (h * CHUNK < m) copy_async(&depths[wid][k][lane * SPANS + h], &chunk_depth[base + c * SPANS + h]);
        }
        commit_copies();
    };
    if (steps > 0) post_step(0);
#endif
    double t_end = 1.0, t_next = 1.0;
    for (u64 j = 0; j < steps; ++j) {
        Stage<T>& st = stage[wid][j % STAGES];
        u64 c, s0;
        int m = span(j, c, s0);
#if PIPELINED
        // The next step's spans go out before this step's are waited for.
        if (j + 1 < steps) {
            post_step(j + 1);
            wait_copies<1>();
        } else {
            wait_copies<0>();
        }
        __syncwarp();
        const double* my_depth = &depths[wid][j % STAGES][lane * SPANS];
#else
        stage_step(sigma, delta, color, warp_start, s0, m, st, lane);
        const double* my_depth = &chunk_depth[base + c * SPANS];
#endif
        T* my_sigma = &st.sigma[lane * (SPAN + 1)];
        T* my_delta = &st.delta[lane * (SPAN + 1)];
        T* my_color = &st.color[lane * (3 * SPAN + 1)];
        // The span's chunks, back to front.
#pragma unroll
        for (int h = SPANS - 1; h >= 0; --h) {
            int mh = m - h * CHUNK;
            if (mh > 0) {
                bool last = j == 0 && (h + 1) * CHUNK >= m;
                backward_chunk(my_sigma + h * CHUNK, my_delta + h * CHUNK, my_color + 3 * h * CHUNK,
                               mh < CHUNK ? mh : CHUNK, my_depth[h], last, g0, g1, g2, go, behind, t_next, t_end);
            }
        }
        __syncwarp();
        // Coalesced stores of the warp's gradients.
        scatter<T, 1>(g_sigma + warp_start, st.sigma, st, lane);
        scatter<T, 1>(g_delta + warp_start, st.delta, st, lane);
        scatter<T, 3>(g_color + 3 * warp_start, st.color, st, lane);
        // Before the next step overwrites the spans and the lanes' bounds.
        __syncwarp();
    }
    double gb0 = 0.0, gb1 = 0.0, gb2 = 0.0;
    if (active) {
        gb0 = t_end * g0;
        gb1 = t_end * g1;
        gb2 = t_end * g2;
    }
    // The shared background's gradient: a fixed-order tree sum over the warp's 32 rays (the
    // same bits at any block size), the warps' sums added by `reduce_background`.
#pragma unroll
    for (int o = 16; o > 0; o >>= 1) {
        gb0 += __shfl_down_sync(0xffffffffu, gb0, o);
        gb1 += __shfl_down_sync(0xffffffffu, gb1, o);
        gb2 += __shfl_down_sync(0xffffffffu, gb2, o);
    }
    if (lane == 0) {
        bg_partial[3 * (first / 32)] = gb0;
        bg_partial[3 * (first / 32) + 1] = gb1;
        bg_partial[3 * (first / 32) + 2] = gb2;
    }
}

// Threads of the background gradient's reduction, a power of 2 (`REDUCE_BLOCK` on the host,
// which launches it).
#ifndef REDUCE
#define REDUCE 256
#endif

template <typename T>
__device__ __forceinline__ void reduce_background(const double* __restrict__ bg_partial, u64 partials,
                                                  T* __restrict__ g_background) {
    __shared__ double red[3][REDUCE];
    unsigned tid = threadIdx.x;
    double a0 = 0.0, a1 = 0.0, a2 = 0.0;
    for (u64 b = tid; b < partials; b += REDUCE) {
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
        T* g_delta, T* g_color, double* bg_partial, u64 partials) {                                                 \
        backward<T>(offsets, rays, sigma, delta, color, background, d_color, d_opacity, has_d_opacity, chunk_depth, \
                    g_sigma, g_delta, g_color, bg_partial, partials);                                               \
    }                                                                                                               \
    extern "C" __global__ void __launch_bounds__(REDUCE)                                                            \
        composite_reduce_background_##SUFFIX(const double* bg_partial, u64 partials, T* g_background) {             \
        reduce_background<T>(bg_partial, partials, g_background);                                                   \
    }

INSTANTIATE(float, f32)
INSTANTIATE(double, f64)
