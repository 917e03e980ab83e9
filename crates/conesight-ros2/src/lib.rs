//! ROS 2 interop for conesight.
//!
//! - [`msg`]: the messages as serde types in their `.msg` field order, with their `ros2msg`
//!   definitions: `conesight_msgs/{Cone, ConeArray, Keypoint}` (from `ros2/conesight_msgs`,
//!   the package a team builds with colcon) and the standard ones conesight reads and writes
//!   (`sensor_msgs/{Image, CompressedImage, CameraInfo}`).
//! - [`cdr`]: their CDR payloads, as ROS 2 puts them on the wire and in bags.
//! - [`convert`]: from and to the bus's protobuf messages.
//! - [`dds`]: the topics over DDS (Dust DDS), as ROS 2 nodes on Cyclone DDS or Fast DDS see
//!   them.
//! - [`bag`]: rosbag2 bags in MCAP (the `ros2` profile: `ros2msg` schemas, `cdr` messages,
//!   `metadata.yaml` beside), written by `conesight record --ros2` and read by `conesight
//!   replay`.

pub mod bag;
pub mod cdr;
pub mod convert;
pub mod dds;
pub mod msg;
pub mod rmw_zenoh;

pub use cdr::{from_cdr, to_cdr};

/// The ROS 2 middleware a camera topic is read from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Rmw {
    /// DDS (RTPS over UDP): rmw_cyclonedds_cpp, rmw_fastrtps_cpp, rmw_connextdds.
    Dds,
    /// rmw_zenoh_cpp.
    Zenoh,
}

impl Rmw {
    /// As ROS 2 picks it: `RMW_IMPLEMENTATION=rmw_zenoh_cpp` is Zenoh; unset or a DDS one is
    /// DDS; anything else is refused, named.
    pub fn from_env() -> Result<Self, Ros2Error> {
        let value = std::env::var("RMW_IMPLEMENTATION").unwrap_or_default();
        Self::parse(&value)
    }

    fn parse(value: &str) -> Result<Self, Ros2Error> {
        match value.trim() {
            "rmw_zenoh_cpp" => Ok(Self::Zenoh),
            ""
            | "rmw_cyclonedds_cpp"
            | "rmw_fastrtps_cpp"
            | "rmw_fastrtps_dynamic_cpp"
            | "rmw_connextdds" => Ok(Self::Dds),
            other => Err(Ros2Error::Invalid {
                type_name: "RMW_IMPLEMENTATION",
                reason: format!(
                    "`{other}` is not one conesight speaks: use rmw_zenoh_cpp, or \
                     rmw_cyclonedds_cpp / rmw_fastrtps_cpp (DDS), or leave it unset (DDS)"
                ),
            }),
        }
    }
}

/// What can go wrong between conesight and ROS 2.
#[derive(Debug, thiserror::Error)]
pub enum Ros2Error {
    /// A CDR payload that does not decode as its type, or a value that cannot be encoded.
    #[error("{type_name}: CDR: {reason}")]
    Cdr {
        /// The Rust type.
        type_name: &'static str,
        /// Why.
        reason: String,
    },
    /// A message that decodes but cannot be used (a wrong encoding, a step that does not
    /// match the width, an implausible calibration).
    #[error("{type_name}: {reason}")]
    Invalid {
        /// The ROS 2 type.
        type_name: &'static str,
        /// Why, and what to change.
        reason: String,
    },
    /// Reading or writing a bag.
    #[error("{path}: {reason}")]
    Bag {
        /// The bag's file or folder.
        path: std::path::PathBuf,
        /// Why.
        reason: String,
    },
}

impl Ros2Error {
    /// A short stable name for `conesight_errors_total{kind=...}`.
    pub fn kind(&self) -> &'static str {
        match self {
            Self::Cdr { .. } => "ros2_cdr",
            Self::Invalid { .. } => "ros2_invalid",
            Self::Bag { .. } => "ros2_bag",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_middleware_follows_rmw_implementation() {
        assert_eq!(Rmw::parse("").unwrap(), Rmw::Dds);
        assert_eq!(Rmw::parse("rmw_cyclonedds_cpp").unwrap(), Rmw::Dds);
        assert_eq!(Rmw::parse("rmw_zenoh_cpp").unwrap(), Rmw::Zenoh);
        let error = Rmw::parse("rmw_iceoryx_cpp").unwrap_err().to_string();
        assert!(error.contains("rmw_iceoryx_cpp") && error.contains("rmw_zenoh_cpp"));
    }
}
