# The composite as a PyTorch user writes it, timed with CUDA events (the anchor of reports/cuda).
import time, torch
R, S = 1048576, 64
dev = "cuda"
print(torch.__version__, torch.cuda.get_device_name(0), flush=True)
g = torch.Generator(device=dev).manual_seed(0)
sigma = (torch.rand(R, S, device=dev, generator=g) * 5).requires_grad_()
delta = torch.full((R, S), 0.02, device=dev).requires_grad_()
color = torch.rand(R, S, 3, device=dev, generator=g).requires_grad_()
bg = torch.ones(3, device=dev, requires_grad=True)
gC = torch.rand(R, 3, device=dev, generator=g)

def composite(sigma, delta, color, bg):
    tau = sigma * delta
    depth = torch.cumsum(tau, dim=1)
    T = torch.exp(-(depth - tau))
    alpha = -torch.expm1(-tau)
    w = T * alpha
    return (w.unsqueeze(-1) * color).sum(1) + torch.exp(-depth[:, -1:]) * bg

def step(f):
    C = f(sigma, delta, color, bg)
    (C * gC).sum().backward()

def bench(name, f):
    t0 = time.time(); step(f); torch.cuda.synchronize(); first = time.time() - t0
    for _ in range(3): step(f)
    torch.cuda.synchronize()
    a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
    a.record()
    for _ in range(20): step(f)
    b.record(); torch.cuda.synchronize()
    ms = a.elapsed_time(b) / 20
    print(f"{name}: {ms:.3f} ms fwd+bwd, {R*S/ms/1e6:.2f} G samples/s (first call {first:.1f} s)", flush=True)

bench("torch eager", composite)
bench("torch.compile", torch.compile(composite))
x = torch.empty(1 << 28, device=dev); y = torch.empty_like(x)
for _ in range(3): y.copy_(x)
torch.cuda.synchronize()
a, b = torch.cuda.Event(enable_timing=True), torch.cuda.Event(enable_timing=True)
a.record()
for _ in range(20): y.copy_(x)
b.record(); torch.cuda.synchronize()
ms = a.elapsed_time(b) / 20
print(f"device-to-device copy of 1 GiB: {ms:.3f} ms, {2 * (1 << 30) / ms / 1e6:.0f} GB/s read + written", flush=True)
