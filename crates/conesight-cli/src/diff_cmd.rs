//! `conesight diff A.mcap B.mcap`: the cones of two runs of the same drive compared
//! (`conesight_replay::diff`): a table per range band on stdout (or `--json`), PNG plots in
//! `--out`, and `--fail-above METRES` as a CI gate on the 95th percentile position change.

use std::path::{Path, PathBuf};

use anyhow::Context;
use conesight_replay::{DiffParams, DiffReport};
use plotters::prelude::*;

/// Arguments of `conesight diff`.
#[derive(Debug, clap::Args)]
pub struct DiffArgs {
    /// Recording A (e.g. the old model's run); a split recording by its base name.
    a: PathBuf,
    /// Recording B (e.g. the new model's run of the same drive); a split recording by its
    /// base name.
    b: PathBuf,
    /// Folder for the plots (position_change_vs_range.png, count_change_per_frame.png).
    #[arg(long, default_value = "out/diff")]
    out: PathBuf,
    /// The summary as one JSON object on stdout instead of the table.
    #[arg(long)]
    json: bool,
    /// Exit with status 1 when the 95th percentile of the position change over every band
    /// exceeds this many metres.
    #[arg(long = "fail-above")]
    fail_above: Option<f64>,
    /// Constant part of the matching gate, metres.
    #[arg(long = "gate-m", default_value_t = 1.0)]
    gate_m: f64,
    /// Part of the gate proportional to the range (0.1: 10 % of the range).
    #[arg(long = "gate-fraction", default_value_t = 0.1)]
    gate_fraction: f64,
}

/// Runs `conesight diff`; exit status 1 when `--fail-above` is exceeded.
pub fn run(args: &DiffArgs) -> anyhow::Result<std::process::ExitCode> {
    let params = DiffParams {
        gate_m: args.gate_m,
        gate_fraction: args.gate_fraction,
        ..DiffParams::default()
    };
    // A split recording may be named by its base name, as `conesight record --out` was given.
    let a = conesight_replay::recording_files(std::slice::from_ref(&args.a))?;
    let b = conesight_replay::recording_files(std::slice::from_ref(&args.b))?;
    let report = conesight_replay::diff(&a, &b, &params)?;
    std::fs::create_dir_all(&args.out)
        .with_context(|| format!("cannot create {}", args.out.display()))?;
    let scatter = args.out.join("position_change_vs_range.png");
    plot_changes(&scatter, &report)?;
    let counts = args.out.join("count_change_per_frame.png");
    plot_counts(&counts, &report)?;
    let p95 = report.total().and_then(|t| t.p95_change_m).unwrap_or(0.0);
    let passed = args.fail_above.is_none_or(|limit| p95 <= limit);
    if args.json {
        let mut value = serde_json::to_value(&report)?;
        value["zero_change"] = report.is_zero_change().into();
        value["plots"] = vec![scatter.display().to_string(), counts.display().to_string()].into();
        if let Some(limit) = args.fail_above {
            value["fail_above_m"] = limit.into();
            value["passed"] = passed.into();
        }
        println!("{value}");
    } else {
        print_table(&report);
        println!("plots: {}, {}", scatter.display(), counts.display());
        if let Some(limit) = args.fail_above {
            println!(
                "{}: p95 position change {p95:.3} m {} --fail-above {limit} m",
                if passed { "pass" } else { "FAIL" },
                if passed { "<=" } else { ">" }
            );
        }
    }
    Ok(if passed {
        std::process::ExitCode::SUCCESS
    } else {
        std::process::ExitCode::FAILURE
    })
}

fn fmt_m(value: Option<f64>) -> String {
    value.map_or_else(|| "-".to_owned(), |v| format!("{v:.3}"))
}

fn print_table(report: &DiffReport) {
    println!(
        "A: {}\nB: {}\nframes: {} in A, {} in B, {} compared, {} only in A, {} only in B, {} with a different cone count",
        conesight_replay::describe(&report.a),
        conesight_replay::describe(&report.b),
        report.frames_in_a,
        report.frames_in_b,
        report.frames_compared,
        report.frames_only_in_a,
        report.frames_only_in_b,
        report.frames_with_count_change,
    );
    println!(
        "cones matched by class, nearest first, within {} m + {:.0} % of range (vehicle frame)\n",
        report.params.gate_m,
        100.0 * report.params.gate_fraction
    );
    println!(
        "{:>8} {:>7} {:>8} {:>8} {:>8} {:>7} {:>7} {:>10} {:>10} {:>10}",
        "range_m",
        "frames",
        "cones_A",
        "cones_B",
        "matched",
        "only_A",
        "only_B",
        "median_m",
        "p95_m",
        "max_m"
    );
    for band in &report.bands {
        println!(
            "{:>8} {:>7} {:>8} {:>8} {:>8} {:>7} {:>7} {:>10} {:>10} {:>10}",
            band.band,
            band.frames_compared,
            band.cones_in_a,
            band.cones_in_b,
            band.matched,
            band.only_in_a,
            band.only_in_b,
            fmt_m(band.median_change_m),
            fmt_m(band.p95_change_m),
            fmt_m(band.max_change_m),
        );
    }
    println!(
        "\n{}",
        if report.is_zero_change() {
            "zero change: the same cones in the same places in every frame"
        } else {
            "the runs differ"
        }
    );
}

fn plot_error(path: &Path) -> impl Fn(Box<dyn std::error::Error>) -> anyhow::Error + '_ {
    move |e| anyhow::anyhow!("cannot write {}: {e}", path.display())
}

/// Position change of every matched pair against A's range.
fn plot_changes(path: &Path, report: &DiffReport) -> anyhow::Result<()> {
    crate::bev::register_font()?;
    let max_range = report
        .pairs
        .iter()
        .map(|p| p.range_m)
        .fold(40.0_f64, f64::max);
    let max_change = report
        .pairs
        .iter()
        .map(|p| p.change_m)
        .fold(0.0_f64, f64::max)
        .max(0.01)
        * 1.1;
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption(
                "Position change of matched cones, B vs A",
                ("sans-serif", 22),
            )
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..max_range, 0.0..max_change)?;
        chart
            .configure_mesh()
            .x_desc("range of the cone in A (m)")
            .y_desc("position change (m)")
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()?;
        let blue = RGBColor(30, 80, 200);
        chart
            .draw_series(
                report
                    .pairs
                    .iter()
                    .map(|p| Circle::new((p.range_m, p.change_m), 3, blue.filled())),
            )?
            .label(format!("matched cone pair ({})", report.pairs.len()))
            .legend(move |(x, y)| Circle::new((x + 9, y), 4, blue.filled()));
        if let Some(p95) = report.total().and_then(|t| t.p95_change_m) {
            let red = RGBColor(200, 40, 40);
            chart
                .draw_series(LineSeries::new(
                    [(0.0, p95), (max_range, p95)],
                    red.stroke_width(2),
                ))?
                .label(format!("95th percentile, all ranges ({p95:.3} m)"))
                .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], red.stroke_width(2)));
        }
        crate::bev::draw_legend(&mut chart, SeriesLabelPosition::UpperLeft)?;
        root.present()?;
        Ok(())
    };
    draw().map_err(plot_error(path))
}

/// Cones in B minus cones in A, per compared frame.
fn plot_counts(path: &Path, report: &DiffReport) -> anyhow::Result<()> {
    crate::bev::register_font()?;
    let points: Vec<(f64, f64)> = report
        .frames
        .iter()
        .enumerate()
        .map(|(i, f)| (i as f64, f.cones_in_b as f64 - f.cones_in_a as f64))
        .collect();
    let extent = points.iter().map(|p| p.1.abs()).fold(1.0_f64, f64::max) + 0.5;
    let frames = (points.len() as f64).max(1.0);
    let draw = || -> Result<(), Box<dyn std::error::Error>> {
        let root = BitMapBackend::new(path, (900, 600)).into_drawing_area();
        root.fill(&WHITE)?;
        let mut chart = ChartBuilder::on(&root)
            .caption("Cone count change per frame, B - A", ("sans-serif", 22))
            .margin(12)
            .x_label_area_size(44)
            .y_label_area_size(70)
            .build_cartesian_2d(0.0..frames, -extent..extent)?;
        chart
            .configure_mesh()
            .x_desc("compared frame (in camera, sequence order)")
            .y_desc("cones in B - cones in A (count)")
            .label_style(("sans-serif", 15))
            .axis_desc_style(("sans-serif", 17))
            .light_line_style(RGBColor(235, 235, 235))
            .draw()?;
        let grey = RGBColor(150, 150, 150);
        chart
            .draw_series(LineSeries::new([(0.0, 0.0), (frames, 0.0)], grey))?
            .label("no change")
            .legend(move |(x, y)| PathElement::new([(x, y), (x + 18, y)], grey));
        let orange = RGBColor(230, 110, 0);
        chart
            .draw_series(points.iter().map(|p| Circle::new(*p, 3, orange.filled())))?
            .label(format!(
                "frame ({} of {} with a different count)",
                report.frames_with_count_change, report.frames_compared
            ))
            .legend(move |(x, y)| Circle::new((x + 9, y), 4, orange.filled()));
        crate::bev::draw_legend(&mut chart, SeriesLabelPosition::UpperRight)?;
        root.present()?;
        Ok(())
    };
    draw().map_err(plot_error(path))
}
