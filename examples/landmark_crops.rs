//! Cuts the landmark network's training crops from the Caltech development faces
//! (`unshear::dev::landmark_crops`), for `scripts/train_landmarks.py`, and shear-only crops of
//! extra faces.
//!
//! ```sh
//! cargo run --release --example landmark_crops -- ../shared/data/caltech-webfaces target/landmark-crops
//! ```
//!
//! Optional flags: `--size N` (crop side), `--per-face N`, `--min-eye PX`, `--max-eye PX`,
//! `--negatives N` (non-face crops per photo and kind). By default only faces with eyes 15-40 px
//! apart are used, from photos without a face 40 px or more apart, so that no photo the
//! accuracy tables measure (eyes at least 40 px apart) is trained on.
//!
//! `--extra GROUND_TRUTH IMAGES` (repeatable) adds the faces of the file `GROUND_TRUTH` (the
//! Caltech format, names relative to the folder `IMAGES`: pseudo-labels from
//! `scripts/pseudo_annotations.py`, such as `assets/train/`'s; with an `identity.txt` beside
//! `IMAGES`, as the LFW subset has, only the identities trained on) as shear-only crops,
//! `--extra-per-face N` each (default 8), after the Caltech crops, which stay as they are
//! without them (`landmark_crops::extra_faces`). The extra faces tried for issue 64 (the
//! committed network is trained without them; see models/README.md):
//!
//! ```sh
//! cargo run --release --example landmark_crops -- ../shared/data/caltech-webfaces target/landmark-crops \
//!     --extra assets/train/orl-pseudo.txt ../shared/data/att-orl-faces/att_faces \
//!     --extra assets/train/lfw-pseudo.txt ../shared/data/lfw-subset/images --extra-per-face 8
//! ```

use std::path::PathBuf;

use unshear::dev::dataset::{CaltechWebFaces, FaceDataset};
use unshear::dev::landmark_crops::{export_crops_with_extra, extra_faces, ExportOptions};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let mut args = std::env::args().skip(1);
    let mut positional = Vec::new();
    let mut extra_sources = Vec::new();
    let mut options = ExportOptions::default();
    while let Some(a) = args.next() {
        let mut value = || args.next().ok_or_else(|| format!("{a} needs a value"));
        match a.as_str() {
            "--size" => options.size = value()?.parse()?,
            "--per-face" => options.per_face = value()?.parse()?,
            "--min-eye" => options.min_eye_distance = value()?.parse()?,
            "--max-eye" => options.max_eye_distance = value()?.parse()?,
            "--negatives" => options.negatives_per_image = value()?.parse()?,
            "--extra" => {
                let truth = PathBuf::from(value()?);
                extra_sources.push((truth, PathBuf::from(value()?)));
            }
            "--extra-per-face" => options.extra_per_face = value()?.parse()?,
            _ => positional.push(PathBuf::from(a)),
        }
    }
    let [data, out] = positional.as_slice() else {
        return Err("usage: landmark_crops CALTECH_DIR OUT_DIR [--size N] [--per-face N] [--min-eye PX] [--max-eye PX] [--negatives N] [--extra GROUND_TRUTH IMAGES]... [--extra-per-face N]".into());
    };
    let faces = CaltechWebFaces::new(data).faces()?;
    let mut extra = Vec::new();
    for (truth, images) in &extra_sources {
        let found = extra_faces(truth, images)?;
        println!("{}: {} extra faces", truth.display(), found.len());
        extra.extend(found);
    }
    let summary = export_crops_with_extra(faces, extra, &options, out)?;
    println!(
        "{} crops of {} faces ({} shear-only crops of {} extra faces) and {} non-face crops written to {} ({} unreadable images)",
        summary.crops,
        summary.faces,
        summary.extra_crops,
        summary.extra_faces,
        summary.negatives,
        out.display(),
        summary.unreadable.len()
    );
    for u in &summary.unreadable {
        eprintln!("unreadable: {u}");
    }
    Ok(())
}
