//! The Formula Student cones: classes, the 7 keypoints, the 3D keypoint model, the cross-ratio
//! and the exact silhouette keypoints of a cone seen from a camera.
//!
//! - [`ConeClass`]: blue, yellow, orange, large orange.
//! - [`Keypoint`]: the 7 keypoints in the order the network regresses them.
//! - [`ConeModel`] (in `model.rs`): cone geometry in the cone frame, fitted to real cones.
//! - [`ConeGeometry`] (in `geometry.rs`): the model of every class, shipped or from a team's
//!   `--cone-geometry` YAML.
//! - [`cross_ratio`] and [`CR3D`] (in `cross_ratio.rs`).
//! - [`silhouette_keypoints`] and [`silhouette_points_in_cone`] (in `silhouette.rs`): where the
//!   rays from the camera graze the cone body at the keypoint heights.
//!
//! Cone frame: origin at the centre of the cone's base on the ground, z up along the axis.

mod cross_ratio;
mod geometry;
mod model;
mod silhouette;

pub use cross_ratio::{CR3D, cross_ratio, side_cross_ratios};
pub use geometry::ConeGeometry;
pub use model::ConeModel;
pub use silhouette::{silhouette_angles, silhouette_keypoints, silhouette_points_in_cone};

use std::{fmt, str::FromStr};

use serde::{Deserialize, Serialize};

/// The four cone classes of Formula Student Driverless.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ConeClass {
    /// Small blue cone with a white stripe (left track boundary).
    #[serde(alias = "blue_cone")]
    Blue,
    /// Small yellow cone with a black stripe (right track boundary).
    #[serde(alias = "yellow_cone")]
    Yellow,
    /// Small orange cone with white stripes.
    #[serde(alias = "orange_cone")]
    Orange,
    /// Large orange cone (start, finish, timekeeping lines).
    #[serde(alias = "large_orange_cone")]
    LargeOrange,
}

impl ConeClass {
    /// Every class, in class-index order (the detector's class ids).
    pub const ALL: [Self; 4] = [Self::Blue, Self::Yellow, Self::Orange, Self::LargeOrange];

    /// The snake-case name: `blue`, `yellow`, `orange` or `large_orange`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Blue => "blue",
            Self::Yellow => "yellow",
            Self::Orange => "orange",
            Self::LargeOrange => "large_orange",
        }
    }

    /// The class index, the position in [`Self::ALL`].
    pub fn index(self) -> usize {
        self as usize
    }

    /// True for the large orange cone (the only large cone).
    pub fn is_large(self) -> bool {
        matches!(self, Self::LargeOrange)
    }
}

impl fmt::Display for ConeClass {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.as_str())
    }
}

/// A cone class name that is not one of the known names.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error(
    "unknown cone class `{name}`; expected one of blue, yellow, orange, large_orange \
     (or the FSOCO names blue_cone, yellow_cone, orange_cone, large_orange_cone)"
)]
pub struct ParseConeClassError {
    /// The name that was given.
    pub name: String,
}

impl FromStr for ConeClass {
    type Err = ParseConeClassError;

    /// Accepts `blue`, `yellow`, `orange`, `large_orange` and the FSOCO names `blue_cone`,
    /// `yellow_cone`, `orange_cone`, `large_orange_cone` (ASCII case-insensitive).
    fn from_str(name: &str) -> Result<Self, Self::Err> {
        let lower = name.trim().to_ascii_lowercase();
        let base = lower.strip_suffix("_cone").unwrap_or(&lower);
        Self::ALL
            .into_iter()
            .find(|class| class.as_str() == base)
            .ok_or_else(|| ParseConeClassError {
                name: name.to_owned(),
            })
    }
}

/// Number of keypoints per cone.
pub const KEYPOINT_COUNT: usize = 7;

/// The 7 keypoints, in the order the keypoint network outputs them. "Left" and "right" are
/// image left and right.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Keypoint {
    /// Top centre of the cone.
    Apex = 0,
    /// Image-left edge of the body at the upper stripe edge.
    LeftUpper = 1,
    /// Image-left edge of the body at the lower stripe edge.
    LeftLower = 2,
    /// Image-left edge of the body at its base (where it meets the base plate).
    LeftBase = 3,
    /// Image-right edge of the body at the upper stripe edge.
    RightUpper = 4,
    /// Image-right edge of the body at the lower stripe edge.
    RightLower = 5,
    /// Image-right edge of the body at its base.
    RightBase = 6,
}

impl Keypoint {
    /// Every keypoint, in index order.
    pub const ALL: [Self; KEYPOINT_COUNT] = [
        Self::Apex,
        Self::LeftUpper,
        Self::LeftLower,
        Self::LeftBase,
        Self::RightUpper,
        Self::RightLower,
        Self::RightBase,
    ];

    /// The index in a 7-keypoint array.
    pub fn index(self) -> usize {
        self as usize
    }

    /// The snake-case name, e.g. `left_upper`.
    pub fn as_str(self) -> &'static str {
        match self {
            Self::Apex => "apex",
            Self::LeftUpper => "left_upper",
            Self::LeftLower => "left_lower",
            Self::LeftBase => "left_base",
            Self::RightUpper => "right_upper",
            Self::RightLower => "right_lower",
            Self::RightBase => "right_base",
        }
    }

    /// Index into [`ConeModel::keypoint_heights_m`] (0 base, 1 lower stripe edge,
    /// 2 upper stripe edge, 3 apex).
    pub fn level(self) -> usize {
        match self {
            Self::Apex => 3,
            Self::LeftUpper | Self::RightUpper => 2,
            Self::LeftLower | Self::RightLower => 1,
            Self::LeftBase | Self::RightBase => 0,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn class_names_round_trip_and_fsoco_names_parse() {
        for class in ConeClass::ALL {
            assert_eq!(class.as_str().parse::<ConeClass>(), Ok(class));
            assert_eq!(
                format!("{}_cone", class.as_str()).parse::<ConeClass>(),
                Ok(class)
            );
            assert_eq!(ConeClass::ALL[class.index()], class);
        }
        assert_eq!(
            "Large_Orange_Cone".parse::<ConeClass>(),
            Ok(ConeClass::LargeOrange)
        );
        let error = "unknown_cone".parse::<ConeClass>().unwrap_err();
        assert!(error.to_string().contains("unknown_cone"));
        assert!("cone".parse::<ConeClass>().is_err());
    }

    #[test]
    fn serde_names_match_as_str() {
        for class in ConeClass::ALL {
            let json = serde_json::to_string(&class).unwrap();
            assert_eq!(json, format!("\"{}\"", class.as_str()));
            let fsoco: ConeClass =
                serde_json::from_str(&format!("\"{}_cone\"", class.as_str())).unwrap();
            assert_eq!(fsoco, class);
        }
    }

    #[test]
    fn keypoint_indices_follow_the_network_order() {
        for (i, keypoint) in Keypoint::ALL.iter().enumerate() {
            assert_eq!(keypoint.index(), i);
        }
        assert_eq!(Keypoint::LeftBase.level(), 0);
        assert_eq!(Keypoint::RightUpper.level(), 2);
    }
}
