//! Cuts the landmark network's training crops from the Caltech development faces
//! (`unshear::dev::landmark_crops`), for `scripts/train_landmarks.py`.
//!
//! ```sh
//! cargo run --release --example landmark_crops -- ../shared/data/caltech-webfaces target/landmark-crops
//! ```
//!
//! Optional flags: `--size N` (crop side), `--per-face N`, `--min-eye PX`, `--max-eye PX`,
//! `--negatives N` (non-face crops per photo and kind). By default only faces with eyes 15-40 px
//! apart are used, from photos without a face 40 px or more apart, so that no photo the
//! accuracy tables measure (eyes at least 40 px apart) is trained on.

use std::path::PathBuf;

use unshear::dev::dataset::{CaltechWebFaces, FaceDataset};
use unshear::dev::landmark_crops::{export_crops, ExportOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut positional = Vec::new();
    let mut options = ExportOptions::default();
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or_else(|| format!("{a} needs a value"));
        match a.as_str() {
            "--size" => options.size = value()?.parse()?,
            "--per-face" => options.per_face = value()?.parse()?,
            "--min-eye" => options.min_eye_distance = value()?.parse()?,
            "--max-eye" => options.max_eye_distance = value()?.parse()?,
            "--negatives" => options.negatives_per_image = value()?.parse()?,
            _ => positional.push(PathBuf::from(a)),
        }
    }
    let [data, out] = positional.as_slice() else {
        return Err("usage: landmark_crops CALTECH_DIR OUT_DIR [--size N] [--per-face N] [--min-eye PX] [--max-eye PX]".into());
    };
    let faces = CaltechWebFaces::new(data).faces()?;
    let summary = export_crops(faces, &options, out)?;
    println!(
        "{} crops of {} faces and {} non-face crops written to {} ({} unreadable images)",
        summary.crops,
        summary.faces,
        summary.negatives,
        out.display(),
        summary.unreadable.len()
    );
    Ok(())
}
