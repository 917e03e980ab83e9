//! `conesight`: the command-line tool.
//!
//! Subcommands:
//! - `demo`: the geometry demo (see [`demo`]); `make demo` runs it.
//! - `sim`: the synthetic scene renderer ([`conesight_sim::cli`]).

mod bev;
mod demo;
mod demo_frame;

use clap::{Parser, Subcommand};

/// Real-time 3D traffic-cone perception from a single camera.
#[derive(Debug, Parser)]
#[command(name = "conesight", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Demo: (1) a Formula Student track seen by the paper's camera, exact silhouette keypoints
    /// plus noise, solved by the cone PnP (bird's-eye PNG); (2) a rendered frame through the
    /// shipped keypoint network and the PnP (annotated PNG).
    Demo(demo::DemoArgs),
    /// Render synthetic Formula Student scenes with exact labels (random frames, or
    /// `sim sequence` for a driven track).
    Sim(conesight_sim::cli::SimArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Demo(args) => demo::run(&args),
        Command::Sim(args) => conesight_sim::cli::run(args),
    }
}
