//! nn throughput on the AutoDef "X" shapes: the single-vector decoder operations latent dynamics
//! call every iteration, and autoencoder training.
//!
//! * `nn_decoder`: the decoder 6 → 200 → 200 → 49 (ELU, f64) at one latent point: forward,
//!   VJP Jᵀv (with its own forward pass, and `vjp_cached` after a forward), JVP Jw and the full
//!   49 × 6 Jacobian, in ns per call.
//! * `nn_decoder_width`: a decode and its VJP (`forward` then `vjp_cached`, what a reduced
//!   L-BFGS iteration runs) of the decoder 25 → w → w → 50, the catapult's minimal scene's shape
//!   (k = 50, d = 25), at the default widths for k = 50 and 100 (64 and 100) and AutoDef's 200.
//! * `nn_train`: one epoch of the 49 → 200 → 200 → 6 → 200 → 200 → 49 autoencoder (Adam lr 10⁻³,
//!   batch 256, no validation split) on 2,000 samples of
//!   [`nn::synthetic::TanhManifold::autodef_x`] (seed 7) per iteration, inside rayon pools of 1 and
//!   2 threads; the throughput is in samples per second.
//!
//! After the criterion groups a summary measures the same operations side by side (median of
//! short rounds, robust on a shared machine) and prints them beside the PyTorch and hand-written
//! numpy figures of `benches/peers/torch_autoencoder.py`, read from `target/peers/torch.json`
//! (or `$NN_PEERS_JSON`) when that file exists. Each figure is also given as a fraction of the
//! f64 multiply–add rate this thread sustains ([`nn::peak::fma_rate`], probed before and after
//! the summary): the number that stays put when the machine's clock does not.
//!
//! ```sh
//! python3 benches/peers/torch_autoencoder.py     # optional: needs torch and numpy
//! cargo bench -p benches --bench nn
//! ```

use std::hint::black_box;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use criterion::{Criterion, SamplingMode, Throughput};
use nn::synthetic::TanhManifold;
use nn::{Activation, Autoencoder, AutoencoderConfig, Mlp, Trainer};
use rayon::{ThreadPool, ThreadPoolBuilder};

/// Thread counts of the training benchmarks.
const THREADS: [usize; 2] = [1, 2];
/// Training samples (one epoch per iteration).
const SAMPLES: usize = 2_000;
/// Seed of the synthetic data (the peer script's default).
const DATA_SEED: u64 = 7;
/// Latent dimension of the X autoencoder.
const LATENT: usize = 6;

fn pool(threads: usize) -> ThreadPool {
    ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("can start a rayon thread pool")
}

/// A named single-vector operation with its own buffers and workspace.
type Operation<'a> = (&'static str, Box<dyn FnMut() + 'a>);

/// The X decoder and fixed arguments for its single-vector operations.
struct Decoder {
    mlp: Mlp,
    z: [f64; LATENT],
    w: [f64; LATENT],
    v: Vec<f64>,
}

impl Decoder {
    fn new() -> Self {
        Self {
            mlp: Mlp::new(&[LATENT, 200, 200, 49], Activation::Elu, 1)
                .expect("the X decoder shape is valid"),
            z: [0.3, -0.2, 0.5, -0.7, 0.1, 0.9],
            w: [1.0, 0.5, -0.25, 0.125, -1.0, 2.0],
            v: (0..49).map(|i| (i as f64 * 0.37).sin()).collect(),
        }
    }

    /// The first hidden layer's units with σ(a) ≠ a at z (ELU's a < 0).
    fn nonlinear_units(&self) -> usize {
        let (w, b) = (self.mlp.weights(0), self.mlp.bias(0));
        w.chunks_exact(LATENT)
            .zip(b)
            .map(|(row, b)| row.iter().zip(&self.z).map(|(w, z)| w * z).sum::<f64>() + b)
            .filter(|&a| Activation::Elu.value(a) != a)
            .count()
    }

    /// The operations, by name, as closures over their own output buffers and workspace.
    fn operations(&self) -> Vec<Operation<'_>> {
        let mlp = &self.mlp;
        let (z, w, v) = (&self.z, &self.w, &self.v);
        let mut y = vec![0.0; 49];
        let mut ws = mlp.workspace();
        let forward = Box::new(move || {
            mlp.forward(black_box(z), &mut y, &mut ws);
            black_box(&y);
        });
        let mut g = vec![0.0; LATENT];
        let mut ws = mlp.workspace();
        let vjp = Box::new(move || {
            mlp.vjp(black_box(z), black_box(v), &mut g, &mut ws);
            black_box(&g);
        });
        // vjp_cached reuses the forward state of one earlier forward pass.
        let mut g = vec![0.0; LATENT];
        let mut ws = mlp.workspace();
        mlp.forward(z, &mut vec![0.0; 49], &mut ws);
        let vjp_cached = Box::new(move || {
            mlp.vjp_cached(black_box(v), &mut g, &mut ws);
            black_box(&g);
        });
        let (mut y, mut g) = (vec![0.0; 49], vec![0.0; LATENT]);
        let mut ws = mlp.workspace();
        let forward_vjp_cached = Box::new(move || {
            mlp.forward(black_box(z), &mut y, &mut ws);
            mlp.vjp_cached(black_box(v), &mut g, &mut ws);
            black_box(&g);
        });
        let mut y = vec![0.0; 49];
        let mut ws = mlp.workspace();
        let jvp = Box::new(move || {
            mlp.jvp(black_box(z), black_box(w), &mut y, &mut ws);
            black_box(&y);
        });
        let mut jac = vec![0.0; 49 * LATENT];
        let mut ws = mlp.workspace();
        let jacobian = Box::new(move || {
            mlp.jacobian(black_box(z), &mut jac, &mut ws);
            black_box(&jac);
        });
        vec![
            ("forward", forward),
            ("vjp", vjp),
            ("vjp_cached", vjp_cached),
            ("forward+vjp_cached", forward_vjp_cached),
            ("jvp", jvp),
            ("jacobian", jacobian),
        ]
    }
}

fn bench_decoder(c: &mut Criterion, decoder: &Decoder) {
    let mut group = c.benchmark_group("nn_decoder");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    for (name, mut op) in decoder.operations() {
        group.bench_function(name, |b| b.iter(&mut op));
    }
    group.finish();
}

/// A decode and its VJP at hidden widths 64, 100 and 200 of a k = 50, d = 25 decoder.
fn bench_decoder_width(c: &mut Criterion) {
    let mut group = c.benchmark_group("nn_decoder_width");
    group
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(2));
    let (d, k) = (25, 50);
    let z: Vec<f64> = (0..d).map(|i| 0.3 * (i as f64 * 0.7).sin()).collect();
    let v: Vec<f64> = (0..k).map(|i| (i as f64 * 0.37).sin()).collect();
    for width in [64, 100, 200] {
        let mlp = Mlp::new(&[d, width, width, k], Activation::Elu, 1).expect("a valid shape");
        let (mut y, mut g, mut ws) = (vec![0.0; k], vec![0.0; d], mlp.workspace());
        group.bench_function(format!("forward+vjp_cached/{width}"), |b| {
            b.iter(|| {
                mlp.forward(black_box(&z), &mut y, &mut ws);
                mlp.vjp_cached(black_box(&v), &mut g, &mut ws);
                black_box(&g);
            })
        });
    }
    group.finish();
}

/// The X autoencoder's training configuration (all samples train; no early stopping).
fn train_config() -> AutoencoderConfig {
    AutoencoderConfig {
        latent_dim: Some(LATENT),
        hidden: Some(vec![200, 200]),
        activation: Activation::Elu,
        epochs: 1000,
        batch_size: 256,
        learning_rate: 1e-3,
        validation_fraction: 0.0,
        patience: 0,
        seed: 0,
        ..AutoencoderConfig::default()
    }
}

fn new_trainer() -> Trainer {
    let data = TanhManifold::autodef_x().sample(SAMPLES, DATA_SEED);
    Trainer::new(data.as_ref(), LATENT, &train_config()).expect("the X autoencoder trains")
}

fn bench_train(c: &mut Criterion, pools: &[(usize, ThreadPool)]) {
    let mut group = c.benchmark_group("nn_train");
    group
        .sampling_mode(SamplingMode::Flat)
        .sample_size(10)
        .warm_up_time(Duration::from_secs(1))
        .measurement_time(Duration::from_secs(5))
        .throughput(Throughput::Elements(SAMPLES as u64));
    for (threads, pool) in pools {
        let mut trainer = new_trainer();
        group.bench_function(format!("x_autoencoder_epoch/{threads}t"), |b| {
            pool.install(|| b.iter(|| trainer.run_epoch().expect("training stays finite")))
        });
    }
    group.finish();
}

/// (median, best) nanoseconds per call of `f` over `rounds` rounds of `reps` calls. On a shared
/// machine the best round is the robust figure for short operations.
fn timings_ns(rounds: usize, reps: usize, mut f: impl FnMut()) -> (f64, f64) {
    f();
    let mut times: Vec<f64> = (0..rounds)
        .map(|_| {
            let start = Instant::now();
            for _ in 0..reps {
                f();
            }
            start.elapsed().as_nanos() as f64 / reps as f64
        })
        .collect();
    times.sort_by(f64::total_cmp);
    (times[rounds / 2], times[0])
}

/// The PyTorch / numpy figures written by `benches/peers/torch_autoencoder.py`.
struct Peers {
    path: PathBuf,
    text: String,
}

impl Peers {
    fn load() -> Option<Self> {
        let path = std::env::var_os("NN_PEERS_JSON")
            .map(PathBuf::from)
            .unwrap_or_else(|| {
                PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../target/peers/torch.json")
            });
        match std::fs::read_to_string(&path) {
            Ok(text) => Some(Self { path, text }),
            Err(e) => {
                eprintln!(
                    "no peer figures: cannot read {} ({e}); run benches/peers/torch_autoencoder.py \
                     (needs torch and numpy) or set NN_PEERS_JSON",
                    path.display()
                );
                None
            }
        }
    }

    /// The raw text after `"key":` in the flat JSON object the script writes (numbers and
    /// strings only, so no JSON library is needed).
    fn raw(&self, key: &str) -> Option<&str> {
        let pattern = format!("\"{key}\"");
        let rest = &self.text[self.text.find(&pattern)? + pattern.len()..];
        let rest = rest.trim_start().strip_prefix(':')?.trim_start();
        let end = rest.find([',', '\n', '}']).unwrap_or(rest.len());
        Some(rest[..end].trim())
    }

    fn number(&self, key: &str) -> Option<f64> {
        self.raw(key)?.parse().ok()
    }

    fn string(&self, key: &str) -> String {
        self.raw(key)
            .map(|s| s.trim_matches('"').to_string())
            .unwrap_or_else(|| "?".into())
    }
}

fn cell(value: Option<f64>, scale: f64, unit: &str) -> String {
    value.map_or_else(|| "—".into(), |v| format!("{:.1} {unit}", v / scale))
}

/// "median / best" in µs, or a dash.
fn micros(median: Option<f64>, best: Option<f64>) -> String {
    match (median, best) {
        (Some(m), Some(b)) => format!("{:.1} / {:.1}", m / 1e3, b / 1e3),
        (Some(m), None) => format!("{:.1}", m / 1e3),
        _ => "—".into(),
    }
}

/// Σ n_l n_{l+1} over the layers of `sizes` (the multiply–adds of one matrix–vector product per
/// layer).
fn layer_products(sizes: &[usize]) -> usize {
    sizes.windows(2).map(|w| w[0] * w[1]).sum()
}

/// The multiply–adds of a single-vector decoder operation on a network of `sizes` (bias
/// additions and activations not counted), of which `nonlinear` first-layer units are not
/// linear at z (ELU's a < 0): `Mlp` runs the second layer over those units only when they are
/// few enough, and counts here follow it.
fn multiply_adds(name: &str, sizes: &[usize], nonlinear: usize) -> Option<usize> {
    let all = layer_products(sizes);
    let last = sizes[sizes.len() - 2] * sizes[sizes.len() - 1];
    let (n0, n1, n2, s) = (sizes[0], sizes[1], sizes[2], nonlinear);
    let (first, second) = (n0 * n1, n1 * n2);
    // The second layer forward (W₂W₁z plus the nonlinear units' columns of W₂), and the
    // backward step through it and the first ((W₂W₁)ᵀg plus those columns and W₁'s rows).
    let sparse = sizes.len() > 3 && 4 * (s + n0) < 3 * n1;
    let (forward_second, backward_low) = if sparse {
        (n2 * (n0 + s), s * n2 + n0 * n2 + s * n0)
    } else {
        (second, second + first)
    };
    let forward = all - second + forward_second;
    let backward = all - second - first + backward_low;
    Some(match name {
        "forward" => forward,
        "vjp_cached" => backward,
        // The forward pass up to the last hidden layer, then the reverse sweep.
        "vjp" => forward - last + backward,
        "forward+vjp_cached" => forward + backward,
        // Value and tangent side by side below the output layer, the tangent alone through it.
        "jvp" => 2 * (all - last) + last,
        // Forward mode with n₀ tangents: the first layer's tangents are its weights (only the
        // value is a product), the hidden layers carry 1 + n₀ columns, the output layer n₀;
        // the second layer's product over the nonlinear units only, plus W₂W₁z (when fewer
        // than 3/4 of the units are nonlinear).
        "jacobian" => {
            let second = if 4 * s < 3 * n1 {
                n2 * (s * (1 + n0) + n0)
            } else {
                n2 * n1 * (1 + n0)
            };
            first + second + (all - first - n1 * n2 - last) * (1 + n0) + last * n0
        }
        _ => return None,
    })
}

/// The multiply–adds of one training sample of `ae`: the forward pass, the weights' gradients
/// and the data gradients, all but the input's.
fn training_multiply_adds(ae: &Autoencoder) -> usize {
    let (encoder, decoder) = (ae.encoder().sizes(), ae.decoder().sizes());
    3 * (layer_products(encoder) + layer_products(decoder)) - encoder[0] * encoder[1]
}

/// The probed multiply–add rate, printed.
fn probe(when: &str) -> f64 {
    let rate = nn::peak::fma_rate(Duration::from_millis(300));
    println!(
        "f64 multiply–add rate of one thread ({when}, {} SIMD lanes, {} chains): {:.1} G/s",
        rate.lanes,
        nn::peak::CHAINS,
        rate.multiply_adds_per_second / 1e9
    );
    rate.multiply_adds_per_second
}

/// Side-by-side figures of this build and the peers.
fn summary(decoder: &Decoder, pools: &[(usize, ThreadPool)]) {
    let peers = Peers::load();
    let peer = |key: &str| peers.as_ref().and_then(|p| p.number(key));
    println!("\nsummary (short rounds, median and best; this machine, this run)");
    let peak = probe("before");
    if let Some(p) = &peers {
        println!(
            "peers from {}: torch {} ({}), numpy {}, {}",
            p.path.display(),
            p.string("torch_version"),
            p.string("dtype"),
            p.string("numpy_version"),
            p.string("cpu"),
        );
    }
    println!(
        "{:<22} {:>15} {:>17} {:>15} {:>18}",
        "decoder 6→200→200→49", "nn µs", "torch µs", "numpy µs", "nn multiply–adds"
    );
    println!(
        "{:<22} {:>15} {:>17} {:>15} {:>18}",
        "", "median / best", "median / best", "median / best", "(best, % of rate)"
    );
    let peer_keys = [
        (
            "forward",
            "decoder_forward_ns_torch",
            "decoder_forward_ns_numpy",
        ),
        ("vjp", "decoder_vjp_ns_torch", "decoder_vjp_ns_numpy"),
        (
            "jacobian",
            "decoder_jacrev_ns_torch",
            "decoder_jacobian_ns_numpy",
        ),
    ];
    let nonlinear = decoder.nonlinear_units();
    println!("(first hidden layer at z: {nonlinear} of 200 units nonlinear)");
    for (name, mut op) in decoder.operations() {
        let (median, best) = timings_ns(501, 20, &mut op);
        let peer_pair = |key: &str| (peer(key), peer(&format!("{key}_best")));
        let ((torch, torch_best), (numpy, numpy_best)) = peer_keys
            .iter()
            .find(|(n, _, _)| *n == name)
            .map_or(((None, None), (None, None)), |(_, t, n)| {
                (peer_pair(t), peer_pair(n))
            });
        let share = multiply_adds(name, decoder.mlp.sizes(), nonlinear).map_or_else(
            || "—".into(),
            |n| format!("{n} ({:.0} %)", 100.0 * n as f64 / (best * 1e-9) / peak),
        );
        println!(
            "{name:<22} {:>15} {:>17} {:>15} {share:>18}",
            micros(Some(median), Some(best)),
            micros(torch, torch_best),
            micros(numpy, numpy_best),
        );
    }
    println!("(torch jacobian: torch.func.jacrev; numpy: hand-written forward mode)");

    println!(
        "{:<22} {:>12} {:>12} {:>8} {:>14} {:>10}",
        "training (2000 samples)", "nn", "torch", "nn/torch", "nn 1000 epochs", "% of rate"
    );
    for (threads, pool) in pools {
        let mut trainer = new_trainer();
        let per_sample = training_multiply_adds(trainer.model());
        let epoch_ns = pool.install(|| {
            timings_ns(7, 1, || {
                trainer.run_epoch().expect("training stays finite");
            })
            .0
        });
        let rate = SAMPLES as f64 / (epoch_ns * 1e-9);
        let torch = peer(&format!("train_{threads}t_samples_per_s"));
        // Against one thread's rate times the threads: what the cores could give at most.
        let share = 100.0 * rate * per_sample as f64 / (peak * *threads as f64);
        println!(
            "{:<22} {:>12} {:>12} {:>8} {:>12.1} s {:>8.0} %",
            format!("{threads} thread(s)"),
            cell(Some(rate), 1e3, "k/s"),
            cell(torch, 1e3, "k/s"),
            torch.map_or_else(|| "—".into(), |t| format!("{:.2}×", rate / t)),
            1e3 * epoch_ns * 1e-9,
            share,
        );
    }
    if let Some(p) = &peers {
        println!(
            "(torch: figures of the peer file, measured when the script ran; on a shared machine \
             compare runs made under the same load)"
        );
        for threads in THREADS {
            let key = |what: &str| p.number(&format!("train_{threads}t_{what}"));
            if let (Some(s), Some(mse)) = (key("seconds"), key("final_mse")) {
                let epochs = key("epochs").or_else(|| p.number("epochs")).unwrap_or(0.0);
                let cpu = key("cpu_seconds").map_or(String::new(), |c| format!(" ({c:.1} s CPU)"));
                println!(
                    "torch {threads} thread(s): {epochs} epochs in {s:.1} s{cpu}, final MSE \
                     {mse:.3e} (nn: cargo run -p nn --release --example train_x -- {epochs} \
                     {threads})"
                );
            }
        }
    }
    probe("after");
}

fn main() {
    let decoder = Decoder::new();
    let pools: Vec<(usize, ThreadPool)> = THREADS.iter().map(|&t| (t, pool(t))).collect();
    let mut c = Criterion::default().configure_from_args();
    bench_decoder(&mut c, &decoder);
    bench_decoder_width(&mut c);
    bench_train(&mut c, &pools);
    c.final_summary();
    summary(&decoder, &pools);
}
