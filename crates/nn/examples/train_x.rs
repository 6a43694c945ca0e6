//! Trains the AutoDef "X" autoencoder (49 → 200 → 200 → 6, mirrored decoder, ELU, Adam lr 10⁻³,
//! batch 256, no validation split) on 2,000 samples of the synthetic tanh manifold (seed 7) for
//! a fixed number of epochs, as `benches/peers/torch_autoencoder.py` trains the PyTorch peer, and
//! prints the wall time, the throughput and the final mean squared error (in scaled units, like
//! the peer's).
//!
//! ```sh
//! cargo run -p nn --release --example train_x -- 1000 1   # epochs, threads
//! ```

use std::time::Instant;

use nn::synthetic::TanhManifold;
use nn::{Activation, AutoencoderConfig, Trainer};

fn main() -> Result<(), nn::NnError> {
    let mut args = std::env::args().skip(1);
    let epochs: usize = args.next().map_or(1000, |a| a.parse().expect("epochs"));
    let threads: usize = args.next().map_or(1, |a| a.parse().expect("threads"));
    let data = TanhManifold::autodef_x().sample(2_000, 7);
    let config = AutoencoderConfig {
        latent_dim: Some(6),
        hidden: Some(vec![200, 200]),
        activation: Activation::Elu,
        epochs,
        batch_size: 256,
        learning_rate: 1e-3,
        validation_fraction: 0.0,
        patience: 0,
        ..AutoencoderConfig::default()
    };
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(threads)
        .build()
        .expect("can start a rayon thread pool");
    pool.install(|| {
        let mut trainer = Trainer::new(data.as_ref(), 6, &config)?;
        let start = Instant::now();
        for _ in 0..epochs {
            trainer.run_epoch()?;
        }
        let seconds = start.elapsed().as_secs_f64();
        let mse = trainer.model().loss(data.as_ref())?;
        println!(
            "{epochs} epochs on {threads} thread(s): {seconds:.2} s, {:.0} samples/s, \
             final MSE {mse:.3e}",
            (2_000 * epochs) as f64 / seconds
        );
        Ok(())
    })
}
