//! # conesight-replay
//!
//! Recordings of `conesight record` (MCAP, one channel per Zenoh key, protobuf schemas named
//! after their message) played back onto the bus, and the cones of two recordings compared.
//!
//! Modules:
//! - `reader`: [`McapFile`] streams one file's messages (one chunk in memory at a time; a
//!   file cut short by a killed recorder gives every message before the cut and says so),
//!   [`Recording`] merges several files in log-time order. Clear errors for a missing file,
//!   a file that is not MCAP, a channel whose schema is not a conesight message, an
//!   undecodable message ([`ReplayError`]).
//! - `files`: [`recording_files`], the files of the recordings named (a split recording by
//!   its base name: `drive.mcap` for `drive_0000.mcap`, `drive_0001.mcap`, ...).
//! - `player`: [`Player`], the recorded frames and camera info published into a chosen
//!   namespace, at the recorded timing scaled by a rate or as fast as the pipeline answers
//!   (one frame at a time, paced on its cones, so no frame is replaced in a service's slot).
//! - `diff`: [`diff`], cones of two runs matched per frame and per cone, by range band.
//! - `job`: replay jobs at scale: the sorted recording list split by [`Shard`] (recording `i`
//!   to shard `i mod count`), results filed per drive and renamed into place
//!   ([`ResultPaths`], [`write_atomic`]), [`JobSummary`], and the merge of a results folder
//!   ([`totals`], [`compare_folders`] against a baseline folder).
//!
//! Entry points: `Player::new(&session, &topics, options)`, `prepare(&paths)`, `play(..)`;
//! `diff(&a, &b, &DiffParams::default())`.

mod diff;
mod error;
mod files;
pub mod job;
mod player;
mod reader;

pub use diff::{
    BandSummary, DiffCone, DiffParams, DiffReport, FrameCount, FrameKey, MatchedPair, RunCones,
    compare, describe, diff, match_frame, percentile, read_cones,
};
pub use error::ReplayError;
pub use files::recording_files;
pub use job::{
    JobSummary, ModelDigest, ResultPaths, Shard, compare_folders, list_recordings, read_summaries,
    totals, write_atomic,
};
pub use player::{Pacing, Player, ReplayOptions, ReplayProgress, ReplaySummary};
pub use reader::{McapFile, RecordedMessage, Recording, decode_message, stream_of_schema};
