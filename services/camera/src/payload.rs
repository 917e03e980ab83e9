//! The bus payload of a frame: raw RGB8 written once into shared memory (a looped frame's
//! pixels kept there and sent again behind a new header) or JPEG.

use conesight_bus::{FrameEncoding, PayloadStorage, write_payload};
use conesight_pipeline::{Node, SourceFrame};
use conesight_proto::pb;

/// Pixels of looped frames kept in shared memory, by source index (a preloaded or folder
/// frame's index), while they fit in the session's pool with [`KEPT_HEADROOM_FRAMES`] frames
/// to spare.
#[derive(Debug)]
pub(crate) struct KeptPixels {
    slices: std::collections::HashMap<u64, conesight_bus::PixelSlice>,
    pool_bytes: usize,
}

/// Frames' worth of the shared-memory pool [`KeptPixels`] leaves free: for frames that are
/// not kept, and for the ones receivers still hold.
const KEPT_HEADROOM_FRAMES: usize = 3;

impl KeptPixels {
    pub(crate) fn new(pool_bytes: usize) -> Self {
        Self {
            slices: std::collections::HashMap::new(),
            pool_bytes,
        }
    }

    /// The pixels of `frame` in shared memory: kept from an earlier loop, or written now and
    /// kept when they fit; `None` when they do not (or the session has no pool).
    fn get_or_write(
        &mut self,
        session: &conesight_bus::zenoh::Session,
        frame: &SourceFrame,
    ) -> Option<conesight_bus::PixelSlice> {
        let pixels = frame.image.as_raw();
        if let Some(slice) = self.slices.get(&frame.index) {
            if slice.is_valid() {
                return (slice.len() == pixels.len()).then(|| slice.clone());
            }
            // Invalidated by Zenoh (this process stalled): receivers would drop it.
            tracing::debug!(
                index = frame.index,
                "kept pixels invalidated; writing them again"
            );
            self.slices.remove(&frame.index);
        }
        let kept_bytes: usize = self.slices.values().map(|slice| slice.len()).sum();
        let needed = pixels
            .len()
            .saturating_mul(1 + KEPT_HEADROOM_FRAMES)
            .saturating_add(kept_bytes);
        if needed > self.pool_bytes {
            return None;
        }
        let slice = conesight_bus::PixelSlice::write(session, pixels)?;
        self.slices.insert(frame.index, slice.clone());
        Some(slice)
    }
}

/// The bus payload of one frame, its header stamped as published. Raw RGB8 frames: a looped
/// frame's pixels are written into shared memory once and kept ([`KeptPixels`]), so each
/// publish adds only a small header slice before them; other frames are encoded with their
/// pixels copied once, straight into the session's shared memory when it has a pool
/// (`conesight_bus::write_payload`). JPEG frames are compressed and encoded as usual.
pub(crate) fn frame_payload(
    node: &Node,
    mut header: pb::Header,
    frame: &SourceFrame,
    encoding: FrameEncoding,
    quality: u8,
    kept: Option<&mut KeptPixels>,
) -> anyhow::Result<(conesight_bus::zenoh::bytes::ZBytes, PayloadStorage)> {
    let image = &*frame.image;
    match encoding {
        FrameEncoding::Raw => {
            header.stamp_publish();
            let head = pb::ImageFrame::rgb_header_only(header, image.width(), image.height());
            let pixels = image.as_raw();
            if let Some(slice) = kept.and_then(|kept| kept.get_or_write(&node.session, frame)) {
                let mut bytes = Vec::with_capacity(128);
                head.encode_pixels_prefix(pixels.len(), &mut bytes);
                return Ok((slice.payload(bytes), PayloadStorage::SharedMemory));
            }
            let len = head.encoded_len_with_pixels(pixels.len());
            Ok(write_payload(
                &node.session,
                len,
                |mut buf: &mut [u8]| head.encode_with_pixels(pixels, &mut buf),
            )?)
        }
        FrameEncoding::Jpeg => {
            let mut message = pb::ImageFrame::from_rgb_jpeg(header, image, quality)?;
            if let Some(h) = message.header.as_mut() {
                h.stamp_publish();
            }
            Ok((conesight_bus::encode(&message), PayloadStorage::Heap))
        }
    }
}
