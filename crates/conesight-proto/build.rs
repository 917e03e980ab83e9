//! Generates the Rust types of `proto/conesight/v1/*.proto` with protox (a pure-Rust protobuf
//! compiler, so no `protoc` is needed) and prost-build.

use std::path::PathBuf;

/// The proto files, relative to the include root.
const PROTO_FILES: [&str; 4] = [
    "conesight/v1/header.proto",
    "conesight/v1/frame.proto",
    "conesight/v1/detections.proto",
    "conesight/v1/cones.proto",
];

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let include_root = PathBuf::from(std::env::var("CARGO_MANIFEST_DIR")?).join("../../proto");
    for file in PROTO_FILES {
        println!(
            "cargo:rerun-if-changed={}",
            include_root.join(file).display()
        );
    }
    let descriptors = protox::compile(PROTO_FILES, [&include_root])?;
    // The encoded FileDescriptorSet: recordings carry it as each channel's protobuf schema.
    let out_dir = PathBuf::from(std::env::var("OUT_DIR")?);
    std::fs::write(
        out_dir.join("file_descriptor_set.bin"),
        prost::Message::encode_to_vec(&descriptors),
    )?;
    prost_build::Config::new()
        // Image bytes as `bytes::Bytes`: cloning a frame does not copy its pixels.
        .bytes([".conesight.v1.ImageFrame.data"])
        .compile_fds(descriptors)?;
    Ok(())
}
