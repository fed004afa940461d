//! `filtrace view` in a real window under Xvfb (Mesa's software OpenGL), driven by xdotool
//! and by the window manager's close message, as a person would use it:
//!
//! - the screenshot after N still frames is `filtrace render`'s PNG for the same camera,
//!   samples and seed (the film is the same bits; only the window's 8-bit path could differ);
//! - a mouse drag moves the camera where [`filtrace_viewer::camera::orbit`] says, and the
//!   image is then `filtrace render`'s from that camera;
//! - a layer key shows that layer; Escape and WM_DELETE_WINDOW close the window, exit 0;
//! - a scene that fails to load shows its error in the window and on stderr (exit 1); a
//!   reload of a broken file keeps the last good scene.
//!
//! Each test starts its own Xvfb on a free display. Without Xvfb or xdotool the tests print
//! SKIP, unless the environment has CI set: then they fail (`.ci/run` installs both).

use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

use filtrace_viewer::camera::{format_camera, orbit, parse_camera};

fn bin() -> Command {
    Command::new(env!("CARGO_BIN_EXE_filtrace"))
}

fn temp_dir(tag: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("filtrace-view-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn have(tool: &str) -> bool {
    Command::new("sh").args(["-c", &format!("command -v {tool}")]).output().is_ok_and(|o| o.status.success())
}

/// An Xvfb server of its own; killed on drop.
struct Xvfb {
    child: Child,
    display: String,
}

impl Xvfb {
    /// `None` (after printing SKIP) when Xvfb or xdotool is missing and CI is not set.
    fn start(test: &str) -> Option<Xvfb> {
        let missing: Vec<_> = ["Xvfb", "xdotool"].into_iter().filter(|t| !have(t)).collect();
        if !missing.is_empty() {
            assert!(
                std::env::var_os("CI").is_none(),
                "{test}: {} missing (CI must install them: .ci/run)",
                missing.join(" and ")
            );
            eprintln!("SKIP {test}: {} not installed (apt-get install xvfb xdotool)", missing.join(" and "));
            return None;
        }
        for n in 0..50 {
            let num = 200 + (std::process::id() as usize * 7 + n * 13 + test.len() * 31) % 700;
            if Path::new(&format!("/tmp/.X11-unix/X{num}")).exists()
                || Path::new(&format!("/tmp/.X{num}-lock")).exists()
            {
                continue;
            }
            let display = format!(":{num}");
            let mut child = Command::new("Xvfb")
                .args([display.as_str(), "-screen", "0", "1280x1024x24", "-nolisten", "tcp"])
                .stdout(Stdio::null())
                .stderr(Stdio::null())
                .spawn()
                .expect("Xvfb starts");
            let until = Instant::now() + Duration::from_secs(10);
            while Instant::now() < until {
                if Path::new(&format!("/tmp/.X11-unix/X{num}")).exists() {
                    return Some(Xvfb { child, display });
                }
                if child.try_wait().ok().flatten().is_some() {
                    break; // lost a race for this display number
                }
                std::thread::sleep(Duration::from_millis(50));
            }
            let _ = child.kill();
            let _ = child.wait();
        }
        panic!("{test}: no free X display for Xvfb");
    }

    fn cmd(&self, program: &str) -> Command {
        let mut c = Command::new(program);
        // One image pixel per screen pixel whatever DPI the X server reports.
        c.env("DISPLAY", &self.display).env_remove("WAYLAND_DISPLAY").env("WINIT_X11_SCALE_FACTOR", "1");
        c
    }

    /// Presses `key` in `window` (given the keyboard focus first: there is no window
    /// manager to give it).
    fn key(&self, window: &str, key: &str) {
        self.xdotool(&["windowfocus", "--sync", window]);
        self.xdotool(&["key", key]);
    }

    fn xdotool(&self, args: &[&str]) -> String {
        // `search --sync` and `windowfocus --sync` wait for ever if the window never comes.
        let o = self.cmd("timeout").arg("30").arg("xdotool").args(args).output().expect("xdotool runs");
        assert!(o.status.success(), "xdotool {args:?}: {}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stdout).trim().to_string()
    }
}

impl Drop for Xvfb {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// A running `filtrace view` whose stderr lines are collected.
struct Viewer {
    child: Child,
    lines: Arc<Mutex<Vec<String>>>,
}

impl Viewer {
    fn start(x: &Xvfb, args: &[&str]) -> Viewer {
        let mut c = x.cmd(env!("CARGO_BIN_EXE_filtrace"));
        let mut child = c
            .arg("view")
            .args(args)
            .stdout(Stdio::null())
            .stderr(Stdio::piped())
            .spawn()
            .expect("view starts");
        let lines = Arc::new(Mutex::new(Vec::new()));
        let (l, err) = (lines.clone(), child.stderr.take().unwrap());
        std::thread::spawn(move || {
            for line in BufReader::new(err).lines().map_while(Result::ok) {
                l.lock().unwrap().push(line);
            }
        });
        Viewer { child, lines }
    }

    fn stderr(&self) -> String {
        self.lines.lock().unwrap().join("\n")
    }

    /// The first stderr line after `from` lines that satisfies `pred`; fails after 60 s.
    fn wait_line(&mut self, from: usize, what: &str, pred: impl Fn(&str) -> bool) -> (usize, String) {
        let until = Instant::now() + Duration::from_secs(60);
        loop {
            {
                let lines = self.lines.lock().unwrap();
                if let Some((i, l)) = lines.iter().enumerate().skip(from).find(|(_, l)| pred(l)) {
                    return (i + 1, l.clone());
                }
            }
            if let Ok(Some(status)) = self.child.try_wait() {
                std::thread::sleep(Duration::from_millis(200));
                panic!("viewer exited ({status}) while waiting for {what}:\n{}", self.stderr());
            }
            assert!(Instant::now() < until, "no {what} within 60 s:\n{}", self.stderr());
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    /// Waits for the exit (at most 20 s) and returns its code.
    fn wait_exit(&mut self) -> i32 {
        let until = Instant::now() + Duration::from_secs(20);
        loop {
            if let Some(status) = self.child.try_wait().unwrap() {
                std::thread::sleep(Duration::from_millis(100)); // the reader takes the last lines
                return status.code().unwrap_or(-1);
            }
            if Instant::now() > until {
                let _ = self.child.kill();
                panic!("the viewer did not exit within 20 s:\n{}", self.stderr());
            }
            std::thread::sleep(Duration::from_millis(20));
        }
    }

    fn window(&self, x: &Xvfb) -> String {
        let pid = self.child.id().to_string();
        x.xdotool(&["search", "--sync", "--onlyvisible", "--pid", &pid, "--name", "filtrace view"])
            .lines()
            .next()
            .expect("a window")
            .to_string()
    }
}

impl Drop for Viewer {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn rgb(path: &Path) -> image::RgbImage {
    image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgb8()
}

/// Largest channel difference of two images of one size.
fn max_diff(a: &image::RgbImage, b: &image::RgbImage) -> u8 {
    assert_eq!(a.dimensions(), b.dimensions(), "image sizes");
    a.as_raw().iter().zip(b.as_raw()).map(|(x, y)| x.abs_diff(*y)).max().unwrap_or(0)
}

/// `filtrace render` of `scene` to `dir/name.exr` (+ .png).
fn render(scene: &str, dir: &Path, name: &str, args: &[&str]) -> PathBuf {
    let out = dir.join(format!("{name}.exr"));
    let o = bin().args(["render", scene, "--out"]).arg(&out).args(args).output().unwrap();
    assert!(o.status.success(), "render: {}", String::from_utf8_lossy(&o.stderr));
    out
}

/// A small TOML scene (a box on a floor under a quad light) with `camera`.
fn scene_toml(camera: &str) -> String {
    let v: Vec<&str> = camera.split(',').collect();
    format!(
        "[camera]\neye = [{}, {}, {}]\ntarget = [{}, {}, {}]\nup = [{}, {}, {}]\nvfov = {}\n\n\
         [[materials]]\nname = \"red\"\ntype = \"diffuse\"\ncolor = [0.7, 0.2, 0.1]\n\n\
         [[objects]]\nshape = \"quad\"\ntransform = {{ scale = 6 }}\n\n\
         [[objects]]\nshape = \"cube\"\nmaterial = \"red\"\ntransform = {{ translate = [0, 0.5, 0], rotate = {{ deg = 30, axis = [0, 1, 0] }} }}\n\n\
         [[lights]]\ntype = \"quad\"\ncorner = [-1, 3, -1]\nedge1 = [0, 0, 2]\nedge2 = [2, 0, 0]\nradiance = [6, 6, 6]\n\n\
         [[lights]]\ntype = \"sky\"\n",
        v[0], v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9]
    )
}

const START_CAMERA: &str = "2.5,2,-3.5,0,0.5,0,0,1,0,40";
const TINY: &[&str] = &["--res", "48x40", "--max-depth", "4", "--seed", "7", "--threads", "2"];

#[test]
fn screenshot_after_n_still_frames_equals_the_render_png() {
    let Some(x) = Xvfb::start("screenshot_after_n_still_frames_equals_the_render_png") else { return };
    let dir = temp_dir("shot");
    let shot = dir.join("shot.png");
    let mut v = Viewer::start(
        &x,
        &[
            &["cornell", "--frames", "3", "--spp-per-frame", "2", "--no-overlay", "--screenshot"],
            &[shot.to_str().unwrap()][..],
            TINY,
        ]
        .concat(),
    );
    assert_eq!(v.wait_exit(), 0, "{}", v.stderr());
    let png = render("cornell", &dir, "ref", &[&["--spp", "6"], TINY].concat()).with_extension("png");
    let (a, b) = (rgb(&shot), rgb(&png));
    assert_eq!(a.dimensions(), (48, 40));
    assert!(max_diff(&a, &b) <= 1, "screenshot differs from the render by {}", max_diff(&a, &b));
    assert!(a.as_raw().iter().any(|&c| c > 30), "a black screenshot");
}

#[test]
fn a_mouse_drag_orbits_the_camera_to_where_a_render_agrees() {
    let Some(x) = Xvfb::start("a_mouse_drag_orbits_the_camera_to_where_a_render_agrees") else { return };
    let dir = temp_dir("drag");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, scene_toml(START_CAMERA)).unwrap();
    let args = [
        &[
            scene.to_str().unwrap(),
            "--spp-per-frame",
            "4",
            "--max-spp",
            "4",
            "--log-frames",
            "--no-overlay",
            "--out-dir",
            dir.to_str().unwrap(),
        ][..],
        TINY,
    ]
    .concat();
    let mut v = Viewer::start(&x, &args);
    let (seen, first) = v.wait_line(0, "the first still frame", |l| l.contains("kind=still spp=4"));
    let image_at = first
        .split("image=")
        .nth(1)
        .expect("frame line names the image position")
        .split_whitespace()
        .next()
        .unwrap()
        .to_string();
    let (ix, iy) = image_at.split_once(',').unwrap();
    let (x0, y0) = (ix.parse::<i32>().unwrap() + 10, iy.parse::<i32>().unwrap() + 10);
    let w = v.window(&x);
    x.xdotool(&["mousemove", "--window", &w, &x0.to_string(), &y0.to_string()]);
    x.xdotool(&["mousedown", "1"]);
    x.xdotool(&["mousemove", "--window", &w, &(x0 + 30).to_string(), &(y0 + 10).to_string()]);
    x.xdotool(&["mouseup", "1"]);
    let (seen, moved) = v.wait_line(seen, "a still frame from the moved camera", |l| {
        l.contains("kind=still spp=4")
            && !l.contains(&format!("camera={}", format_camera(&parse_camera(START_CAMERA).unwrap())))
    });
    let logged = parse_camera(moved.split("camera=").nth(1).unwrap()).unwrap();
    let want = orbit(&parse_camera(START_CAMERA).unwrap(), 30.0, 10.0);
    assert!((logged.eye - want.eye).length() < 1e-4, "camera {logged:?}, expected {want:?}");
    assert_eq!(logged.target, want.target);
    x.key(&w, "F12");
    let (_, saved) = v.wait_line(seen, "the screenshot", |l| l.contains("saved screenshot"));
    let shot = PathBuf::from(saved.rsplit("saved screenshot ").next().unwrap());
    x.key(&w, "Escape");
    assert_eq!(v.wait_exit(), 0, "{}", v.stderr());
    // The same scene from the camera the drag gave, rendered by `filtrace render`.
    let moved_scene = dir.join("moved.toml");
    std::fs::write(&moved_scene, scene_toml(&format_camera(&logged))).unwrap();
    let png = render(moved_scene.to_str().unwrap(), &dir, "moved", &[&["--spp", "4"], TINY].concat())
        .with_extension("png");
    let start_png = render(scene.to_str().unwrap(), &dir, "start", &[&["--spp", "4"], TINY].concat())
        .with_extension("png");
    let (a, b) = (rgb(&shot), rgb(&png));
    assert!(max_diff(&a, &b) <= 1, "screenshot vs render from the expected camera: {}", max_diff(&a, &b));
    assert!(max_diff(&a, &rgb(&start_png)) > 10, "the image did not change with the camera");
}

#[test]
fn a_layer_key_shows_that_layer() {
    let Some(x) = Xvfb::start("a_layer_key_shows_that_layer") else { return };
    let dir = temp_dir("layer");
    let args = [
        &[
            "cornell",
            "--spp-per-frame",
            "1",
            "--max-spp",
            "1",
            "--log-frames",
            "--no-overlay",
            "--out-dir",
            dir.to_str().unwrap(),
        ][..],
        TINY,
    ]
    .concat();
    let mut v = Viewer::start(&x, &args);
    let (seen, _) =
        v.wait_line(0, "the first frame", |l| l.contains("kind=still spp=1") && l.contains("layer=colour"));
    let w = v.window(&x);
    x.key(&w, "5");
    let (seen, _) = v.wait_line(seen, "the normal layer", |l| l.contains("layer=normal"));
    x.key(&w, "F12");
    let (_, saved) = v.wait_line(seen, "the screenshot", |l| l.contains("saved screenshot"));
    x.key(&w, "Escape");
    assert_eq!(v.wait_exit(), 0);
    let shot = rgb(Path::new(saved.rsplit("saved screenshot ").next().unwrap()));
    let exr = render("cornell", &dir, "ref", &[&["--spp", "1"], TINY].concat());
    let normal = filtrace_io::read_exr(&exr).unwrap().layer(&["normal"]).unwrap();
    let want = image::RgbImage::from_fn(48, 40, |px, py| {
        let n = normal.pixel(px as usize, py as usize);
        image::Rgb(std::array::from_fn(|k| ((0.5 + 0.5 * n[k]).clamp(0.0, 1.0) * 255.0).round() as u8))
    });
    assert!(max_diff(&shot, &want) <= 1, "normal layer differs by {}", max_diff(&shot, &want));
}

/// Starts a viewer, waits for its first frame and returns it with its window.
fn started(x: &Xvfb, tag: &str) -> (Viewer, String) {
    let dir = temp_dir(tag);
    let args =
        [&["cornell", "--max-spp", "1000000", "--log-frames", "--out-dir", dir.to_str().unwrap()][..], TINY]
            .concat();
    let mut v = Viewer::start(x, &args);
    v.wait_line(0, "the first frame", |l| l.contains("kind=still"));
    let w = v.window(x);
    (v, w)
}

#[test]
fn escape_closes_the_window_and_the_process() {
    let Some(x) = Xvfb::start("escape_closes_the_window_and_the_process") else { return };
    let (mut v, w) = started(&x, "escape");
    x.key(&w, "Escape");
    assert_eq!(v.wait_exit(), 0, "{}", v.stderr());
    assert!(v.stderr().contains("filtrace view: closed"), "{}", v.stderr());
}

#[test]
fn the_window_managers_close_closes_the_window_and_the_process() {
    let Some(x) = Xvfb::start("the_window_managers_close_closes_the_window_and_the_process") else { return };
    let (mut v, w) = started(&x, "wmclose");
    send_wm_delete(&x.display, w.parse().unwrap());
    assert_eq!(v.wait_exit(), 0, "{}", v.stderr());
    assert!(v.stderr().contains("filtrace view: closed"), "{}", v.stderr());
}

/// What a window manager sends when the user clicks the close button: a ClientMessage
/// WM_PROTOCOLS / WM_DELETE_WINDOW to the window.
fn send_wm_delete(display: &str, window: u32) {
    use x11rb::protocol::xproto::{ClientMessageEvent, ConnectionExt, EventMask};
    let (conn, _) = x11rb::connect(Some(display)).expect("connect to Xvfb");
    let atom = |name: &str| conn.intern_atom(false, name.as_bytes()).unwrap().reply().unwrap().atom;
    let (protocols, delete) = (atom("WM_PROTOCOLS"), atom("WM_DELETE_WINDOW"));
    let event = ClientMessageEvent::new(32, window, protocols, [delete, 0, 0, 0, 0]);
    conn.send_event(false, window, EventMask::NO_EVENT, event)
        .unwrap()
        .check()
        .expect("the X server took the event");
}

#[test]
fn a_scene_that_fails_to_load_shows_the_error_in_the_window_and_on_stderr() {
    let Some(x) = Xvfb::start("a_scene_that_fails_to_load_shows_the_error_in_the_window_and_on_stderr")
    else {
        return;
    };
    let dir = temp_dir("broken");
    let scene = dir.join("broken.toml");
    std::fs::write(
        &scene,
        "[camera]\neye = [0, 0, 1]\ntarget = [0, 0, 0]\n\n[[objects]]\nshape = \"torus\"\n",
    )
    .unwrap();
    let shot = dir.join("error.png");
    let mut v = Viewer::start(
        &x,
        &[&[scene.to_str().unwrap(), "--frames", "1", "--screenshot"], &[shot.to_str().unwrap()][..], TINY]
            .concat(),
    );
    let code = v.wait_exit();
    let err = v.stderr();
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("broken.toml") && err.contains("torus"), "{err}");
    // The window showed the message: the image area is not plain black.
    let img = rgb(&shot);
    assert!(img.as_raw().iter().filter(|&&c| c > 60).count() > 20, "no error text in the window");
}

#[test]
fn a_reload_with_a_broken_file_keeps_the_last_good_scene() {
    let Some(x) = Xvfb::start("a_reload_with_a_broken_file_keeps_the_last_good_scene") else { return };
    let dir = temp_dir("reload");
    let scene = dir.join("scene.toml");
    std::fs::write(&scene, scene_toml(START_CAMERA)).unwrap();
    let args = [
        &[scene.to_str().unwrap(), "--spp-per-frame", "1", "--max-spp", "2", "--log-frames", "--no-overlay"]
            [..],
        TINY,
    ]
    .concat();
    let mut v = Viewer::start(&x, &args);
    let (seen, _) = v.wait_line(0, "the first frame", |l| l.contains("kind=still"));
    std::fs::write(&scene, format!("{}\n[[objects]]\nshape = \"torus\"\n", scene_toml(START_CAMERA)))
        .unwrap();
    let (seen, e) = v.wait_line(seen, "the reload error", |l| l.contains("cannot load scene"));
    assert!(e.contains("scene.toml") && e.contains("keeping the last good scene"), "{e}");
    // A good file with another camera is taken, and its camera with it.
    let other = "0,3,-4,0,0.5,0,0,1,0,50";
    std::fs::write(&scene, scene_toml(other)).unwrap();
    let (seen, _) = v.wait_line(seen, "the reload", |l| l.contains("reloaded"));
    let want = format!("camera={}", format_camera(&parse_camera(other).unwrap()));
    v.wait_line(seen, "a frame of the new camera", |l| l.contains("kind=still") && l.contains(&want));
    let w = v.window(&x);
    x.key(&w, "Escape");
    assert_eq!(v.wait_exit(), 0, "{}", v.stderr());
}

/// The PNG (or EXR) `filtrace render --frame N --out dir/name.exr` writes for frame `n`.
fn frame_file(dir: &Path, name: &str, n: u32, ext: &str) -> PathBuf {
    dir.join(format!("{name}.{n:04}.{ext}"))
}

#[test]
fn a_frame_of_an_animation_equals_the_render_of_that_frame() {
    let Some(x) = Xvfb::start("a_frame_of_an_animation_equals_the_render_of_that_frame") else { return };
    let dir = temp_dir("anim-frame");
    let shot = dir.join("shot.png");
    let mut v = Viewer::start(
        &x,
        &[
            &["cornell-anim", "--frame", "5", "--frames", "2", "--spp-per-frame", "2", "--no-overlay"],
            &["--screenshot", shot.to_str().unwrap()][..],
            TINY,
        ]
        .concat(),
    );
    assert_eq!(v.wait_exit(), 0, "{}", v.stderr());
    render("cornell-anim", &dir, "ref", &[&["--frame", "5", "--spp", "4"], TINY].concat());
    let (a, b) = (rgb(&shot), rgb(&frame_file(&dir, "ref", 5, "png")));
    assert!(max_diff(&a, &b) <= 1, "screenshot differs from frame 5's render by {}", max_diff(&a, &b));
    // Frame 5 is not frame 0: the animation moved the camera and the light.
    render("cornell-anim", &dir, "first", &[&["--frame", "0", "--spp", "4"], TINY].concat());
    assert!(max_diff(&a, &rgb(&frame_file(&dir, "first", 0, "png"))) > 10, "frame 5 looks like frame 0");
}

#[test]
fn arrow_keys_step_the_animation_space_plays_it_and_the_motion_layer_shows_the_step() {
    let Some(x) = Xvfb::start("arrow_keys_step_the_animation_space_plays_it") else { return };
    let dir = temp_dir("anim-keys");
    let args = [
        &["cornell-anim", "--frame", "3", "--spp-per-frame", "1", "--max-spp", "1", "--log-frames"][..],
        &["--no-overlay", "--out-dir", dir.to_str().unwrap()],
        TINY,
    ]
    .concat();
    let mut v = Viewer::start(&x, &args);
    let still_at =
        |n: i64| move |l: &str| l.contains("kind=still") && l.contains(&format!("anim_frame={n} "));
    let (seen, _) = v.wait_line(0, "a still frame of frame 3", still_at(3));
    let w = v.window(&x);
    x.key(&w, "Right");
    let (seen, _) = v.wait_line(seen, "a still frame of frame 4", still_at(4));
    // Key 0: the motion layer, which after the step points from frame 4 back to frame 3.
    x.key(&w, "0");
    let (seen, _) = v.wait_line(seen, "the motion layer", |l| l.contains("layer=motion anim_frame=4 "));
    x.key(&w, "F12");
    let (seen, saved) = v.wait_line(seen, "the screenshot", |l| l.contains("saved screenshot"));
    // Space: playback, filtered frames of later frames.
    x.key(&w, "space");
    v.wait_line(seen, "a moving frame of a later frame", |l| {
        l.contains("kind=moving") && !l.contains("anim_frame=4 ") && !l.contains("anim_frame=3 ")
    });
    x.key(&w, "Escape");
    assert_eq!(v.wait_exit(), 0, "{}", v.stderr());
    let shot = rgb(Path::new(saved.rsplit("saved screenshot ").next().unwrap()));
    render("cornell-anim", &dir, "ref", &[&["--frame", "4", "--spp", "1"], TINY].concat());
    let exr = filtrace_io::read_exr(frame_file(&dir, "ref", 4, "exr")).unwrap();
    let motion = exr.layer(&["motion"]).unwrap();
    assert!(motion.data().iter().any(|m| m.abs() > 0.01), "the camera moves between frames 3 and 4");
    let tonemap = filtrace_io::TonemapParams::srgb_clamp();
    let want = filtrace_viewer::layers::to_rgb8(&motion, filtrace_viewer::layers::Display::Motion, &tonemap);
    let want = image::RgbImage::from_raw(48, 40, want).unwrap();
    assert!(max_diff(&shot, &want) <= 1, "motion layer differs by {}", max_diff(&shot, &want));
}

#[test]
fn the_many_light_renderer_shows_the_vpl_render() {
    let Some(x) = Xvfb::start("the_many_light_renderer_shows_the_vpl_render") else { return };
    let dir = temp_dir("vpl");
    let shot = dir.join("shot.png");
    let mut v = Viewer::start(
        &x,
        &[
            &["cornell", "--integrator", "vpl", "--frames", "1", "--spp-per-frame", "2", "--no-overlay"],
            &["--screenshot", shot.to_str().unwrap()][..],
            TINY,
        ]
        .concat(),
    );
    assert_eq!(v.wait_exit(), 0, "{}", v.stderr());
    let png = render("cornell", &dir, "ref", &[&["--integrator", "vpl", "--spp", "2"], TINY].concat())
        .with_extension("png");
    let (a, b) = (rgb(&shot), rgb(&png));
    assert!(max_diff(&a, &b) <= 1, "screenshot differs from the VPL render by {}", max_diff(&a, &b));
    assert!(a.as_raw().iter().any(|&c| c > 30), "a black screenshot");
}
