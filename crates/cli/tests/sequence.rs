//! `filtrace render --frames A..B` / `--frame N` end to end: numbered EXR + PNG files and a
//! preview animation, a still scene's frame equal to its still render bit for bit, `--json`
//! lines, `--resume`, Ctrl-C and bad frame ranges (docs/animation.md).

#[path = "support/run.rs"]
mod run;

use run::*;
use std::io::BufReader;
use std::path::{Path, PathBuf};
use std::process::Output;
use std::time::Duration;

fn temp_dir(tag: &str) -> PathBuf {
    fresh_dir(&format!("seq-{tag}"))
}

/// `filtrace render SCENE --res 16x12 --spp 2 --threads 2 EXTRA --out OUT`.
fn render(scene: &str, extra: &[&str], out: &Path) -> Output {
    let base = ["render", scene, "--res", "16x12", "--spp", "2", "--threads", "2", "--max-depth", "4"];
    bin().args(base).args(extra).arg("--out").arg(out).output().expect("the filtrace binary runs")
}

/// Size of the PNG at `path`, decoded whole.
fn png_size(path: &Path) -> (u32, u32) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut reader = png::Decoder::new(BufReader::new(file)).read_info().unwrap();
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    let info = reader.next_frame(&mut buf).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    (info.width, info.height)
}

/// Frames and size of the APNG at `path`, every frame decoded.
fn preview_frames(path: &Path) -> (u32, u32, u32) {
    let file = std::fs::File::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut reader = png::Decoder::new(BufReader::new(file)).read_info().unwrap();
    let (w, h) = (reader.info().width, reader.info().height);
    let frames = reader.info().animation_control().expect("an animated PNG").num_frames;
    let mut buf = vec![0; reader.output_buffer_size().unwrap()];
    for k in 0..frames {
        reader.next_frame(&mut buf).unwrap_or_else(|e| panic!("frame {k} of {}: {e}", path.display()));
    }
    (frames, w, h)
}

#[test]
fn a_still_scene_rendered_as_frame_n_is_bit_identical_to_the_still_render() {
    let dir = temp_dir("still");
    for (scene, mode, frame) in [
        ("cornell", &[][..], "7"),
        ("cornell", &["--filter", "atrous"][..], "3"),
        ("cornell", &["--adaptive", "--budget-spp", "1"][..], "2"),
        // Frame 0 of an animated built-in is its rest pose, the still render.
        ("cornell-anim", &[][..], "0"),
    ] {
        ok(render(scene, mode, &dir.join("still.exr")));
        let args: Vec<&str> = mode.iter().copied().chain(["--frame", frame]).collect();
        ok(render(scene, &args, &dir.join("seq.exr")));
        let numbered = dir.join(format!("seq.{:0>4}.exr", frame));
        assert_eq!(channel_bits(&numbered), channel_bits(&dir.join("still.exr")), "{scene} {mode:?}");
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn frames_are_numbered_files_with_a_preview_and_json_lines() {
    let dir = temp_dir("files");
    let out = dir.join("shot.exr");
    let o = ok(render("cornell-anim", &["--frames", "2..4", "--json"], &out));
    let lines = json_lines(&o);
    assert_eq!(lines.len(), 4, "one line per frame and the summary");
    for (k, line) in lines[..3].iter().enumerate() {
        let frame = 2 + k as u64;
        assert_eq!((line["kind"].as_str(), line["frame"].as_u64()), (Some("frame"), Some(frame)));
        assert_eq!(line["resumed"], false);
        assert!((line["time_s"].as_f64().unwrap() - frame as f64 / 24.0).abs() < 1e-9);
        for key in ["spp_done", "render_s", "mean_rgb", "build_s", "cancelled"] {
            assert!(line.get(key).is_some(), "frame line lacks '{key}': {line}");
        }
        let exr = dir.join(format!("shot.{frame:04}.exr"));
        assert_eq!(line["output"].as_str(), Some(exr.to_str().unwrap()));
        let image = filtrace_io::read_exr(&exr).unwrap();
        assert_eq!(image.attribute("filtrace:frame"), Some(frame.to_string().as_str()));
        assert_eq!(image.attribute("filtrace:cancelled"), Some("false"));
        assert!(image.layer(&["color"]).unwrap().mean()[0] > 0.0, "frame {frame} is black");
        assert_eq!(png_size(&exr.with_extension("png")), (16, 12));
    }
    let last = &lines[3];
    assert_eq!(last["kind"], "sequence");
    assert_eq!(last["rendered"], serde_json::json!([2, 3, 4]));
    assert_eq!(last["cancelled"], false);
    assert_eq!(preview_frames(&dir.join("shot.preview.png")), (3, 16, 12));
    // The light and camera move: no two frames are the same image.
    let (a, b) = (channel_bits(&dir.join("shot.0002.exr")), channel_bits(&dir.join("shot.0004.exr")));
    assert_ne!(a, b);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn filtered_and_adaptive_sequences_write_every_frame() {
    let dir = temp_dir("filtered");
    for (tag, mode) in [("f", &["--filter", "guided"][..]), ("a", &["--adaptive", "--budget-spp", "1"][..])] {
        let out = dir.join(format!("{tag}.exr"));
        let args: Vec<&str> = mode.iter().copied().chain(["--frames", "0..2"]).collect();
        ok(render("classroom", &args, &out));
        for frame in 0..3 {
            let exr = filtrace_io::read_exr(dir.join(format!("{tag}.{frame:04}.exr"))).unwrap();
            assert!(
                exr.layer(&["filtered"]).is_some(),
                "{mode:?}: frame {frame} lacks the pipeline's layers"
            );
        }
        assert_eq!(preview_frames(&dir.join(format!("{tag}.preview.png"))).0, 3);
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn filtered_sequence_frames_carry_the_motion_layers_of_the_plain_frames() {
    // The motion AOV depends on the camera and the instances only, not on the integrator:
    // filtered (and adaptive) frames of an animation write the layers the plain frames
    // write, with the same values, and the camera move makes them non-zero.
    let dir = temp_dir("motion");
    ok(render("cornell-anim", &["--frames", "1..2"], &dir.join("plain.exr")));
    let channels =
        ["motion.X", "motion.Y", "prev_depth.Z", "prev_normal.X", "prev_normal.Y", "prev_normal.Z"];
    for (tag, mode) in [("f", &["--filter", "guided"][..]), ("a", &["--adaptive", "--budget-spp", "1"][..])] {
        let args: Vec<&str> = mode.iter().copied().chain(["--frames", "1..2"]).collect();
        ok(render("cornell-anim", &args, &dir.join(format!("{tag}.exr"))));
        for frame in 1..3 {
            let plain = filtrace_io::read_exr(dir.join(format!("plain.{frame:04}.exr"))).unwrap();
            let filtered = filtrace_io::read_exr(dir.join(format!("{tag}.{frame:04}.exr"))).unwrap();
            for ch in channels {
                let got = filtered.channel(ch).unwrap_or_else(|| {
                    panic!("{mode:?}: frame {frame} lacks {ch}: {:?}", filtered.channel_names())
                });
                let want = plain.channel(ch).unwrap();
                let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
                assert_eq!(bits(got), bits(want), "{mode:?}: frame {frame}, {ch}");
            }
            let motion = filtered.channel("motion.X").unwrap();
            assert!(motion.iter().any(|&m| m != 0.0), "{mode:?}: frame {frame}: the camera moves");
        }
    }
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn resume_keeps_finished_frames_and_renders_missing_corrupt_or_different_ones_again() {
    let dir = temp_dir("resume");
    let out = dir.join("r.exr");
    ok(render("cornell-anim", &["--frames", "0..3"], &out));
    let frame = |k: u32| dir.join(format!("r.{k:04}.exr"));
    let originals: Vec<_> = (0..4).map(|k| channel_bits(&frame(k))).collect();
    // Frame 1 truncated, frame 2's PNG gone, frame 3's EXR replaced by garbage.
    let bytes = std::fs::read(frame(1)).unwrap();
    std::fs::write(frame(1), &bytes[..bytes.len() / 2]).unwrap();
    std::fs::remove_file(frame(2).with_extension("png")).unwrap();
    std::fs::write(frame(3), b"not an exr").unwrap();
    let o = ok(render("cornell-anim", &["--frames", "0..3", "--resume", "--json"], &out));
    let resumed: Vec<bool> = json_lines(&o)[..4].iter().map(|l| l["resumed"].as_bool().unwrap()).collect();
    assert_eq!(resumed, [true, false, false, false]);
    for k in 0..4 {
        assert_eq!(channel_bits(&frame(k)), originals[k as usize], "frame {k} differs after --resume");
    }
    assert_eq!(preview_frames(&dir.join("r.preview.png")).0, 4);
    // All on disk and finished: nothing is rendered; other settings: everything is.
    let o = ok(render("cornell-anim", &["--frames", "0..3", "--resume", "--json"], &out));
    assert_eq!(json_lines(&o)[4]["resumed"], serde_json::json!([0, 1, 2, 3]));
    let o = ok(render("cornell-anim", &["--frames", "0..3", "--resume", "--json", "--seed", "9"], &out));
    assert_eq!(json_lines(&o)[4]["rendered"], serde_json::json!([0, 1, 2, 3]));
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn a_still_scene_renders_as_frames_of_one_image_and_says_so() {
    let dir = temp_dir("stillseq");
    let o = ok(render("cornell", &["--frames", "0..2"], &dir.join("s.exr")));
    assert!(stderr(&o).contains("no animation"), "{}", stderr(&o));
    let first = channel_bits(&dir.join("s.0000.exr"));
    assert_eq!(channel_bits(&dir.join("s.0002.exr")), first);
    std::fs::remove_dir_all(&dir).ok();
}

#[test]
fn bad_frame_ranges_are_errors_naming_the_value() {
    let dir = temp_dir("bad");
    let out = dir.join("b.exr");
    for (scene, args, want) in [
        (
            "cornell-anim",
            &["--frames", "0..60"][..],
            "outside the animation of scene 'cornell-anim', which has frames 0..48",
        ),
        ("cornell-anim", &["--frame", "49"][..], "frames 49..49 are outside"),
        ("cornell", &["--frames", "5..2"][..], "frame range 5..2 is empty"),
        ("cornell", &["--frames", "1-4"][..], "'1-4' is not a frame range"),
        ("cornell", &["--frames", "a..4"][..], "'a' is not a frame number"),
        ("cornell", &["--frame", "-1"][..], "'-1' is not a frame number"),
        ("cornell", &["--frames", "all"][..], "scene 'cornell' has no animation"),
        ("cornell", &["--resume"][..], "--resume needs --frames"),
        ("cornell", &["--frame", "1", "--frames", "0..2"][..], "cannot be used with"),
    ] {
        let o = render(scene, args, &out);
        assert!(!o.status.success(), "{args:?} succeeded");
        assert!(stderr(&o).contains(want), "{args:?}: {}", stderr(&o));
        assert!(!stderr(&o).contains("panicked"), "{args:?}: {}", stderr(&o));
    }
    assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "a refused sequence wrote files");
    std::fs::remove_dir_all(&dir).ok();
}

/// Ctrl-C after frame 1 of 0..3 is written: frames 0 and 1 stay, 2 and 3 are not started,
/// the preview shows the two, the summary says cancelled, exit code 130.
#[cfg(unix)]
#[test]
fn ctrl_c_keeps_every_finished_frame() {
    let dir = temp_dir("cancel");
    let out = dir.join("c.exr");
    let out_s = out.to_str().unwrap();
    let args = [
        "render",
        "cornell-anim",
        "--frames",
        "0..3",
        "--res",
        "16x12",
        "--spp",
        "2",
        "--json",
        "--out",
        out_s,
    ];
    let (code, stdout, err) = interrupt_at(&args, "frame 1 written", "frame 1 written", Duration::ZERO);
    assert_eq!(code, Some(130), "{err}");
    for k in 0..2 {
        let exr = filtrace_io::read_exr(dir.join(format!("c.{k:04}.exr"))).unwrap();
        assert_eq!(exr.attribute("filtrace:cancelled"), Some("false"));
    }
    assert!(!dir.join("c.0002.exr").exists() && !dir.join("c.0003.exr").exists());
    assert_eq!(preview_frames(&dir.join("c.preview.png")).0, 2);
    let last: serde_json::Value = serde_json::from_str(stdout.lines().last().unwrap()).unwrap();
    assert_eq!(
        (last["cancelled"].as_bool(), last["rendered"].clone()),
        (Some(true), serde_json::json!([0, 1]))
    );
    assert!(err.contains("2 finished frame(s) kept"), "{err}");
    std::fs::remove_dir_all(&dir).ok();
}

/// Ctrl-C among the further samples of a `--filter` frame: that frame is written cut
/// short (header `filtrace:cancelled` true, as a still render's), exit 130; `--resume`
/// then renders it again rather than keeping it.
#[cfg(unix)]
#[test]
fn a_frame_cut_by_ctrl_c_is_marked_and_resume_renders_it_again() {
    let dir = temp_dir("cut");
    let out = dir.join("k.exr");
    let out_s = out.to_str().unwrap();
    let args = [
        "render",
        "cornell",
        "--frames",
        "0..1",
        "--res",
        "16x16",
        "--spp",
        "4096",
        "--max-depth",
        "3",
        "--threads",
        "1",
        "--filter",
        "atrous",
        "--json",
        "--out",
        out_s,
    ];
    let (code, _, err) = interrupt_at(&args, "-", "rendering", Duration::from_millis(30));
    assert_eq!(code, Some(130), "{err}");
    let exr = filtrace_io::read_exr(dir.join("k.0000.exr")).unwrap();
    assert_eq!(exr.attribute("filtrace:cancelled"), Some("true"));
    assert!(!dir.join("k.0001.exr").exists());
    let mut resume: Vec<&str> = args.to_vec();
    resume.extend(["--frame", "0", "--resume"]);
    resume.retain(|a| *a != "--frames" && *a != "0..1");
    let o = bin().args(&resume).output().unwrap();
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(json_lines(&o)[0]["resumed"], false, "a cut frame was kept");
    std::fs::remove_dir_all(&dir).ok();
}
