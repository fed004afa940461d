//! Standard output of command results. `println!` panics (exit 101) when stdout is a closed
//! pipe or a full disk (issue 17); results are written through [`stdout`] instead, whose
//! errors are [`StdoutError`]s, and `main` turns them into an exit without a panic:
//! quietly with code 141 (128 + SIGPIPE, what a shell shows for Unix tools stopped by a
//! closed pipe, e.g. `filtrace compare a.exr b.exr | head -1`) for a closed pipe, and with
//! a message and code 1 for any other error (`> /dev/full`). Output files are written
//! before the results are printed, so neither loses a file.

use std::io::{self, Write};

/// Standard output could not be written.
#[derive(Debug)]
pub struct StdoutError(pub io::Error);

impl std::fmt::Display for StdoutError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "cannot write to standard output: {}", self.0)
    }
}

impl std::error::Error for StdoutError {}

/// Locked standard output whose write errors are [`StdoutError`]s (inside the `io::Error`,
/// so that `writeln!(out, ...)?` works in any function returning `anyhow::Result`).
pub struct Stdout(io::StdoutLock<'static>);

pub fn stdout() -> Stdout {
    Stdout(io::stdout().lock())
}

fn mark(e: io::Error) -> io::Error {
    io::Error::new(e.kind(), StdoutError(e))
}

impl Write for Stdout {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.0.write(buf).map_err(mark)
    }
    fn flush(&mut self) -> io::Result<()> {
        self.0.flush().map_err(mark)
    }
}

impl Drop for Stdout {
    /// Flushes what is left quietly: the results are flushed (with errors seen) by the
    /// commands themselves; this only matters after an earlier error.
    fn drop(&mut self) {
        let _ = self.0.flush();
    }
}

/// The stdout error behind `e`, if `e` is one.
pub fn stdout_failure(e: &anyhow::Error) -> Option<&io::Error> {
    e.chain().find_map(|cause| {
        let marked = cause.downcast_ref::<StdoutError>().map(|s| &s.0);
        let wrapped =
            || cause.downcast_ref::<io::Error>()?.get_ref()?.downcast_ref::<StdoutError>().map(|s| &s.0);
        marked.or_else(wrapped)
    })
}

/// Ends the process for a failed write to stdout (see the module documentation).
pub fn exit_on_stdout_failure(e: &io::Error) -> ! {
    if e.kind() == io::ErrorKind::BrokenPipe {
        std::process::exit(141);
    }
    eprintln!("error: cannot write to standard output: {e}");
    std::process::exit(1);
}

/// Prints a benchmark's `report`: pretty JSON with `--json`, else the markdown `table`.
pub fn print_report<R: serde::Serialize>(
    json: bool,
    report: &R,
    table: impl FnOnce(&mut Stdout, &R) -> io::Result<()>,
) -> anyhow::Result<()> {
    let mut out = stdout();
    if json {
        writeln!(out, "{}", serde_json::to_string_pretty(report)?)?;
    } else {
        table(&mut out, report)?;
    }
    Ok(out.flush()?)
}
