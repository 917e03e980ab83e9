//! `conesight-eval`: the Rust half of `make eval` (see the crate docs).

use clap::Parser;
use conesight_eval::cli::{EvalArgs, run};

#[derive(Debug, Parser)]
#[command(
    name = "conesight-eval",
    about = "The paper's experiments on the held-out synthetic set"
)]
struct Cli {
    #[command(flatten)]
    eval: EvalArgs,
}

fn main() -> anyhow::Result<()> {
    run(&Cli::parse().eval)
}
