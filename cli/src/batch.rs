//! Many inputs: collecting files from the paths given, running them in parallel, and handing
//! the results back in input order (so output is reproducible), with a progress bar on stderr
//! when stderr is a terminal.

use std::collections::{BTreeMap, HashSet};
use std::io::IsTerminal;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use rayon::prelude::*;

/// File extensions picked up when walking a folder (files named directly are always tried).
pub const IMAGE_EXTENSIONS: &[&str] = &[
    "jpg", "jpeg", "png", "pgm", "ppm", "pnm", "pbm", "bmp", "tif", "tiff", "webp",
];

/// One input: the path as the user should see it, and the folder it was found under (for
/// `--out-dir`, which keeps the sub-folder structure below that root).
#[derive(Debug, Clone)]
pub struct Input {
    /// The file.
    pub path: PathBuf,
    /// The folder given on the command line that contains it, if it came from a folder walk.
    pub root: Option<PathBuf>,
}

/// Expands folders (recursively, in name order) into image files; a path that cannot be walked,
/// and a folder that holds no image, become inputs that fail with their own error, so the rest
/// of the batch goes on.
///
/// Links to files inside folders are followed; links to folders only with `follow_links`
/// (`-L`), where a link loop is reported as the error of the link that closes it. Files whose
/// stem ends in `.unshear` (this tool's own outputs) are skipped in folders, so running twice
/// over a folder does not correct the corrections; so is the folder `exclude` (the output
/// folder, compared by canonical path) wherever it lies below a folder walked.
///
/// A file reached twice (named twice, or named and also found in a folder given), compared by
/// canonical path, is an input only the first time.
pub fn collect_inputs(
    paths: &[PathBuf],
    follow_links: bool,
    exclude: Option<&Path>,
) -> Vec<Result<Input, (PathBuf, String)>> {
    let exclude = exclude.and_then(|d| d.canonicalize().ok());
    let mut seen = HashSet::new();
    // True the first time a file is met (files that cannot be resolved are always new: they
    // fail on their own when read).
    let mut first_time = |path: &Path| match path.canonicalize() {
        Ok(c) => seen.insert(c),
        Err(_) => true,
    };
    let mut out = Vec::new();
    for p in paths {
        if !p.is_dir() {
            if first_time(p) {
                out.push(Ok(Input {
                    path: p.clone(),
                    root: None,
                }));
            }
            continue;
        }
        let before = out.len();
        let mut found_image = false;
        let walk = walkdir::WalkDir::new(p)
            .follow_links(follow_links)
            .sort_by_file_name()
            .into_iter()
            .filter_entry(|e| {
                e.depth() == 0
                    || !e.file_type().is_dir()
                    || exclude
                        .as_deref()
                        .is_none_or(|x| e.path().canonicalize().ok().as_deref() != Some(x))
            });
        for entry in walk {
            match entry {
                Ok(e) => {
                    // Without `follow_links` a link is reported as a link: take it when it
                    // leads to a file (`metadata` follows it).
                    let is_file = e.file_type().is_file()
                        || (e.path_is_symlink()
                            && std::fs::metadata(e.path()).is_ok_and(|m| m.is_file()));
                    if is_file && is_image_name(e.path()) {
                        found_image = true;
                        if first_time(e.path()) {
                            out.push(Ok(Input {
                                path: e.path().to_path_buf(),
                                root: Some(p.clone()),
                            }));
                        }
                    }
                }
                Err(err) => {
                    let at = err.path().unwrap_or(p).to_path_buf();
                    out.push(Err((at, err.to_string())));
                }
            }
        }
        if out.len() == before && !found_image {
            let hint = if follow_links {
                ""
            } else {
                " (links to folders are followed with -L/--follow)"
            };
            out.push(Err((
                p.clone(),
                format!("no image files in this folder{hint}"),
            )));
        }
    }
    out
}

/// What [`collect_inputs`] gives for one input.
pub type Collected = Result<Input, (PathBuf, String)>;

/// The `index`-th of `count` slices of `inputs` (`--shard`): every input, failed ones too,
/// sorted by path, cut into `count` contiguous slices whose sizes differ by at most one. The
/// same inputs give every process the same order, so `count` processes with the indices
/// `0..count` take every input exactly once.
pub fn shard(mut inputs: Vec<Collected>, index: usize, count: usize) -> Vec<Collected> {
    let path = |c: &Collected| match c {
        Ok(input) => input.path.clone(),
        Err((p, _)) => p.clone(),
    };
    inputs.sort_by_key(path);
    let bound = |i: usize| (inputs.len() as u128 * i as u128 / count.max(1) as u128) as usize;
    let (start, end) = (bound(index), bound(index + 1));
    inputs
        .into_iter()
        .skip(start)
        .take(end.saturating_sub(start))
        .collect()
}

fn is_image_name(p: &Path) -> bool {
    let ext_ok = p
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
    // Compared as bytes: a stem that is not UTF-8 (an old Latin-1 archive) is still ours.
    let own_output = p
        .file_stem()
        .is_some_and(|s| s.as_encoded_bytes().ends_with(b".unshear"));
    ext_ok && !own_output
}

/// Runs `work` on every item in parallel and calls `emit` with each result in item order, as
/// soon as all earlier items are done. `emit` runs on the calling thread.
///
/// Once `stop` is set no further item is started; the items already started are finished and
/// emitted (in order, skipping those never started). Returns how many items were emitted.
pub fn run_ordered<T, R, W, E>(items: &[T], stop: &AtomicBool, work: W, mut emit: E) -> usize
where
    T: Sync,
    R: Send,
    W: Fn(&T) -> R + Sync,
    E: FnMut(&T, R, &ProgressBar),
{
    let progress = progress_bar(items.len() as u64);
    let mut emitted = 0;
    let (tx, rx) = mpsc::channel();
    std::thread::scope(|scope| {
        let work = &work;
        scope.spawn(move || {
            items
                .par_iter()
                .enumerate()
                .for_each_with(tx, |tx, (i, item)| {
                    if stop.load(Ordering::SeqCst) {
                        return;
                    }
                    // The receiver only goes away if the caller panicked; nothing to report then.
                    let _ = tx.send((i, work(item)));
                });
        });
        let mut pending = BTreeMap::new();
        let mut next = 0;
        for (i, r) in rx {
            pending.insert(i, r);
            while let Some(r) = pending.remove(&next) {
                emit(&items[next], r, &progress);
                progress.inc(1);
                emitted += 1;
                next += 1;
            }
        }
        // Stopped early: what finished after a skipped item, still in order.
        for (i, r) in pending {
            emit(&items[i], r, &progress);
            emitted += 1;
        }
    });
    progress.finish_and_clear();
    emitted
}

fn progress_bar(len: u64) -> ProgressBar {
    if len < 2 || !std::io::stderr().is_terminal() {
        return ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
    }
    let bar = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::stderr());
    if let Ok(style) =
        ProgressStyle::with_template("{bar:40} {pos}/{len} {per_sec} eta {eta} {wide_msg}")
    {
        bar.set_style(style);
    }
    bar
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn folder_walk_picks_images_in_order_and_skips_own_outputs() {
        let dir = tempfile::tempdir().expect("temp dir");
        for name in ["b.jpg", "a.PNG", "notes.txt", "a.unshear.png"] {
            std::fs::write(dir.path().join(name), b"x").expect("write");
        }
        std::fs::create_dir(dir.path().join("sub")).expect("mkdir");
        std::fs::write(dir.path().join("sub/c.webp"), b"x").expect("write");
        let found: Vec<String> = collect_inputs(&[dir.path().to_path_buf()], false, None)
            .into_iter()
            .filter_map(Result::ok)
            .map(|i| {
                i.path
                    .strip_prefix(dir.path())
                    .expect("under root")
                    .display()
                    .to_string()
            })
            .collect();
        assert_eq!(found, ["a.PNG", "b.jpg", "sub/c.webp"]);
    }

    proptest::proptest! {
        /// N shards take every input exactly once, whatever the order the inputs came in.
        #[test]
        fn shards_cover_every_input_once(
            names in proptest::collection::vec("[a-c]{1,3}(/[a-c]{1,2})?", 0..40),
            count in 1usize..9,
        ) {
            let inputs = || -> Vec<Collected> {
                names
                    .iter()
                    .enumerate()
                    .map(|(i, n)| {
                        if i % 7 == 3 {
                            Err((PathBuf::from(n), "unreadable".to_string()))
                        } else {
                            Ok(Input { path: PathBuf::from(n), root: None })
                        }
                    })
                    .collect()
            };
            let key = |c: &Collected| match c {
                Ok(i) => i.path.clone(),
                Err((p, _)) => p.clone(),
            };
            let mut seen: Vec<PathBuf> = Vec::new();
            let mut sizes = Vec::new();
            for index in 0..count {
                let part = shard(inputs(), index, count);
                sizes.push(part.len());
                seen.extend(part.iter().map(key));
            }
            let mut all: Vec<PathBuf> = inputs().iter().map(key).collect();
            all.sort();
            proptest::prop_assert_eq!(seen, all);
            let (lo, hi) = (sizes.iter().min().copied(), sizes.iter().max().copied());
            proptest::prop_assert!(hi.unwrap_or(0) - lo.unwrap_or(0) <= 1);
        }
    }

    /// The names found under `root` (walking it with `follow`), and the errors, as text.
    #[cfg(unix)]
    fn walk(root: &Path, follow: bool) -> (Vec<String>, Vec<String>) {
        let (mut found, mut failed) = (Vec::new(), Vec::new());
        for r in collect_inputs(&[root.to_path_buf()], follow, None) {
            match r {
                Ok(i) => found.push(
                    i.path
                        .strip_prefix(root)
                        .expect("under root")
                        .display()
                        .to_string(),
                ),
                Err((p, e)) => failed.push(format!("{}: {e}", p.display())),
            }
        }
        (found, failed)
    }

    /// A data set kept as a folder of links: links to files are taken, links to folders only
    /// with `-L`, where a loop is an error of its own and the rest is still walked; a folder
    /// with no image is an error naming it, not silence.
    #[cfg(unix)]
    #[test]
    fn links_to_files_are_followed_and_links_to_folders_with_follow() {
        use std::os::unix::fs::symlink;
        let store = tempfile::tempdir().expect("temp dir");
        std::fs::write(store.path().join("one.jpg"), b"x").expect("write");
        std::fs::create_dir(store.path().join("more")).expect("mkdir");
        std::fs::write(store.path().join("more/two.png"), b"x").expect("write");
        let farm = tempfile::tempdir().expect("temp dir");
        symlink(store.path().join("one.jpg"), farm.path().join("link.jpg")).expect("link");
        symlink(store.path().join("more"), farm.path().join("dir")).expect("link");
        symlink(farm.path(), farm.path().join("loop")).expect("link");
        symlink(
            store.path().join("gone.jpg"),
            farm.path().join("dangling.jpg"),
        )
        .expect("link");
        let (found, failed) = walk(farm.path(), false);
        assert_eq!(found, ["link.jpg"]);
        assert!(failed.is_empty(), "{failed:?}");
        let (found, failed) = walk(farm.path(), true);
        assert_eq!(found, ["dir/two.png", "link.jpg"]);
        assert_eq!(
            failed.len(),
            2,
            "the loop and the dangling link: {failed:?}"
        );
        let empty = tempfile::tempdir().expect("temp dir");
        symlink(store.path().join("more"), empty.path().join("dir")).expect("link");
        let (found, failed) = walk(empty.path(), false);
        assert!(found.is_empty());
        assert_eq!(failed.len(), 1);
        assert!(failed[0].contains("no image files") && failed[0].contains("-L"));
    }

    #[test]
    fn results_come_back_in_order() {
        let items: Vec<u64> = (0..50).collect();
        let mut seen = Vec::new();
        let emitted = run_ordered(
            &items,
            &AtomicBool::new(false),
            |&i| {
                std::thread::sleep(std::time::Duration::from_micros((50 - i) * 20));
                i * 2
            },
            |&i, r, _| seen.push((i, r)),
        );
        assert_eq!(seen, items.iter().map(|&i| (i, i * 2)).collect::<Vec<_>>());
        assert_eq!(emitted, 50);
    }

    #[test]
    fn a_stop_request_ends_the_batch_early_but_reports_what_finished() {
        let items: Vec<u64> = (0..200).collect();
        let stop = AtomicBool::new(false);
        let started = std::sync::atomic::AtomicUsize::new(0);
        let mut seen = Vec::new();
        let emitted = run_ordered(
            &items,
            &stop,
            |&i| {
                started.fetch_add(1, Ordering::SeqCst);
                if i == 10 {
                    stop.store(true, Ordering::SeqCst);
                }
                std::thread::sleep(std::time::Duration::from_millis(1));
                i
            },
            |&i, r, _| seen.push((i, r)),
        );
        let started = started.load(Ordering::SeqCst);
        // Item 10 and whatever the other threads had started by then; far from all 200.
        assert!((11..100).contains(&started), "{started} started");
        assert_eq!(emitted, started);
        assert_eq!(seen.len(), started);
        assert!(seen.iter().all(|&(i, r)| i == r));
        assert!(seen.windows(2).all(|w| w[0].0 < w[1].0), "in order");
        assert!(seen.iter().any(|&(i, _)| i == 10));
    }
}
