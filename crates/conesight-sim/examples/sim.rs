//! `conesight sim` without building the whole CLI (`make eval` renders its cone-free frames
//! with it): `cargo run --release -p conesight-sim --example sim -- --frames 10 --out out/sim`.

use clap::Parser;

#[derive(Parser)]
struct Cli {
    #[command(flatten)]
    sim: conesight_sim::cli::SimArgs,
}

fn main() -> anyhow::Result<()> {
    conesight_sim::cli::run(Cli::parse().sim)
}
