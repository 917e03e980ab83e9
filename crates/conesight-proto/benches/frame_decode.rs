//! Bytes on the bus -> RGB8 image for a 1920x1200 frame: raw RGB8, raw BGR8 and JPEG (q90),
//! side by side in one group, then the JPEG/raw ratio from one timed pass of each.

#![allow(clippy::unwrap_used, missing_docs)]

use std::time::Instant;

use conesight_proto::{Message, pb};
use criterion::{Criterion, criterion_group, criterion_main};

fn test_image() -> image::RgbImage {
    image::RgbImage::from_fn(1920, 1200, |x, y| {
        image::Rgb([(x % 251) as u8, (y % 241) as u8, ((x * y) % 239) as u8])
    })
}

fn encoded_frames() -> Vec<(&'static str, Vec<u8>)> {
    let image = test_image();
    let header = pb::Header::new("front", 0, 0, "front_optical");
    let raw = pb::ImageFrame::from_rgb(header.clone(), &image);
    let mut bgr = raw.clone();
    bgr.encoding = pb::ImageEncoding::Bgr8.into();
    let jpeg = pb::ImageFrame::from_rgb_jpeg(header, &image, 90).unwrap();
    vec![
        ("rgb8", raw.encode_to_vec()),
        ("bgr8", bgr.encode_to_vec()),
        ("jpeg_q90", jpeg.encode_to_vec()),
    ]
}

fn decode(bytes: &[u8]) -> image::RgbImage {
    pb::ImageFrame::decode(bytes).unwrap().into_rgb().unwrap()
}

fn frame_decode(c: &mut Criterion) {
    let frames = encoded_frames();
    let mut group = c.benchmark_group("frame_to_rgb_1920x1200");
    group.sample_size(20);
    for (name, bytes) in &frames {
        group.bench_function(*name, |b| b.iter(|| decode(bytes)));
    }
    group.finish();

    let mean_secs = |bytes: &[u8]| {
        let started = Instant::now();
        for _ in 0..10 {
            std::hint::black_box(decode(bytes));
        }
        started.elapsed().as_secs_f64() / 10.0
    };
    let raw = mean_secs(&frames[0].1);
    let jpeg = mean_secs(&frames[2].1);
    println!(
        "frame_to_rgb: rgb8 {:.2} ms ({} bytes), jpeg_q90 {:.2} ms ({} bytes): jpeg/raw time x{:.1}, size x{:.3}",
        raw * 1e3,
        frames[0].1.len(),
        jpeg * 1e3,
        frames[2].1.len(),
        jpeg / raw,
        frames[2].1.len() as f64 / frames[0].1.len() as f64,
    );
}

criterion_group!(benches, frame_decode);
criterion_main!(benches);
