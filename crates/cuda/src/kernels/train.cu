// The parts of a dense grid's training step that are not ops: drawing a batch of rays and
// sampling them, the squared-error loss and its gradient, and Adam. Compiled at run time by
// NVRTC (see `src/kernel.rs`), so it includes no header. f32 data.

typedef unsigned long long u64;

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

// Ray r's `samples` samples between where it enters and leaves the box, at the centres of
// equal steps shifted by `offset` in [0, 1) of a step (0.5: the centres): positions and step
// lengths. A ray that misses the box gets steps of length 0 (nothing), at its origin.
__device__ __forceinline__ void sample_ray(const float* __restrict__ origins, const float* __restrict__ dirs, u64 r,
                                           Box box, u64 samples, double offset, float* __restrict__ positions,
                                           float* __restrict__ delta) {
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
    for (u64 k = 0; k < samples; ++k) {
        double t = t0 + ((double)k + offset) * step;
#pragma unroll
        for (int a = 0; a < 3; ++a) positions[3 * k + a] = (float)(o[a] + t * d[a]);
        delta[k] = (float)step;
    }
}

// Batch ray b takes ray picked[b] = hash(seed, step, b) mod rays, with a random offset of its
// samples (stratified sampling: every point of a ray is sampled over the steps).
extern "C" __global__ void sample_batch(const float* origins, const float* dirs, u64 rays, u64 batch, u64 samples,
                                        u64 seed, u64 step, Box box, float* positions, float* delta, u64* picked) {
    u64 b = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (b >= batch) return;
    u64 h = mix(seed ^ mix(step * 0x100000001b3ull + b));
    u64 r = h % rays;
    picked[b] = r;
    sample_ray(origins, dirs, r, box, samples, unit(mix(h)), positions + 3 * b * samples, delta + b * samples);
}

// Rays first .. first + count, sampled at the centres of their steps (for rendering).
extern "C" __global__ void sample_range(const float* origins, const float* dirs, u64 first, u64 count, u64 samples,
                                        Box box, float* positions, float* delta) {
    u64 b = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (b >= count) return;
    sample_ray(origins, dirs, first + b, box, samples, 0.5, positions + 3 * b * samples, delta + b * samples);
}

// L = sum over the batch's rays and channels of (C - target)^2 / (3 batch): dL/dC, and the
// sum of squares (added to `sse`, zeroed by the host) for the record.
extern "C" __global__ void squared_error(const float* color, const float* targets, const u64* picked, u64 batch,
                                         float* d_color, double* sse) {
    u64 b = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (b >= batch) return;
    double sum = 0.0;
    double scale = 2.0 / (3.0 * (double)batch);
#pragma unroll
    for (int c = 0; c < 3; ++c) {
        double diff = (double)color[3 * b + c] - (double)targets[3 * picked[b] + c];
        d_color[3 * b + c] = (float)(scale * diff);
        sum += diff * diff;
    }
    atomicAdd(sse, sum);
}

// Adam with bias-corrected moments: `c1 = 1 - beta1^t`, `c2 = 1 - beta2^t`.
extern "C" __global__ void adam(float* x, const float* g, float* m, float* v, u64 n, double lr, double beta1,
                                double beta2, double eps, double c1, double c2) {
    u64 i = (u64)blockIdx.x * blockDim.x + threadIdx.x;
    if (i >= n) return;
    double gi = (double)g[i];
    double mi = beta1 * (double)m[i] + (1.0 - beta1) * gi;
    double vi = beta2 * (double)v[i] + (1.0 - beta2) * gi * gi;
    m[i] = (float)mi;
    v[i] = (float)vi;
    x[i] = (float)((double)x[i] - lr * (mi / c1) / (sqrt(vi / c2) + eps));
}
