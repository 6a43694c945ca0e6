//! Times the AutoDef "X" decoder shape (6 → 200 → 200 → 49, ELU) and autoencoder training
//! (not a benchmark harness; run once with `cargo run -p nn --release --example decoder_timing
//! [epochs] [train-only]`).

use std::hint::black_box;
use std::time::Instant;

use faer::Mat;
use nn::{Activation, AutoencoderConfig, Mlp, train};

/// Median nanoseconds per call of `f` over `rounds` rounds of `reps` calls. Short rounds keep the
/// median robust on a shared machine: rounds interrupted by the scheduler are outliers.
fn median_ns(rounds: usize, reps: usize, mut f: impl FnMut()) -> f64 {
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
    times[rounds / 2]
}

/// SplitMix64 → uniform in [-1, 1).
fn uniform(state: &mut u64) -> f64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    2.0 * ((z >> 11) as f64 / (1u64 << 53) as f64) - 1.0
}

fn main() -> Result<(), nn::NnError> {
    let epochs = std::env::args()
        .nth(1)
        .map_or(5, |a| a.parse::<usize>().expect("epochs"));
    if std::env::args().nth(2).as_deref() != Some("train-only") {
        time_decoder()?;
    }
    time_training(epochs)
}

fn time_decoder() -> Result<(), nn::NnError> {
    let decoder = Mlp::new(&[6, 200, 200, 49], Activation::Elu, 1)?;
    let mut ws = decoder.workspace();
    let z = [0.3, -0.2, 0.5, -0.7, 0.1, 0.9];
    let w = [1.0, 0.5, -0.25, 0.125, -1.0, 2.0];
    let v: Vec<f64> = (0..49).map(|i| (i as f64 * 0.37).sin()).collect();
    let mut y = vec![0.0; 49];
    let mut g = vec![0.0; 6];
    let mut jac = vec![0.0; 49 * 6];
    let (rounds, reps) = (2_001, 20);
    println!("decoder 6 → 200 → 200 → 49 (ELU), median of {rounds} rounds × {reps} calls");
    let t = median_ns(rounds, reps, || {
        decoder.forward(black_box(&z), &mut y, &mut ws);
        black_box(&y);
    });
    println!("  forward          {:>9.0} ns", t);
    let t = median_ns(rounds, reps, || {
        decoder.vjp(black_box(&z), black_box(&v), &mut g, &mut ws);
        black_box(&g);
    });
    println!("  vjp              {:>9.0} ns", t);
    let t = median_ns(rounds, reps, || {
        decoder.forward(black_box(&z), &mut y, &mut ws);
        decoder.vjp_cached(black_box(&v), &mut g, &mut ws);
        black_box(&g);
    });
    println!("  forward + cached vjp {:>5.0} ns", t);
    let t = median_ns(rounds, reps, || {
        decoder.jvp(black_box(&z), black_box(&w), &mut y, &mut ws);
        black_box(&y);
    });
    println!("  jvp              {:>9.0} ns", t);
    let t = median_ns(rounds, reps, || {
        decoder.jacobian(black_box(&z), &mut jac, &mut ws);
        black_box(&jac);
    });
    println!("  jacobian (49×6)  {:>9.0} ns", t);

    Ok(())
}

/// Training throughput: 49 → 200 → 200 → 6 / 6 → 200 → 200 → 49 on 2,000 samples.
fn time_training(epochs: usize) -> Result<(), nn::NnError> {
    let (k, n) = (49, 2_000);
    let mut state = 11;
    let basis = Mat::from_fn(k, 6, |_, _| uniform(&mut state));
    let data = Mat::from_fn(k, n, |i, j| {
        let t = j as f64 / n as f64;
        let u: Vec<f64> = (0..6).map(|m| ((m + 1) as f64 * 3.0 * t).sin()).collect();
        (0..6).map(|m| basis[(i, m)] * u[m]).sum::<f64>() / (i + 1) as f64
    });
    let config = AutoencoderConfig {
        epochs,
        batch_size: 256,
        patience: 0,
        ..AutoencoderConfig::default()
    };
    let start = Instant::now();
    let outcome = train(data.as_ref(), 6, &config, |_| {})?;
    let secs = start.elapsed().as_secs_f64();
    let samples = outcome.train_indices.len() * outcome.history.len();
    println!(
        "training 49→200→200→6→200→200→49, batch 256, {} train samples, {} epochs on {} threads: \
         {:.2} s, {:.0} samples/s ({:.1} ms/epoch; 1000 epochs ≈ {:.1} s)",
        outcome.train_indices.len(),
        outcome.history.len(),
        rayon::current_num_threads(),
        secs,
        samples as f64 / secs,
        1e3 * secs / outcome.history.len() as f64,
        1e3 * secs / outcome.history.len() as f64,
    );
    Ok(())
}
