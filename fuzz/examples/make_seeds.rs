//! Writes the seed corpora in `fuzz/corpus/` (committed; run again only to change them):
//! `cargo run --manifest-path fuzz/Cargo.toml --example make_seeds`.
//!
//! Every seed is small (a few KB at most), so the fuzzer mutates structure, not bulk.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use image::{DynamicImage, ImageFormat};

/// A one-stage, one-stump cascade on a 4x4 window (the new OpenCV layout).
const TINY_NEW: &str = r#"<?xml version="1.0"?>
<opencv_storage>
<cascade type_id="opencv-cascade-classifier"><stageType>BOOST</stageType>
  <featureType>HAAR</featureType>
  <height>4</height>
  <width>4</width>
  <stageParams><maxWeakCount>1</maxWeakCount></stageParams>
  <featureParams><maxCatCount>0</maxCatCount></featureParams>
  <stageNum>1</stageNum>
  <stages>
    <_>
      <maxWeakCount>1</maxWeakCount>
      <stageThreshold>0.5</stageThreshold>
      <weakClassifiers>
        <_>
          <internalNodes>0 -1 0 0.25</internalNodes>
          <leafValues>0 1</leafValues></_></weakClassifiers></_></stages>
  <features>
    <_>
      <rects>
        <_>0 0 2 4 1.</_>
        <_>2 0 2 4 -1.</_></rects>
      <tilted>0</tilted></_></features></cascade>
</opencv_storage>
"#;

/// The old layout, a depth-2 tree with a tilted feature.
const TINY_OLD: &str = r#"<opencv_storage><old type_id="opencv-haar-classifier">
  <size>4 4</size>
  <stages><_>
    <trees><_>
      <_><feature><rects><_>0 0 2 4 1.</_><_>2 0 2 4 -1.</_></rects><tilted>0</tilted></feature>
         <threshold>0.25</threshold><left_val>0</left_val><right_node>1</right_node></_>
      <_><feature><rects><_>2 0 2 2 1.</_></rects><tilted>1</tilted></feature>
         <threshold>0.1</threshold><left_val>0.5</left_val><right_val>1</right_val></_>
    </_></trees>
    <stage_threshold>0.5</stage_threshold><parent>-1</parent><next>-1</next></_></stages>
</old></opencv_storage>"#;

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn write(dir: &str, name: &str, bytes: &[u8]) {
    let dir = root().join("corpus").join(dir);
    std::fs::create_dir_all(&dir).expect("mkdir");
    std::fs::write(dir.join(name), bytes).expect("write seed");
}

fn encode(img: &DynamicImage, format: ImageFormat) -> Vec<u8> {
    let mut out = Vec::new();
    img.write_to(&mut Cursor::new(&mut out), format)
        .expect("encode");
    out
}

fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

fn main() {
    // Cascades: the two tiny layouts, and the start of the real alt2 file (cut mid-stage).
    write("cascade_xml", "tiny_new.xml", TINY_NEW.as_bytes());
    write("cascade_xml", "tiny_old.xml", TINY_OLD.as_bytes());
    let alt2 = std::fs::read_to_string(root().join("../models/haarcascade_frontalface_alt2.xml"))
        .expect("alt2");
    let start = alt2.find("<opencv_storage>").expect("storage");
    let cut = alt2[start..].char_indices().nth(3000).map_or(alt2.len() - start, |(i, _)| i);
    write("cascade_xml", "alt2_head.xml", alt2[start..start + cut].as_bytes());

    // Filter files: the smallest valid file (8x8 filters), without and with its checksum (the
    // target appends a checksum to every input, see filter_file.rs), and a bare header.
    let mut body = b"UNSHEARF".to_vec();
    for v in [1u32, 1, 8, 150, 3] {
        body.extend_from_slice(&v.to_le_bytes());
    }
    let header = body.clone();
    for f in 0..3u32 {
        body.extend_from_slice(&(10 + f).to_le_bytes());
        for i in 0..64 {
            let re = ((i + f as usize) as f32 * 0.37).sin();
            let im = ((i * 3) as f32 * 0.11).cos();
            body.extend_from_slice(&re.to_le_bytes());
            body.extend_from_slice(&im.to_le_bytes());
        }
    }
    write("filter_file", "size8_body.bin", &body);
    let mut sealed = body.clone();
    sealed.extend_from_slice(&fnv1a(&body).to_le_bytes());
    write("filter_file", "size8_sealed.bin", &sealed);
    write("filter_file", "header.bin", &header);

    // Images: a face cut from a fixture and shrunk to 64x48 (small enough to stay a few KB, large
    // enough for the 20x20 detector window), in each readable format; plus tiny odd shapes.
    let face = image::open(root().join("../tests/fixtures/faces/subject01.normal.jpeg"))
        .expect("fixture");
    let face = face
        .crop_imm(80, 20, 160, 120)
        .resize_exact(64, 48, image::imageops::FilterType::Triangle);
    let gray = DynamicImage::ImageLuma8(face.to_luma8());
    let dir = "decode_estimate";
    let mut jpeg = Vec::new();
    image::codecs::jpeg::JpegEncoder::new_with_quality(&mut jpeg, 60)
        .encode_image(&face)
        .expect("jpeg");
    write(dir, "face.jpg", &jpeg);
    write(dir, "face_gray.png", &encode(&gray, ImageFormat::Png));
    write(dir, "face_gray.pgm", &encode(&gray, ImageFormat::Pnm));
    write(dir, "face_gray.bmp", &encode(&gray, ImageFormat::Bmp));
    let small = DynamicImage::ImageRgba8(face.resize_exact(16, 12, image::imageops::FilterType::Triangle).to_rgba8());
    write(dir, "small_rgba.webp", &encode(&small, ImageFormat::WebP));
    write(dir, "small_rgba.tif", &encode(&small, ImageFormat::Tiff));
    write(dir, "one.png", &encode(&DynamicImage::ImageRgb8(image::RgbImage::new(1, 1)), ImageFormat::Png));
    write(dir, "narrow16.png", &encode(&DynamicImage::ImageLuma16(image::ImageBuffer::new(1, 40)), ImageFormat::Png));
    let sizes: Vec<(String, u64)> = ["cascade_xml", "filter_file", dir]
        .iter()
        .flat_map(|d| {
            std::fs::read_dir(root().join("corpus").join(d))
                .expect("list")
                .map(|e| {
                    let e = e.expect("entry");
                    (Path::new(d).join(e.file_name()).display().to_string(), e.metadata().expect("meta").len())
                })
                .collect::<Vec<_>>()
        })
        .collect();
    for (name, len) in sizes {
        println!("{len:>6} {name}");
    }
}
