//! Payloads written in place: a large message (an image frame) is written once, straight into
//! a buffer of the session's shared-memory pool when it has one, so neither the encoder nor
//! Zenoh copies it again ([`write_payload`]). Subscribers on the same host then see the
//! publisher's buffer itself, and `crate::codec::decode_with_limit` slices the pixels out of it
//! without a copy. When the pool is missing (shared memory off, still initialising, or
//! unavailable, e.g. no memlock allowance) or full, the payload goes to the heap and Zenoh
//! sends it over the socket. Pixels published again and again (a looped frame) are written
//! once and kept in the pool ([`PixelSlice`]): each publish then costs a header.

use std::convert::Infallible;

use zenoh::Session;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::shm::{GarbageCollect, ShmBuf, ZShm, ZShmMut};

/// Where a payload from [`write_payload`] was written.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PayloadStorage {
    /// A buffer of the session's shared-memory pool.
    SharedMemory,
    /// The heap.
    Heap,
}

/// A payload of exactly `len` bytes filled by `write` (given a zeroed `&mut [u8]` of `len`
/// bytes), in the session's shared memory when possible (see the module docs).
pub fn write_payload<E>(
    session: &Session,
    len: usize,
    write: impl FnOnce(&mut [u8]) -> Result<(), E>,
) -> Result<(ZBytes, PayloadStorage), E> {
    if let Some(mut buffer) = alloc_shared(session, len) {
        write(&mut buffer[..])?;
        return Ok((ZBytes::from(buffer), PayloadStorage::SharedMemory));
    }
    let mut buffer = vec![0_u8; len];
    write(&mut buffer)?;
    Ok((ZBytes::from(buffer), PayloadStorage::Heap))
}

/// A buffer of `len` bytes from `session`'s shared-memory pool (released buffers collected
/// first when it is full); `None` without a pool or room.
fn alloc_shared(session: &Session, len: usize) -> Option<ZShmMut> {
    let provider = session.get_shm_provider().into_option()?;
    provider
        .alloc(len)
        .with_policy::<GarbageCollect>()
        .wait()
        .ok()
}

/// [`write_payload`] for writers that cannot fail.
pub fn write_payload_infallible(
    session: &Session,
    len: usize,
    write: impl FnOnce(&mut [u8]),
) -> (ZBytes, PayloadStorage) {
    let result: Result<_, Infallible> = write_payload(session, len, |buf| {
        write(buf);
        Ok(())
    });
    match result {
        Ok(payload) => payload,
        Err(never) => match never {},
    }
}

/// Whether any slice of `payload` is in shared memory: a payload written whole into the pool
/// ([`write_payload`]) or a cached frame's pixels after its header ([`PixelSlice`]).
pub fn in_shared_memory(payload: &ZBytes) -> bool {
    if payload.as_shm().is_some() {
        return true;
    }
    let zbuf = zenoh_buffers::ZBuf::from(payload.clone());
    zbuf.zslices()
        .any(|slice| slice.downcast_ref::<zenoh_shm::ShmBufInner>().is_some())
}

/// A large immutable part of a message (a frame's pixels) written once into a buffer of the
/// session's shared-memory pool and published again and again without a copy: each payload is
/// a small slice of its own (the header, which changes) followed by this buffer
/// ([`PixelSlice::payload`]). A camera looping over cached frames keeps one per frame, so a
/// frame costs a header, not a 6.9 MB copy. Receivers must not change it (nothing here does:
/// decoded frames are read-only views).
#[derive(Debug, Clone)]
pub struct PixelSlice(ZShm);

impl PixelSlice {
    /// `data` copied into a new buffer of `session`'s pool, when it has one with room for it
    /// (the caller keeps count of what it holds against [`shm_pool_bytes`]).
    pub fn write(session: &Session, data: &[u8]) -> Option<Self> {
        let mut buffer = alloc_shared(session, data.len())?;
        buffer.copy_from_slice(data);
        Some(Self(ZShm::from(buffer)))
    }

    /// False once Zenoh has invalidated the buffer: its watchdog went unconfirmed, as when the
    /// process stalled (stopped, swapped out) for more than about 100 ms. Receivers drop an
    /// invalid buffer, so it must be written again.
    pub fn is_valid(&self) -> bool {
        self.0.is_valid()
    }

    /// Bytes held.
    pub fn len(&self) -> usize {
        self.0.len()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// `head` followed by this buffer, without copying it.
    pub fn payload(&self, head: Vec<u8>) -> ZBytes {
        let mut writer = ZBytes::writer();
        writer.append(ZBytes::from(head));
        writer.append(ZBytes::from(self.0.clone()));
        writer.finish()
    }
}
