//! Peak memory for one 4000x3000 photo (12 MP; 36 MB as 8-bit RGB), through the same steps as
//! `unshear correct`: read the JPEG, estimate, correct, free the input, write a JPEG.
//!
//! Run: `cargo bench --bench memory`. It prints, relative to the decoded size:
//!
//! * peak heap of the library path, counted by this binary's global allocator (exact: every
//!   allocation made while the steps run, above what was allocated before);
//! * peak resident memory (VmHWM) of a fresh process running those steps (heap plus code, thread
//!   stacks and allocator slack);
//! * peak resident memory (maximum RSS) of the `unshear correct` command on the same file.
//!
//! The photo is generated: a fixture face enlarged to 1600 px wide on a noisy background (so the
//! JPEG has realistic size and detail), with one face for the estimate to find.

use std::alloc::{GlobalAlloc, Layout, System};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};

/// Counts live heap bytes and their peak; delegates to the system allocator.
struct Counting;

static LIVE: AtomicUsize = AtomicUsize::new(0);
static PEAK: AtomicUsize = AtomicUsize::new(0);

fn grew(by: usize) {
    let now = LIVE.fetch_add(by, Ordering::Relaxed) + by;
    PEAK.fetch_max(now, Ordering::Relaxed);
}

// SAFETY: every method forwards to `System` with the same arguments; the counters do not affect
// what is returned.
unsafe impl GlobalAlloc for Counting {
    unsafe fn alloc(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc(layout);
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }
    unsafe fn alloc_zeroed(&self, layout: Layout) -> *mut u8 {
        let p = System.alloc_zeroed(layout);
        if !p.is_null() {
            grew(layout.size());
        }
        p
    }
    unsafe fn dealloc(&self, ptr: *mut u8, layout: Layout) {
        System.dealloc(ptr, layout);
        LIVE.fetch_sub(layout.size(), Ordering::Relaxed);
    }
    unsafe fn realloc(&self, ptr: *mut u8, layout: Layout, new_size: usize) -> *mut u8 {
        let p = System.realloc(ptr, layout, new_size);
        if !p.is_null() {
            if new_size >= layout.size() {
                grew(new_size - layout.size());
            } else {
                LIVE.fetch_sub(layout.size() - new_size, Ordering::Relaxed);
            }
        }
        p
    }
}

#[global_allocator]
static ALLOC: Counting = Counting;

const WIDTH: u32 = 4000;
const HEIGHT: u32 = 3000;
const DECODED: f64 = (WIDTH * HEIGHT * 3) as f64;
const MB: f64 = 1e6;
/// Set in the child process that measures the library path: the photo to read.
const CHILD_ENV: &str = "UNSHEAR_MEMORY_BENCH_PHOTO";

fn fail(what: &str, e: impl std::fmt::Display) -> ! {
    eprintln!("memory bench: {what}: {e}");
    std::process::exit(1)
}

/// Writes the generated 4000x3000 JPEG into `dir`.
fn make_photo(dir: &Path) -> PathBuf {
    let face = concat!(
        concat!(env!("CARGO_MANIFEST_DIR"), "/.."),
        "/tests/fixtures/faces/subject01.normal.jpeg"
    );
    let face = image::open(face).unwrap_or_else(|e| fail("fixture", e));
    let face = face
        .resize(1600, 1600, image::imageops::FilterType::Triangle)
        .to_rgb8();
    let mut state = 0x2545_f491_u32;
    let mut photo = image::RgbImage::from_fn(WIDTH, HEIGHT, |x, y| {
        state ^= state << 13;
        state ^= state >> 17;
        state ^= state << 5;
        let n = (state >> 24) as u8 / 8;
        image::Rgb([(x / 20) as u8 / 2 + n, (y / 15) as u8 / 2 + n, 100 + n])
    });
    let (fx, fy) = ((WIDTH - face.width()) / 2, (HEIGHT - face.height()) / 2);
    image::imageops::overlay(&mut photo, &face, i64::from(fx), i64::from(fy));
    let path = dir.join("photo.jpg");
    image::DynamicImage::ImageRgb8(photo)
        .save(&path)
        .unwrap_or_else(|e| fail("writing the photo", e));
    path
}

/// VmHWM of this process, bytes (Linux); `None` elsewhere.
fn vm_hwm() -> Option<f64> {
    let status = std::fs::read_to_string("/proc/self/status").ok()?;
    let line = status.lines().find(|l| l.starts_with("VmHWM:"))?;
    let kb: f64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kb * 1024.0)
}

/// The child: the library path on `photo`, printing one line per figure.
fn measure_library(photo: &Path) {
    let unshear =
        unshear::Unshear::new(unshear::Config::default()).unwrap_or_else(|e| fail("models", e));
    let base = LIVE.load(Ordering::Relaxed);
    PEAK.store(base, Ordering::Relaxed);
    let img = unshear::imageio::read_image(photo, unshear::imageio::DEFAULT_MAX_PIXELS)
        .unwrap_or_else(|e| fail("reading", e));
    let after_read = PEAK.load(Ordering::Relaxed) - base;
    let report = unshear.estimate(&img);
    let Some(k) = report.k else {
        fail("estimate", "no face found in the generated photo")
    };
    let after_estimate = PEAK.load(Ordering::Relaxed) - base;
    let fixed = unshear::Unshear::correct(&img, &report, &Default::default())
        .unwrap_or_else(|e| fail("correcting", e));
    drop(img);
    let out = photo.with_file_name("fixed.jpg");
    unshear::imageio::write_image_atomic(&fixed, &out, Default::default())
        .unwrap_or_else(|e| fail("writing", e));
    drop(fixed);
    let peak = PEAK.load(Ordering::Relaxed) - base;
    println!("k estimated: {k:+.3}");
    for (what, bytes) in [
        ("peak heap after reading", after_read),
        ("peak heap after estimating", after_estimate),
        ("peak heap, whole correct path", peak),
    ] {
        println!(
            "{what:<40} {:>7.1} MB = {:.2} x decoded",
            bytes as f64 / MB,
            bytes as f64 / DECODED
        );
    }
    if let Some(hwm) = vm_hwm() {
        println!(
            "{:<40} {:>7.1} MB = {:.2} x decoded",
            "peak RSS (VmHWM), library path",
            hwm / MB,
            hwm / DECODED
        );
    }
}

/// Maximum RSS of the largest finished child process, bytes.
#[cfg(unix)]
fn children_max_rss() -> Option<f64> {
    // SAFETY: getrusage writes into the zeroed struct we own.
    let mut usage: libc::rusage = unsafe { std::mem::zeroed() };
    let rc = unsafe { libc::getrusage(libc::RUSAGE_CHILDREN, &mut usage) };
    (rc == 0).then_some(usage.ru_maxrss as f64 * 1024.0)
}

#[cfg(not(unix))]
fn children_max_rss() -> Option<f64> {
    None
}

fn main() {
    if let Some(photo) = std::env::var_os(CHILD_ENV) {
        measure_library(Path::new(&photo));
        return;
    }
    let dir = tempfile::tempdir().unwrap_or_else(|e| fail("temp dir", e));
    let photo = make_photo(dir.path());
    println!(
        "photo: {WIDTH}x{HEIGHT} JPEG, {:.1} MB on disk, {:.1} MB decoded (RGB 8-bit)",
        std::fs::metadata(&photo).map_or(0.0, |m| m.len() as f64 / MB),
        DECODED / MB
    );
    let me = std::env::current_exe().unwrap_or_else(|e| fail("own path", e));
    let status = std::process::Command::new(me)
        .env(CHILD_ENV, &photo)
        .env("RAYON_NUM_THREADS", "2")
        .status()
        .unwrap_or_else(|e| fail("running the library measurement", e));
    if !status.success() {
        fail("library measurement", status);
    }
    // The command itself; the children's maximum RSS is the larger of the two runs, so it is
    // read after each.
    let lib_rss = children_max_rss();
    let out = dir.path().join("cli.jpg");
    let status = std::process::Command::new(env!("CARGO_BIN_EXE_unshear"))
        .args(["correct", "--jobs", "2", "-o"])
        .arg(&out)
        .arg(&photo)
        .status()
        .unwrap_or_else(|e| fail("running unshear correct", e));
    if !status.success() {
        fail("unshear correct", status);
    }
    match (children_max_rss(), lib_rss) {
        (Some(rss), Some(before)) if rss > before => println!(
            "{:<40} {:>7.1} MB = {:.2} x decoded",
            "peak RSS of `unshear correct`",
            rss / MB,
            rss / DECODED
        ),
        (Some(rss), _) => println!(
            "peak RSS of `unshear correct`: at most {:.1} MB = {:.2} x decoded (not above the library run)",
            rss / MB,
            rss / DECODED
        ),
        _ => println!("peak RSS of `unshear correct`: not available on this platform"),
    }
}
