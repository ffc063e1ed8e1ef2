//! Helpers shared by the integration tests.

use std::io::{BufRead, BufReader};
use std::path::PathBuf;
use std::process::{Child, ChildStdout, Command, Stdio};

/// The keys of a face object in the `--json` output of `estimate` and `video`, sorted.
#[allow(dead_code)] // Not every test file uses every helper.
pub const FACE_JSON_KEYS: [&str; 13] = [
    "box",
    "confidence",
    "k",
    "k_measured",
    "left_eye",
    "left_nostril",
    "mouth",
    "nose",
    "outvoted",
    "refused",
    "right_eye",
    "right_nostril",
    "roll",
];

/// Each line of a command's `--json` output, parsed.
#[allow(dead_code)] // Not every test file uses every helper.
pub fn json_lines(stdout: &[u8]) -> Vec<serde_json::Value> {
    String::from_utf8_lossy(stdout)
        .lines()
        .map(|l| serde_json::from_str(l).expect("each line is JSON"))
        .collect()
}

/// A committed fixture face (tests/fixtures/faces, see SOURCE.md there).
#[allow(dead_code)] // Not every test file uses every helper.
pub fn fixture(name: &str) -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .join("tests/fixtures/faces")
        .join(name)
}

/// `../shared/data/<rel>` if it exists; otherwise notes the skip and returns `None`.
#[allow(dead_code)]
pub fn shared_data(rel: &str) -> Option<PathBuf> {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
        .join("../shared/data")
        .join(rel);
    if p.exists() {
        Some(p)
    } else {
        // Written to stderr directly, past the test harness's output capture, so the skip shows.
        let note = format!(
            "skipped: {} not found (../shared is not checked out)\n",
            p.display()
        );
        let _ = std::io::Write::write_all(&mut std::io::stderr(), note.as_bytes());
        None
    }
}

/// Spawns `cmd` with its output piped and reads the first line it prints (for tests that act
/// while it runs), returning the child, the rest of its output and that line.
#[allow(dead_code)] // Not every test file uses every helper.
pub fn spawn_and_read_first_line(cmd: &mut Command) -> (Child, BufReader<ChildStdout>, String) {
    let mut child = cmd
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("spawn");
    let mut stdout = BufReader::new(child.stdout.take().expect("stdout"));
    let mut first = String::new();
    stdout.read_line(&mut first).expect("first line");
    (child, stdout, first)
}
