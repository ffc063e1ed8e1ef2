//! Bounded cost for any shape of image (issue 39, item 4): a very tall or very wide image must
//! not cost memory or time out of proportion to its pixels. Before the bound on views
//! (`pipeline::MAX_VIEW_PIXELS_RATIO`), a 308x56826 image took 3.5 GB and 113 s with
//! `estimate --quick`: its de-sheared and turned views were gigapixel canvases of padding.
//!
//! Heap use is counted by a global allocator in this test binary (one test, so nothing else
//! allocates meanwhile): the peak during `estimate` must stay within 4 times the decoded RGB
//! image, the bound of `docs/performance.md`.

use std::alloc::{GlobalAlloc, Layout, System};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use image::{DynamicImage, RgbImage};
use unshear::{Config, Unshear};

struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = LIVE.fetch_add(by, Ordering::Relaxed) + by;
    PEAK.fetch_max(now, Ordering::Relaxed);
}

// SAFETY: every call is forwarded to the system allocator unchanged; only counts are added.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = unsafe { System.alloc_zeroed(layout) };
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        unsafe { System.dealloc(ptr, layout) };
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = unsafe { System.realloc(ptr, layout, new_size) };
        if !p.is_null() {
            LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
            grew(new_size);
        }
        p
    }
}

#[global_allocator]
static ALLOCATOR: Counting = Counting;

/// A textured image (a smooth pattern with fine detail, so the cascade has work to do but
/// finds no face) of `width` x `height`.
fn textured(width: u32, height: u32) -> DynamicImage {
    DynamicImage::ImageRgb8(RgbImage::from_fn(width, height, |x, y| {
        let (fx, fy) = (f64::from(x), f64::from(y));
        let v =
            128.0 + 60.0 * (fx * 0.37).sin() * (fy * 0.23).cos() + 30.0 * (fx * fy * 1e-3).sin();
        let g = v.clamp(0.0, 255.0) as u8;
        image::Rgb([g, g.wrapping_add(20), g / 2])
    }))
}

/// Peak heap bytes above what was live before, and seconds, of one estimate.
fn measure(unshear: &Unshear, img: &DynamicImage) -> (usize, f64, unshear::ImageReport) {
    let before = LIVE.load(Ordering::Relaxed);
    PEAK.store(before, Ordering::Relaxed);
    let start = Instant::now();
    let report = unshear.estimate(img);
    let seconds = start.elapsed().as_secs_f64();
    (PEAK.load(Ordering::Relaxed) - before, seconds, report)
}

#[test]
fn very_tall_and_very_wide_images_cost_memory_and_time_in_proportion_to_their_pixels() {
    let network = Unshear::new(Config::default()).expect("models");
    let thorough = Unshear::new(Config::thorough()).expect("models");
    let quick = Unshear::new(Config::quick()).expect("models");
    // The reference: a square of the same number of pixels (6 MP), searched quickly.
    let square = textured(2450, 2450);
    let (_, square_seconds, _) = measure(&quick, &square);
    drop(square);
    for (w, h) in [(300, 20_000), (20_000, 300)] {
        let img = textured(w, h);
        let decoded = img.as_bytes().len();
        for (name, unshear) in [
            ("network", &network),
            ("thorough", &thorough),
            ("quick", &quick),
        ] {
            let (peak, seconds, report) = measure(unshear, &img);
            eprintln!(
                "{w}x{h} {name}: peak {:.1} MB ({:.2}x the decoded {:.1} MB), {seconds:.2} s (square {square_seconds:.2} s)",
                peak as f64 / 1e6,
                peak as f64 / decoded as f64,
                decoded as f64 / 1e6
            );
            assert!(
                peak <= 4 * decoded,
                "{w}x{h} {name}: peak heap {peak} bytes, more than 4x the decoded {decoded}"
            );
            // Time in proportion to the pixels: no more than 3 times the square's (each view
            // searched is at most 4 times the pixels, the square's views up to 2 times), plus a
            // second of slack for a loaded machine's noise on short runs.
            assert!(
                seconds <= 3.0 * square_seconds + 1.0,
                "{w}x{h} {name}: {seconds:.2} s against {square_seconds:.2} s for the square"
            );
            assert!(report.k.is_none(), "{w}x{h} {name}: a shear from a texture");
            // The cascade's searches skip the views that would be mostly padding, and say so;
            // the network detector searches no views.
            let viola_jones = unshear.config().detector == unshear::Detector::ViolaJones;
            assert_eq!(
                report.warnings.iter().any(|w| w.contains("not searched")),
                viola_jones,
                "{w}x{h} {name}: the skipped views are reported: {:?}",
                report.warnings
            );
        }
    }
}
