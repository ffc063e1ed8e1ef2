//! Ctrl-C and termination signals (SIGINT, SIGTERM, SIGHUP on Unix).
//!
//! In a batch (`correct`, `estimate`) the first signal asks the batch to stop: no new input is
//! started, the inputs in progress are finished (so each output is either complete or absent and
//! no temporary file remains), their results are printed, and the process exits with 130. A
//! second signal, or the first one in a command that is not a batch, stops at once: the
//! temporary files of writes still in progress are removed first (see
//! [`unshear::imageio::abandon_writes`]; `unshear video` first ends its `ffmpeg` children and
//! removes its temporary video file, [`crate::ffmpeg::abandon`]), then the process exits with
//! 130.
//!
//! SIGKILL cannot be caught: a killed run can leave `.unshear-*.tmp` files beside the outputs,
//! never a partial output (outputs appear only by an atomic rename).

use std::sync::atomic::{AtomicBool, Ordering};

/// The exit code after an interruption (128 + SIGINT, as shells report it).
pub const EXIT_INTERRUPTED: u8 = 130;

static STOP: AtomicBool = AtomicBool::new(false);

/// Installs the handler. `graceful`: the command polls [`flag`] and stops by itself after the
/// first signal; otherwise the first signal already exits.
pub fn install(graceful: bool) {
    let result = ctrlc::set_handler(move || {
        let again = STOP.swap(true, Ordering::SeqCst);
        if graceful && !again {
            eprintln!(
                "unshear: interrupted; finishing the images in progress (interrupt again to stop now)"
            );
            return;
        }
        crate::ffmpeg::abandon();
        unshear::imageio::abandon_writes();
        eprintln!("unshear: interrupted");
        std::process::exit(i32::from(EXIT_INTERRUPTED));
    });
    if let Err(e) = result {
        // Without the handler a signal kills the process as usual: outputs stay atomic, only
        // temporary files may be left behind.
        eprintln!("unshear: warning: cannot handle interruptions ({e})");
    }
}

/// Set once a stop was requested.
pub fn flag() -> &'static AtomicBool {
    &STOP
}

/// Whether a stop was requested.
pub fn requested() -> bool {
    STOP.load(Ordering::SeqCst)
}
