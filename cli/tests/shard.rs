//! `--shard I/N`: N processes, each given the same inputs and its own index, handle every input
//! exactly once with no coordinator (a Kubernetes Indexed Job, a Slurm array, ...).

mod common;

use std::collections::BTreeMap;
use std::path::Path;

use assert_cmd::Command;
use common::json_lines;

fn unshear() -> Command {
    Command::cargo_bin("unshear").expect("binary built")
}

/// A folder of small blank images (no face: quick to search) in two sub-folders, with one
/// corrupt file whose error line must be reported by exactly one shard too.
fn batch(dir: &Path) -> usize {
    let mut n = 0;
    for (sub, count) in [("a", 5), ("b", 6)] {
        std::fs::create_dir_all(dir.join(sub)).expect("mkdir");
        for i in 0..count {
            let img = image::GrayImage::from_pixel(24 + i, 20, image::Luma([(i * 20) as u8]));
            img.save(dir.join(sub).join(format!("img{i:02}.png")))
                .expect("write png");
            n += 1;
        }
    }
    std::fs::write(dir.join("b/broken.jpg"), b"\xFF\xD8 not really a JPEG").expect("write");
    n + 1
}

/// The `file` of every JSON line of `estimate --json` with `args`, counted.
fn files(dir: &Path, args: &[&str], env: &[(&str, &str)]) -> (Vec<String>, i32) {
    let mut cmd = unshear();
    cmd.args(["estimate", "--json", "-j", "1"])
        .args(args)
        .arg(dir)
        .env_remove("JOB_COMPLETION_INDEX")
        .env_remove("JOB_COMPLETIONS");
    for (k, v) in env {
        cmd.env(k, v);
    }
    let out = cmd.output().expect("runs");
    let names = json_lines(&out.stdout)
        .iter()
        .map(|v| v["file"].as_str().expect("file").to_string())
        .collect();
    (names, out.status.code().unwrap_or(-1))
}

#[test]
fn n_shards_cover_every_input_exactly_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let total = batch(dir.path());
    let (all, _) = files(dir.path(), &[], &[]);
    assert_eq!(all.len(), total);
    for count in [1usize, 2, 3, 5, 13] {
        let mut seen: BTreeMap<String, usize> = BTreeMap::new();
        let mut sizes = Vec::new();
        for index in 0..count {
            let (part, code) = files(dir.path(), &["--shard", &format!("{index}/{count}")], &[]);
            // Exit code 1 only for the shard holding the corrupt file.
            assert!(code == 0 || code == 1, "shard {index}/{count}: exit {code}");
            assert_eq!(code == 1, part.iter().any(|f| f.ends_with("broken.jpg")));
            sizes.push(part.len());
            for f in part {
                *seen.entry(f).or_default() += 1;
            }
        }
        assert_eq!(seen.len(), total, "{count} shards: every input");
        assert!(
            seen.values().all(|&c| c == 1),
            "{count} shards: each input once: {seen:?}"
        );
        let (lo, hi) = (sizes.iter().min(), sizes.iter().max());
        assert!(hi.zip(lo).is_some_and(|(h, l)| h - l <= 1), "{sizes:?}");
    }
}

#[test]
fn shard_auto_reads_the_indexed_job_variables() {
    let dir = tempfile::tempdir().expect("temp dir");
    batch(dir.path());
    let (fixed, _) = files(dir.path(), &["--shard", "1/3"], &[]);
    let env = [("JOB_COMPLETION_INDEX", "1"), ("JOB_COMPLETIONS", "3")];
    assert_eq!(files(dir.path(), &["--shard", "auto"], &env).0, fixed);
    let index_only = [("JOB_COMPLETION_INDEX", "1")];
    assert_eq!(
        files(dir.path(), &["--shard", "auto/3"], &index_only).0,
        fixed
    );
    // Missing or out-of-range variables are usage errors (exit 2), not an empty shard.
    assert_eq!(files(dir.path(), &["--shard", "auto"], &index_only).1, 2);
    assert_eq!(files(dir.path(), &["--shard", "auto/3"], &[]).1, 2);
    let beyond = [("JOB_COMPLETION_INDEX", "3"), ("JOB_COMPLETIONS", "3")];
    assert_eq!(files(dir.path(), &["--shard", "auto"], &beyond).1, 2);
    assert_eq!(files(dir.path(), &["--shard", "3/3"], &[]).1, 2);
}

#[test]
fn correct_shards_write_each_output_once() {
    let dir = tempfile::tempdir().expect("temp dir");
    let face = dir.path().join("in");
    std::fs::create_dir(&face).expect("mkdir");
    // Three faces sheared by `distort`, which `correct` writes; one shard each of two.
    let src = common::fixture("subject01.normal.jpeg");
    for (i, k) in ["0.1", "0.2", "-0.2"].iter().enumerate() {
        unshear()
            .args(["distort", "--k", k, "-o"])
            .arg(face.join(format!("f{i}.png")))
            .arg(&src)
            .assert()
            .success();
    }
    let out = dir.path().join("out");
    for index in 0..2 {
        unshear()
            .args([
                "correct",
                "--quick",
                "--shard",
                &format!("{index}/2"),
                "--out-dir",
            ])
            .arg(&out)
            .arg(&face)
            .assert()
            .success();
    }
    let mut written: Vec<String> = std::fs::read_dir(&out)
        .expect("outputs")
        .map(|e| e.expect("entry").file_name().to_string_lossy().into_owned())
        .collect();
    written.sort();
    assert_eq!(written, ["f0.png", "f1.png", "f2.png"]);
    // -o names one output, which N processes would all write: refused with --shard.
    unshear()
        .args(["correct", "--shard", "0/2", "-o"])
        .arg(dir.path().join("x.png"))
        .arg(&face)
        .assert()
        .code(2);
}
