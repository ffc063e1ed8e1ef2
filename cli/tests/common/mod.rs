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

/// A PNG chunk: length, type, data and CRC-32 (for the corrupt and hostile PNGs of the
/// bad-input tests).
#[allow(dead_code)]
pub fn png_chunk(kind: &[u8; 4], data: &[u8]) -> Vec<u8> {
    let mut crc = !0u32;
    for &b in kind.iter().chain(data) {
        crc ^= u32::from(b);
        for _ in 0..8 {
            crc = if crc & 1 != 0 {
                (crc >> 1) ^ 0xEDB8_8320
            } else {
                crc >> 1
            };
        }
    }
    let mut c = (data.len() as u32).to_be_bytes().to_vec();
    c.extend_from_slice(kind);
    c.extend_from_slice(data);
    c.extend_from_slice(&(!crc).to_be_bytes());
    c
}

/// A PNG that declares 100000 x 100000 RGB pixels (30 GB decoded) in 57 bytes: a
/// decompression bomb, refused from its header alone.
#[allow(dead_code)]
pub fn png_bomb() -> Vec<u8> {
    let mut ihdr = 100_000u32.to_be_bytes().to_vec();
    ihdr.extend_from_slice(&100_000u32.to_be_bytes());
    ihdr.extend_from_slice(&[8, 2, 0, 0, 0]);
    let mut bomb = b"\x89PNG\r\n\x1a\n".to_vec();
    bomb.extend(png_chunk(b"IHDR", &ihdr));
    bomb.extend(png_chunk(b"IDAT", &[]));
    bomb.extend(png_chunk(b"IEND", &[]));
    bomb
}
