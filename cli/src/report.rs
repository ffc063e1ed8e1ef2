//! The `--json` line for one input, in the documented shape:
//! `{"file": ..., "k": number|null, "faces": [{"box": [x, y, w, h], "right_eye": [x, y],
//! "left_eye": [x, y], "right_nostril": [x, y], "left_nostril": [x, y], "nose": [x, y]|null,
//! "mouth": [x, y]|null, "k": number|null, "k_measured": number, "roll": number,
//! "confidence": number}]}` plus
//! `"error": "..."` when the input failed, `"faces_disagree"` and `"warnings"`, `"k_source"`
//! (which rulers made `k`) when `k` is set, `"scene_k"` and `"scene_uncertainty"` when the
//! scene's verticals give a shear, `"scene_disagrees": true` when they disagree with the faces, `"k_rows"` when the shear
//! changes down the rows (faces at different heights disagreeing), and
//! `"readout": "columns"` for a picture read out column by column; each face also
//! has `"refused"` (why its `k` is null) and `"outvoted"`. A face's `k` is null when its
//! estimate was refused; `k_measured` is what was measured all the same; `roll` is in degrees.

use serde::Serialize;
use unshear::{FaceReport, ImageReport, Point, Readout};

/// One face, as printed.
#[derive(Debug, Serialize)]
pub struct JsonFace {
    #[serde(rename = "box")]
    face_box: [f64; 4],
    right_eye: [f64; 2],
    left_eye: [f64; 2],
    right_nostril: [f64; 2],
    left_nostril: [f64; 2],
    nose: Option<[f64; 2]>,
    mouth: Option<[f64; 2]>,
    k: Option<f64>,
    k_measured: f64,
    roll: f64,
    confidence: f64,
    refused: Option<&'static str>,
    outvoted: bool,
}

/// One input, as printed.
#[derive(Debug, Serialize)]
pub struct JsonLine {
    file: String,
    k: Option<f64>,
    /// Which rulers made `k`: `"faces"`, `"faces+scene"` or `"scene"`; left out when `k` is
    /// null.
    #[serde(skip_serializing_if = "Option::is_none")]
    k_source: Option<&'static str>,
    /// The shear the scene's verticals give, and its uncertainty (one standard deviation);
    /// left out when the scene gives none.
    #[serde(skip_serializing_if = "Option::is_none")]
    scene_k: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    scene_uncertainty: Option<f64>,
    /// Whether the faces and the scene disagree (the faces made `k`); left out when false.
    #[serde(skip_serializing_if = "std::ops::Not::not")]
    scene_disagrees: bool,
    /// `[[row, k], [row, k]]`: the shear at the highest and the lowest face's row when faces at
    /// different heights disagree beyond their uncertainty (linear between, held beyond; `k`
    /// is then its value at the middle row); left out otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    k_rows: Option<[[f64; 2]; 2]>,
    faces: Vec<JsonFace>,
    faces_disagree: bool,
    warnings: Vec<String>,
    /// `"columns"` for a picture read out column by column (its `k` shears it vertically);
    /// left out for the usual rows.
    #[serde(skip_serializing_if = "Option::is_none")]
    readout: Option<&'static str>,
    /// `correct --deblur`: the motion blur removed, pixels; left out otherwise.
    #[serde(skip_serializing_if = "Option::is_none")]
    blur: Option<f64>,
    #[serde(skip_serializing_if = "Option::is_none")]
    error: Option<String>,
}

/// Rounds to 4 decimals: sub-pixel positions and k to 1e-4 are more than the method resolves,
/// and short lines are easier to read. Values too large to scale are kept as they are (rounding
/// through infinity would turn them into `null`); NaN and infinities print as `null`.
pub fn r4(v: f64) -> f64 {
    let scaled = v * 1e4;
    if scaled.is_finite() {
        scaled.round() / 1e4
    } else {
        v
    }
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
            k_source: report.k_source.map(|s| s.name()),
            scene_k: report.scene.as_ref().map(|s| r4(s.k)),
            scene_uncertainty: report.scene.as_ref().map(|s| r4(s.uncertainty)),
            scene_disagrees: report.scene_disagrees,
            k_rows: report
                .row_shear
                .map(|r| [[r4(r.top.0), r4(r.top.1)], [r4(r.bottom.0), r4(r.bottom.1)]]),
            faces: report.faces.iter().map(face).collect(),
            faces_disagree: report.faces_disagree,
            warnings: report.warnings.clone(),
            readout: (report.readout == Readout::Columns).then_some("columns"),
            blur: None,
            error: None,
        }
    }

    /// With the motion blur removed (`correct --deblur`).
    pub fn with_blur(self, blur: Option<f64>) -> Self {
        Self {
            blur: blur.map(r4),
            ..self
        }
    }

    /// The line for a failed input.
    pub fn error(file: &str, message: String) -> Self {
        Self {
            file: file.to_string(),
            k: None,
            k_source: None,
            scene_k: None,
            scene_uncertainty: None,
            scene_disagrees: false,
            k_rows: None,
            faces: Vec::new(),
            faces_disagree: false,
            warnings: Vec::new(),
            readout: None,
            blur: None,
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
        nose: f.nose_tip.map(pt),
        mouth: f.mouth.map(pt),
        k: f.k.map(r4),
        k_measured: r4(f.k_measured),
        roll: r4(f.roll_degrees),
        confidence: r4(f.confidence),
        refused: f.refused.map(|r| r.name()),
        outvoted: f.outvoted,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;
    use unshear::Rect;

    fn number() -> impl Strategy<Value = f64> {
        prop_oneof![
            any::<f64>(),
            Just(f64::NAN),
            Just(f64::INFINITY),
            Just(f64::NEG_INFINITY),
            Just(f64::MAX),
            Just(-0.0),
            -1e4f64..1e4,
        ]
    }

    fn face() -> impl Strategy<Value = FaceReport> {
        (
            prop::array::uniform16(number()),
            prop::array::uniform8(number()),
            any::<bool>(),
        )
            .prop_map(|(v, w, refused)| {
                let mut f = FaceReport::default();
                f.face_box = Rect::new(v[0], v[1], v[2], v[3]);
                f.right_eye = Point { x: v[4], y: v[5] };
                f.left_eye = Point { x: v[6], y: v[7] };
                f.right_nostril = Point { x: v[8], y: v[9] };
                f.left_nostril = Point { x: v[10], y: v[11] };
                f.mouth = (!refused).then_some(Point { x: w[3], y: w[4] });
                f.k = (!refused).then_some(v[12]);
                f.k_measured = v[12];
                f.refused = refused.then_some(unshear::pipeline::Refusal::LowConfidence);
                f.outvoted = !refused;
                f.k_nose = Some(w[5]);
                f.nose_tip_psr = w[7];
                f.roll_degrees = w[6];
                f.confidence = v[13];
                f.psr = [v[14], v[15], w[0], w[1], w[2]];
                f.locator = unshear::pipeline::Locator::Filters;
                f
            })
    }

    /// The value printed for `v`: `null` for NaN and infinities, otherwise `v` to 1e-4.
    fn check_number(printed: &serde_json::Value, v: f64) -> Result<(), TestCaseError> {
        if v.is_finite() {
            let p = printed
                .as_f64()
                .ok_or_else(|| TestCaseError::fail(format!("{v} -> {printed}")))?;
            prop_assert!((p - v).abs() <= 0.5e-4 + v.abs() * 1e-15, "{} -> {}", v, p);
        } else {
            prop_assert!(printed.is_null(), "{} -> {}", v, printed);
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 256, failure_persistence: None, ..ProptestConfig::default() })]

        /// Any report, any file name (control characters, quotes, any Unicode) and any error
        /// message give one line of valid JSON with the documented fields.
        #[test]
        fn json_line_always_parses(
            file in any::<String>(),
            k in prop::option::of(number()),
            faces in prop::collection::vec(face(), 0..3),
            error in prop::option::of(any::<String>()),
        ) {
            let mut report = ImageReport::empty(10, 10);
            (report.k, report.faces, report.warnings) = (k, faces.clone(), vec![file.clone()]);
            let line = match &error {
                None => JsonLine::ok(&file, &report),
                Some(e) => JsonLine::error(&file, e.clone()),
            }
            .to_line();
            prop_assert!(!line.contains('\n'), "one line");
            let v: serde_json::Value = serde_json::from_str(&line)
                .map_err(|e| TestCaseError::fail(format!("{e}: {line}")))?;
            prop_assert_eq!(v["file"].as_str(), Some(file.as_str()));
            match &error {
                Some(e) => {
                    prop_assert_eq!(v["error"].as_str(), Some(e.as_str()));
                    prop_assert!(v["k"].is_null());
                }
                None => {
                    prop_assert!(v.get("error").is_none());
                    prop_assert_eq!(v["warnings"][0].as_str(), Some(file.as_str()));
                    match k {
                        Some(k) => check_number(&v["k"], k)?,
                        None => prop_assert!(v["k"].is_null()),
                    }
                    let printed = v["faces"].as_array().ok_or_else(|| TestCaseError::fail("faces"))?;
                    prop_assert_eq!(printed.len(), faces.len());
                    for (p, f) in printed.iter().zip(&faces) {
                        match f.k {
                            Some(k) => check_number(&p["k"], k)?,
                            None => prop_assert!(p["k"].is_null()),
                        }
                        check_number(&p["k_measured"], f.k_measured)?;
                        prop_assert_eq!(p["refused"].as_str(), f.refused.map(|r| r.name()));
                        prop_assert_eq!(p["outvoted"].as_bool(), Some(f.outvoted));
                        check_number(&p["roll"], f.roll_degrees)?;
                        check_number(&p["confidence"], f.confidence)?;
                        check_number(&p["box"][2], f.face_box.width)?;
                        check_number(&p["left_nostril"][1], f.left_nostril.y)?;
                    }
                }
            }
        }
    }
}
