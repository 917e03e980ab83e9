//! Strict decoding refuses no real image: every `STRIDE`-th JPEG and PNG of the shared real data
//! (`../shared/data`, FSOCO frames and keypoint crops of several teams and cameras) decodes, to
//! the size `image`'s lenient decoder gives. Skipped when `../shared` is absent.
//! `CONESIGHT_DECODE_ALL=1` checks every image (4,700 here, 10 s in a release build).

#![allow(clippy::unwrap_used, clippy::expect_used)]

use std::path::{Path, PathBuf};

use conesight_vision::{DecodeLimits, decode_rgb};

const STRIDE: usize = 4;

fn images(dir: &Path, out: &mut Vec<PathBuf>) {
    let Ok(entries) = std::fs::read_dir(dir) else {
        return;
    };
    let mut entries: Vec<PathBuf> = entries.filter_map(|e| e.ok().map(|e| e.path())).collect();
    entries.sort();
    for path in entries {
        if path.is_dir() {
            images(&path, out);
        } else if path
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| matches!(e.to_ascii_lowercase().as_str(), "jpg" | "jpeg" | "png"))
        {
            out.push(path);
        }
    }
}

#[test]
fn every_real_image_decodes_strictly() {
    let shared = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data");
    if !shared.is_dir() {
        eprintln!("SKIPPED: no {}", shared.display());
        return;
    }
    let mut all = Vec::new();
    images(&shared, &mut all);
    let stride = if std::env::var_os("CONESIGHT_DECODE_ALL").is_some() {
        1
    } else {
        STRIDE
    };
    let checked: Vec<&PathBuf> = all.iter().step_by(stride).collect();
    assert!(
        checked.len() >= 50,
        "{} images under {}",
        all.len(),
        shared.display()
    );
    let mut refused = Vec::new();
    for path in &checked {
        let data = std::fs::read(path).unwrap();
        match decode_rgb(&data, DecodeLimits::default()) {
            Ok(image) => {
                let lenient = image::load_from_memory(&data).unwrap();
                assert_eq!(
                    image.dimensions(),
                    (lenient.width(), lenient.height()),
                    "{path:?}"
                );
            }
            Err(error) => refused.push(format!("{}: {error}", path.display())),
        }
    }
    eprintln!(
        "{} of {} real images decoded",
        checked.len() - refused.len(),
        checked.len()
    );
    assert!(refused.is_empty(), "real images refused: {refused:#?}");
}
