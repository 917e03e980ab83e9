//! Size limits enforced by every decoder, so an oversize or hostile message is rejected before
//! anything large is allocated.

/// Largest accepted image side, pixels.
pub const MAX_IMAGE_SIDE_PX: u32 = 8192;
/// Most detections, keypoint sets or cones in one message.
pub const MAX_ITEMS_PER_MESSAGE: usize = 1024;
/// Longest accepted camera id, bytes.
pub const MAX_CAMERA_ID_LEN: usize = 64;
/// Tolerance on a quaternion's norm before it is normalised.
pub const QUATERNION_NORM_TOLERANCE: f64 = 1e-3;
/// Bytes per pixel of the raw encodings (RGB8, BGR8).
pub const RAW_BYTES_PER_PIXEL: usize = 3;
