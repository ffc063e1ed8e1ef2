//! The JSON example in the README and docs/cli.md is what `unshear estimate --json` prints for
//! the bundled example: the documents must follow the models, not lag behind them.

mod common;

use assert_cmd::Command;
use serde_json::Value;
use std::path::Path;

/// The numbers may differ by this much between machines (floating-point order in the networks);
/// the printed values have four decimals, and a change of the models moves them far more.
const TOLERANCE: f64 = 2e-4;

/// The example line (the one JSON object for `face-k0.30.png`) in `doc`.
fn documented(doc: &str) -> Value {
    let path = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/..")).join(doc);
    let text = std::fs::read_to_string(&path).expect("document readable");
    let line = text
        .lines()
        .find(|l| l.starts_with(r#"{"file":"assets/example/face-k0.30.png""#))
        .unwrap_or_else(|| panic!("{doc} shows the example's JSON line"));
    serde_json::from_str(line).expect("the documented line is JSON")
}

/// Whether `a` and `b` are the same JSON value, numbers within [`TOLERANCE`]; the first
/// difference's place otherwise.
fn differ(a: &Value, b: &Value, at: &str) -> Option<String> {
    match (a, b) {
        (Value::Number(x), Value::Number(y)) => {
            let (x, y) = (x.as_f64()?, y.as_f64()?);
            ((x - y).abs() > TOLERANCE).then(|| format!("{at}: {x} vs {y}"))
        }
        (Value::Array(x), Value::Array(y)) if x.len() == y.len() => x
            .iter()
            .zip(y)
            .enumerate()
            .find_map(|(i, (x, y))| differ(x, y, &format!("{at}[{i}]"))),
        (Value::Object(x), Value::Object(y)) if x.len() == y.len() => {
            x.iter().find_map(|(k, v)| {
                y.get(k).map_or_else(
                    || Some(format!("{at}.{k}: missing")),
                    |w| differ(v, w, &format!("{at}.{k}")),
                )
            })
        }
        _ => (a != b).then(|| format!("{at}: {a} vs {b}")),
    }
}

#[test]
fn the_documented_json_is_what_the_example_gives() {
    let out = Command::cargo_bin("unshear")
        .expect("binary built")
        .current_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .args(["estimate", "assets/example/face-k0.30.png", "--json"])
        .output()
        .expect("runs");
    assert!(out.status.success());
    let lines = common::json_lines(&out.stdout);
    assert_eq!(lines.len(), 1);
    for doc in ["README.md", "docs/cli.md"] {
        if let Some(d) = differ(&documented(doc), &lines[0], "") {
            panic!(
                "{doc}'s example JSON is out of date ({d}); it prints\n{}",
                lines[0]
            );
        }
    }
}
