//! Bad recordings give errors that name the file, the channel and the fix; a truncated file
//! gives every message before the cut. Real files written with `McapSink` and the `mcap` crate.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use conesight_bus::Stream;
use conesight_proto::{Message, pb};
use conesight_record::{McapSink, SinkOptions};
use conesight_replay::{Recording, ReplayError, read_cones};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

fn dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("conesight-replay-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn cones(sequence: u64) -> Vec<u8> {
    pb::Cones::new_stamped(
        pb::Header::new("front", sequence, 7 + sequence, "front_optical"),
        &[],
    )
    .encode_to_vec()
}

/// `count` cones messages, `chunk_bytes` per chunk.
fn write_recording(path: &Path, count: u64, chunk_bytes: u64) {
    let options = SinkOptions {
        chunk_bytes,
        ..SinkOptions::default()
    };
    let mut sink = McapSink::create(path, options).unwrap();
    for sequence in 0..count {
        let data = cones(sequence);
        sink.write(
            "conesight/x/car/front/cones",
            Stream::Cones,
            1_000 + sequence,
            1_000 + sequence,
            &data,
        )
        .unwrap();
    }
    sink.finish().unwrap();
}

/// The frame sequence of every cones message, in file order.
fn cone_sequences(recording: &mut Recording) -> Vec<u64> {
    let mut sequences = Vec::new();
    while let Some(message) = recording.next_message().unwrap() {
        let cones = pb::Cones::decode(&message.data[..]).unwrap();
        sequences.push(cones.header.unwrap().frame_sequence);
    }
    sequences
}

fn open_error(path: &Path) -> String {
    match Recording::open(&[path.to_path_buf()]).and_then(|mut r| {
        while r.next_message()?.is_some() {}
        Ok(())
    }) {
        Ok(()) => panic!("{} opened", path.display()),
        Err(error) => error.to_string(),
    }
}

#[test]
fn a_missing_file_and_a_file_that_is_not_mcap_are_named() {
    let dir = dir("bad");
    let missing = dir.join("nope.mcap");
    let message = open_error(&missing);
    assert!(
        message.contains("nope.mcap") && message.contains("check the path"),
        "{message}"
    );
    let text = dir.join("notes.mcap");
    std::fs::write(&text, "not a recording").unwrap();
    let message = open_error(&text);
    assert!(
        message.contains("notes.mcap") && message.contains("not an MCAP file"),
        "{message}"
    );
}

#[test]
fn a_channel_of_another_schema_is_named_with_its_topic() {
    let dir = dir("schema");
    let path = dir.join("other.mcap");
    let mut writer = mcap::Writer::new(std::fs::File::create(&path).unwrap()).unwrap();
    let schema = writer.add_schema("foxglove.Log", "protobuf", b"").unwrap();
    let channel = writer
        .add_channel(schema, "/rosout", "protobuf", &BTreeMap::new())
        .unwrap();
    writer
        .write_to_known_channel(
            &mcap::records::MessageHeader {
                channel_id: channel,
                sequence: 0,
                log_time: 1,
                publish_time: 1,
            },
            b"x",
        )
        .unwrap();
    writer.finish().unwrap();
    let message = open_error(&path);
    assert!(
        message.contains("/rosout")
            && message.contains("foxglove.Log")
            && message.contains("conesight.v1.Cones"),
        "{message}"
    );
}

#[test]
fn an_undecodable_message_is_named_with_its_channel_and_index() {
    let dir = dir("undecodable");
    let path = dir.join("broken.mcap");
    let mut sink = McapSink::create(&path, SinkOptions::default()).unwrap();
    sink.write(
        "conesight/x/car/front/cones",
        Stream::Cones,
        1,
        1,
        &cones(0),
    )
    .unwrap();
    sink.write(
        "conesight/x/car/front/cones",
        Stream::Cones,
        2,
        2,
        &[0xff, 0xff, 0xff],
    )
    .unwrap();
    sink.finish().unwrap();
    let error = read_cones(std::slice::from_ref(&path)).unwrap_err();
    assert!(
        matches!(error, ReplayError::Undecodable { index: 1, .. }),
        "{error:?}"
    );
    let message = error.to_string();
    assert!(
        message.contains("broken.mcap")
            && message.contains("conesight/x/car/front/cones")
            && message.contains("conesight.v1.Cones"),
        "{message}"
    );
}

#[test]
fn a_truncated_file_gives_every_message_of_its_closed_chunks() {
    let dir = dir("truncated");
    let path = dir.join("full.mcap");
    write_recording(&path, 400, 4096);
    let bytes = std::fs::read(&path).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    assert!(summary.chunk_indexes.len() >= 4);
    let chunk = &summary.chunk_indexes[summary.chunk_indexes.len() / 2];
    // Log times are 1000 + sequence: the messages before the cut chunk.
    let before = (chunk.message_start_time - 1_000) as usize;
    assert!(before > 0);
    let cut = dir.join("cut.mcap");
    std::fs::write(
        &cut,
        &bytes[..(chunk.chunk_start_offset + chunk.chunk_length / 2) as usize],
    )
    .unwrap();
    let mut recording = Recording::open(std::slice::from_ref(&cut)).unwrap();
    let sequences = cone_sequences(&mut recording);
    assert!(sequences.len() >= before, "{} of {before}", sequences.len());
    assert_eq!(sequences, (0..sequences.len() as u64).collect::<Vec<_>>());
    assert_eq!(recording.truncated(), vec![cut.clone()]);
    // The whole file reads to the end and is not truncated.
    let run = read_cones(std::slice::from_ref(&path)).unwrap();
    assert_eq!(run.frames.len(), 400);
    assert!(!run.truncated);
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A file `mcap`'s default writer left when killed with a chunk open: the chunk is written in
/// place (a placeholder header, then the compressed data as zstd emits it), as conesight's
/// recorder did before it appended chunks whole. Recordings made then still read.
#[test]
fn a_file_killed_inside_a_chunk_written_in_place_reads_as_truncated() {
    let dir = dir("in-place");
    let path = dir.join("killed.mcap");
    let file = std::fs::File::create(&path).unwrap();
    let mut writer = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(0)
        .chunk_size(Some(8 << 20))
        .create(file)
        .unwrap();
    let schema = writer
        .add_schema(
            conesight_record::message_name(Stream::Cones),
            conesight_record::SCHEMA_ENCODING,
            conesight_proto::FILE_DESCRIPTOR_SET,
        )
        .unwrap();
    let channel = writer
        .add_channel(
            schema,
            "conesight/x/car/front/cones",
            conesight_record::MESSAGE_ENCODING,
            &BTreeMap::new(),
        )
        .unwrap();
    let write = |writer: &mut mcap::Writer<std::fs::File>, sequence: u64, data: &[u8]| {
        let header = mcap::records::MessageHeader {
            channel_id: channel,
            sequence: sequence as u32,
            log_time: 1_000 + sequence,
            publish_time: 1_000 + sequence,
        };
        writer.write_to_known_channel(&header, data).unwrap();
    };
    for sequence in 0..100 {
        write(&mut writer, sequence, &cones(sequence));
    }
    // Closes the chunk: 100 messages are on disk for good.
    writer.flush().unwrap();
    // One large incompressible message: zstd emits blocks of it into the open chunk.
    let mut noise = vec![0; 400 << 10];
    ChaCha8Rng::seed_from_u64(7).fill_bytes(&mut noise);
    write(&mut writer, 100, &noise);
    // kill -9: nothing more reaches the file.
    std::mem::forget(writer);
    let len = std::fs::metadata(&path).unwrap().len();
    assert!(
        len > 256 << 10,
        "zstd emitted the open chunk's data: {len} bytes"
    );

    let mut recording = Recording::open(std::slice::from_ref(&path)).unwrap();
    let sequences = cone_sequences(&mut recording);
    assert_eq!(sequences, (0..100).collect::<Vec<_>>());
    assert_eq!(recording.truncated(), vec![path.clone()]);

    // The same damage in a finished file (its footer intact) is an error naming the file.
    let finished = dir.join("finished.mcap");
    write_recording(&finished, 400, 4096);
    let mut bytes = std::fs::read(&finished).unwrap();
    let summary = mcap::Summary::read(&bytes).unwrap().unwrap();
    let chunk = &summary.chunk_indexes[1];
    // The chunk's compressed size as the placeholder a killed in-place writer leaves.
    let at = (chunk.chunk_start_offset + 9 + 8 + 8 + 8 + 4 + 4 + 4) as usize;
    bytes[at..at + 8].copy_from_slice(&u64::MAX.to_le_bytes());
    std::fs::write(&finished, &bytes).unwrap();
    let message = open_error(&finished);
    assert!(
        message.contains("finished.mcap") && message.contains("damaged"),
        "{message}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}
