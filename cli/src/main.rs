//! `unshear`: the command-line tool. Argument parsing lives in [`args`], batch running in
//! [`batch`], the JSON line in [`report`]; this file wires them to the library.
//!
//! Exit codes: 0 every input handled; 1 some input failed (the others were still processed);
//! 2 usage error; 130 interrupted (see [`interrupt`]).

mod args;
mod batch;
mod ffmpeg;
mod interrupt;
mod models;
mod report;
mod serve;
mod simulate;
mod video;

use std::collections::hash_map::{Entry, HashMap};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::process::ExitCode;

use anyhow::{bail, Context, Result};
use clap::Parser;

use args::{
    Cli, Command, CorrectArgs, DistortArgs, EstimateArgs, EvalCanvasArg, EvalCommand, EvalFaces,
    EvalNostrilsArgs, EvalRecognitionArgs, EvalShearArgs, EvalVideoArgs, TrainArgs,
};
use batch::{collect_inputs, run_ordered, shard, Collected, Input, IMAGE_EXTENSIONS};
use models::load_models;
use report::JsonLine;
use unshear::filters::FilterType;
use unshear::imageio::{self, WriteOptions};
use unshear::{Config, CorrectOptions, ImageReport, Readout, Refusal, Shear, ShearSource, Unshear};

fn main() -> ExitCode {
    let cli = Cli::parse();
    // Batches stop cleanly after the images in progress; other commands stop at once.
    interrupt::install(matches!(
        cli.command,
        Command::Estimate(_) | Command::Correct(_)
    ));
    let result = match cli.command {
        Command::Estimate(a) => estimate(a),
        Command::Correct(a) => correct(a),
        Command::Distort(a) => distort(a).map(|()| true),
        Command::Video(a) => video::video(a).map(|()| true),
        Command::Calibrate(a) => video::calibrate(a),
        Command::Simulate(a) => simulate::simulate(a).map(|()| true),
        Command::Serve(a) => serve::serve(a).map(|()| true),
        Command::Train(a) => train(a).map(|()| true),
        Command::Eval(e) => match e.what {
            EvalCommand::Shear(a) => eval_shear(a).map(|()| true),
            EvalCommand::Nostrils(a) => eval_nostrils(a).map(|()| true),
            EvalCommand::Recognition(a) => eval_recognition(a).map(|()| true),
            EvalCommand::Video(a) => eval_video(a).map(|()| true),
        },
    };
    if interrupt::requested() {
        return ExitCode::from(interrupt::EXIT_INTERRUPTED);
    }
    match result {
        Ok(true) => ExitCode::SUCCESS,
        Ok(false) => ExitCode::from(1),
        Err(e) => {
            eprintln!("unshear: {}", error_chain(&e));
            ExitCode::from(1)
        }
    }
}

/// [`imageio::write_image_atomic`], with the flag that allows replacing an existing output named
/// in its refusal.
fn write_atomic(img: &image::DynamicImage, path: &Path, options: WriteOptions) -> Result<()> {
    imageio::write_image_atomic(img, path, options).map_err(|e| match e {
        unshear::Error::Refused {
            ref reason,
            ref path,
        } if reason == imageio::EXISTS => exists_error(path),
        e => e.into(),
    })
}

/// The error for an output that exists, `--force` not given.
fn exists_error(path: &Path) -> anyhow::Error {
    let refused = unshear::Error::Refused {
        path: path.to_path_buf(),
        reason: imageio::EXISTS.to_owned(),
    };
    anyhow::anyhow!("{refused}; use --force to replace it")
}

/// Prints a line to stdout, ignoring a closed pipe (e.g. `| head`) rather than panicking.
fn print_line(line: &str) {
    let mut out = std::io::stdout().lock();
    let _ = writeln!(out, "{line}");
}

fn display(p: &Path) -> String {
    p.display().to_string()
}

fn describe(report: &ImageReport) -> String {
    match report.k {
        Some(k) => {
            let n = report.faces.len();
            let conf = report
                .faces
                .iter()
                .map(|f| f.confidence)
                .fold(f64::NEG_INFINITY, f64::max);
            // A photo turned by its EXIF orientation was read out by columns: its k is vertical.
            let along = match report.readout {
                Readout::Rows => "",
                Readout::Columns => " along the columns (turned by its EXIF orientation)",
            };
            if report.k_source == Some(ShearSource::Scene) {
                return format!("k = {k:+.3} (from the scene's verticals; no face)");
            }
            let scene = match (&report.scene, report.k_source) {
                (Some(_), Some(ShearSource::FacesAndScene)) => ", with the scene's verticals",
                _ => "",
            };
            let disagree = match (&report.scene, report.scene_disagrees) {
                (Some(s), true) => format!(
                    "; the scene's verticals disagree (k = {:+.3}): the subject moved",
                    s.k
                ),
                _ => String::new(),
            };
            format!(
                "k = {k:+.3}{along} ({n} face{}, best confidence {conf:.1}{scene}){disagree}",
                if n == 1 { "" } else { "s" }
            )
        }
        None => no_shear_reason(report),
    }
}

/// Why an image got no shear, in a few words: no face, faces that disagree, or each refused
/// face's reason with what it measured.
fn no_shear_reason(report: &ImageReport) -> String {
    if report.faces.is_empty() {
        return match &report.scene {
            Some(s) => format!(
                "no face found (the scene's verticals give k = {:+.3} +- {:.3}: --ruler scene \
                 corrects by it)",
                s.k, s.uncertainty
            ),
            None => "no face found".to_string(),
        };
    }
    if report.faces_disagree {
        return format!(
            "no trustworthy shear: the {} faces' estimates disagree with no consistent majority",
            report.faces.len()
        );
    }
    let refused: Vec<String> = report
        .faces
        .iter()
        .filter_map(|f| {
            let why = match f.refused? {
                Refusal::LowConfidence => "low confidence",
                Refusal::ImplausibleShear => "implausible shear",
                Refusal::OutsideImage => "outside the image",
                Refusal::NotFaceLike => "not face-like",
                Refusal::UnreliablePose => "tipped and rolled head",
                other => other.name(),
            };
            Some(format!(
                "{why} (k_measured {:+.3}, confidence {:.2})",
                f.k_measured, f.confidence
            ))
        })
        .collect();
    format!(
        "no trustworthy face: {} refused: {}",
        refused.len(),
        refused.join("; ")
    )
}

/// One failed input: its JSON line (with `--json`) and one line on stderr naming the file.
fn report_failure(json: bool, file: &str, error: String, bar: &indicatif::ProgressBar) {
    let error = one_line(file, &error);
    bar.suspend(|| eprintln!("unshear: {file}: {error}"));
    if json {
        print_line(&JsonLine::error(file, error).to_line());
    }
}

/// An error message as one line: line breaks and other control characters (some decoders end
/// their messages with a newline) become spaces, runs of spaces are collapsed, and a leading
/// `file: ` is dropped since the report names the file already.
fn one_line(file: &str, message: &str) -> String {
    let flat = message
        .split(|c: char| c.is_control() || c.is_whitespace())
        .filter(|w| !w.is_empty())
        .collect::<Vec<_>>()
        .join(" ");
    match flat.strip_prefix(file).and_then(|m| m.strip_prefix(": ")) {
        Some(rest) if !rest.is_empty() => rest.to_string(),
        _ => flat,
    }
}

/// An error and its causes as one message, leaving out a cause whose text the message already
/// contains (the library's errors include their source's text, so `{:#}` would repeat it).
fn error_chain(e: &anyhow::Error) -> String {
    let mut message = String::new();
    for cause in e.chain() {
        let text = cause.to_string();
        if !message.contains(text.trim()) {
            if !message.is_empty() {
                message.push_str(": ");
            }
            message.push_str(&text);
        }
    }
    message
}

/// The inputs collected, or with `--shard` this process's slice of them.
fn shard_of(inputs: Vec<Collected>, shard_arg: Option<args::ShardArg>) -> Vec<Collected> {
    let Some(spec) = shard_arg else {
        return inputs;
    };
    match spec.resolve(|name| std::env::var(name).ok()) {
        Ok((index, count)) => shard(inputs, index, count),
        Err(e) => usage_error(&format!("--shard: {e}")),
    }
}

/// Refuses `-` as an input of `estimate` and `correct` (a usage error): standard input is read by
/// `video` only, and a still named `-` would otherwise fail as a missing file.
fn refuse_stdin(inputs: &[PathBuf]) {
    if inputs.iter().any(|p| p.as_os_str() == "-") {
        usage_error(
            "'-' (standard input) is supported for video only: give image files or folders \
             (a file named '-' as ./-)",
        );
    }
}

fn estimate(a: EstimateArgs) -> Result<bool> {
    refuse_stdin(&a.inputs);
    let unshear = load_models(&a.model, Config::default())?;
    let inputs = shard_of(collect_inputs(&a.inputs, a.follow, None), a.shard);
    let mut all_ok = true;
    let done = run_ordered(
        &inputs,
        interrupt::flag(),
        |input| -> Result<ImageReport, String> {
            let input = input.as_ref().map_err(|(_, e)| e.clone())?;
            let (img, metadata) =
                imageio::read_image_with_metadata(&input.path, a.model.max_pixels)
                    .map_err(|e| e.to_string())?;
            Ok(unshear.estimate_photo(&img, &metadata))
        },
        |input, result, bar| {
            let file = match input {
                Ok(i) => display(&i.path),
                Err((p, _)) => display(p),
            };
            match result {
                Ok(report) if a.json => print_line(&JsonLine::ok(&file, &report).to_line()),
                Ok(report) => bar.suspend(|| print_line(&format!("{file}: {}", describe(&report)))),
                Err(e) => {
                    all_ok = false;
                    report_failure(a.json, &file, e, bar);
                }
            }
        },
    );
    report_interruption(done, inputs.len());
    Ok(all_ok)
}

/// After a batch: says how many inputs were left out if it was interrupted.
fn report_interruption(done: usize, total: usize) {
    if interrupt::requested() {
        eprintln!(
            "unshear: interrupted: {done} of {total} inputs processed, {} not started",
            total.saturating_sub(done)
        );
    }
}

/// Where the corrected image of `input` goes. The name is built from the input's name as an
/// `OsStr`, so names that are not UTF-8 keep their bytes. An input that is not a regular file
/// (a device, a pipe, `/dev/stdin`) has no folder to write beside: it needs `-o` or `--out-dir`.
fn output_path(a: &CorrectArgs, input: &Input) -> Result<PathBuf> {
    if let Some(o) = &a.output {
        return Ok(o.clone());
    }
    let name = input.path.file_name().context("input has no file name")?;
    if a.out_dir.is_none() && std::fs::metadata(&input.path).is_ok_and(|m| !m.is_file()) {
        bail!(
            "not a regular file (a device, a pipe or /dev/stdin): give -o OUT (or --out-dir DIR) \
             to say where the corrected image goes"
        );
    }
    if let Some(dir) = &a.out_dir {
        let relative = input
            .root
            .as_ref()
            .and_then(|root| input.path.strip_prefix(root).ok())
            .map(Path::to_path_buf)
            .unwrap_or_else(|| PathBuf::from(name));
        return Ok(written_as(dir.join(relative), None));
    }
    Ok(written_as(input.path.clone(), Some(".unshear")))
}

/// `path` with `tag` (if any) added before its extension, and the extension made one that is
/// written: an input's own when it is, `.png` in place of one that is only read (`.pbm`, 1-bit)
/// and after a name with none or another (a pipe, `photo.2024`). PNG keeps every image's
/// channels and depth.
fn written_as(path: PathBuf, tag: Option<&str>) -> PathBuf {
    let Some(name) = path.file_name() else {
        return path;
    };
    let ext = path.extension().and_then(|e| e.to_str());
    let readable = ext.is_some_and(|e| IMAGE_EXTENSIONS.contains(&e.to_ascii_lowercase().as_str()));
    let (mut file, ext) = match path.file_stem() {
        Some(stem) if imageio::output_format_supported(&path) => (stem.to_os_string(), ext),
        Some(stem) if readable => (stem.to_os_string(), Some("png")),
        _ => (name.to_os_string(), Some("png")),
    };
    if let Some(tag) = tag {
        file.push(tag);
    }
    if let Some(ext) = ext {
        file.push(".");
        file.push(ext);
    }
    path.with_file_name(file)
}

/// `path` made absolute, its longest existing ancestor canonicalised (links and `..` resolved
/// by the file system) and the rest cleaned lexically: two spellings of one output give the
/// same result.
fn normalise(path: &Path) -> PathBuf {
    let absolute = std::env::current_dir()
        .map(|d| d.join(path))
        .unwrap_or_else(|_| path.to_path_buf());
    let mut existing = absolute.as_path();
    let mut rest = Vec::new();
    let mut clean = loop {
        if let Ok(c) = existing.canonicalize() {
            break c;
        }
        match (existing.parent(), existing.components().next_back()) {
            (Some(parent), Some(last)) => {
                rest.push(last);
                existing = parent;
            }
            _ => break PathBuf::new(),
        }
    };
    for c in rest.into_iter().rev() {
        match c {
            std::path::Component::CurDir => {}
            std::path::Component::ParentDir => {
                clean.pop();
            }
            c => clean.push(c),
        }
    }
    clean
}

/// What two outputs collide on: the [`normalise`]d path, in lower case where file systems are
/// case-insensitive by default (macOS, Windows), where `A.jpg` and `a.jpg` are one file.
pub(crate) fn output_key(path: &Path) -> PathBuf {
    fold_case(
        normalise(path),
        cfg!(any(target_os = "macos", target_os = "windows")),
    )
}

/// `path` in lower case when `fold` (a path that is not Unicode is kept as it is).
fn fold_case(path: PathBuf, fold: bool) -> PathBuf {
    match path.to_str() {
        Some(s) if fold => PathBuf::from(s.to_lowercase()),
        _ => path,
    }
}

/// Decides every input's output before any work, in input order (the command line's, then each
/// folder's walk): an input whose output another input earlier in that order already takes
/// fails with an error naming both, and so does an input whose output cannot be decided. An
/// output that is also the `--annotate` picture is a usage error.
fn refuse_colliding_outputs(a: &CorrectArgs, inputs: Vec<Collected>) -> Vec<Collected> {
    let annotate = a.annotate.as_deref().map(output_key);
    let mut taken: HashMap<PathBuf, PathBuf> = HashMap::new();
    inputs
        .into_iter()
        .map(|collected| {
            let input = collected?;
            let out = match output_path(a, &input) {
                Ok(out) => out,
                Err(e) => return Err((input.path, error_chain(&e))),
            };
            let key = output_key(&out);
            if annotate.as_ref() == Some(&key) {
                usage_error(&format!(
                    "--annotate and the corrected image are both {}",
                    out.display()
                ));
            }
            match taken.entry(key) {
                Entry::Occupied(first) => Err((
                    input.path,
                    format!(
                        "its output {} is also the output of {}, given earlier: nothing written \
                         for this input (write it elsewhere with -o or another --out-dir)",
                        out.display(),
                        first.get().display()
                    ),
                )),
                Entry::Vacant(slot) => {
                    slot.insert(input.path.clone());
                    Ok(input)
                }
            }
        })
        .collect()
}

/// The `--annotate` picture of `img`: the faces' boxes, eyes, nostrils, mouths and axes, and
/// the scene's verticals when they were read.
pub(crate) fn annotated(img: &image::DynamicImage, report: &ImageReport) -> image::DynamicImage {
    let mut picture = unshear::annotate::draw_annotations(img, &report.marks());
    if let Some(scene) = &report.scene {
        unshear::annotate::draw_scene_segments(&mut picture, scene);
    }
    image::DynamicImage::ImageRgb8(picture)
}

/// What happened to one input of `correct`.
enum Corrected {
    /// The report, the output, and the motion blur removed (`--deblur`).
    Written(ImageReport, PathBuf, Option<f64>),
    NoFace(ImageReport),
}

fn correct_one(
    a: &CorrectArgs,
    unshear: &Unshear,
    input: &Input,
    protected: &[PathBuf],
) -> Result<Corrected> {
    let out = output_path(a, input)?;
    if !imageio::output_format_supported(&out) {
        bail!(
            "{}: unsupported output format ({OUTPUT_FORMATS})",
            out.display()
        );
    }
    // Both outputs are checked before any work, so a refused one leaves the other unwritten.
    if !a.force {
        if let Some(path) = std::iter::once(&out)
            .chain(&a.annotate)
            .find(|p| p.exists())
        {
            return Err(exists_error(path));
        }
    }
    let (img, metadata) = imageio::read_image_with_metadata(&input.path, a.model.max_pixels)?;
    // A motion blur is removed first, so the faces are found and read in the sharp picture.
    let mut img = img;
    let blur = if a.deblur {
        Unshear::remove_blur(&mut img, a.blur)?
    } else {
        None
    };
    let report = unshear.estimate_photo(&img, &metadata);
    if let Some(annotate) = &a.annotate {
        create_parent(annotate)?;
        write_atomic(
            &annotated(&img, &report),
            annotate,
            WriteOptions {
                overwrite: a.force,
                protected: protected.to_vec(),
                ..Default::default()
            },
        )?;
    }
    let options = CorrectOptions {
        region: a.region.into(),
        canvas: a.canvas.into(),
        interpolation: a.interp.into(),
        k: a.k,
        blur: None,
    };
    if !options.changes(&report) {
        return Ok(Corrected::NoFace(report));
    }
    let fixed = Unshear::correct(&img, &report, &options)?;
    // The input is not needed any more: free it before encoding (peak memory, see README).
    drop(img);
    create_parent(&out)?;
    write_atomic(
        &fixed,
        &out,
        WriteOptions {
            overwrite: a.force,
            protected: protected.to_vec(),
            // The photo's colour profile, camera, date and place stay with it.
            metadata,
            ..Default::default()
        },
    )?;
    Ok(Corrected::Written(report, out, blur))
}

/// Creates the folder an output goes into, if it does not exist; a file in the way is named as
/// not a folder.
pub(crate) fn create_parent(path: &Path) -> Result<()> {
    if let Some(parent) = path.parent().filter(|p| !p.as_os_str().is_empty()) {
        if let Some(file) = parent
            .ancestors()
            .find(|p| !p.as_os_str().is_empty() && p.exists() && !p.is_dir())
        {
            bail!("{} is not a folder", file.display());
        }
        std::fs::create_dir_all(parent)
            .with_context(|| format!("creating {}", parent.display()))?;
    }
    Ok(())
}

fn correct(a: CorrectArgs) -> Result<bool> {
    refuse_stdin(&a.inputs);
    if let Some(dir) = &a.out_dir {
        if dir.exists() && !dir.is_dir() {
            usage_error(&format!(
                "--out-dir {}: not a folder (a file of that name exists)",
                dir.display()
            ));
        }
    }
    // The output folder is left out of the walk: outputs of an earlier run are not inputs.
    let inputs = collect_inputs(&a.inputs, a.follow, a.out_dir.as_deref());
    // Every input is protected from being written over, whatever the output naming does (also
    // those refused below, and those of the other shards).
    let protected: Vec<PathBuf> = inputs
        .iter()
        .filter_map(|i| i.as_ref().ok().map(|i| i.path.clone()))
        .collect();
    // Before sharding, so that every shard decides collisions alike.
    let inputs = shard_of(refuse_colliding_outputs(&a, inputs), a.shard);
    if inputs.len() > 1 && a.output.is_some() {
        usage_error("-o/--output takes one input; use --out-dir for several");
    }
    if inputs.len() > 1 && a.annotate.is_some() {
        usage_error("--annotate takes one input");
    }
    if let Some(k) = a.k {
        if !k.is_finite() {
            usage_error("--k must be a finite number");
        }
    }
    let unshear = load_models(&a.model, Config::default())?;
    let mut all_ok = true;
    let done = run_ordered(
        &inputs,
        interrupt::flag(),
        |input| -> Result<Corrected, String> {
            let input = input.as_ref().map_err(|(_, e)| e.clone())?;
            correct_one(&a, &unshear, input, &protected).map_err(|e| error_chain(&e))
        },
        |input, result, bar| {
            let file = match input {
                Ok(i) => display(&i.path),
                Err((p, _)) => display(p),
            };
            match result {
                Ok(Corrected::Written(report, out, blur)) => {
                    if a.json {
                        print_line(&JsonLine::ok(&file, &report).with_blur(blur).to_line());
                    } else {
                        let how = match a.k {
                            Some(k) => format!("k = {k:+.3} (given)"),
                            None => describe(&report),
                        };
                        let how = match (a.deblur, blur) {
                            (true, Some(b)) => format!("{how}, motion blur of {b:.1} px removed"),
                            (true, None) => format!("{how}, no motion blur found"),
                            _ => how,
                        };
                        bar.suspend(|| print_line(&format!("{file}: {how} -> {}", out.display())));
                    }
                }
                Ok(Corrected::NoFace(report)) => {
                    if a.json {
                        print_line(&JsonLine::ok(&file, &report).to_line());
                    }
                    let why = no_shear_reason(&report);
                    let written = match &a.annotate {
                        Some(p) => format!(
                            "no corrected image written (only the annotation, {})",
                            p.display()
                        ),
                        None => "nothing written".to_string(),
                    };
                    bar.suspend(|| eprintln!("unshear: {file}: {why}; {written}, the input is left as it is (give --k to correct anyway)"));
                }
                Err(e) => {
                    all_ok = false;
                    report_failure(a.json, &file, e, bar);
                }
            }
        },
    );
    report_interruption(done, inputs.len());
    Ok(all_ok)
}

/// The output extensions, for messages.
const OUTPUT_FORMATS: &str = "use .jpg/.jpeg, .png, .pgm, .ppm, .pnm, .bmp, .tif/.tiff or .webp";

/// Reports a usage error the way clap does (exit code 2).
fn usage_error(message: &str) -> ! {
    let mut cmd = <Cli as clap::CommandFactory>::command();
    cmd.error(clap::error::ErrorKind::ArgumentConflict, message)
        .exit()
}

fn distort(a: DistortArgs) -> Result<()> {
    if !a.k.is_finite() || a.pivot.is_some_and(|p| !p.is_finite()) {
        usage_error("--k and --pivot must be finite numbers");
    }
    if !imageio::output_format_supported(&a.output) {
        bail!(
            "{}: unsupported output format ({OUTPUT_FORMATS})",
            a.output.display()
        );
    }
    let img = imageio::read_image(&a.input, a.max_pixels)?;
    let shear = match a.pivot {
        Some(p) => Shear::new(a.k, p),
        None => Shear::about_middle(a.k, img.height()),
    };
    let (out, _) = unshear::warp::try_apply_shear(&img, shear, a.interp.into(), a.canvas.into())
        .with_context(|| format!("shearing {}", a.input.display()))?;
    write_atomic(
        &out,
        &a.output,
        WriteOptions {
            overwrite: a.force,
            protected: vec![a.input.clone()],
            ..Default::default()
        },
    )?;
    Ok(())
}

fn train(a: TrainArgs) -> Result<()> {
    use unshear::dev::dataset::{CaltechWebFaces, FaceDataset};
    let faces = CaltechWebFaces::new(&a.data)
        .faces()
        .with_context(|| format!("reading the data set in {}", a.data.display()))?;
    let options = unshear::dev::train::TrainOptions {
        faces: a.faces.into(),
        min_eye_distance: a.min_eye_distance,
        mirror: !a.no_mirror,
        filter_type: a.filter_type.map_or(FilterType::DEFAULT, FilterType::from),
        ..Default::default()
    };
    let (filters, summary) = unshear::dev::train::train_eye_filters(faces, &options)?;
    for u in &summary.unreadable {
        eprintln!("unshear: skipped {u}");
    }
    let path = &a.output;
    let bytes = filters.to_bytes();
    imageio::write_atomic(
        path,
        &WriteOptions {
            overwrite: a.force,
            ..Default::default()
        },
        |w| {
            w.write_all(&bytes).map_err(|source| unshear::Error::Io {
                path: path.clone(),
                source,
            })
        },
    )?;
    eprintln!(
        "unshear: trained {} filters on {} faces ({} crops per feature{}, {} patches per filter; {} faces not selected, {} below {} px eye distance skipped) -> {}",
        filters.kind,
        summary.faces,
        summary.crops,
        if a.no_mirror { "" } else { ", mirrored copies included" },
        filters.right_eye.training_count,
        summary.not_selected,
        summary.too_small,
        a.min_eye_distance,
        path.display()
    );
    Ok(())
}

fn eval_shear(a: EvalShearArgs) -> Result<()> {
    use unshear::dev::dataset::{CaltechWebFaces, FaceDataset};
    use unshear::dev::eval::{evaluate_shear_in_context, ShearEvalOptions};
    let mut model = a.model.clone();
    // Every evaluated face's box is about 2.6 eye distances wide (the detector's box for a
    // face): skipping boxes under 1.5 eye distances loses none of them and saves most of the
    // detector's time (its smallest scales).
    model.min_face = model
        .min_face
        .or(Some((1.5 * a.min_eye_distance.max(0.0)).floor() as u32));
    let unshear = load_models(&model, Config::default())?;
    let annotated = CaltechWebFaces::new(&a.data)
        .faces()
        .with_context(|| format!("reading the data set in {}", a.data.display()))?;
    let chosen = match a.faces {
        EvalFaces::Measured => vec![true; annotated.len()],
        EvalFaces::Unseen => unshear::dev::landmark_crops::unseen_faces(
            &annotated,
            &unshear::dev::landmark_crops::ExportOptions::default(),
        ),
    };
    let (faces, also_annotated): (Vec<_>, Vec<_>) = annotated
        .into_iter()
        .zip(chosen)
        .partition(|(f, chosen)| *chosen && f.eye_distance() >= a.min_eye_distance);
    let mut faces: Vec<_> = faces.into_iter().map(|(f, _)| f).collect();
    let mut also_annotated: Vec<_> = also_annotated.into_iter().map(|(f, _)| f).collect();
    if let Some(n) = a.limit {
        also_annotated.extend(faces.split_off(n.min(faces.len())));
    }
    if let Some(path) = &a.unannotated {
        let text =
            std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))?;
        also_annotated.extend(
            CaltechWebFaces::parse(&text, &a.data.join("images"))
                .with_context(|| format!("reading {}", path.display()))?,
        );
    }
    // The faces not evaluated still tell which detections are real faces, in the images
    // evaluated.
    let evaluated: std::collections::HashSet<_> = faces.iter().map(|f| f.image.clone()).collect();
    also_annotated.retain(|f| evaluated.contains(&f.image));
    let options = ShearEvalOptions {
        shears: a.k.clone(),
        max_pixels: a.model.max_pixels,
        also_annotated,
        face_free: a.face_free,
        roll_degrees: a.roll,
        canvas: match a.canvas {
            EvalCanvasArg::Crop => unshear::dev::eval::shear::EvalCanvas::Crop,
            EvalCanvasArg::Expand => unshear::dev::eval::shear::EvalCanvas::Expand,
        },
        camera: a
            .camera
            .then(|| {
                let camera = unshear::dev::eval::camera::CameraLike {
                    readout_fraction: a.camera_readout,
                    acceleration: a.camera_acceleration,
                    exposure: a.camera_exposure,
                    noise: a.camera_noise,
                    jpeg_quality: a.camera_jpeg,
                    ..Default::default()
                };
                camera.validate().map(|()| camera)
            })
            .transpose()?,
        deblur: a.deblur,
    };
    let bar = progress_bar((faces.len() * a.k.len()) as u64);
    let result = evaluate_shear_in_context(&unshear, &faces, &options, a.context, || bar.inc(1));
    bar.finish_and_clear();
    for u in &result.unreadable {
        eprintln!("unshear: skipped {u}");
    }
    print!("{}", result.markdown());
    if let Some(csv) = &a.csv {
        std::fs::write(csv, result.csv()).with_context(|| format!("writing {}", csv.display()))?;
    }
    if let Some(dir) = &a.out {
        result
            .write_outputs(dir)
            .with_context(|| format!("writing the report into {}", dir.display()))?;
    }
    Ok(())
}

/// A progress bar on stderr, hidden when stderr is not a terminal.
fn progress_bar(len: u64) -> indicatif::ProgressBar {
    let bar = indicatif::ProgressBar::new(len);
    if !std::io::IsTerminal::is_terminal(&std::io::stderr()) {
        bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    bar
}

fn eval_video(a: EvalVideoArgs) -> Result<()> {
    use unshear::dev::dataset::{CaltechWebFaces, FaceDataset};
    use unshear::dev::eval::video::{evaluate_video, Mode, MotionKind, VideoEvalOptions};
    use unshear::dev::simulate::{development_faces, Scene, ScenePhoto};
    let motions = a
        .motion
        .iter()
        .map(|m| {
            MotionKind::ALL
                .into_iter()
                .find(|k| k.name() == m.trim())
                .unwrap_or_else(|| {
                    usage_error(&format!(
                        "--motion {m}: not one of constant, pause, accelerate, shaky, walk"
                    ))
                })
        })
        .collect();
    let modes = a
        .modes
        .iter()
        .map(|m| {
            Mode::ALL
                .into_iter()
                .find(|k| k.key() == m.trim())
                .unwrap_or_else(|| {
                    usage_error(&format!(
                        "--modes {m}: not one of calibrated, one-pass, given, faces"
                    ))
                })
        })
        .collect();
    if !(a.fps.is_finite() && a.fps > 0.0 && a.exposure_ms.is_finite() && a.exposure_ms >= 0.0) {
        usage_error("--fps must be above 0 and --exposure-ms at least 0");
    }
    let options = VideoEvalOptions {
        width: a.width,
        height: a.height,
        frames: a.frames,
        fps: a.fps,
        readout_fractions: a.rho.clone(),
        motions,
        peak_k: a.peak_k,
        exposure: (a.exposure_ms / 1000.0 * a.fps).min(1.0),
        noise: a.noise,
        clips: a.clips,
        skip: a.skip,
        seed: a.seed,
        modes,
        ..VideoEvalOptions::default()
    };
    let unshear = load_models(&a.model, Config::video())?;
    let annotated = CaltechWebFaces::new(&a.data)
        .faces()
        .with_context(|| format!("reading the data set in {}", a.data.display()))?;
    let max_pixels = a.model.max_pixels;
    let scene = |clip: usize| {
        let faces = development_faces(
            annotated.clone(),
            a.height,
            40.0,
            clip * a.faces_per_clip,
            a.faces_per_clip,
            a.seed,
        )?;
        let photos = Scene::from_annotated(&faces, a.height, max_pixels)?;
        // A stretch of wall without faces (1.5 frame widths, a seeded texture) after the
        // photos, so some frames have no face in view.
        let wall = Scene::textured(a.width * 3 / 2, a.height, a.seed + clip as u64);
        Scene::from_images(
            &[
                ScenePhoto {
                    image: image::DynamicImage::ImageRgb8(photos.image().clone()),
                    faces: photos.faces().to_vec(),
                },
                ScenePhoto {
                    image: image::DynamicImage::ImageRgb8(wall.image().clone()),
                    faces: Vec::new(),
                },
            ],
            a.height,
        )
    };
    let total = options.motions.len() * options.readout_fractions.len() * options.clips;
    let bar = progress_bar(total as u64);
    let result = evaluate_video(&unshear, &options, scene, |_| bar.inc(1))?;
    bar.finish_and_clear();
    print!("{}", result.markdown());
    if let Some(path) = &a.json {
        std::fs::write(path, result.json_lines())
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn eval_nostrils(a: EvalNostrilsArgs) -> Result<()> {
    use unshear::dev::dataset::DlibLandmarks;
    if !(a.upscale.is_finite() && a.upscale > 0.0 && a.upscale <= 8.0) {
        usage_error("--upscale must be a number in (0, 8]");
    }
    let unshear = load_models(&a.model, Config::default())?;
    let mut faces = Vec::new();
    for xml in &a.xml {
        faces.extend(
            DlibLandmarks::new(xml)
                .faces()
                .with_context(|| format!("reading {}", xml.display()))?,
        );
    }
    let result = unshear::dev::eval::nostrils::evaluate_nostrils(
        &unshear,
        &faces,
        a.upscale,
        a.model.max_pixels,
    );
    for u in &result.unreadable {
        eprintln!("unshear: skipped {u}");
    }
    print!("{}", result.markdown());
    Ok(())
}

fn eval_recognition(a: EvalRecognitionArgs) -> Result<()> {
    use unshear::dev::dataset::{celeba_identities, yale_identities};
    use unshear::dev::eval::recognition::{evaluate_recognition, RecognitionOptions};
    if a.gallery == 0 || a.grid == 0 || a.grid > 8 || a.k.iter().any(|k| !k.is_finite()) {
        usage_error("--gallery must be >= 1, --grid in 1..=8 and every --k finite");
    }
    let unshear = load_models(&a.model, Config::default())?;
    let items = if a.data.join("identity.txt").is_file() {
        celeba_identities(&a.data)
    } else {
        yale_identities(&a.data)
    }
    .with_context(|| format!("reading the data set in {}", a.data.display()))?;
    let options = RecognitionOptions {
        shears: a.k.clone(),
        gallery: a.gallery,
        grid: a.grid,
        max_pixels: a.model.max_pixels,
    };
    let bar = progress_bar(items.len() as u64);
    let result = evaluate_recognition(&unshear, items, &options, || bar.inc(1));
    bar.finish_and_clear();
    for u in &result.unreadable {
        eprintln!("unshear: skipped {u}");
    }
    print!("{}", result.markdown(&a.data.display().to_string()));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn outputs_differing_in_case_collide_only_where_case_is_folded() {
        let (a, b) = (
            PathBuf::from("/out/Face.JPG"),
            PathBuf::from("/out/face.jpg"),
        );
        assert_eq!(fold_case(a.clone(), true), fold_case(b.clone(), true));
        assert_ne!(fold_case(a.clone(), false), fold_case(b, false));
        assert_eq!(fold_case(a.clone(), false), a);
    }

    #[test]
    fn failure_messages_are_one_line_without_the_file_twice() {
        assert_eq!(
            one_line("a/b.jpg", "a/b.jpg: Format error\nNot enough bytes\n"),
            "Format error Not enough bytes"
        );
        assert_eq!(
            one_line("a/b.jpg", "refusing to write c.jpg: it exists"),
            "refusing to write c.jpg: it exists"
        );
        assert_eq!(one_line("x", "x: "), "x:");
    }

    #[test]
    fn error_chains_leave_out_repeated_causes() {
        let io = std::io::Error::other("disk full");
        let lib = unshear::Error::Io {
            path: "out.png".into(),
            source: io,
        };
        let e = anyhow::Error::new(lib).context("writing the output");
        assert_eq!(
            error_chain(&e),
            "writing the output: out.png: disk full",
            "the library error already holds its source's text"
        );
    }
}
