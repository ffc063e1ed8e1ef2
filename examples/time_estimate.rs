//! The Rust side of `python/bench/overhead.py`: times `Unshear::estimate` and
//! `Unshear::correct` (by a given `k`) on one decoded image, as the Python binding's calls do
//! without the copy between numpy and Rust, and prints the fastest of the runs, in
//! milliseconds, as one JSON line (`RUNS` estimates, 20 times as many corrections).
//!
//! ```sh
//! cargo run --release --example time_estimate -- IMAGE [RUNS] [--quick]
//! ```

use std::time::Instant;

use unshear::{imageio, Config, CorrectOptions, Unshear};

/// Corrections per estimate (as `CORRECT_RUNS` in `python/bench/overhead.py`).
const CORRECT_RUNS: usize = 20;

fn fastest(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let quick = args.iter().any(|a| a == "--quick");
    let positional: Vec<&String> = args.iter().filter(|a| !a.starts_with("--")).collect();
    let Some(path) = positional.first() else {
        return Err("usage: time_estimate IMAGE [RUNS] [--quick]".into());
    };
    let runs: usize = positional.get(1).map_or(Ok(10), |r| r.parse())?;
    let config = if quick {
        Config::quick()
    } else {
        Config::default()
    };
    let unshear = Unshear::new(config)?;
    let img = imageio::read_image(path.as_ref(), imageio::DEFAULT_MAX_PIXELS)?;
    // One call first: thread pools, per-thread workspaces and caches, as in the Python runs.
    let report = unshear.estimate(&img);
    let options = CorrectOptions {
        k: Some(0.2),
        ..Default::default()
    };
    let mut estimate = Vec::with_capacity(runs);
    for _ in 0..runs {
        let t = Instant::now();
        let r = unshear.estimate(&img);
        estimate.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(r);
    }
    let mut correct = Vec::with_capacity(runs * CORRECT_RUNS);
    for _ in 0..runs * CORRECT_RUNS {
        let t = Instant::now();
        let fixed = Unshear::correct(&img, &report, &options)?;
        correct.push(t.elapsed().as_secs_f64() * 1e3);
        std::hint::black_box(fixed);
    }
    println!(
        "{{\"estimate_ms\": {:.4}, \"correct_ms\": {:.4}, \"k\": {}, \"faces\": {}}}",
        fastest(&estimate),
        fastest(&correct),
        report.k.map_or("null".to_string(), |k| format!("{k:.4}")),
        report.faces.len()
    );
    Ok(())
}
