//! Output files are never destroyed by a failed write (issue 17, defect 1): every writer goes
//! through `write_atomic` (a temporary file renamed into place), devices, FIFOs and links
//! are never removed or replaced, and `check_writable` refuses what the write would refuse.
//!
//! The tests run as root in CI, where permission bits do not stop writes: failures are
//! made by a failing writer closure, an invalid EXR, a path under a regular file, a folder
//! at the path and a link to /dev/full (writing /dev/full is safe; nothing here removes a
//! device node: the tests only check that the node and links are still there).

use filtrace_core::Image;
use filtrace_io::{check_writable, write_atomic, write_exr, write_image, ExrImage, IoError};
use std::io::{self, Read};
use std::path::{Path, PathBuf};

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-io-atomic-{tag}-{}", std::process::id()));
    std::fs::remove_dir_all(&d).ok();
    std::fs::create_dir_all(&d).unwrap();
    d
}

/// The names in `dir`, sorted (temporary files start with '.').
fn names(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    v.sort();
    v
}

fn small_exr() -> ExrImage {
    let mut exr = ExrImage::new(3, 2);
    exr.insert("", &["R", "G", "B"], &Image::filled(3, 2, 3, 0.25)).unwrap();
    exr
}

const OLD: &[u8] = b"the old file's bytes, which must survive";

#[test]
fn a_complete_write_replaces_the_file_and_leaves_no_temporary() {
    let dir = temp_dir("complete");
    let path = dir.join("out.txt");
    std::fs::write(&path, OLD).unwrap();
    let n = write_atomic(&path, |w| w.write_all(b"new").map(|_| 7)).unwrap();
    assert_eq!(n, 7, "the closure's value is returned");
    assert_eq!(std::fs::read(&path).unwrap(), b"new");
    assert_eq!(names(&dir), ["out.txt"]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_writer_error_midway_keeps_the_old_bytes_exactly() {
    let dir = temp_dir("midway");
    let path = dir.join("keep.exr");
    std::fs::write(&path, OLD).unwrap();
    let e = write_atomic(&path, |w| {
        w.write_all(&[0u8; 100_000])?;
        Err::<(), _>(io::Error::other("disk on fire"))
    })
    .unwrap_err();
    assert!(e.to_string().contains("keep.exr") && e.to_string().contains("disk on fire"), "{e}");
    assert_eq!(std::fs::read(&path).unwrap(), OLD);
    assert_eq!(names(&dir), ["keep.exr"], "the temporary file is removed");
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_panic_in_the_writer_keeps_the_old_bytes_and_removes_the_temporary() {
    let dir = temp_dir("panic");
    let path = dir.join("keep.png");
    std::fs::write(&path, OLD).unwrap();
    let r = std::panic::catch_unwind(|| {
        let _ = write_atomic(&path, |w| -> io::Result<()> {
            w.write_all(b"partial")?;
            panic!("encoder bug");
        });
    });
    assert!(r.is_err());
    assert_eq!(std::fs::read(&path).unwrap(), OLD);
    assert_eq!(names(&dir), ["keep.png"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// Before the fix the `exr` crate truncated the file, failed on the invalid channel name and
/// deleted the file.
#[test]
fn an_exr_that_cannot_be_encoded_leaves_the_old_file() {
    let dir = temp_dir("badexr");
    let path = dir.join("keep.exr");
    std::fs::write(&path, OLD).unwrap();
    let mut exr = ExrImage::new(2, 2);
    exr.insert_channel("", vec![1.0; 4]).unwrap();
    assert!(write_exr(&path, &exr).is_err(), "an empty channel name is not valid EXR");
    assert_eq!(std::fs::read(&path).unwrap(), OLD);
    assert_eq!(names(&dir), ["keep.exr"]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_folder_at_the_path_or_a_file_above_it_is_refused_before_and_at_the_write() {
    let dir = temp_dir("refused");
    let file = dir.join("file.txt");
    std::fs::write(&file, OLD).unwrap();
    let under_file = file.join("x.exr");
    let folder = dir.join("folder.exr");
    std::fs::create_dir(&folder).unwrap();
    for bad in [&under_file, &folder] {
        let e = check_writable(bad).unwrap_err();
        assert!(matches!(e, IoError::Io { .. }) && e.to_string().contains(&*bad.to_string_lossy()), "{e}");
        assert!(write_exr(bad, &small_exr()).is_err(), "{}", bad.display());
    }
    assert!(check_writable(&folder).unwrap_err().to_string().contains("folder"));
    assert_eq!(std::fs::read(&file).unwrap(), OLD);
    assert!(folder.is_dir());
    assert_eq!(names(&dir), ["file.txt", "folder.exr"]);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn check_writable_accepts_new_and_existing_files_and_creates_nothing() {
    let dir = temp_dir("check");
    check_writable(dir.join("new.exr")).unwrap();
    std::fs::write(dir.join("old.exr"), OLD).unwrap();
    check_writable(dir.join("old.exr")).unwrap();
    assert_eq!(std::fs::read(dir.join("old.exr")).unwrap(), OLD);
    assert_eq!(names(&dir), ["old.exr"]);
    std::fs::remove_dir_all(&dir).ok();
}

#[cfg(unix)]
#[test]
fn a_link_to_a_file_is_kept_and_its_target_replaced() {
    let dir = temp_dir("link");
    let target = dir.join("real.exr");
    std::fs::write(&target, OLD).unwrap();
    let link = dir.join("link.exr");
    std::os::unix::fs::symlink("real.exr", &link).unwrap();
    write_exr(&link, &small_exr()).unwrap();
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink());
    assert_eq!(filtrace_io::read_exr(&target).unwrap().channel("R").unwrap(), &[0.25; 6]);
    // A dangling link: its target is created, the link stays.
    let dangling = dir.join("dangling.exr");
    std::os::unix::fs::symlink("made.exr", &dangling).unwrap();
    write_image(&dangling, &Image::filled(2, 2, 3, 1.0)).unwrap();
    assert!(std::fs::symlink_metadata(&dangling).unwrap().file_type().is_symlink());
    assert!(dir.join("made.exr").is_file());
    assert_eq!(names(&dir), ["dangling.exr", "link.exr", "made.exr", "real.exr"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// Before the fix a failed write to /dev/full (through a link here) removed the node.
#[cfg(target_os = "linux")]
#[test]
fn a_failed_write_to_a_device_removes_nothing() {
    use std::os::unix::fs::FileTypeExt;
    let dir = temp_dir("devfull");
    let link = dir.join("full.exr");
    std::os::unix::fs::symlink("/dev/full", &link).unwrap();
    check_writable(&link).unwrap();
    let e = write_exr(&link, &small_exr()).unwrap_err();
    assert!(e.to_string().contains("full.exr"), "{e}");
    assert!(std::fs::symlink_metadata(&link).unwrap().file_type().is_symlink(), "the link is kept");
    assert!(std::fs::metadata("/dev/full").unwrap().file_type().is_char_device());
    assert_eq!(names(&dir), ["full.exr"]);
    std::fs::remove_dir_all(&dir).ok();
}

/// Lets a reader blocked in opening `fifo` go (it sees the end of the data), whether or not
/// the writer under test opened it: a failing writer never hangs the test.
#[cfg(target_os = "linux")]
fn release_reader(fifo: &Path) {
    use std::os::unix::fs::OpenOptionsExt;
    const O_NONBLOCK: i32 = 0o4000; // Linux; without a waiting reader the open fails (ENXIO)
    let _ = std::fs::OpenOptions::new().write(true).custom_flags(O_NONBLOCK).open(fifo);
}

/// A named pipe is written in place (an EXR can be streamed to a reader) and never replaced,
/// also when the write fails.
#[cfg(target_os = "linux")]
#[test]
fn a_fifo_is_written_in_place_and_kept_on_failure() {
    use std::os::unix::fs::FileTypeExt;
    let dir = temp_dir("fifo");
    let fifo = dir.join("pipe.exr");
    let made = std::process::Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs");
    assert!(made.success());
    let reader_path = fifo.clone();
    let reader = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        std::fs::File::open(&reader_path).unwrap().read_to_end(&mut bytes).unwrap();
        bytes
    });
    let written = write_exr(&fifo, &small_exr());
    release_reader(&fifo);
    let bytes = reader.join().unwrap();
    written.unwrap();
    assert_eq!(&bytes[..4], &[0x76, 0x2f, 0x31, 0x01], "EXR magic number");
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo());

    let reader_path = fifo.clone();
    let reader = std::thread::spawn(move || {
        let mut bytes = Vec::new();
        std::fs::File::open(&reader_path).unwrap().read_to_end(&mut bytes).unwrap();
    });
    let failed = write_atomic(&fifo, |_| Err::<(), _>(io::Error::other("no")));
    release_reader(&fifo);
    assert!(failed.is_err());
    reader.join().unwrap();
    assert!(std::fs::metadata(&fifo).unwrap().file_type().is_fifo(), "the FIFO is kept");
    assert_eq!(names(&dir), ["pipe.exr"]);
    std::fs::remove_dir_all(&dir).ok();
}
