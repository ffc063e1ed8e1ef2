//! The cascade XML loader on arbitrary text: it must return `Ok` or `Err`, never panic, hang or
//! run out of memory. A cascade that loads is also run over a small image, so the detector's
//! use of what the loader accepted (feature rectangles, thresholds, tree links) is fuzzed too.
#![no_main]

use libfuzzer_sys::fuzz_target;
use unshear::detect::{Cascade, DetectorParams, FaceDetector};

fuzz_target!(|data: &[u8]| {
    let Ok(text) = std::str::from_utf8(data) else {
        return;
    };
    if let Ok(cascade) = Cascade::from_xml(text) {
        let detector = FaceDetector::new(cascade, DetectorParams::default());
        let gray = image::GrayImage::from_fn(48, 40, |x, y| image::Luma([((x * 7 + y * 13) % 251) as u8]));
        let _ = detector.detect(&gray);
    }
});
