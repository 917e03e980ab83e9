//! [`ConeGeometry`]: the cone model of every class, the shipped (fitted) defaults or a team's own
//! cones from a YAML file (`--cone-geometry cones.yaml`).
//!
//! Teams race on different cones (FSG's, FS UK's, FSOCO's mix, plain traffic cones), and a
//! cone 10 % larger than the model is put 10 % too far. The file sets the sizes and keypoint
//! heights per size or per class; anything it leaves out keeps the shipped value:
//!
//! ```yaml
//! # metres; `small` is blue, yellow and orange, `large` is large_orange; a class entry
//! # (blue, yellow, orange, large_orange) overrides its size's entry
//! small:
//!   height_m: 0.325              # ground to the top of the body: the top of the cone's box
//!   plate_half_width_m: 0.114    # half the side of the square base plate
//!   plate_height_m: 0.033        # the base plate's thickness: the body starts there
//!   keypoint_heights_m: {base: 0.033, lower_stripe: 0.132, upper_stripe: 0.222, apex: 0.323}
//!   body_radius_m: {base: 0.0801, apex: 0.0187}   # at the base and apex keypoint heights
//! large:
//!   scale: 1.1                   # the shipped large cone, 10 % larger in every dimension
//! ```
//!
//! `scale` multiplies the entry's lengths after the fields are set. The merged geometry must be
//! a cone: every length finite and positive, `plate_height_m <= base < lower_stripe <
//! upper_stripe < apex <= height_m`, the body narrowing upwards and inside the plate. A file
//! that breaks this is refused with the field named.

use std::path::Path;

use serde::Deserialize;

use super::{ConeClass, ConeModel};
use crate::camera::read_text;
use crate::error::ConfigError;

/// The cone model of every class.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ConeGeometry {
    /// Indexed by [`ConeClass::index`].
    models: [ConeModel; 4],
}

impl Default for ConeGeometry {
    fn default() -> Self {
        Self::shipped()
    }
}

impl ConeGeometry {
    /// The fitted defaults: [`ConeModel::small`] and [`ConeModel::large`].
    pub fn shipped() -> Self {
        Self {
            models: ConeClass::ALL.map(ConeModel::for_class),
        }
    }

    /// The model of `class`.
    pub fn model(&self, class: ConeClass) -> ConeModel {
        self.models[class.index()]
    }

    /// Every class's model `factor` times larger.
    pub fn scaled(&self, factor: f64) -> Self {
        Self {
            models: self.models.map(|m| m.scaled(factor)),
        }
    }

    /// Reads a geometry file (module docs).
    pub fn from_yaml_file(path: impl AsRef<Path>) -> Result<Self, ConfigError> {
        let path = path.as_ref();
        let text = read_text(path)?;
        Self::from_yaml_str(&text, &path.display().to_string())
    }

    /// The geometry of the YAML file at `path`, or the shipped one when there is none.
    pub fn from_file_or_shipped(path: Option<&Path>) -> Result<Self, ConfigError> {
        path.map_or_else(|| Ok(Self::shipped()), Self::from_yaml_file)
    }

    /// Parses a geometry YAML text; `what` names the source in errors.
    pub fn from_yaml_str(text: &str, what: &str) -> Result<Self, ConfigError> {
        let file: GeometryFile =
            crate::camera::yaml_from_str(text, what, HINT, FIELDS, expected_for)?;
        let mut models = Self::shipped().models;
        for class in ConeClass::ALL {
            let (size_name, size_entry) = if class.is_large() {
                ("large", &file.large)
            } else {
                ("small", &file.small)
            };
            let class_entry = match class {
                ConeClass::Blue => &file.blue,
                ConeClass::Yellow => &file.yellow,
                ConeClass::Orange => &file.orange,
                ConeClass::LargeOrange => &file.large_orange,
            };
            let mut model = models[class.index()];
            for (name, entry) in [(size_name, size_entry), (class.as_str(), class_entry)] {
                if let Some(entry) = entry {
                    model = entry.apply(model, name, what)?;
                }
            }
            models[class.index()] = model;
        }
        Ok(Self { models })
    }
}

const HINT: &str = "a mapping of `small`, `large`, `blue`, `yellow`, `orange` or `large_orange` to \
     cone sizes in metres (height_m, plate_half_width_m, plate_height_m, keypoint_heights_m \
     {base, lower_stripe, upper_stripe, apex}, body_radius_m {base, apex}, scale); see \
     `conesight predict --help`";

/// A geometry file (module docs).
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct GeometryFile {
    small: Option<Entry>,
    large: Option<Entry>,
    blue: Option<Entry>,
    yellow: Option<Entry>,
    orange: Option<Entry>,
    large_orange: Option<Entry>,
}

/// One size's or class's cone.
#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Entry {
    scale: Option<f64>,
    height_m: Option<f64>,
    plate_half_width_m: Option<f64>,
    plate_height_m: Option<f64>,
    keypoint_heights_m: Option<Heights>,
    body_radius_m: Option<Radii>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Heights {
    base: Option<f64>,
    lower_stripe: Option<f64>,
    upper_stripe: Option<f64>,
    apex: Option<f64>,
}

#[derive(Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
struct Radii {
    base: Option<f64>,
    apex: Option<f64>,
}

/// The field names of one entry, after its name and a dot.
const ENTRY_FIELDS: [&str; 12] = [
    "scale",
    "height_m",
    "plate_half_width_m",
    "plate_height_m",
    "keypoint_heights_m",
    "keypoint_heights_m.base",
    "keypoint_heights_m.lower_stripe",
    "keypoint_heights_m.upper_stripe",
    "keypoint_heights_m.apex",
    "body_radius_m",
    "body_radius_m.base",
    "body_radius_m.apex",
];

macro_rules! entry_fields {
    ($($entry:literal),*) => {
        &[$(
            $entry,
            concat!($entry, ".scale"),
            concat!($entry, ".height_m"),
            concat!($entry, ".plate_half_width_m"),
            concat!($entry, ".plate_height_m"),
            concat!($entry, ".keypoint_heights_m"),
            concat!($entry, ".keypoint_heights_m.base"),
            concat!($entry, ".keypoint_heights_m.lower_stripe"),
            concat!($entry, ".keypoint_heights_m.upper_stripe"),
            concat!($entry, ".keypoint_heights_m.apex"),
            concat!($entry, ".body_radius_m"),
            concat!($entry, ".body_radius_m.base"),
            concat!($entry, ".body_radius_m.apex"),
        )*]
    };
}

/// Every field an error may name.
const FIELDS: &[&str] = entry_fields!("small", "large", "blue", "yellow", "orange", "large_orange");

/// The static name of `entry.field` (both from the lists above).
fn field(entry: &str, suffix: &str) -> &'static str {
    FIELDS
        .iter()
        .find(|f| {
            f.strip_prefix(entry)
                .and_then(|rest| rest.strip_prefix('.'))
                .is_some_and(|rest| rest == suffix)
        })
        .copied()
        .unwrap_or("cone geometry")
}

fn expected_for(field: &str) -> &'static str {
    let suffix = field.split_once('.').map_or("", |(_, rest)| rest);
    match suffix {
        "" => {
            "an entry of height_m, plate_half_width_m, plate_height_m, keypoint_heights_m, \
               body_radius_m and scale (each optional)"
        }
        "scale" => "a positive factor (1.1: every length 10 % larger)",
        "keypoint_heights_m" => {
            "{base, lower_stripe, upper_stripe, apex} in metres above the ground"
        }
        "body_radius_m" => "{base, apex}: the body's radius at those keypoint heights, metres",
        _ if ENTRY_FIELDS.contains(&suffix) => "a positive number of metres",
        _ => "metres",
    }
}

impl Entry {
    /// `model` with this entry's fields set, then scaled, checked.
    fn apply(&self, model: ConeModel, name: &str, what: &str) -> Result<ConeModel, ConfigError> {
        let positive = |value: Option<f64>, suffix: &str| -> Result<Option<f64>, ConfigError> {
            match value {
                Some(v) if !(v.is_finite() && v > 0.0) => Err(ConfigError::Field {
                    what: what.to_owned(),
                    field: field(name, suffix),
                    problem: format!("is {v}"),
                    expected: expected_for(field(name, suffix)),
                }),
                other => Ok(other),
            }
        };
        let mut heights = model.keypoint_heights_m;
        let old_base = heights[0];
        // The radii at the keypoint heights as given, else the straight taper's.
        let mut base_radius = model.keypoint_radii_m[0];
        let mut apex_radius = model.keypoint_radii_m[3];
        let mut height = model.body_height_m;
        let mut plate_half = model.plate_half_width_m;
        let mut plate_height = model.plate_height_m;
        if let Some(v) = positive(self.height_m, "height_m")? {
            height = v;
        }
        if let Some(v) = positive(self.plate_half_width_m, "plate_half_width_m")? {
            plate_half = v;
        }
        if let Some(v) = positive(self.plate_height_m, "plate_height_m")? {
            plate_height = v;
        }
        if let Some(h) = &self.keypoint_heights_m {
            for (slot, (value, suffix)) in heights.iter_mut().zip([
                (h.base, "keypoint_heights_m.base"),
                (h.lower_stripe, "keypoint_heights_m.lower_stripe"),
                (h.upper_stripe, "keypoint_heights_m.upper_stripe"),
                (h.apex, "keypoint_heights_m.apex"),
            ]) {
                if let Some(v) = positive(value, suffix)? {
                    *slot = v;
                }
            }
        }
        if heights[0] != old_base && self.body_radius_m.as_ref().and_then(|r| r.base).is_none() {
            // A moved base keeps the body's surface: its radius there follows the old taper.
            base_radius = model.keypoint_radii_m[0] + model.taper_dr_dh() * (heights[0] - old_base);
        }
        if let Some(r) = &self.body_radius_m {
            if let Some(v) = positive(r.base, "body_radius_m.base")? {
                base_radius = v;
            }
            if let Some(v) = positive(r.apex, "body_radius_m.apex")? {
                apex_radius = v;
            }
        }
        let scale = positive(self.scale, "scale")?.unwrap_or(1.0);
        let refuse = |suffix: &str, problem: String| ConfigError::Field {
            what: what.to_owned(),
            field: field(name, suffix),
            problem,
            expected: match suffix {
                "keypoint_heights_m" => {
                    "plate_height_m <= base < lower_stripe < upper_stripe < apex <= height_m"
                }
                "body_radius_m" => {
                    "a body narrowing upwards (base > apex > 0) that stands inside the plate \
                     (base < plate_half_width_m * 1.41)"
                }
                _ => "a positive number of metres",
            },
        };
        let [h0, h1, h2, h3] = heights;
        if !(plate_height <= h0 && h0 < h1 && h1 < h2 && h2 < h3 && h3 <= height) {
            return Err(refuse(
                "keypoint_heights_m",
                format!(
                    "gives plate {plate_height}, base {h0}, lower stripe {h1}, upper stripe {h2}, \
                     apex {h3}, height {height}"
                ),
            ));
        }
        if !(base_radius > apex_radius && base_radius < plate_half * std::f64::consts::SQRT_2) {
            return Err(refuse(
                "body_radius_m",
                format!(
                    "is base {base_radius}, apex {apex_radius} (plate half width {plate_half})"
                ),
            ));
        }
        let tapered = ConeModel::tapered(
            plate_half,
            plate_height,
            height,
            heights,
            base_radius,
            apex_radius,
            model.stripes,
        );
        if tapered.top_radius_m() <= 0.0 {
            return Err(refuse(
                "body_radius_m",
                format!(
                    "narrows to nothing below the top ({} m at height_m)",
                    tapered.top_radius_m()
                ),
            ));
        }
        Ok(tapered.scaled(scale))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn an_empty_file_is_the_shipped_geometry() {
        let geometry = ConeGeometry::from_yaml_str("{}", "test").unwrap();
        assert_eq!(geometry, ConeGeometry::shipped());
    }

    #[test]
    fn sizes_and_classes_override_in_order() {
        let text =
            "small: {scale: 1.1}\nyellow: {height_m: 0.5, keypoint_heights_m: {apex: 0.45}}\n";
        let geometry = ConeGeometry::from_yaml_str(text, "test").unwrap();
        let small = ConeModel::small();
        let blue = geometry.model(ConeClass::Blue);
        assert_relative_eq!(
            blue.body_height_m,
            1.1 * small.body_height_m,
            epsilon = 1e-12
        );
        assert_relative_eq!(
            blue.keypoint_radii_m[1],
            1.1 * small.keypoint_radii_m[1],
            epsilon = 1e-12
        );
        let yellow = geometry.model(ConeClass::Yellow);
        assert_relative_eq!(yellow.body_height_m, 0.5, epsilon = 1e-12);
        assert_relative_eq!(yellow.keypoint_heights_m[3], 0.45, epsilon = 1e-12);
        assert_eq!(geometry.model(ConeClass::LargeOrange), ConeModel::large());
    }

    #[test]
    fn every_kind_of_bad_file_names_its_field() {
        for (text, needle) in [
            ("small: [1, 2", "not valid YAML"),
            ("- 1\n- 2\n", "not a mapping"),
            ("smal: {scale: 1.1}", "smal"),
            ("small: {hieght_m: 0.3}", "hieght_m"),
            ("small: {height_m: -0.3}", "`small.height_m` is -0.3"),
            ("large: {scale: .nan}", "`large.scale` is NaN"),
            ("blue: {height_m: abc}", "`blue.height_m`"),
            (
                "small: {keypoint_heights_m: {apex: 0.4}}",
                "`small.keypoint_heights_m` gives",
            ),
            (
                "orange: {keypoint_heights_m: {lower_stripe: 0.25}}",
                "`orange.keypoint_heights_m`",
            ),
            (
                "small: {body_radius_m: {base: 0.3}}",
                "`small.body_radius_m`",
            ),
            (
                "small: {body_radius_m: {apex: 0.09}}",
                "`small.body_radius_m`",
            ),
            (
                "large_orange: {keypoint_heights_m: {middle: 0.2}}",
                "`large_orange.keypoint_heights_m` has the unknown key",
            ),
        ] {
            let error = ConeGeometry::from_yaml_str(text, "cones.yaml")
                .unwrap_err()
                .to_string();
            assert!(error.contains(needle), "{text:?}: {error}");
            assert!(error.contains("cones.yaml"), "{error}");
        }
        let missing = ConeGeometry::from_yaml_file("/nonexistent/cones.yaml")
            .unwrap_err()
            .to_string();
        assert!(missing.contains("/nonexistent/cones.yaml"), "{missing}");
    }
}
