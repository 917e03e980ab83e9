//! `conesight`: the command-line tool.
//!
//! Subcommands:
//! - `demo`: the geometry demo (see [`demo`]); `make demo` runs it.

mod bev;
mod demo;

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
    /// Geometry demo: a Formula Student track seen by the paper's camera, exact silhouette
    /// keypoints plus noise, solved by the cone PnP; prints errors, writes a bird's-eye PNG.
    Demo(demo::DemoArgs),
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    match cli.command {
        Command::Demo(args) => demo::run(&args),
    }
}
