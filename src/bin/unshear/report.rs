//! The `--json` line for one input, in the documented shape:
//! `{"file": ..., "k": number|null, "faces": [{"box": [x, y, w, h], "right_eye": [x, y],
//! "left_eye": [x, y], "right_nostril": [x, y], "left_nostril": [x, y], "mouth": [x, y]|null,
//! "k": number|null, "k_measured": number, "roll": number, "confidence": number}]}` plus
//! `"error": "..."` when the input failed. A face's `k` is null when its estimate was refused for
//! low confidence; `k_measured` is what was measured all the same; `roll` is in degrees.

use serde::Serialize;
use unshear::{FaceReport, ImageReport, Point};

/// One face, as printed.
#[derive(Debug, Serialize)]
pub struct JsonFace {
    #[serde(rename = "box")]
    face_box: [f64; 4],
    right_eye: [f64; 2],
    left_eye: [f64; 2],
    right_nostril: [f64; 2],
    left_nostril: [f64; 2],
    mouth: Option<[f64; 2]>,
    k: Option<f64>,
    k_measured: f64,
    roll: f64,
    confidence: f64,
}

/// One input, as printed.
#[derive(Debug, Serialize)]
pub struct JsonLine {
    file: String,
    k: Option<f64>,
    faces: Vec<JsonFace>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

/// Rounds to 4 decimals: sub-pixel positions and k to 1e-4 are more than the method resolves,
/// and short lines are easier to read.
pub fn r4(v: f64) -> f64 {
    (v * 1e4).round() / 1e4
}

fn pt(p: Point) -> [f64; 2] {
    [r4(p.x), r4(p.y)]
}

impl JsonLine {
    /// The line for a processed input.
    pub fn ok(file: &str, report: &ImageReport) -> Self {
        Self {
            file: file.to_string(),
            k: report.k.map(r4),
            faces: report.faces.iter().map(face).collect(),
            error: None,
        }
    }

    /// The line for a failed input.
    pub fn error(file: &str, message: String) -> Self {
        Self {
            file: file.to_string(),
            k: None,
            faces: Vec::new(),
            error: Some(message),
        }
    }

    /// As one line of JSON.
    pub fn to_line(&self) -> String {
        // Serialising these plain structs cannot fail (no maps with non-string keys, and
        // non-finite floats become null); fall back to a valid line all the same.
        serde_json::to_string(self).unwrap_or_else(|e| {
            format!(
                "{{\"file\":{},\"k\":null,\"faces\":[],\"error\":{}}}",
                serde_json::Value::String(self.file.clone()),
                serde_json::Value::String(e.to_string())
            )
        })
    }
}

/// One face as printed (shared by `estimate --json` and `video --json`).
pub fn face(f: &FaceReport) -> JsonFace {
    let b = f.face_box;
    JsonFace {
        face_box: [r4(b.x), r4(b.y), r4(b.width), r4(b.height)],
        right_eye: pt(f.right_eye),
        left_eye: pt(f.left_eye),
        right_nostril: pt(f.right_nostril),
        left_nostril: pt(f.left_nostril),
        mouth: f.mouth.map(pt),
        k: f.k.map(r4),
        k_measured: r4(f.k_measured),
        roll: (f.roll_degrees * 100.0).round() / 100.0,
        confidence: r4(f.confidence),
    }
}
