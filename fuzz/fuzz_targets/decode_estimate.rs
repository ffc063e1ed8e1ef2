//! Decode-then-estimate on arbitrary bytes: `imageio::read_image_from_memory` (format detected
//! from the content, size limit checked before decoding) with a small pixel limit, then the whole
//! estimate (detection, features, shear). Nothing may panic, hang or allocate without bound.
#![no_main]

use std::sync::OnceLock;

use libfuzzer_sys::fuzz_target;
use unshear::Unshear;

/// Small enough that one estimate stays fast; large enough for a detectable face (the
/// detector's window is 20x20).
const MAX_PIXELS: u64 = 256 * 256;

fn unshear() -> &'static Unshear {
    static U: OnceLock<Unshear> = OnceLock::new();
    U.get_or_init(|| Unshear::new(unshear::Config::default()).expect("the built-in models load"))
}

fuzz_target!(|data: &[u8]| {
    if let Ok(img) = unshear::imageio::read_image_from_memory(data, MAX_PIXELS) {
        assert!(u64::from(img.width()) * u64::from(img.height()) <= MAX_PIXELS);
        let report = unshear().estimate(&img);
        if let Some(k) = report.k {
            assert!(k.is_finite());
        }
    }
});
