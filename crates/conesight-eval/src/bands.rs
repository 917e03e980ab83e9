//! Range bands and the console summary (median, p90, % of range per band). The report makes
//! the published tables from the JSONL; this is the quick look printed at the end of a run.

use conesight_pipeline::stats::percentile;

/// Range bands of the 3D tables, metres (upper bound exclusive).
pub const RANGE_BANDS_M: [(f64, f64); 6] = [
    (2.0, 5.0),
    (5.0, 10.0),
    (10.0, 15.0),
    (15.0, 20.0),
    (20.0, 25.0),
    (25.0, 30.0),
];

/// One band's errors.
#[derive(Debug, Clone, PartialEq)]
pub struct BandRow {
    /// Band label, e.g. `5-10 m`.
    pub band: String,
    /// Cones in the band.
    pub count: usize,
    /// Median Euclidean error, metres.
    pub median_m: Option<f64>,
    /// 90th percentile error, metres.
    pub p90_m: Option<f64>,
    /// Median error as a percentage of the true range.
    pub median_percent_of_range: Option<f64>,
}

/// Per-band summary of `(true range, error)` pairs; cones outside every band are left out.
pub fn band_table(samples: &[(f64, f64)]) -> Vec<BandRow> {
    RANGE_BANDS_M
        .iter()
        .map(|(low, high)| {
            let inside: Vec<(f64, f64)> = samples
                .iter()
                .copied()
                .filter(|(range, error)| *range >= *low && *range < *high && error.is_finite())
                .collect();
            let errors: Vec<f64> = inside.iter().map(|(_, e)| *e).collect();
            let relative: Vec<f64> = inside.iter().map(|(r, e)| 100.0 * e / r).collect();
            BandRow {
                band: format!("{low:.0}-{high:.0} m"),
                count: inside.len(),
                median_m: percentile(&errors, 50.0),
                p90_m: percentile(&errors, 90.0),
                median_percent_of_range: percentile(&relative, 50.0),
            }
        })
        .collect()
}

/// The table as aligned text.
pub fn format_table(title: &str, rows: &[BandRow]) -> String {
    let fmt =
        |v: Option<f64>, unit: &str| v.map_or_else(|| "-".to_owned(), |v| format!("{v:.3}{unit}"));
    let mut text = format!(
        "{title}\n{:<10}{:>7}{:>12}{:>12}{:>12}\n",
        "band", "n", "median", "p90", "% range"
    );
    for row in rows {
        text.push_str(&format!(
            "{:<10}{:>7}{:>12}{:>12}{:>12}\n",
            row.band,
            row.count,
            fmt(row.median_m, " m"),
            fmt(row.p90_m, " m"),
            fmt(row.median_percent_of_range, " %"),
        ));
    }
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn bands_split_by_range_and_report_percent_of_range() {
        // 5-10 m: errors 0.1, 0.2, 0.3 at 5, 8, 9.99 m; 20-25 m: one at 20 m; 31 m is outside.
        let samples = [
            (5.0, 0.1),
            (8.0, 0.2),
            (9.99, 0.3),
            (20.0, 1.0),
            (31.0, 9.0),
            (3.0, f64::NAN),
        ];
        let rows = band_table(&samples);
        assert_eq!(rows.len(), RANGE_BANDS_M.len());
        assert_eq!(rows[0].count, 0, "NaN errors are not counted");
        assert_eq!(rows[1].band, "5-10 m");
        assert_eq!(rows[1].count, 3);
        assert!((rows[1].median_m.unwrap() - 0.2).abs() < 1e-12);
        assert!((rows[1].p90_m.unwrap() - 0.28).abs() < 1e-12);
        assert!((rows[1].median_percent_of_range.unwrap() - 2.5).abs() < 1e-12);
        assert_eq!(rows[4].count, 1);
        assert!((rows[4].median_percent_of_range.unwrap() - 5.0).abs() < 1e-12);
        assert!(rows[5].median_m.is_none());
        assert!(format_table("t", &rows).contains("5-10 m"));
    }
}
