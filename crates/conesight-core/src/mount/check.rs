//! [`MountCheck`]: does the road of the extrinsics hold the cones? At run time every placed
//! cone's base should lie on the road (vehicle z = 0, the vehicle origin on the road). Over a
//! window of recent cones within [`MountCheckParams::max_range_m`], the check takes the median
//! base height and the slope of base height against range (least squares, the bases more than
//! four robust deviations from the median left out). A height offset means a wrong camera
//! height; a slope, a wrong pitch (a pitch `d` off lifts a cone at range `r` by about
//! `r tan d`). Either beyond its limit is a mismatch: the extrinsics do not describe how the
//! camera is mounted, and `conesight mount` estimates it.

use std::collections::VecDeque;

/// Limits and window of the check.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountCheckParams {
    /// Most recent cones kept.
    pub window_cones: usize,
    /// Least number of cones in the window before the check says anything.
    pub min_cones: usize,
    /// Cones farther than this are left out, metres (far cones' heights are noisy).
    pub max_range_m: f64,
    /// A median base height farther than this from the road is a mismatch, metres.
    pub max_median_height_m: f64,
    /// A slope of base height with range steeper than this is a mismatch, metres per metre
    /// (0.01: a pitch about 0.6 degrees off, 0.3 m at 30 m).
    pub max_slope: f64,
    /// The slope is only judged when the ranges spread at least this much (one standard
    /// deviation), metres.
    pub min_range_spread_m: f64,
}

impl Default for MountCheckParams {
    fn default() -> Self {
        Self {
            window_cones: 200,
            min_cones: 30,
            max_range_m: 30.0,
            max_median_height_m: 0.15,
            max_slope: 0.01,
            min_range_spread_m: 3.0,
        }
    }
}

/// What the check sees in its window.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct MountCheckStatus {
    /// Cones in the window.
    pub cones: usize,
    /// Median height of their bases above the road of the extrinsics, metres.
    pub median_height_m: f64,
    /// Slope of base height with range, metres per metre (`None` when the ranges do not
    /// spread enough to tell).
    pub slope: Option<f64>,
    /// The bases are off the road beyond a limit.
    pub mismatch: bool,
}

impl MountCheckStatus {
    /// How far the pitch of the extrinsics seems off, radians (positive: the camera looks
    /// further down than the extrinsics say).
    pub fn pitch_error_rad(&self) -> f64 {
        self.slope.unwrap_or(0.0).atan()
    }

    /// One sentence with the numbers, for logs and the dashboard (the slope when it means a
    /// pitch at least 0.1 degrees off).
    pub fn describe(&self) -> String {
        let slope = match self.slope {
            Some(slope) if slope.atan().abs() >= 0.1_f64.to_radians() => format!(
                ", {:+.1} cm per metre of range (a pitch about {:+.1} degrees off)",
                100.0 * slope,
                self.pitch_error_rad().to_degrees()
            ),
            _ => String::new(),
        };
        format!(
            "cone bases lie {:+.2} m from the road of the extrinsics (median of {} cones){slope}",
            self.median_height_m, self.cones
        )
    }
}

/// The check over a window of recent cones (module docs).
#[derive(Debug, Clone)]
pub struct MountCheck {
    params: MountCheckParams,
    /// (range, base height) of the recent cones.
    window: VecDeque<(f64, f64)>,
    reported: bool,
}

impl Default for MountCheck {
    fn default() -> Self {
        Self::new(MountCheckParams::default())
    }
}

impl MountCheck {
    /// An empty check.
    pub fn new(params: MountCheckParams) -> Self {
        Self {
            params,
            window: VecDeque::with_capacity(params.window_cones),
            reported: false,
        }
    }

    /// Adds one cone: its range from the camera and its base height in the vehicle frame,
    /// metres. Far and non-finite ones are left out.
    pub fn add(&mut self, range_m: f64, base_height_m: f64) {
        if !(range_m.is_finite() && base_height_m.is_finite() && range_m <= self.params.max_range_m)
        {
            return;
        }
        self.window.push_back((range_m, base_height_m));
        while self.window.len() > self.params.window_cones {
            self.window.pop_front();
        }
    }

    /// Forgets every cone (the extrinsics changed); a mismatch will be reported again.
    pub fn reset(&mut self) {
        self.window.clear();
        self.reported = false;
    }

    /// The status of the window; `None` before it holds `min_cones` cones.
    pub fn status(&self) -> Option<MountCheckStatus> {
        if self.window.len() < self.params.min_cones.max(2) {
            return None;
        }
        let mut heights: Vec<f64> = self.window.iter().map(|(_, h)| *h).collect();
        let median = median_of(&mut heights);
        let mut deviations: Vec<f64> = heights.iter().map(|h| (h - median).abs()).collect();
        // 1.4826 MAD: a standard deviation for normal data; at least 5 cm.
        let spread = (1.4826 * median_of(&mut deviations)).max(0.05);
        let kept: Vec<(f64, f64)> = self
            .window
            .iter()
            .copied()
            .filter(|(_, h)| (h - median).abs() <= 4.0 * spread)
            .collect();
        let n = kept.len() as f64;
        let mean_range = kept.iter().map(|(r, _)| r).sum::<f64>() / n;
        let mean_height = kept.iter().map(|(_, h)| h).sum::<f64>() / n;
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for (r, h) in &kept {
            sxx += (r - mean_range).powi(2);
            sxy += (r - mean_range) * (h - mean_height);
        }
        let slope = (kept.len() >= 2 && (sxx / n).sqrt() >= self.params.min_range_spread_m)
            .then(|| sxy / sxx);
        let mismatch = median.abs() > self.params.max_median_height_m
            || slope.is_some_and(|s| s.abs() > self.params.max_slope);
        Some(MountCheckStatus {
            cones: self.window.len(),
            median_height_m: median,
            slope,
            mismatch,
        })
    }

    /// The status, and `true` the first time it is a mismatch since the start (or the last
    /// [`Self::reset`]): report that once.
    pub fn update(&mut self) -> (Option<MountCheckStatus>, bool) {
        let status = self.status();
        let first = status.is_some_and(|s| s.mismatch) && !self.reported;
        self.reported |= first;
        (status, first)
    }
}

/// The median of `values` (reordered); 0 when empty.
fn median_of(values: &mut [f64]) -> f64 {
    if values.is_empty() {
        return 0.0;
    }
    values.sort_by(f64::total_cmp);
    let mid = values.len() / 2;
    if values.len() % 2 == 1 {
        values[mid]
    } else {
        0.5 * (values[mid - 1] + values[mid])
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn fed(heights: impl Fn(f64, usize) -> f64) -> MountCheck {
        let mut check = MountCheck::default();
        for i in 0..120 {
            let range = 3.0 + f64::from(i % 27);
            check.add(range, heights(range, i as usize));
        }
        check
    }

    #[test]
    fn bases_on_the_road_pass() {
        let mut check = fed(|_, i| 0.03 * ((i % 7) as f64 - 3.0) / 3.0);
        let (status, first) = check.update();
        let status = status.unwrap();
        assert!(!status.mismatch && !first, "{status:?}");
        assert!(status.slope.unwrap().abs() < 0.002);
    }

    #[test]
    fn a_wrong_height_or_pitch_is_reported_once() {
        // The camera 0.3 m higher than the extrinsics say: bases 0.3 m below the road.
        let mut check = fed(|_, _| -0.3);
        let (status, first) = check.update();
        assert!(status.unwrap().mismatch && first);
        assert!(!check.update().1, "reported twice");
        // Pitched 2 degrees further down than they say: bases rise with range.
        let mut check = fed(|range, _| range * 2_f64.to_radians().tan());
        let status = check.update().0.unwrap();
        assert!(status.mismatch, "{status:?}");
        assert!((status.pitch_error_rad().to_degrees() - 2.0).abs() < 0.01);
        assert!(
            status.describe().contains("+2.0 degrees"),
            "{}",
            status.describe()
        );
        check.reset();
        assert!(check.status().is_none());
    }

    #[test]
    fn a_few_wild_bases_and_far_cones_do_not_count() {
        let mut check = fed(|_, i| if i % 10 == 0 { 2.5 } else { 0.0 });
        for _ in 0..50 {
            check.add(60.0, 5.0);
        }
        let status = check.update().0.unwrap();
        assert!(!status.mismatch, "{status:?}");
        assert_eq!(status.cones, 120);
    }
}
