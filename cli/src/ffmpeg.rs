//! Running the `ffmpeg` and `ffprobe` programs for `unshear video` on containers: finding them,
//! the decoding child (a y4m pipe read as a [`FrameSource`]) and the encoding child (a y4m pipe
//! written as a [`FrameSink`]), their error output, and ending them. Their command lines and
//! the reading of `ffprobe`'s answer are in [`plan`], which starts no process.
//!
//! Every child runs in a process group of its own, so a Ctrl-C at the terminal reaches only
//! `unshear`, which then ends the children itself ([`abandon`], called by the signal handler)
//! before it removes its temporary output. Children still running when their handle is dropped
//! (an error elsewhere) are killed and reaped. A child that keeps `unshear` waiting (for a
//! frame, for room in its pipe, for its end) longer than `--ffmpeg-timeout` is taken as stuck
//! and killed by a watchdog thread, so that an unattended batch fails instead of hanging.

pub mod plan;

use std::ffi::{OsStr, OsString};
use std::io::{BufReader, BufWriter, Read};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, ExitStatus, Stdio};
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::sync::{Arc, Mutex, Once};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use anyhow::{bail, Context, Result};
use plan::{Capabilities, Probe};
use unshear::video::y4m::{Y4mReader, Y4mWriter};
use unshear::video::{FrameSink, FrameSource, VideoFrame};

/// What to tell a user without the programs.
const INSTALL_HINT: &str = "install FFmpeg (Debian/Ubuntu: `apt-get install ffmpeg`, Fedora: \
    `dnf install ffmpeg`, macOS: `brew install ffmpeg`, Windows: `winget install ffmpeg`) or \
    give its path with --ffmpeg; y4m files and pipes (`-`) and frame folders work without it";

/// Default of `--ffmpeg-timeout`, seconds: far beyond the wait for any one frame of a slow
/// encoder, short enough that a stuck child does not hold a batch for long.
pub const DEFAULT_TIMEOUT_SECS: u64 = 600;

/// The `ffmpeg` and `ffprobe` programs to run.
#[derive(Debug, Clone)]
pub struct Tools {
    /// `ffmpeg`.
    pub ffmpeg: PathBuf,
    /// `ffprobe`: beside `ffmpeg` when that was given by path, else on `PATH`.
    pub ffprobe: PathBuf,
    /// Longest wait on a child before it is killed as stuck (`None`: no limit).
    pub timeout: Option<Duration>,
}

/// `name` (with `.exe` on Windows) in the folders of `PATH`.
fn on_path(name: &str) -> Option<PathBuf> {
    let file = format!("{name}{}", std::env::consts::EXE_SUFFIX);
    std::env::split_paths(&std::env::var_os("PATH")?)
        .map(|dir| dir.join(&file))
        .find(|p| is_executable(p))
}

fn is_executable(p: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        p.metadata()
            .is_ok_and(|m| m.is_file() && m.permissions().mode() & 0o111 != 0)
    }
    #[cfg(not(unix))]
    {
        p.is_file()
    }
}

impl Tools {
    /// Finds the programs (`given`: `--ffmpeg PATH`); `why` says what needs them; `timeout`:
    /// the longest wait on a child (`None`: no limit).
    pub fn find(given: Option<&Path>, why: &str, timeout: Option<Duration>) -> Result<Self> {
        let ffmpeg = match given {
            Some(p) if is_executable(p) => p.to_path_buf(),
            Some(p) => bail!(
                "--ffmpeg {}: no such program; {why} needs the ffmpeg program: {INSTALL_HINT}",
                p.display()
            ),
            None => on_path("ffmpeg").with_context(|| {
                format!("ffmpeg was not found on PATH; {why} needs it: {INSTALL_HINT}")
            })?,
        };
        let probe_name = format!("ffprobe{}", std::env::consts::EXE_SUFFIX);
        let beside = given
            .and_then(Path::parent)
            .map(|d| d.join(&probe_name))
            .filter(|p| is_executable(p));
        let ffprobe = beside.or_else(|| on_path("ffprobe")).with_context(|| {
            format!(
                "ffprobe (part of FFmpeg) was not found beside {} or on PATH; {why} needs it: \
                 {INSTALL_HINT}",
                ffmpeg.display()
            )
        })?;
        Ok(Self {
            ffmpeg,
            ffprobe,
            timeout,
        })
    }

    /// What this `ffmpeg` can do (two quick runs of it, side by side: each start of a
    /// distribution's ffmpeg loads a few hundred shared libraries).
    pub fn capabilities(&self) -> Result<Capabilities> {
        let text = |args: &[&str], what: &str| {
            self.output(&self.ffmpeg, args, what)
                .map(|(_, _, out)| String::from_utf8_lossy(&out).into_owned())
        };
        let (help, encoders) = std::thread::scope(|scope| {
            let help = scope.spawn(|| text(&["-hide_banner", "-h", "long"], "listing its options"));
            let encoders = text(&["-hide_banner", "-encoders"], "listing its encoders");
            let help = help
                .join()
                .unwrap_or_else(|_| Err(anyhow::anyhow!("ffmpeg -h panicked")));
            (help, encoders)
        });
        Ok(Capabilities::parse(&help?, &encoders?))
    }

    /// The probe of `input`.
    pub fn probe(&self, input: &Path) -> Result<Probe> {
        let what = format!("probing {}", input.display());
        let args = plan::probe_args(input);
        let (mut child, status, stdout) = self.output(&self.ffprobe, &args, &what)?;
        if !status.success() {
            bail!(
                "{}: not a video ffprobe can read: {}",
                input.display(),
                child.stderr_tail()
            );
        }
        Probe::parse(&stdout).with_context(|| format!("{}", input.display()))
    }

    /// Runs `program` to its end and returns it (its error output kept), how it ended and its
    /// standard output.
    fn output<S: AsRef<OsStr>>(
        &self,
        program: &Path,
        args: &[S],
        what: &str,
    ) -> Result<(ChildProcess, ExitStatus, Vec<u8>)> {
        let args: Vec<OsString> = args.iter().map(|a| a.as_ref().to_owned()).collect();
        let (mut child, _, stdout) = spawn_with(
            program,
            &args,
            Stdio::null(),
            Stdio::piped(),
            what,
            self.timeout,
        )?;
        let mut out = Vec::new();
        if let Some(mut stdout) = stdout {
            let _busy = child.busy();
            let _ = stdout.read_to_end(&mut out);
        }
        // A child killed as stuck fails here, before its output is looked at.
        let status = child.wait()?;
        Ok((child, status, out))
    }

    /// Runs `ffmpeg` with `args` to the end (the remux pass).
    pub fn run(&self, args: &[OsString], what: &str) -> Result<()> {
        let mut child = spawn_with(
            &self.ffmpeg,
            args,
            Stdio::null(),
            Stdio::null(),
            what,
            self.timeout,
        )?
        .0;
        let status = child.wait()?;
        if !status.success() {
            bail!("ffmpeg failed {what} ({status}): {}", child.stderr_tail());
        }
        Ok(())
    }
}

/// The last lines of a child's error output, for a message.
fn tail(text: &str) -> String {
    let text = text.trim();
    let lines: Vec<&str> = text.lines().collect();
    let start = lines.len().saturating_sub(6);
    let t = lines[start..].join(" | ");
    if t.is_empty() {
        "(no message)".into()
    } else {
        t
    }
}

/// Children of this process that are running, so that [`abandon`] can end them.
static CHILDREN: Mutex<Vec<(u64, Child)>> = Mutex::new(Vec::new());
/// Temporary outputs that [`abandon`] removes.
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());
/// Set by [`abandon`]: nothing new is started afterwards.
static ABANDONED: AtomicBool = AtomicBool::new(false);
static NEXT_ID: AtomicU64 = AtomicU64::new(0);

/// Ends every child and removes every temporary output (the signal handler's first step).
pub fn abandon() {
    ABANDONED.store(true, Ordering::SeqCst);
    if let Ok(mut children) = CHILDREN.lock() {
        for (_, child) in children.iter_mut() {
            let _ = child.kill();
            let _ = child.wait();
        }
        children.clear();
    }
    if let Ok(mut temps) = TEMPORARIES.lock() {
        for p in temps.drain(..) {
            let _ = std::fs::remove_file(p);
        }
    }
}

/// A temporary output file beside the final one, removed when dropped or on [`abandon`].
pub struct TempOutput {
    path: Option<tempfile::TempPath>,
}

impl TempOutput {
    /// A new empty file in `dir`, named `.unshear-XXXXXX.EXT` (the extension kept so that
    /// `ffmpeg` picks the container by it).
    pub fn new(dir: &Path, extension: &str) -> Result<Self> {
        let suffix = format!(".{extension}");
        let mut builder = tempfile::Builder::new();
        builder.prefix(".unshear-").suffix(&suffix);
        // tempfile creates 0600 files; an output should get the usual 0666-minus-umask.
        #[cfg(unix)]
        builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
        let file = builder
            .tempfile_in(dir)
            .with_context(|| format!("creating a temporary file in {}", dir.display()))?;
        let path = file.into_temp_path();
        if let Ok(mut t) = TEMPORARIES.lock() {
            t.push(path.to_path_buf());
        }
        Ok(Self { path: Some(path) })
    }

    /// Where it is.
    pub fn path(&self) -> &Path {
        self.path.as_deref().unwrap_or(Path::new(""))
    }

    /// Renames it to `dest`; an existing `dest` is replaced only when `overwrite`.
    pub fn persist(mut self, dest: &Path, overwrite: bool) -> Result<()> {
        let Some(path) = self.path.take() else {
            bail!("temporary output already used");
        };
        let own = path.to_path_buf();
        let result = if overwrite {
            path.persist(dest).map_err(|e| e.error)
        } else {
            path.persist_noclobber(dest).map_err(|e| e.error)
        };
        unlist(&own);
        result.with_context(|| format!("renaming the finished output to {}", dest.display()))
    }
}

fn unlist(p: &Path) {
    if let Ok(mut t) = TEMPORARIES.lock() {
        t.retain(|q| q != p);
    }
}

impl Drop for TempOutput {
    fn drop(&mut self) {
        if let Some(p) = self.path.take() {
            unlist(&p);
            // TempPath removes the file when dropped.
        }
    }
}

/// A running child: listed for [`abandon`], its error output collected by a thread.
pub struct ChildProcess {
    id: u64,
    what: String,
    stderr: Option<JoinHandle<String>>,
    stderr_text: Option<String>,
    done: bool,
    watch: Arc<Watch>,
}

/// What the watchdog knows of one child: since when `unshear` has been waiting on it.
#[derive(Debug)]
struct Watch {
    id: u64,
    /// The longest wait allowed (`None`: no limit).
    limit: Option<Duration>,
    /// Milliseconds since [`epoch`] at which the current wait began; 0 while not waiting.
    waiting_since: AtomicU64,
    /// Set when the watchdog killed the child.
    stalled: AtomicBool,
}

/// The watches of the running children, checked by the watchdog thread.
static WATCHES: Mutex<Vec<Arc<Watch>>> = Mutex::new(Vec::new());
static WATCHDOG: Once = Once::new();

/// The watchdog's clock, started at its first use; never 0 once read (0 means "not waiting").
fn now_millis() -> u64 {
    static EPOCH: std::sync::OnceLock<Instant> = std::sync::OnceLock::new();
    let epoch = *EPOCH.get_or_init(Instant::now);
    epoch.elapsed().as_millis() as u64 + 1
}

/// Starts, once, the thread that kills children waited on for longer than their limit.
fn start_watchdog() {
    WATCHDOG.call_once(|| {
        let spawned = std::thread::Builder::new()
            .name("ffmpeg-watchdog".into())
            .spawn(|| loop {
                std::thread::sleep(Duration::from_millis(100));
                let now = now_millis();
                let stuck: Vec<Arc<Watch>> = match WATCHES.lock() {
                    Ok(w) => w
                        .iter()
                        .filter(|w| {
                            let since = w.waiting_since.load(Ordering::SeqCst);
                            w.limit.is_some_and(|limit| {
                                since != 0 && now - since > limit.as_millis() as u64
                            })
                        })
                        .cloned()
                        .collect(),
                    Err(_) => return,
                };
                for w in stuck {
                    w.stalled.store(true, Ordering::SeqCst);
                    if let Ok(mut children) = CHILDREN.lock() {
                        if let Some(pos) = children.iter().position(|(id, _)| *id == w.id) {
                            // Killed but left listed: its owner reaps it and reports the stall.
                            let _ = children[pos].1.kill();
                        }
                    }
                }
            });
        if let Err(e) = spawned {
            eprintln!("unshear video: warning: no ffmpeg watchdog ({e}); --ffmpeg-timeout is off");
        }
    });
}

/// A wait on a child, from its making to its drop (see [`ChildProcess::busy`]).
pub struct Busy(Arc<Watch>);

impl Drop for Busy {
    fn drop(&mut self) {
        self.0.waiting_since.store(0, Ordering::SeqCst);
    }
}

/// Starts `program` and returns it with its piped stdin and stdout (when asked for); a wait on
/// it longer than `timeout` kills it.
fn spawn_with(
    program: &Path,
    args: &[OsString],
    stdin: Stdio,
    stdout: Stdio,
    what: &str,
    timeout: Option<Duration>,
) -> Result<(ChildProcess, Option<ChildStdin>, Option<ChildStdout>)> {
    if ABANDONED.load(Ordering::SeqCst) {
        bail!("interrupted");
    }
    let mut cmd = Command::new(program);
    cmd.args(args)
        .stdin(stdin)
        .stdout(stdout)
        .stderr(Stdio::piped());
    #[cfg(unix)]
    {
        // Its own process group: a Ctrl-C at the terminal goes to unshear only, which ends the
        // child itself (ffmpeg would otherwise finish its output on SIGINT as if complete).
        use std::os::unix::process::CommandExt;
        cmd.process_group(0);
    }
    let mut child = cmd
        .spawn()
        .with_context(|| format!("starting {} for {what}", program.display()))?;
    let (stdin, stdout) = (child.stdin.take(), child.stdout.take());
    let stderr = child.stderr.take().map(|mut e| {
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = e.read_to_string(&mut text);
            text
        })
    });
    let id = NEXT_ID.fetch_add(1, Ordering::SeqCst);
    let mut children = CHILDREN
        .lock()
        .map_err(|_| anyhow::anyhow!("child list poisoned"))?;
    children.push((id, child));
    drop(children);
    let watch = Arc::new(Watch {
        id,
        limit: timeout,
        waiting_since: AtomicU64::new(0),
        stalled: AtomicBool::new(false),
    });
    if timeout.is_some() {
        start_watchdog();
        if let Ok(mut watches) = WATCHES.lock() {
            watches.push(watch.clone());
        }
    }
    let process = ChildProcess {
        id,
        what: what.to_string(),
        stderr,
        stderr_text: None,
        done: false,
        watch,
    };
    Ok((process, stdin, stdout))
}

impl ChildProcess {
    /// Marks a wait on the child (a read from it, a write to it, its end) until the guard is
    /// dropped: the watchdog kills the child if it lasts longer than the limit.
    pub fn busy(&self) -> Busy {
        let w = self.watch.clone();
        w.waiting_since.store(now_millis(), Ordering::SeqCst);
        Busy(w)
    }

    /// The error for a child the watchdog killed, `None` for any other.
    fn stall(&self) -> Option<anyhow::Error> {
        let w = &self.watch;
        let limit = w.limit.filter(|_| w.stalled.load(Ordering::SeqCst))?;
        Some(anyhow::anyhow!(
            "ffmpeg made no progress {} for {} s and was stopped (--ffmpeg-timeout)",
            self.what,
            limit.as_secs_f64()
        ))
    }

    /// Waits for the child to end (polling, so that [`abandon`] can take the list meanwhile).
    /// A child the watchdog killed is an error that says so.
    pub fn wait(&mut self) -> Result<ExitStatus> {
        let busy = self.busy();
        loop {
            {
                let mut children = CHILDREN
                    .lock()
                    .map_err(|_| anyhow::anyhow!("child list poisoned"))?;
                let Some(pos) = children.iter().position(|(id, _)| *id == self.id) else {
                    self.done = true;
                    bail!("ffmpeg ({}) was stopped", self.what);
                };
                if let Some(status) = children[pos].1.try_wait()? {
                    children.remove(pos);
                    self.done = true;
                    drop(busy);
                    return match self.stall() {
                        Some(e) => Err(e),
                        None => Ok(status),
                    };
                }
            }
            std::thread::sleep(Duration::from_millis(5));
        }
    }

    /// Kills the child if it still runs and reaps it.
    pub fn kill(&mut self) {
        if self.done {
            return;
        }
        if let Ok(mut children) = CHILDREN.lock() {
            if let Some(pos) = children.iter().position(|(id, _)| *id == self.id) {
                let (_, mut child) = children.remove(pos);
                let _ = child.kill();
                let _ = child.wait();
            }
        }
        self.done = true;
    }

    /// The child's whole error output (after it ended).
    pub fn stderr_text(&mut self) -> &str {
        if self.stderr_text.is_none() {
            let text = self
                .stderr
                .take()
                .and_then(|h| h.join().ok())
                .unwrap_or_default();
            self.stderr_text = Some(text);
        }
        self.stderr_text.as_deref().unwrap_or("")
    }

    /// The end of the child's error output (after it ended).
    pub fn stderr_tail(&mut self) -> String {
        tail(self.stderr_text())
    }

    /// Waits and turns a failure into an error naming `what` and ffmpeg's message.
    fn finish(&mut self) -> Result<()> {
        let status = self.wait()?;
        if status.success() {
            Ok(())
        } else {
            let message = self.stderr_tail();
            bail!("ffmpeg failed {} ({status}): {message}", self.what)
        }
    }
}

impl Drop for ChildProcess {
    fn drop(&mut self) {
        self.kill();
        if let Ok(mut watches) = WATCHES.lock() {
            watches.retain(|w| w.id != self.id);
        }
    }
}

/// Frames decoded by an `ffmpeg` child from a container file.
///
/// `-xerror` makes `ffmpeg` fail at a corrupt packet, but a file cut between packets decodes
/// to its end with only "partial file" messages and a success: a decoder that printed errors
/// and gave fewer frames than the container's index lists (or said "partial file") is taken
/// as a truncated input. Fewer frames without a message are normal (an edit list that drops
/// some); messages with every frame decoded are passed on as a warning.
pub struct Decoder {
    reader: Y4mReader<BufReader<ChildStdout>>,
    child: ChildProcess,
    frames: u64,
    indexed: Option<u64>,
}

/// A decoding `ffmpeg` started and not yet read from (see [`Decoder`]).
pub struct PendingDecoder {
    child: ChildProcess,
    stdout: ChildStdout,
    indexed: Option<u64>,
}

impl PendingDecoder {
    /// Starts `ffmpeg` with `args` (from [`plan::decode_args`]) on `input`;
    /// `indexed`: the frame count of the container's index, when it has one.
    pub fn spawn(
        tools: &Tools,
        args: &[OsString],
        input: &Path,
        indexed: Option<u64>,
    ) -> Result<Self> {
        let what = format!("decoding {}", input.display());
        let (child, _, stdout) = spawn_with(
            &tools.ffmpeg,
            args,
            Stdio::null(),
            Stdio::piped(),
            &what,
            tools.timeout,
        )?;
        let stdout = stdout.context("ffmpeg's output pipe")?;
        Ok(Self {
            child,
            stdout,
            indexed,
        })
    }

    /// Reads the y4m header the decoder writes.
    pub fn open(self, max_pixels: u64) -> Result<Decoder> {
        let Self {
            mut child,
            stdout,
            indexed,
        } = self;
        let busy = child.busy();
        let opened = Y4mReader::new(BufReader::with_capacity(1 << 20, stdout), max_pixels);
        drop(busy);
        match opened {
            Ok(reader) => Ok(Decoder {
                reader,
                child,
                frames: 0,
                indexed,
            }),
            Err(e) => {
                // Most likely ffmpeg could not open or decode the input: its message says why.
                child.wait()?;
                let message = child.stderr_tail();
                bail!("{}: {message} ({e})", child.what)
            }
        }
    }
}

impl Decoder {
    /// The y4m header line the decoder wrote.
    pub fn header(&self) -> &[u8] {
        self.reader.header()
    }

    /// The stream's format.
    pub fn format(&self) -> &unshear::video::VideoFormat {
        self.reader.format()
    }
}

impl FrameSource for Decoder {
    fn next_frame(&mut self) -> unshear::Result<Option<VideoFrame>> {
        let video_err = |m: String| unshear::Error::Video(m);
        let busy = self.child.busy();
        let read = self.reader.read_video_frame();
        drop(busy);
        match read {
            Ok(Some(f)) => {
                self.frames += 1;
                Ok(Some(f))
            }
            Ok(None) => {
                self.child
                    .finish()
                    .map_err(|e| video_err(format!("{e:#} (after {} frames)", self.frames)))?;
                let messages = self.child.stderr_text().trim().to_string();
                if messages.is_empty() {
                    return Ok(None);
                }
                let short = self.indexed.is_some_and(|n| self.frames < n);
                if short || messages.contains("partial file") {
                    let of = self.indexed.map(|n| format!(" of {n}")).unwrap_or_default();
                    let tail = self.child.stderr_tail();
                    return Err(video_err(format!(
                        "{}: the input looks truncated or corrupt: {} frames{of} decoded; \
                         ffmpeg: {tail}",
                        self.child.what, self.frames
                    )));
                }
                let tail = self.child.stderr_tail();
                eprintln!(
                    "unshear video: warning: ffmpeg reported while {}: {tail}",
                    self.child.what
                );
                Ok(None)
            }
            Err(e) => {
                if let Err(stopped) = self.child.wait() {
                    return Err(video_err(format!("{stopped:#}")));
                }
                let message = self.child.stderr_tail();
                Err(video_err(format!(
                    "{e}; ffmpeg {}: {message}",
                    self.child.what
                )))
            }
        }
    }
}

/// Frames encoded by an `ffmpeg` child into a container file.
pub struct Encoder {
    writer: Option<Y4mWriter<BufWriter<ChildStdin>>>,
    child: ChildProcess,
    /// The size frames are padded to (see [`plan::even_size`]).
    pad: Option<(u32, u32)>,
}

/// `frame` padded to `pad` when given (see [`Encoder`]'s `pad`).
fn pad_to<T: unshear::video::YuvSample>(
    frame: &mut unshear::video::YuvFrame<T>,
    pad: Option<(u32, u32)>,
) {
    if let Some((w, h)) = pad {
        plan::pad_luma(frame, w, h);
    }
}

/// An encoding `ffmpeg` started and not yet written to (see [`Encoder`]).
pub struct PendingEncoder {
    child: ChildProcess,
    stdin: ChildStdin,
}

impl PendingEncoder {
    /// Starts `ffmpeg` with `args` (from [`plan::EncodePlan`]) writing
    /// `output` (named in messages).
    pub fn spawn(tools: &Tools, args: &[OsString], output: &Path) -> Result<Self> {
        let what = format!("encoding {}", output.display());
        let (child, stdin, _) = spawn_with(
            &tools.ffmpeg,
            args,
            Stdio::piped(),
            Stdio::null(),
            &what,
            tools.timeout,
        )?;
        let stdin = stdin.context("ffmpeg's input pipe")?;
        Ok(Self { child, stdin })
    }

    /// Writes the y4m `header` into it; with `pad`, the header says that size and every frame
    /// is padded to it by repeating its last luma column and row.
    pub fn begin(self, header: &[u8], pad: Option<(u32, u32)>) -> Result<Encoder> {
        let mut encoder = Encoder {
            writer: None,
            child: self.child,
            pad,
        };
        let header = match pad {
            Some((w, h)) => plan::resize_header(header, w, h),
            None => header.to_vec(),
        };
        match Y4mWriter::with_header(BufWriter::with_capacity(1 << 20, self.stdin), &header) {
            Ok(w) => encoder.writer = Some(w),
            Err(e) => return Err(encoder.failure(e).into()),
        }
        Ok(encoder)
    }
}

impl Encoder {
    /// A write error, explained by ffmpeg's own message when it has ended.
    fn failure(&mut self, e: unshear::Error) -> unshear::Error {
        // A broken pipe means ffmpeg stopped reading: it has ended or is about to.
        drop(self.writer.take());
        if let Err(stopped) = self.child.wait() {
            return unshear::Error::Video(format!("{stopped:#}"));
        }
        let message = self.child.stderr_tail();
        unshear::Error::Video(format!("ffmpeg {}: {message} ({e})", self.child.what))
    }
}

impl FrameSink for Encoder {
    fn write_frame(&mut self, frame: VideoFrame) -> unshear::Result<()> {
        let Some(w) = self.writer.as_mut() else {
            return Err(unshear::Error::Video("the encoder is closed".into()));
        };
        let pad = self.pad;
        let busy = self.child.busy();
        let result = match frame {
            VideoFrame::Image(i) => {
                let f = w.format();
                let mut yuv = unshear::video::color::image_to_yuv(&i, f.chroma, f.full_range);
                pad_to(&mut yuv, pad);
                w.write_frame(&yuv)
            }
            VideoFrame::Yuv(mut f) => {
                pad_to(&mut f, pad);
                w.write_frame(&f)
            }
            VideoFrame::Yuv16(mut f) => {
                pad_to(&mut f, pad);
                w.write_frame16(&f)
            }
        };
        drop(busy);
        result.map_err(|e| self.failure(e))
    }

    fn finish(&mut self) -> unshear::Result<()> {
        let Some(w) = self.writer.take() else {
            return Err(unshear::Error::Video("the encoder is closed".into()));
        };
        // Closing the pipe tells ffmpeg the stream has ended; it then finishes the file.
        let busy = self.child.busy();
        let flushed = w.finish().map(drop);
        drop(busy);
        if let Err(e) = flushed {
            return Err(self.failure(e));
        }
        self.child
            .finish()
            .map_err(|e| unshear::Error::Video(format!("{e:#}")))
    }
}
