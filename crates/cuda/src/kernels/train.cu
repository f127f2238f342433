// The parts of a dense grid's training step that are not ops: drawing a batch of rays,
// placing their samples and packing the ones an occupancy grid keeps, the occupancy grid's
// refresh, the photometric and distortion losses with their gradients, the lattice a grid is
// resampled at, and Adam. Compiled at run time by NVRTC (see `src/kernel.rs`), so it includes
// no header. f32 data.

typedef unsigned long long u64;
typedef long long i64;

struct Box {
    double min[3];
    double max[3];
};

// splitmix64: a well-mixed 64-bit hash of a counter.
__device__ __forceinline__ u64 mix(u64 x) {
    x += 0x9e3779b97f4a7c15ull;
    x = (x ^ (x >> 30)) * 0xbf58476d1ce4e5b9ull;
    x = (x ^ (x >> 27)) * 0x94d049bb133111ebull;
    return x ^ (x >> 31);
}

// A uniform double in [0, 1) from 53 bits of a hash.
__device__ __forceinline__ double unit(u64 h) { return (double)(h >> 11) * (1.0 / 9007199254740992.0); }

// The occupancy grid: `cells` per axis over the box (0: none, every sample kept), one byte a
// cell (nonzero: occupied), and `scale = cells / (max - min)` per axis.
struct Cells {
    double min[3];
    double scale[3];
    u64 cells;
};

// Whether the sample at `p` (its f32 coordinates) lies in an occupied cell.
__device__ __forceinline__ bool occupied(const Cells& g, const unsigned char* __restrict__ occ, const float p[3]) {
    if (g.cells == 0) return true;
    u64 cell = 0;
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        double u = __dmul_rn((double)p[a] - g.min[a], g.scale[a]);
        i64 i = (i64)floor(u);
        i = i < 0 ? 0 : (i >= (i64)g.cells ? (i64)g.cells - 1 : i);
        cell = cell * g.cells + (u64)i;
    }
    return occ[cell] != 0;
}

// Sample k of ray r's `samples` samples between where it enters and leaves the box, at the
// centres of equal steps shifted by `offset` in [0, 1) of a step (0.5: the centres): its
// position and step length (and, with `write_dirs`, its view direction, the ray's). A ray that
// misses the box gets steps of length 0 (nothing), at its origin. One thread a sample: each
// finds its ray's chord itself, which costs less than leaving the device idle with a thread a
// ray.
__device__ __forceinline__ void sample_one(const float* __restrict__ origins, const float* __restrict__ dirs, u64 r,
                                           Box box, u64 samples, u64 k, double offset, float* __restrict__ position,
                                           float* __restrict__ delta, float* __restrict__ t_out, u64 write_dirs,
                                           float* __restrict__ dir_out, Cells cells,
                                           const unsigned char* __restrict__ occ) {
    double o[3], d[3];
    double t0 = 0.0, t1 = 1e300;
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        o[a] = (double)origins[3 * r + a];
        d[a] = (double)dirs[3 * r + a];
        double inv = 1.0 / d[a];
        double lo = (box.min[a] - o[a]) * inv, hi = (box.max[a] - o[a]) * inv;
        if (lo > hi) {
            double s = lo;
            lo = hi;
            hi = s;
        }
        // A direction parallel to the axis: inside the slab (infinite bounds) or not (NaN
        // when the origin sits on a face; treated as inside).
        if (lo == lo) t0 = fmax(t0, lo);
        if (hi == hi) t1 = fmin(t1, hi);
    }
    bool hit = t1 > t0;
    double step = hit ? (t1 - t0) / (double)samples : 0.0;
    double t = t0 + ((double)k + offset) * step;
    float p[3];
#pragma unroll
    for (int a = 0; a < 3; ++a) p[a] = (float)(o[a] + t * d[a]);
    // A sample in an empty cell is skipped: no length (it adds nothing and gets no gradient)
    // and a position past the box (the lookup reads no node for it).
    bool keep = occupied(cells, occ, p);
#pragma unroll
    for (int a = 0; a < 3; ++a) position[a] = keep ? p[a] : __int_as_float(0x7f800000);
    *delta = keep ? (float)step : 0.0f;
    // The midpoint's distance along the ray (for the distortion loss).
    *t_out = (float)t;
    if (write_dirs) {
#pragma unroll
        for (int a = 0; a < 3; ++a) dir_out[a] = dirs[3 * r + a];
    }
}

// The hash of batch ray b at `step`: it picks the ray, its samples' offset and its random
// background.
__device__ __forceinline__ u64 batch_hash(u64 seed, u64 step, u64 b) {
    return mix(seed ^ mix(step * 0x100000001b3ull + b));
}

// Batch ray b takes ray picked[b] = hash(seed, step, b) mod rays, with a random offset of its
// samples (stratified sampling: every point of a ray is sampled over the steps). One thread a
// sample of the `batch * samples`.
extern "C" __global__ void sample_batch(const float* origins, const float* dirs, u64 rays, u64 batch, u64 samples,
                                        u64 seed, u64 step, Box box, float* positions, float* delta, float* ts,
                                        u64* picked, u64 write_dirs, float* sample_dirs, Cells cells,
                                        const unsigned char* occ) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= batch * samples) return;
    u64 b = i / samples, k = i % samples;
    u64 h = batch_hash(seed, step, b);
    u64 r = h % rays;
    if (k == 0) picked[b] = r;
    sample_one(origins, dirs, r, box, samples, k, unit(mix(h)), positions + 3 * i, delta + i, ts + i, write_dirs,
               sample_dirs + (write_dirs ? 3 * i : 0), cells, occ);
}

// Rays first .. first + count, sampled at the centres of their steps (for rendering); one
// thread a sample of the `count * samples`.
extern "C" __global__ void sample_range(const float* origins, const float* dirs, u64 first, u64 count, u64 samples,
                                        Box box, float* positions, float* delta, float* ts, u64 write_dirs,
                                        float* sample_dirs, Cells cells, const unsigned char* occ) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= count * samples) return;
    u64 b = i / samples, k = i % samples;
    sample_one(origins, dirs, first + b, box, samples, k, 0.5, positions + 3 * i, delta + i, ts + i, write_dirs,
               sample_dirs + (write_dirs ? 3 * i : 0), cells, occ);
}

// Compaction: the samples of nonzero length (those in occupied cells of rays that cross the
// box) are packed ray by ray, in order, so that everything after the sampling runs on them
// alone. One block of COMPACT_THREADS threads a ray, over its `samples` samples in chunks.
#define COMPACT_THREADS 256

// The rank of this thread's `flag` among the chunk's (an exclusive count of the flags before
// it) and the chunk's count, by warp ballots and the warps' counts in shared memory.
__device__ __forceinline__ unsigned chunk_rank(bool flag, unsigned& count) {
    __shared__ unsigned warp_counts[COMPACT_THREADS / 32];
    unsigned lane = threadIdx.x % 32, warp = threadIdx.x / 32;
    unsigned ballot = __ballot_sync(0xffffffffu, flag);
    unsigned rank = __popc(ballot & ((1u << lane) - 1u));
    if (lane == 0) warp_counts[warp] = __popc(ballot);
    __syncthreads();
    unsigned before = 0;
    count = 0;
    for (unsigned w = 0; w < COMPACT_THREADS / 32; ++w) {
        if (w < warp) before += warp_counts[w];
        count += warp_counts[w];
    }
    __syncthreads();
    return before + rank;
}

// counts[b] = ray b's samples of nonzero length.
extern "C" __global__ void __launch_bounds__(COMPACT_THREADS)
    count_kept(const float* delta, u64 samples, u64* counts) {
    u64 b = blockIdx.x;
    unsigned total = 0;
    for (u64 c = 0; c < samples; c += COMPACT_THREADS) {
        u64 k = c + threadIdx.x;
        bool keep = k < samples && delta[b * samples + k] > 0.0f;
        unsigned count;
        chunk_rank(keep, count);
        total += count;
    }
    if (threadIdx.x == 0) counts[b] = total;
}

// offsets[0] = 0, offsets[b + 1] = offsets[b] + counts[b]: the exclusive scan of the rays'
// counts, in one block of 1024 threads (each scans a run of consecutive rays, then the runs'
// sums are scanned in shared memory).
extern "C" __global__ void __launch_bounds__(1024) scan_offsets(const u64* counts, u64 rays, u64* offsets) {
    __shared__ u64 sums[1024];
    u64 per = (rays + 1023) / 1024;
    u64 first = threadIdx.x * per, end = first + per < rays ? first + per : rays;
    u64 run = 0;
    for (u64 b = first; b < end; ++b) run += counts[b];
    sums[threadIdx.x] = run;
    __syncthreads();
    if (threadIdx.x == 0) {
        u64 acc = 0;
        for (int t = 0; t < 1024; ++t) {
            u64 v = sums[t];
            sums[t] = acc;
            acc += v;
        }
        offsets[0] = 0;
    }
    __syncthreads();
    u64 at = sums[threadIdx.x];
    for (u64 b = first; b < end; ++b) {
        at += counts[b];
        offsets[b + 1] = at;
    }
}

// Packs ray b's kept samples (positions, lengths, midpoints, and with `with_dirs` directions)
// from the full buffers into the compact ones, at offsets[b] on.
extern "C" __global__ void __launch_bounds__(COMPACT_THREADS)
    compact(const float* positions, const float* delta, const float* ts, const float* dirs, u64 with_dirs,
            u64 samples, const u64* offsets, float* c_positions, float* c_delta, float* c_ts, float* c_dirs) {
    u64 b = blockIdx.x;
    u64 at = offsets[b];
    for (u64 c = 0; c < samples; c += COMPACT_THREADS) {
        u64 k = c + threadIdx.x;
        u64 i = b * samples + k;
        bool keep = k < samples && delta[i] > 0.0f;
        unsigned count;
        unsigned rank = chunk_rank(keep, count);
        if (keep) {
            u64 o = at + rank;
#pragma unroll
            for (int a = 0; a < 3; ++a) c_positions[3 * o + a] = positions[3 * i + a];
            c_delta[o] = delta[i];
            c_ts[o] = ts[i];
            if (with_dirs) {
#pragma unroll
                for (int a = 0; a < 3; ++a) c_dirs[3 * o + a] = dirs[3 * i + a];
            }
        }
        at += count;
    }
}

struct Rgb {
    double c[3];
};

// L = sum over the batch's rays and channels of (C - target)^2 / (3 batch), where the batch was
// composited over black: `color0` and `opacity` are its colour and opacity, and the ray's
// colour over its background `bg` is `C = color0 + (1 - opacity) bg`. The background is
// `background` (the colour the targets were composited over), or with `random`, a uniform
// colour drawn from the ray's hash, the target then recomposited over it from its opacity
// `alpha` (`target + (bg - background) (1 - alpha)`). Writes dL/dcolor0 = dL/dC and
// dL/dopacity = -sum_c dL/dC_c bg_c, and adds the sum of squares to `sse` (zeroed by the host).
extern "C" __global__ void photometric_loss(const float* color0, const float* opacity, const float* targets,
                                            const float* alpha, u64 random, const u64* picked, u64 batch,
                                            u64 seed, u64 step, Rgb background, float* d_color,
                                            float* d_opacity, double* sse) {
    u64 b = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (b >= batch) return;
    u64 r = picked[b];
    u64 h = batch_hash(seed, step, b);
    double seen = 1.0 - (double)opacity[b];
    double unseen = random ? 1.0 - (double)alpha[r] : 0.0;
    double sum = 0.0, d_seen = 0.0;
    double scale = 2.0 / (3.0 * (double)batch);
#pragma unroll
    for (int c = 0; c < 3; ++c) {
        double bg = random ? unit(mix(h + 1 + (u64)c)) : background.c[c];
        double target = (double)targets[3 * r + c] + (bg - background.c[c]) * unseen;
        double diff = (double)color0[3 * b + c] + seen * bg - target;
        double g = scale * diff;
        d_color[3 * b + c] = (float)g;
        d_seen += g * bg;
        sum += diff * diff;
    }
    d_opacity[b] = (float)(-d_seen);
    atomicAdd(sse, sum);
}

// The nodes of a `nodes`^3 lattice over the box, row-major (the first axis slowest), as
// positions `[nodes^3, 3]`: node i sits at `min + i (max - min) / (nodes - 1)`, the last on
// the max face exactly.
extern "C" __global__ void lattice(Box box, u64 nodes, float* positions) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= nodes * nodes * nodes) return;
    u64 idx[3] = {i / (nodes * nodes), (i / nodes) % nodes, i % nodes};
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        double span = box.max[a] - box.min[a];
        double p = idx[a] + 1 == nodes ? box.max[a]
                                       : __dadd_rn(box.min[a], __dmul_rn((double)idx[a], span / (double)(nodes - 1)));
        positions[3 * i + a] = (float)p;
    }
}

// The distortion loss of mip-NeRF 360 (`fogray_ops::distortion`) of each batch ray (its
// samples `offsets[b]..offsets[b + 1]`), times `c` (the loss's weight over the batch's ray
// count): its gradient with respect to the densities is added to `d_sigma`, and its value to
// `loss` (zeroed by the host). One thread a ray, in two passes over its samples with the CPU
// op's numerics: front to back, the weights `w` from the running optical depth and
// `A_i = A_{i-1} + S_{<i} (t_i - t_{i-1})`; back to front, `B_i = B_{i+1} + S_{>i} (t_{i+1} - t_i)`,
// `g_i = c (2 A_i + 2 B_i + (2/3) w_i delta_i)` and
// `dL/dsigma_j = delta_j T_{j+1} (g_j - R_{j+1})`, `R_j = R_{j+1} + alpha_j (g_j - R_{j+1})`.
// `w`, `A` and the optical depth after each sample are kept in the f64 scratch buffers
// (a value a sample) between the passes.
extern "C" __global__ void distortion(const float* sigma, const float* delta, const float* ts, const u64* offsets,
                                      u64 batch, double c, double* w_s, double* a_s, double* depth_s,
                                      float* d_sigma, double* loss) {
    u64 b = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (b >= batch) return;
    u64 first = offsets[b], end = offsets[b + 1];
    double depth = 0.0, S = 0.0, A = 0.0, sum = 0.0;
    for (u64 k = first; k < end; ++k) {
        double tau = (double)sigma[k] * (double)delta[k];
        double w = exp(-depth) * -expm1(-tau);
        if (k > first) A += S * ((double)ts[k] - (double)ts[k - 1]);
        sum += 2.0 * w * A + w * w * (double)delta[k] / 3.0;
        S += w;
        depth += tau;
        w_s[k] = w;
        a_s[k] = A;
        depth_s[k] = depth;
    }
    double S_after = 0.0, B = 0.0, R = 0.0;
    for (u64 k = end; k-- > first;) {
        if (k + 1 < end) {
            S_after += w_s[k + 1];
            B += S_after * ((double)ts[k + 1] - (double)ts[k]);
        }
        double w = w_s[k];
        double dk = (double)delta[k];
        double g = c * (2.0 * a_s[k] + 2.0 * B + (2.0 / 3.0) * w * dk);
        double tau = (double)sigma[k] * dk;
        double alpha = -expm1(-tau);
        d_sigma[k] = (float)((double)d_sigma[k] + dk * exp(-depth_s[k]) * (g - R));
        R += alpha * (g - R);
    }
    atomicAdd(loss, c * sum);
}

// The points at which a refresh reads each cell's density: its centre (row 2 i) and a point
// drawn uniformly in it by the hash of (seed, refresh, i) (row 2 i + 1), as positions.
extern "C" __global__ void occupancy_points(Cells g, u64 seed, u64 refresh, float* positions) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    u64 n = g.cells * g.cells * g.cells;
    if (i >= n) return;
    u64 idx[3] = {i / (g.cells * g.cells), (i / g.cells) % g.cells, i % g.cells};
    u64 h = mix(seed ^ mix(0x5bd1e995ull * (refresh + 1) + i));
#pragma unroll
    for (int a = 0; a < 3; ++a) {
        // Rounded step by step (no fused multiply-add), so that the host can recompute them.
        double side = 1.0 / g.scale[a];
        double centre = __dadd_rn((double)idx[a], 0.5), random = __dadd_rn((double)idx[a], unit(mix(h + (u64)a)));
        positions[6 * i + a] = (float)__dadd_rn(g.min[a], __dmul_rn(centre, side));
        positions[6 * i + 3 + a] = (float)__dadd_rn(g.min[a], __dmul_rn(random, side));
    }
}

// softplus(x) = max(x, 0) + ln(1 + exp(-|x|)), as the activation computes it.
__device__ __forceinline__ double softplus(double x) { return fmax(x, 0.0) + log1p(exp(-fabs(x))); }

// A refresh: each cell's estimate becomes max(estimate * decay, the larger density of its two
// points) (raw rows `[2 cells^3, channels]` from the lookup at `occupancy_points`), and the
// cell is occupied while its estimate exceeds `threshold`.
extern "C" __global__ void occupancy_update(const float* raw, u64 channels, u64 n, double shift, double decay,
                                            double threshold, float* estimate, unsigned char* occ) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    double fresh = fmax(softplus((double)raw[2 * i * channels] + shift),
                        softplus((double)raw[(2 * i + 1) * channels] + shift));
    double e = fmax((double)estimate[i] * decay, fresh);
    estimate[i] = (float)e;
    occ[i] = (float)e > threshold ? 1 : 0;
}

// Adam with bias-corrected moments (`c1 = 1 - beta1^t`, `c2 = 1 - beta2^t`) on the gradient
// the grid's scatter summed into `acc` (in f64; rounded once to f32 here, as the grid's
// backward rounds it, and kept in `g` when `keep_g`), which is zeroed for the next step. An
// entry whose gradient is exactly 0 this step (no kept sample reached it) keeps its value and
// moments, as instant-ngp skips them: the step's cost follows the cells the rays reach, not
// the cube (the untouched entries cost the read of their sum alone).
extern "C" __global__ void adam(float* __restrict__ x, double* __restrict__ acc, float* __restrict__ g, u64 keep_g,
                                float* __restrict__ m, float* __restrict__ v, u64 n, double lr, double beta1,
                                double beta2, double eps, double c1, double c2) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    double sum = acc[i];
    float rounded = (float)sum;
    if (keep_g) g[i] = rounded;
    if (sum != 0.0) acc[i] = 0.0;
    if (rounded == 0.0f) return;
    double gi = (double)rounded, m0 = (double)m[i], v0 = (double)v[i], x0 = (double)x[i];
    double mi = beta1 * m0 + (1.0 - beta1) * gi;
    double vi = beta2 * v0 + (1.0 - beta2) * gi * gi;
    m[i] = (float)mi;
    v[i] = (float)vi;
    x[i] = (float)(x0 - lr * (mi / c1) / (sqrt(vi / c2) + eps));
}
