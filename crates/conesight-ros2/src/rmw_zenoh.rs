//! The cones as ROS 2 topics in rmw_zenoh's format, on conesight's own Zenoh session (no
//! bridge): a ROS 2 node running `RMW_IMPLEMENTATION=rmw_zenoh_cpp` (Jazzy) connected to the
//! same Zenoh network sees them in `ros2 topic list` and can subscribe. Per rmw_zenoh's
//! `docs/design.md` (jazzy branch):
//!
//! - data on `<domain>/<topic without its leading />/<package>::msg::dds_::<Type>_/<type hash>`;
//!   the payload is the CDR of the message with its encapsulation header;
//! - the type hash is REP-2011's `RIHS01_<sha256>` of the type description ([`rihs01`]);
//! - every sample carries an attachment: sequence number (i64 LE, from 1), source timestamp
//!   (i64 LE, ns since the Unix epoch), the publisher's 16-byte GID with its length (1 byte,
//!   16) first: 33 bytes, as `zenoh::ext::Serializer` writes them in `AttachmentData`;
//! - liveliness tokens make the node and its publishers part of the ROS graph:
//!   `@ros2_lv/<domain>/<zid>/<node id>/<node id>/NN/%/%/<node>` and
//!   `@ros2_lv/<domain>/<zid>/<node id>/<entity id>/MP/%/%/<node>/<topic, / as %>/<type>/<hash>/<qos>`.
//!
//! No live rmw_zenoh node was run here: the formats are checked against the design document's
//! examples and, in training/tests/test_ros2_zenoh.py, by a Python Zenoh subscriber that
//! decodes the samples with rosbags and compares the hashes rosbags computes from the `.msg`
//! files.

use sha2::{Digest, Sha256};

use crate::msg::{RosMessage, normalised_fields};

/// The ROS 2 domain of `ROS_DOMAIN_ID` (0 when unset; an error names a bad value).
pub fn domain_from_env() -> Result<u32, String> {
    match std::env::var("ROS_DOMAIN_ID") {
        Err(_) => Ok(0),
        Ok(text) if text.trim().is_empty() => Ok(0),
        Ok(text) => text
            .trim()
            .parse::<u32>()
            .ok()
            .filter(|d| *d <= 232)
            .ok_or_else(|| format!("ROS_DOMAIN_ID={text:?} is not a domain id 0..=232")),
    }
}

/// `conesight_msgs/msg/ConeArray` as DDS names it: `conesight_msgs::msg::dds_::ConeArray_`.
pub fn dds_type_name(type_name: &str) -> String {
    let mut parts = type_name.split('/');
    let (package, kind, name) = (
        parts.next().unwrap_or_default(),
        parts.next().unwrap_or("msg"),
        parts.next().unwrap_or_default(),
    );
    format!("{package}::{kind}::dds_::{name}_")
}

/// The key expression of `topic` (`/conesight/front/cones`) carrying `M` on `domain`.
pub fn data_key<M: RosMessage>(domain: u32, topic: &str) -> String {
    format!(
        "{domain}/{}/{}/{}",
        topic.trim_start_matches('/'),
        dds_type_name(M::TYPE),
        rihs01::<M>()
    )
}

/// The QoS chunk of a publisher token: reliable, volatile, keep last 10 (rmw_zenoh writes the
/// values that are its defaults as empty fields).
pub const PUBLISHER_QOS: &str = "::,10:,:,:,,";

/// The liveliness token of node `node` (id `node_id`) of session `zid` on `domain`.
pub fn node_token(domain: u32, zid: &str, node_id: u32, node: &str) -> String {
    format!("@ros2_lv/{domain}/{zid}/{node_id}/{node_id}/NN/%/%/{node}")
}

/// The liveliness token of publisher `entity_id` of `M` on `topic`.
pub fn publisher_token<M: RosMessage>(
    domain: u32,
    zid: &str,
    node_id: u32,
    entity_id: u32,
    node: &str,
    topic: &str,
) -> String {
    format!(
        "@ros2_lv/{domain}/{zid}/{node_id}/{entity_id}/MP/%/%/{node}/{}/{}/{}/{PUBLISHER_QOS}",
        topic.replace('/', "%"),
        dds_type_name(M::TYPE),
        rihs01::<M>()
    )
}

/// The attachment of a sample: sequence number, source timestamp (ns), GID (module docs).
pub fn attachment(sequence: i64, timestamp_ns: i64, gid: &[u8; 16]) -> [u8; 33] {
    let mut out = [0_u8; 33];
    out[..8].copy_from_slice(&sequence.to_le_bytes());
    out[8..16].copy_from_slice(&timestamp_ns.to_le_bytes());
    out[16] = 16;
    out[17..].copy_from_slice(gid);
    out
}

/// A publisher's GID: the first 16 bytes of the SHA-256 of its session id and topic.
pub fn gid(zid: &str, topic: &str) -> [u8; 16] {
    let digest = Sha256::digest(format!("{zid}{topic}").as_bytes());
    let mut gid = [0_u8; 16];
    gid.copy_from_slice(&digest[..16]);
    gid
}

/// REP-2011 type ids (`type_description_interfaces/msg/FieldType`).
fn primitive_id(name: &str) -> Option<u32> {
    Some(match name {
        "int8" => 2,
        "uint8" => 3,
        "int16" => 4,
        "uint16" => 5,
        "int32" => 6,
        "uint32" => 7,
        "int64" => 8,
        "uint64" => 9,
        "float32" => 10,
        "float64" => 11,
        "char" => 13,
        "bool" => 15,
        "byte" => 16,
        "string" => 17,
        _ => return None,
    })
}

/// One field of a type description, as the JSON REP-2011 hashes.
fn field_json(name: &str, field_type: &str) -> (String, Option<String>) {
    // Array and sequence suffixes add 48 (array), 96 (bounded sequence), 144 (sequence).
    let (base, increment, capacity) = match field_type.split_once('[') {
        Some((base, rest)) => {
            let inside = rest.trim_end_matches(']');
            if inside.is_empty() {
                (base, 144, 0)
            } else if let Some(bound) = inside.strip_prefix("<=") {
                (base, 96, bound.parse().unwrap_or(0))
            } else {
                (base, 48, inside.parse().unwrap_or(0))
            }
        }
        None => (field_type, 0, 0),
    };
    let (type_id, string_capacity, nested) = if let Some(bound) = base.strip_prefix("string<=") {
        (21, bound.parse().unwrap_or(0), None)
    } else if let Some(id) = primitive_id(base) {
        (id, 0, None)
    } else {
        // `package/Type` -> `package/msg/Type`.
        let full = match base.split_once('/') {
            Some((package, name)) if !name.contains('/') => format!("{package}/msg/{name}"),
            _ => base.to_owned(),
        };
        (1, 0, Some(full))
    };
    let json = format!(
        "{{\"name\": \"{name}\", \"type\": {{\"type_id\": {}, \"capacity\": {capacity}, \
         \"string_capacity\": {string_capacity}, \"nested_type_name\": \"{}\"}}}}",
        type_id + increment,
        nested.as_deref().unwrap_or_default()
    );
    (json, nested)
}

/// The type description of `type_name` from its normalised `fields` (constants left out, as
/// REP-2011 leaves them out of the hash).
fn struct_json(type_name: &str, fields: &str) -> (String, Vec<String>) {
    let mut entries = Vec::new();
    let mut nested = Vec::new();
    for line in fields.lines() {
        let Some((field_type, name)) = line.split_once(' ') else {
            continue;
        };
        let name = name.split_whitespace().next().unwrap_or_default();
        if name.contains('=') || name.is_empty() {
            continue;
        }
        let (json, sub) = field_json(name, field_type);
        entries.push(json);
        nested.extend(sub);
    }
    if entries.is_empty() {
        entries.push(field_json("structure_needs_at_least_one_member", "uint8").0);
    }
    (
        format!(
            "{{\"type_name\": \"{type_name}\", \"fields\": [{}]}}",
            entries.join(", ")
        ),
        nested,
    )
}

/// REP-2011's RIHS01 hash of `M`: the SHA-256 of its type description and those of every type
/// it uses (sorted by name), as JSON.
pub fn rihs01<M: RosMessage>() -> String {
    let mut known: std::collections::BTreeMap<&str, String> = M::dependencies()
        .into_iter()
        .map(|(name, fields)| (name, normalised_fields(name, fields)))
        .collect();
    known.insert(M::TYPE, normalised_fields(M::TYPE, M::FIELDS));
    let mut described: std::collections::BTreeMap<String, String> = Default::default();
    let mut pending = vec![M::TYPE.to_owned()];
    while let Some(type_name) = pending.pop() {
        if described.contains_key(&type_name) {
            continue;
        }
        let fields = known.get(type_name.as_str()).cloned().unwrap_or_default();
        let (json, nested) = struct_json(&type_name, &fields);
        described.insert(type_name, json);
        pending.extend(nested);
    }
    let main = described.remove(M::TYPE).unwrap_or_default();
    let referenced: Vec<String> = described.into_values().collect();
    let json = format!(
        "{{\"type_description\": {main}, \"referenced_type_descriptions\": [{}]}}",
        referenced.join(", ")
    );
    let digest = Sha256::digest(json.as_bytes());
    let hex: String = digest.iter().map(|b| format!("{b:02x}")).collect();
    format!("RIHS01_{hex}")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::msg::{CameraInfo, CompressedImage, ConeArray, Image};

    /// The hashes ROS 2 Jazzy publishes for its standard messages (`ros2 interface` /
    /// `type_description_interfaces`; rosbags computes the same).
    #[test]
    fn standard_hashes_are_ros_2s() {
        assert_eq!(
            rihs01::<Image>(),
            "RIHS01_d31d41a9a4c4bc8eae9be757b0beed306564f7526c88ea6a4588fb9582527d47"
        );
        assert_eq!(
            rihs01::<CompressedImage>(),
            "RIHS01_15640771531571185e2efc8a100baf923961a4d15d5569652e6cb6691e8e371a"
        );
        assert_eq!(
            rihs01::<CameraInfo>(),
            "RIHS01_b3dfd68ff46c9d56c80fd3bd4ed22c7a4ddce8c8348f2f59c299e73118e7e275"
        );
        assert_eq!(
            rihs01::<crate::msg::MarkerArray>(),
            "RIHS01_86cb8800b6fb05b5eff1abd7a56f62a5641d3ae9a1c29e78e67e704f1d067dcf"
        );
        assert!(rihs01::<ConeArray>().starts_with("RIHS01_"));
    }

    /// The design document's examples, with our names.
    #[test]
    fn keys_and_tokens_have_rmw_zenohs_shape() {
        let key = data_key::<ConeArray>(0, "/conesight/front/cones");
        assert!(
            key.starts_with(
                "0/conesight/front/cones/conesight_msgs::msg::dds_::ConeArray_/RIHS01_"
            ),
            "{key}"
        );
        assert_eq!(
            node_token(0, "aac3178e146ba6f1fc6e6a4085e77f21", 0, "listener"),
            "@ros2_lv/0/aac3178e146ba6f1fc6e6a4085e77f21/0/0/NN/%/%/listener"
        );
        let token = publisher_token::<Image>(3, "ab", 0, 10, "talker", "/cam/image_raw");
        assert_eq!(
            token,
            format!(
                "@ros2_lv/3/ab/0/10/MP/%/%/talker/%cam%image_raw/sensor_msgs::msg::dds_::Image_/{}/::,10:,:,:,,",
                rihs01::<Image>()
            )
        );
        let bytes = attachment(7, 1_700_000_000_000_000_000, &[9; 16]);
        assert_eq!(&bytes[..8], &7_i64.to_le_bytes());
        assert_eq!(bytes[16], 16);
        assert_eq!(&bytes[17..], &[9; 16]);
    }
}
