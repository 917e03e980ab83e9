//! Payloads written in place: a large message (an image frame) is written once, straight into
//! a buffer of the session's shared-memory pool when it has one, so neither the encoder nor
//! Zenoh copies it again ([`write_payload`]). Subscribers on the same host then see the
//! publisher's buffer itself, and `crate::codec::decode_with_limit` slices the pixels out of it
//! without a copy. When the pool is missing (shared memory off, still initialising, or
//! unavailable, e.g. no memlock allowance) or full, the payload goes to the heap and Zenoh
//! sends it over the socket.

use std::convert::Infallible;

use zenoh::Session;
use zenoh::Wait;
use zenoh::bytes::ZBytes;
use zenoh::shm::GarbageCollect;

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
    if let Some(provider) = session.get_shm_provider().into_option()
        && let Ok(mut buffer) = provider.alloc(len).with_policy::<GarbageCollect>().wait()
    {
        write(&mut buffer[..])?;
        return Ok((ZBytes::from(buffer), PayloadStorage::SharedMemory));
    }
    let mut buffer = vec![0_u8; len];
    write(&mut buffer)?;
    Ok((ZBytes::from(buffer), PayloadStorage::Heap))
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
