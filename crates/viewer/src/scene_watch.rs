//! Loading the scene off the UI thread, and loading it again when its file changes on disk.
//!
//! The file's modification time and size are looked at every [`POLL`] (a `stat`, cheap on
//! the UI thread); a change starts a load on a thread. A load that fails keeps the last
//! good scene and reports the error (the window shows it, stderr prints it); the next
//! change of the file is tried again. A built-in scene name has no file to watch.

use std::path::PathBuf;
use std::sync::mpsc::{self, Receiver, TryRecvError};
use std::time::{Duration, Instant, SystemTime};

use filtrace_scene::{LoadOptions, Scene};

/// How often the file is looked at.
pub const POLL: Duration = Duration::from_millis(250);

/// What a poll brought.
pub enum SceneEvent {
    /// A scene loaded (the first one, or a reload).
    Loaded(Box<Scene>),
    /// A load failed: the message names file and line where the loader knows them.
    Failed(String),
}

/// The scene argument and the state of its loading.
pub struct SceneWatch {
    arg: String,
    options: LoadOptions,
    /// The file, when the argument is one.
    path: Option<PathBuf>,
    stamp: Option<(SystemTime, u64)>,
    loading: Option<Receiver<Result<Scene, String>>>,
    last_poll: Instant,
    /// Scenes loaded so far (0: none yet).
    pub loads: u32,
}

impl SceneWatch {
    /// Starts loading `arg` (a built-in name or a file).
    pub fn start(arg: &str, options: LoadOptions) -> Self {
        let is_builtin = filtrace_scene::builtin_names().contains(&arg);
        let path = (!is_builtin).then(|| PathBuf::from(arg));
        let mut w = Self {
            arg: arg.to_string(),
            options,
            path,
            stamp: None,
            loading: None,
            last_poll: Instant::now(),
            loads: 0,
        };
        w.stamp = w.current_stamp();
        w.spawn_load();
        w
    }

    /// True while a load runs.
    pub fn is_loading(&self) -> bool {
        self.loading.is_some()
    }

    /// Call every UI frame: a finished load, or `None`. Starts a reload when the file changed.
    pub fn poll(&mut self) -> Option<SceneEvent> {
        if let Some(rx) = &self.loading {
            return match rx.try_recv() {
                Ok(result) => {
                    self.loading = None;
                    Some(match result {
                        Ok(scene) => {
                            self.loads += 1;
                            SceneEvent::Loaded(Box::new(scene))
                        }
                        Err(e) => SceneEvent::Failed(e),
                    })
                }
                Err(TryRecvError::Empty) => None,
                Err(TryRecvError::Disconnected) => {
                    self.loading = None;
                    Some(SceneEvent::Failed(format!("loading '{}' stopped unexpectedly", self.arg)))
                }
            };
        }
        if self.path.is_some() && self.last_poll.elapsed() >= POLL {
            self.last_poll = Instant::now();
            let stamp = self.current_stamp();
            if stamp != self.stamp {
                self.stamp = stamp;
                self.spawn_load();
            }
        }
        None
    }

    fn current_stamp(&self) -> Option<(SystemTime, u64)> {
        let m = std::fs::metadata(self.path.as_ref()?).ok()?;
        Some((m.modified().ok()?, m.len()))
    }

    fn spawn_load(&mut self) {
        let (tx, rx) = mpsc::channel();
        let (arg, options) = (self.arg.clone(), self.options.clone());
        let spawned = std::thread::Builder::new().name("filtrace-view-load".into()).spawn(move || {
            let result = filtrace_scene::load_scene_with(&arg, &options)
                .map_err(|e| format!("cannot load scene '{arg}': {e}"));
            let _ = tx.send(result);
        });
        self.loading = spawned.is_ok().then_some(rx);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn wait(w: &mut SceneWatch) -> SceneEvent {
        let until = Instant::now() + Duration::from_secs(20);
        loop {
            if let Some(e) = w.poll() {
                return e;
            }
            assert!(Instant::now() < until, "no load event in 20 s");
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    #[test]
    fn a_changed_file_is_loaded_again_and_a_broken_one_reports_its_line() {
        let dir = std::env::temp_dir().join(format!("filtrace-view-watch-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let file = dir.join("s.toml");
        let good =
            "[[objects]]\nshape = \"cube\"\n[[lights]]\ntype = \"environment\"\nradiance = [1, 1, 1]\n";
        std::fs::write(&file, good).unwrap();
        let mut w = SceneWatch::start(file.to_str().unwrap(), LoadOptions::default());
        assert!(matches!(wait(&mut w), SceneEvent::Loaded(_)));
        std::fs::write(&file, format!("{good}\n[[objects]]\nshape = \"torus\"\n")).unwrap();
        match wait(&mut w) {
            SceneEvent::Failed(e) => assert!(e.contains("s.toml") && e.contains("torus"), "{e}"),
            SceneEvent::Loaded(_) => panic!("a broken file loaded"),
        }
        std::fs::write(&file, format!("{good}\n")).unwrap();
        assert!(matches!(wait(&mut w), SceneEvent::Loaded(_)));
        assert_eq!(w.loads, 2);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn a_builtin_scene_loads_and_is_not_watched() {
        let mut w = SceneWatch::start("cornell", LoadOptions::default());
        assert!(matches!(wait(&mut w), SceneEvent::Loaded(_)));
        assert!(w.path.is_none());
    }
}
