#!/usr/bin/env python3
"""Peer figures for the nn benchmark (benches/benches/nn.rs): PyTorch and hand-written numpy.

Trains the AutoDef "X" autoencoder (49 -> 200 -> 200 -> 6 encoder, mirrored decoder, ELU,
Glorot-uniform weights and zero biases as in the Rust crate, Adam lr 1e-3, batch 256, MSE) on
the same synthetic data recipe as `nn::synthetic::TanhManifold::autodef_x()` (the SplitMix64
stream and draw order are mirrored, so the data matches the Rust data up to libm rounding), centred
and divided by one common scale like `InputScaling::centre_uniform`. Trains on all samples (no
validation split) at 1 and at 2 threads, and times the single-vector decoder forward, VJP and
Jacobian (torch.func.jacrev, also jacfwd) in PyTorch and in plain numpy (forward-mode Jacobian).

Writes one flat JSON object (default <repo>/target/peers/torch.json, or torch_f32.json with
--dtype float32) that `cargo bench -p benches --bench nn` prints beside its own figures.

    pip install torch numpy     # CPU wheels: --index-url https://download.pytorch.org/whl/cpu
    python3 benches/peers/torch_autoencoder.py                # 1000 epochs at 1 and 2 threads
    python3 benches/peers/torch_autoencoder.py --epochs 50    # quicker, same per-epoch figures

Figures of thread counts not rerun are kept from the existing file (--fresh starts over); every
training figure records its own epoch count (train_<t>t_epochs).
"""

import argparse
import json
import math
import os
import platform
import statistics
import time
from pathlib import Path

# One BLAS thread for the single-vector numpy timings; torch's count is set explicitly below.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import numpy as np  # noqa: E402
import torch  # noqa: E402

MASK = (1 << 64) - 1
K, D, HIDDEN = 49, 6, [200, 200]


class SplitMix64:
    """Mirror of nn::SplitMix64 (next_u64 and uniform)."""

    def __init__(self, seed):
        self.state = seed & MASK

    def next_u64(self):
        self.state = (self.state + 0x9E3779B97F4A7C15) & MASK
        z = self.state
        z = ((z ^ (z >> 30)) * 0xBF58476D1CE4E5B9) & MASK
        z = ((z ^ (z >> 27)) * 0x94D049BB133111EB) & MASK
        return z ^ (z >> 31)

    def uniform(self):
        return (self.next_u64() >> 11) / float(1 << 53)


def tanh_manifold(samples, seed, ambient=K, latent=D, width=16, noise=0.01):
    """Mirror of nn::synthetic::TanhManifold::sample: returns samples x ambient (one per row)."""
    rng = SplitMix64(seed)

    def sym(n, scale):
        return [scale * (2.0 * rng.uniform() - 1.0) for _ in range(n)]

    b = sym(width * latent, 1.0)
    c = sym(width, 0.5)
    a = sym(ambient * width, 1.0 / math.sqrt(width))
    x = np.zeros((samples, ambient))
    for j in range(samples):
        z = [2.0 * rng.uniform() - 1.0 for _ in range(latent)]
        feats = []
        for m in range(width):
            s = 0.0
            for l in range(latent):
                s += b[m * latent + l] * z[l]
            feats.append(math.tanh(s + c[m]))
        for i in range(ambient):
            clean = 0.0
            for m in range(width):
                clean += a[i * width + m] * feats[m]
            u1, u2 = rng.uniform(), rng.uniform()
            normal = math.sqrt(-2.0 * math.log(1.0 - u1)) * math.cos(2.0 * math.pi * u2)
            x[j, i] = clean + noise * normal
    return x


def centre_uniform(x):
    """Mirror of InputScaling::centre_uniform: subtract the mean, divide by the RMS deviation."""
    shift = x.mean(axis=0)
    scale = math.sqrt(((x - shift) ** 2).mean(axis=0).mean())
    return (x - shift) / scale


def mlp(sizes):
    layers = []
    for i, (n_in, n_out) in enumerate(zip(sizes[:-1], sizes[1:])):
        lin = torch.nn.Linear(n_in, n_out)
        torch.nn.init.xavier_uniform_(lin.weight)
        torch.nn.init.zeros_(lin.bias)
        layers.append(lin)
        if i < len(sizes) - 2:
            layers.append(torch.nn.ELU())
    return torch.nn.Sequential(*layers)


def train(x, epochs, batch, threads, seed):
    torch.set_num_threads(threads)
    torch.manual_seed(seed)
    enc = mlp([K] + HIDDEN + [D])
    dec = mlp([D] + HIDDEN[::-1] + [K])
    opt = torch.optim.Adam(list(enc.parameters()) + list(dec.parameters()), lr=1e-3)
    gen = torch.Generator().manual_seed(seed)
    n = x.shape[0]
    start, cpu_start = time.perf_counter(), time.process_time()
    for _ in range(epochs):
        perm = torch.randperm(n, generator=gen)
        for i in range(0, n, batch):
            xb = x[perm[i : i + batch]]
            opt.zero_grad(set_to_none=True)
            loss = torch.nn.functional.mse_loss(dec(enc(xb)), xb)
            loss.backward()
            opt.step()
    seconds, cpu = time.perf_counter() - start, time.process_time() - cpu_start
    with torch.no_grad():
        mse = torch.nn.functional.mse_loss(dec(enc(x)), x).item()
    return seconds, cpu, mse


def timings_ns(f, rounds=301, reps=20):
    """(median, best) nanoseconds per call over `rounds` rounds of `reps` calls; the best round
    is the robust figure on a shared machine."""
    for _ in range(reps):
        f()
    times = []
    for _ in range(rounds):
        t0 = time.perf_counter_ns()
        for _ in range(reps):
            f()
        times.append((time.perf_counter_ns() - t0) / reps)
    return statistics.median(times), min(times)


def time_decoder(dtype, seed):
    torch.set_num_threads(1)
    torch.manual_seed(seed + 1)
    dec = mlp([D] + HIDDEN[::-1] + [K]).to(dtype)
    for p in dec.parameters():
        p.requires_grad_(False)
    z0 = torch.tensor([0.3, -0.2, 0.5, -0.7, 0.1, 0.9], dtype=dtype)
    v = torch.tensor([math.sin(0.37 * i) for i in range(K)], dtype=dtype)
    out = {}

    def fwd():
        with torch.no_grad():
            return dec(z0)

    def vjp():
        z = z0.clone().requires_grad_(True)
        (g,) = torch.autograd.grad(dec(z), z, v)
        return g

    jacrev = torch.func.jacrev(dec)
    jacfwd = torch.func.jacfwd(dec)

    def record(key, f, rounds=301):
        out[key], out[key + "_best"] = timings_ns(f, rounds=rounds)

    record("decoder_forward_ns_torch", fwd)
    record("decoder_vjp_ns_torch", vjp)
    record("decoder_jacrev_ns_torch", lambda: jacrev(z0), rounds=101)
    record("decoder_jacfwd_ns_torch", lambda: jacfwd(z0), rounds=101)

    # Hand-written numpy, always float64, row-major W (n_out x n_in) as in the Rust crate.
    lin = [m for m in dec if isinstance(m, torch.nn.Linear)]
    w = [m.weight.detach().double().numpy().copy() for m in lin]
    b = [m.bias.detach().double().numpy().copy() for m in lin]
    zn, vn = z0.double().numpy(), v.double().numpy()

    def elu(a):
        return np.where(a > 0, a, np.expm1(np.minimum(a, 0.0)))

    def elu_d(a, h):
        return np.where(a > 0, 1.0, h + 1.0)

    def np_fwd():
        h1 = elu(w[0] @ zn + b[0])
        h2 = elu(w[1] @ h1 + b[1])
        return w[2] @ h2 + b[2]

    def np_vjp():
        a1 = w[0] @ zn + b[0]
        h1 = elu(a1)
        a2 = w[1] @ h1 + b[1]
        h2 = elu(a2)
        g2 = (w[2].T @ vn) * elu_d(a2, h2)
        g1 = (w[1].T @ g2) * elu_d(a1, h1)
        return w[0].T @ g1

    def np_jac():
        a1 = w[0] @ zn + b[0]
        h1 = elu(a1)
        t1 = elu_d(a1, h1)[:, None] * w[0]
        a2 = w[1] @ h1 + b[1]
        t2 = elu_d(a2, elu(a2))[:, None] * (w[1] @ t1)
        return w[2] @ t2

    # The three implementations agree (a check of this script, not a timing).
    jt = jacrev(z0).double().numpy()
    assert np.allclose(np_jac(), jt, rtol=1e-5, atol=1e-8)
    assert np.allclose(np_vjp(), jt.T @ vn, rtol=1e-5, atol=1e-8)
    record("decoder_forward_ns_numpy", np_fwd)
    record("decoder_vjp_ns_numpy", np_vjp)
    record("decoder_jacobian_ns_numpy", np_jac)
    return out


def main():
    repo = Path(__file__).resolve().parents[2]
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--epochs", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=2000)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--threads", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--seed", type=int, default=7, help="data seed (the Rust bench uses 7)")
    ap.add_argument("--dtype", choices=["float64", "float32"], default="float64")
    ap.add_argument("--skip-train", action="store_true")
    ap.add_argument("--skip-decoder", action="store_true")
    ap.add_argument("--out", type=Path, default=None)
    ap.add_argument("--fresh", action="store_true", help="overwrite instead of merging into --out")
    args = ap.parse_args()
    dtype = getattr(torch, args.dtype)
    torch.set_default_dtype(dtype)
    out_path = args.out or repo / "target" / "peers" / (
        "torch.json" if args.dtype == "float64" else "torch_f32.json"
    )

    result = {
        "torch_version": torch.__version__,
        "numpy_version": np.__version__,
        "python": platform.python_version(),
        "cpu": next(
            (l.split(":", 1)[1].strip() for l in open("/proc/cpuinfo") if l.startswith("model name")),
            platform.processor(),
        )
        if os.path.exists("/proc/cpuinfo")
        else platform.processor(),
        "dtype": args.dtype,
        "epochs": args.epochs,
        "samples": args.samples,
        "batch": args.batch,
        "load_average_at_start": os.getloadavg()[0],
    }
    if not args.skip_decoder:
        result.update(time_decoder(dtype, args.seed))
        for key in sorted(k for k in result if k.startswith("decoder_") and "best" not in k):
            print(f"{key:30} {result[key]:>10.0f} ns median, {result[key + '_best']:>10.0f} best")

    if not args.skip_train:
        x = torch.tensor(centre_uniform(tanh_manifold(args.samples, args.seed)), dtype=dtype)
        for threads in args.threads:
            seconds, cpu, mse = train(x, args.epochs, args.batch, threads, args.seed)
            rate = args.samples * args.epochs / seconds
            result[f"train_{threads}t_epochs"] = args.epochs
            result[f"train_{threads}t_seconds"] = seconds
            result[f"train_{threads}t_cpu_seconds"] = cpu
            result[f"train_{threads}t_samples_per_s"] = rate
            result[f"train_{threads}t_final_mse"] = mse
            print(
                f"train {threads} thread(s): {args.epochs} epochs in {seconds:.2f} s "
                f"({cpu:.2f} s CPU), {rate:.0f} samples/s, final MSE {mse:.3e}"
            )

    # Keep the figures of earlier runs that this one did not redo (e.g. --threads 2 alone).
    if out_path.exists() and not args.fresh:
        merged = json.loads(out_path.read_text())
        merged.update(result)
        result = merged
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {out_path}")


if __name__ == "__main__":
    main()
