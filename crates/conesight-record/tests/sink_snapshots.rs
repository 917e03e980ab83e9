//! What a `kill -9` can leave: the file as it is on disk between any two writes of a real
//! `McapSink`. Every such snapshot must read with `mcap`'s own reader, without tolerance for
//! truncation, up to its last byte: closed chunks are appended whole, and the open chunk is not
//! on disk at all.
#![allow(clippy::unwrap_used, clippy::expect_used, missing_docs)]

use conesight_bus::Stream;
use conesight_record::{McapSink, SinkOptions};
use mcap::records::op;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use rand::{RngCore, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// Messages in `bytes`, read strictly: any record cut short or left unfinished is an error.
fn strict_messages(bytes: &[u8]) -> Result<u64, mcap::McapError> {
    let mut reader =
        LinearReader::new_with_options(LinearReaderOptions::default().with_skip_end_magic(true));
    let mut remaining = bytes;
    let mut messages = 0;
    while let Some(event) = reader.next_event() {
        match event? {
            LinearReadEvent::ReadRequest(n) => {
                let n = n.min(remaining.len());
                reader.insert(n).copy_from_slice(&remaining[..n]);
                reader.notify_read(n);
                remaining = &remaining[n..];
            }
            LinearReadEvent::Record { opcode, .. } => messages += u64::from(opcode == op::MESSAGE),
        }
    }
    Ok(messages)
}

/// Incompressible bytes, so zstd emits blocks while a chunk fills.
fn noise(len: usize, seed: u64) -> Vec<u8> {
    let mut bytes = vec![0; len];
    ChaCha8Rng::seed_from_u64(seed).fill_bytes(&mut bytes);
    bytes
}

#[test]
fn the_file_on_disk_reads_whole_between_any_two_writes() {
    let dir = std::env::temp_dir().join(format!("conesight-sink-snapshots-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("run.mcap");
    let options = SinkOptions {
        chunk_bytes: 1 << 20,
        ..SinkOptions::default()
    };
    let mut sink = McapSink::create(&path, options).unwrap();
    const MESSAGES: u64 = 40;
    const MESSAGE_BYTES: usize = 300 << 10;
    let mut seen = Vec::new();
    for sequence in 0..MESSAGES {
        let data = noise(MESSAGE_BYTES, sequence);
        sink.write(
            "conesight/x/car/front/frames",
            Stream::Frame,
            1_000 + sequence,
            1_000 + sequence,
            &data,
        )
        .unwrap();
        let snapshot = std::fs::read(&path).unwrap();
        let read = strict_messages(&snapshot).unwrap_or_else(|error| {
            panic!(
                "after message {sequence} the file ({} bytes) does not read: {error}",
                snapshot.len()
            )
        });
        assert!(read <= sequence + 1);
        seen.push(read);
    }
    // Chunks of 1 MiB close every fourth message: the snapshots saw them close, and the open
    // chunk never held more than one chunk's worth of messages.
    assert!(seen.windows(2).all(|w| w[0] <= w[1]), "{seen:?}");
    let distinct = seen.iter().collect::<std::collections::BTreeSet<_>>().len();
    assert!(distinct >= 8, "chunks seen closing: {seen:?}");
    assert!(seen[seen.len() - 1] + 5 >= MESSAGES, "{seen:?}");
    let files = sink.finish().unwrap();
    let whole = std::fs::read(&files[0]).unwrap();
    let messages = mcap::MessageStream::new(&whole)
        .unwrap()
        .collect::<Result<Vec<_>, _>>()
        .unwrap()
        .len() as u64;
    assert_eq!(messages, MESSAGES);
    std::fs::remove_dir_all(&dir).unwrap();
}
