//! What a rendering command holds while it runs: Ctrl-C handling ([`CtrlC`],
//! [`Interrupted`]), the memory check before loading, the test hook of tests/cancel.rs and
//! progress bars.

use std::io::IsTerminal;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::Arc;
use std::time::{Duration, Instant};

/// What to do when a render does not fit in memory.
const MEMORY_HINT: &str = "Lower --res: the film and the images grow with the pixel count \
(--spp does not change them); set FILTRACE_MEMORY_LIMIT=bytes to test with another limit";

/// Refuses a render whose estimate `needs` is more than this machine has available
/// ([`filtrace_render::memory::check`]): called before the scene is loaded.
pub fn check_memory(needs: filtrace_render::memory::MemoryEstimate) -> anyhow::Result<()> {
    filtrace_render::memory::check(&needs.with_hint(MEMORY_HINT)).map_err(anyhow::Error::msg)
}

/// Returned (as an error) after a cancelled command has written its output: `main`
/// exits with code 130.
#[derive(Debug)]
pub struct Interrupted;

impl std::fmt::Display for Interrupted {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "interrupted by Ctrl-C (partial result written)")
    }
}

impl std::error::Error for Interrupted {}

/// Ctrl-C of the rendering commands. Until [`CtrlC::arm`] there is nothing to keep, and
/// loading and the BVH build cannot stop midway: Ctrl-C exits at once (code 130) and
/// writes nothing. Once armed, Ctrl-C sets [`CtrlC::flag`], which the render polls; the
/// command then writes what is complete and exits with 130. A second Ctrl-C exits at once.
pub struct CtrlC {
    flag: Arc<AtomicBool>,
    armed: Arc<AtomicBool>,
}

impl CtrlC {
    /// Installs the handler (if one is installed already, as in unit tests running several
    /// commands, Ctrl-C keeps that one and this flag is never set).
    pub fn install() -> Self {
        let (flag, armed) = (Arc::new(AtomicBool::new(false)), Arc::new(AtomicBool::new(false)));
        let (f, a) = (flag.clone(), armed.clone());
        let _ = ctrlc::set_handler(move || {
            if f.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            if !a.load(Ordering::SeqCst) {
                eprintln!("\nCtrl-C: stopped before any sample was taken; nothing written");
                std::process::exit(130);
            }
            eprintln!("\nCtrl-C: stopping and writing what is complete (Ctrl-C again to abort)");
        });
        CtrlC { flag, armed }
    }

    /// The render starts: from now on Ctrl-C sets the flag instead of exiting.
    pub fn arm(&self) {
        self.armed.store(true, Ordering::SeqCst);
    }

    pub fn flag(&self) -> &Arc<AtomicBool> {
        &self.flag
    }

    pub fn is_set(&self) -> bool {
        self.flag.load(Ordering::SeqCst)
    }
}

/// Test hook for `tests/cancel.rs`: when the environment has `FILTRACE_TEST_PAUSE`, each
/// stage of a render prints `filtrace-test: STAGE` on stderr, and the stage the variable
/// names then waits up to 10 s (less if `cancel` is set), so that a test can send SIGINT at
/// a known point. Stages: `loaded`, `built`, `rendering`, and `pass N` after each pass of
/// the plain render (N samples per pixel done).
pub fn test_hook(stage: &str, cancel: &AtomicBool) {
    let Some(pause) = std::env::var_os("FILTRACE_TEST_PAUSE") else { return };
    eprintln!("filtrace-test: {stage}");
    if pause == stage {
        let until = Instant::now() + Duration::from_secs(10);
        while Instant::now() < until && !cancel.load(Ordering::SeqCst) {
            std::thread::sleep(Duration::from_millis(10));
        }
    }
}

/// Test hook for tests/vpl_sequence.rs: true when the environment's `FILTRACE_TEST_FAIL`
/// names `what` (e.g. `state 2`, the state file after frame 2), whose write then fails
/// midway, as a full disk would make it.
pub fn test_failure(what: &str) -> bool {
    std::env::var_os("FILTRACE_TEST_FAIL").is_some_and(|v| v == what)
}

/// A progress bar on stderr when it is a terminal, hidden otherwise.
pub fn progress_bar(total: u64, what: &str) -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let bar = indicatif::ProgressBar::new(total);
    let style = indicatif::ProgressStyle::with_template(
        "{msg} [{elapsed_precise}] {wide_bar} {percent:>3}% (eta {eta})",
    )
    .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar());
    bar.set_style(style);
    bar.set_message(what.to_string());
    bar
}

/// A spinner with the elapsed time for a stage that has no count to show (a frame's VPLs
/// and importance cache), on stderr when it is a terminal, hidden otherwise; it ticks on
/// its own thread while the stage runs.
pub fn spinner(what: &str) -> indicatif::ProgressBar {
    if !std::io::stderr().is_terminal() {
        return indicatif::ProgressBar::hidden();
    }
    let spinner = indicatif::ProgressBar::new_spinner();
    let style = indicatif::ProgressStyle::with_template("{spinner} {msg} [{elapsed_precise}]")
        .unwrap_or_else(|_| indicatif::ProgressStyle::default_spinner());
    spinner.set_style(style);
    spinner.set_message(what.to_string());
    spinner.enable_steady_tick(std::time::Duration::from_millis(100));
    spinner
}

/// Bars for several things at once (frames and the samples of the current frame) on stderr
/// when it is a terminal, hidden otherwise.
pub fn multi_progress() -> indicatif::MultiProgress {
    if !std::io::stderr().is_terminal() {
        return indicatif::MultiProgress::with_draw_target(indicatif::ProgressDrawTarget::hidden());
    }
    indicatif::MultiProgress::new()
}
