//! Which protobuf message each stream carries, as MCAP names it.

use conesight_bus::Stream;

/// MCAP schema encoding of every channel: a protobuf `FileDescriptorSet`.
pub const SCHEMA_ENCODING: &str = "protobuf";
/// MCAP message encoding of every channel: protobuf, as on the bus.
pub const MESSAGE_ENCODING: &str = "protobuf";

/// The full protobuf name of the message `stream` carries (the MCAP schema name).
pub fn message_name(stream: Stream) -> &'static str {
    match stream {
        Stream::Frame => "conesight.v1.ImageFrame",
        Stream::CameraInfo => "conesight.v1.CameraInfo",
        Stream::Detections => "conesight.v1.Detections",
        Stream::Keypoints => "conesight.v1.Keypoints",
        Stream::Cones => "conesight.v1.Cones",
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use conesight_proto::Message;

    /// Every schema name is a message of the descriptor set recordings carry.
    #[test]
    fn every_stream_names_a_message_of_the_descriptor_set() {
        let set = prost_types_names(conesight_proto::FILE_DESCRIPTOR_SET);
        for stream in Stream::ALL {
            assert!(set.contains(&message_name(stream).to_owned()), "{stream:?}");
        }
    }

    /// Full names of the top-level messages of an encoded FileDescriptorSet, read with a
    /// hand-written minimal schema (file = 1, package = 2, message_type = 4, name = 1).
    fn prost_types_names(bytes: &[u8]) -> Vec<String> {
        #[derive(Clone, PartialEq, conesight_proto::Message)]
        struct Set {
            #[prost(message, repeated, tag = "1")]
            file: Vec<File>,
        }
        #[derive(Clone, PartialEq, conesight_proto::Message)]
        struct File {
            #[prost(string, optional, tag = "2")]
            package: Option<String>,
            #[prost(message, repeated, tag = "4")]
            message_type: Vec<Descriptor>,
        }
        #[derive(Clone, PartialEq, conesight_proto::Message)]
        struct Descriptor {
            #[prost(string, optional, tag = "1")]
            name: Option<String>,
        }
        let set = Set::decode(bytes).unwrap();
        set.file
            .iter()
            .flat_map(|f| {
                let package = f.package.clone().unwrap_or_default();
                f.message_type
                    .iter()
                    .map(move |m| format!("{package}.{}", m.name.clone().unwrap_or_default()))
            })
            .collect()
    }
}
