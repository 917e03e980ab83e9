//! `conesight aggregate DIR [--baseline DIR2]`: every `<drive>.summary.json` of a results
//! folder of `conesight job` merged into one report (a table on stdout, `DIR/aggregate.json`),
//! and with `--baseline` the cones of every drive in both folders compared
//! (`conesight_replay::compare_folders`: `conesight diff` per drive and pooled over all
//! drives), e.g. the old model's results against the new one's.

use std::path::PathBuf;

use anyhow::Context;
use conesight_replay::job::{BaselineComparison, totals};
use conesight_replay::{DiffParams, JobSummary, read_summaries, write_atomic};

/// Arguments of `conesight aggregate`.
#[derive(Debug, clap::Args)]
pub struct AggregateArgs {
    /// A results folder of `conesight job`.
    dir: PathBuf,
    /// Another results folder of the same drives (e.g. the previous model's) to compare with:
    /// it is A, `DIR` is B.
    #[arg(long)]
    baseline: Option<PathBuf>,
    /// Where the report goes (default: `DIR/aggregate.json`).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Fail (exit status 1) unless exactly this many drives have a result.
    #[arg(long)]
    expect: Option<usize>,
    /// Print the report as JSON on stdout instead of the table.
    #[arg(long)]
    json: bool,
}

/// Runs `conesight aggregate`.
pub fn run(args: &AggregateArgs) -> anyhow::Result<std::process::ExitCode> {
    anyhow::ensure!(
        args.dir.is_dir(),
        "no results folder at {} (give the --out folder of `conesight job`)",
        args.dir.display()
    );
    let summaries = read_summaries(&args.dir)?;
    anyhow::ensure!(
        !summaries.is_empty(),
        "{} has no <drive>.summary.json: run `conesight job --out {}` first",
        args.dir.display(),
        args.dir.display()
    );
    let totals = totals(&summaries);
    let comparison = match &args.baseline {
        Some(baseline) => {
            anyhow::ensure!(
                baseline.is_dir(),
                "no baseline results folder at {} (give another --out folder of `conesight job`)",
                baseline.display()
            );
            Some(conesight_replay::compare_folders(
                &args.dir,
                baseline,
                &DiffParams::default(),
            )?)
        }
        None => None,
    };
    let mut report = serde_json::json!({
        "dir": args.dir.display().to_string(),
        "totals": totals,
        "drives": summaries,
    });
    if let Some(comparison) = &comparison {
        report["baseline"] = comparison_json(comparison);
    }
    let out = args
        .out
        .clone()
        .unwrap_or_else(|| args.dir.join("aggregate.json"));
    let mut bytes = serde_json::to_vec_pretty(&report)?;
    bytes.push(b'\n');
    write_atomic(&out, &bytes).with_context(|| format!("writing {}", out.display()))?;
    if args.json {
        println!("{report}");
    } else {
        print_table(&summaries, &totals);
        if let Some(comparison) = &comparison {
            print_comparison(comparison);
        }
        println!("report: {}", out.display());
    }
    let mut ok = true;
    if totals.models.values().any(|shas| shas.len() > 1) {
        eprintln!(
            "warning: not every drive was processed with the same models (see totals.models)"
        );
    }
    if let Some(expected) = args.expect
        && expected != summaries.len()
    {
        eprintln!(
            "expected {expected} drives with a result, found {} in {}",
            summaries.len(),
            args.dir.display()
        );
        ok = false;
    }
    Ok(if ok {
        std::process::ExitCode::SUCCESS
    } else {
        std::process::ExitCode::FAILURE
    })
}

fn comparison_json(comparison: &BaselineComparison) -> serde_json::Value {
    let per_drive: Vec<serde_json::Value> = comparison
        .drives
        .iter()
        .map(|(drive, report)| {
            serde_json::json!({
                "drive": drive,
                "zero_change": report.is_zero_change(),
                "frames_compared": report.frames_compared,
                "frames_with_count_change": report.frames_with_count_change,
                "all": report.total(),
            })
        })
        .collect();
    serde_json::json!({
        "baseline": comparison.baseline.display().to_string(),
        "only_in_results": comparison.only_in_results,
        "only_in_baseline": comparison.only_in_baseline,
        "zero_change": comparison.pooled.is_zero_change(),
        "frames_compared": comparison.pooled.frames_compared,
        "frames_with_count_change": comparison.pooled.frames_with_count_change,
        "bands": comparison.pooled.bands,
        "drives": per_drive,
    })
}

fn print_table(summaries: &[JobSummary], totals: &conesight_replay::job::Totals) {
    println!(
        "{:<24} {:>5} {:>7} {:>5} {:>7} {:>8} {:>9}  worker",
        "drive", "shard", "frames", "lost", "cones", "replay_s", "frames/s"
    );
    for s in summaries {
        println!(
            "{:<24} {:>5} {:>7} {:>5} {:>7} {:>8.1} {:>9.2}  {}",
            s.drive,
            s.shard.index,
            s.frames,
            s.frames_lost,
            s.cones,
            s.replay_s,
            s.frames_per_s,
            s.worker
        );
    }
    println!(
        "{:<24} {:>5} {:>7} {:>5} {:>7} {:>8.1} {:>9.2}  {} worker(s)",
        format!("all ({} drives)", totals.drives),
        "",
        totals.frames,
        totals.frames_lost,
        totals.cones,
        totals.replay_s,
        totals.frames_per_s,
        totals.workers.len()
    );
    for (role, shas) in &totals.models {
        let short: Vec<&str> = shas.iter().map(|s| s.get(..12).unwrap_or(s)).collect();
        println!("model {role}: sha256 {}", short.join(", "));
    }
}

fn print_comparison(comparison: &BaselineComparison) {
    let fmt = |v: Option<f64>| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.3}"));
    println!(
        "\nagainst {} (A; this folder is B): {} drives compared, {} only here, {} only in the baseline",
        comparison.baseline.display(),
        comparison.drives.len(),
        comparison.only_in_results.len(),
        comparison.only_in_baseline.len()
    );
    println!(
        "{:<24} {:>7} {:>8} {:>8} {:>8} {:>10} {:>10}",
        "drive / range_m", "frames", "cones_A", "cones_B", "matched", "median_m", "p95_m"
    );
    let rows = comparison
        .drives
        .iter()
        .filter_map(|(drive, report)| report.total().map(|t| (drive.clone(), t.clone())))
        .chain(
            comparison
                .pooled
                .bands
                .iter()
                .map(|b| (format!("all drives {}", b.band), b.clone())),
        );
    for (name, row) in rows {
        println!(
            "{:<24} {:>7} {:>8} {:>8} {:>8} {:>10} {:>10}",
            name,
            row.frames_compared,
            row.cones_in_a,
            row.cones_in_b,
            row.matched,
            fmt(row.median_change_m),
            fmt(row.p95_change_m)
        );
    }
    println!(
        "zero change over all drives: {}",
        comparison.pooled.is_zero_change()
    );
}
