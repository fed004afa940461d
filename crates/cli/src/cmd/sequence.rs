//! `filtrace render SCENE --frames A..B` (or `--frame N`): frames of the scene's animation
//! as numbered EXR + PNG files and a preview animation (docs/animation.md).
//!
//! Each frame is rendered as a still render of the scene posed at that frame would be (plain,
//! `--filter` or `--adaptive`; the filtered pipeline keeps its buffers from frame to frame),
//! with the same seed, so that a still scene gives the still render at every frame. The
//! world moves between frames through [`FrameSource`], the one per-frame step.
//!
//! `--integrator vpl` renders each frame with the many-light renderer (`render_vpl`), one
//! integrator carried from frame to frame: its VPLs are drawn anew each frame (their seed
//! follows the frame number, still scenes included) and the `optimized` sampler starts each
//! frame from the parameters the frame before learnt, interpolated at the new cache
//! records (thesis 5.2.2), so a frame of a sequence differs from the same frame rendered
//! alone for `optimized` (equal for the other samplers).
//!
//! Ctrl-C before the first frame starts writes nothing (as a still render). During a frame,
//! that frame follows the still render's rules (written if complete enough, its header
//! saying it was cut short); every finished frame stays, the preview shows the frames on
//! disk, and the command exits with code 130. `--resume` keeps the frames already on disk
//! that are finished with the same settings (sequence_files) and renders the others; when
//! each frame continues the state of the one before (VPL `optimized`), the state is written
//! beside each finished frame and `--resume` keeps the finished frames up to the last whose
//! state it can read, then continues from that state: the files are those of an
//! uninterrupted run.

use anyhow::Context;
use serde::Serialize;
use std::io::Write;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::frame_source::FrameSource;
use super::preview::write_preview;
use super::render_args::CommonArgs;
use super::render_filtered::{build_pipeline_traced, AdaptiveArgs, FilterArgs, FilteredRun, Pipeline};
use super::render_plain::{build_renderer, LoadReport, PlainRun};
use super::render_session::{check_memory, multi_progress, progress_bar, test_hook, CtrlC, Interrupted};
use super::render_vpl::{VplArgs, VplRun};
use super::sequence_files::{frame_path, keep_on_resume, preview_path, state_path, FrameStamp};
use filtrace_vpl::vpls::VplState;

/// Largest frame number accepted.
pub const MAX_FRAME: u64 = 9_999_999;
/// Frame rate of the preview of a still scene (which has no clock).
const STILL_FPS: f32 = 24.0;

/// Sequence options of `filtrace render`.
#[derive(clap::Args, Debug, Clone)]
pub struct SequenceArgs {
    /// Render frames A..B of the scene's animation, both included (`all`: all of them), as
    /// OUT.NNNN.exr + .png and an animated OUT.preview.png (OUT: --out without .exr).
    #[arg(long, value_name = "A..B", value_parser = parse_frames, conflicts_with = "frame", allow_hyphen_values = true)]
    pub frames: Option<FrameSpan>,
    /// Render frame N only, numbered as --frames would.
    #[arg(long, value_name = "N", value_parser = parse_frame, allow_negative_numbers = true)]
    pub frame: Option<u64>,
    /// Keep the frames already on disk that were rendered to the end with the same
    /// settings (a missing, truncated or cut-short frame is rendered again).
    #[arg(long)]
    pub resume: bool,
}

/// The frames asked for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FrameSpan {
    /// Every frame of the scene's animation.
    All,
    /// `first..=last`.
    Range(u64, u64),
}

/// One frame number: 0..=[`MAX_FRAME`].
pub fn parse_frame(s: &str) -> Result<u64, String> {
    let n: u64 = s.trim().parse().map_err(|_| format!("'{s}' is not a frame number (0, 1, 2, ...)"))?;
    if n > MAX_FRAME {
        return Err(format!("frame {n} is too large: at most {MAX_FRAME}"));
    }
    Ok(n)
}

/// `A..B` (also `A..=B`), both included, or `all`.
pub fn parse_frames(s: &str) -> Result<FrameSpan, String> {
    if s.trim() == "all" {
        return Ok(FrameSpan::All);
    }
    let malformed =
        || format!("'{s}' is not a frame range: expected A..B (both included), e.g. 0..48, or all");
    let (a, b) = s.trim().split_once("..").ok_or_else(malformed)?;
    let b = b.strip_prefix('=').unwrap_or(b);
    let (first, last) = (parse_frame(a).map_err(|e| format!("{}: {e}", malformed()))?, parse_frame(b)?);
    if last < first {
        return Err(format!("frame range {s} is empty: the last frame comes before the first"));
    }
    Ok(FrameSpan::Range(first, last))
}

impl SequenceArgs {
    pub fn is_sequence(&self) -> bool {
        self.frames.is_some() || self.frame.is_some()
    }

    /// Options that only mean something for a sequence are refused on a still render.
    pub fn check_still(&self) -> anyhow::Result<()> {
        if self.resume {
            anyhow::bail!("--resume needs --frames A..B or --frame N (a still render is always redone)");
        }
        Ok(())
    }

    /// The frame numbers to render, checked against the scene's animation (`clock`; `None`
    /// for a still scene, whose frames are all the same image).
    pub fn frame_numbers(
        &self,
        scene: &str,
        clock: Option<filtrace_scene::animation::Clock>,
    ) -> anyhow::Result<Vec<u64>> {
        let (first, last) = match (self.frame, self.frames, clock) {
            (Some(n), _, _) => (n, n),
            (None, Some(FrameSpan::Range(a, b)), _) => (a, b),
            (None, Some(FrameSpan::All), Some(c)) => (c.first.max(0) as u64, c.last.max(0) as u64),
            (None, Some(FrameSpan::All), None) => {
                anyhow::bail!(
                    "--frames all: scene '{scene}' has no animation; give a range, e.g. --frames 0..23"
                )
            }
            (None, None, _) => anyhow::bail!("no frames asked for"),
        };
        if let Some(c) = clock {
            if (first as i64) < c.first || last as i64 > c.last {
                anyhow::bail!(
                    "frames {first}..{last} are outside the animation of scene '{scene}', which has frames {}..{}",
                    c.first,
                    c.last
                );
            }
        }
        Ok((first..=last).collect())
    }
}

/// How the frames are rendered, chosen (and their memory checked) before the scene is
/// loaded.
enum Method<'a> {
    Plain,
    Filtered(filtrace_pipeline::PipelineSettings, filtrace_pipeline::FilterChoice),
    Vpl(&'a VplArgs),
}

impl<'a> Method<'a> {
    fn choose(
        common: &CommonArgs,
        filter: &FilterArgs,
        adaptive: &AdaptiveArgs,
        vpl: &'a VplArgs,
    ) -> anyhow::Result<Self> {
        if vpl.enabled() {
            vpl.check_memory(common)?;
            return Ok(Method::Vpl(vpl));
        }
        if filter.enabled() || adaptive.adaptive {
            let (settings, choice) = super::render_filtered::pipeline_settings(common, filter, adaptive)?;
            return Ok(Method::Filtered(settings, choice));
        }
        let s = common.settings()?;
        check_memory(filtrace_render::memory::plain_render(s.width, s.height))?;
        Ok(Method::Plain)
    }

    /// Whether a frame depends on the frames before it (the VPL integrator's state).
    fn carries_state(&self) -> bool {
        matches!(self, Method::Vpl(v) if v.carries_state())
    }

    /// The method as a frame's settings stamp says it.
    fn stamp(&self, common: &CommonArgs, filter: &FilterArgs, adaptive: &AdaptiveArgs) -> String {
        match self {
            Method::Plain => "path".to_string(),
            Method::Filtered(..) => format!("{filter:?} {adaptive:?}"),
            Method::Vpl(v) => v.stamp(common.pass_spp()),
        }
    }
}

/// How each frame is rendered: plain path tracing, the filtered pipeline (which keeps its
/// buffers from frame to frame), or the VPL integrator (which keeps its optimiser's state).
enum Engine<'a> {
    Plain(PlainRun<'a>, Box<filtrace_render::Renderer>),
    Filtered(FilteredRun<'a>, Box<Pipeline>),
    Vpl(VplRun<'a>, Box<filtrace_render::Renderer>),
}

/// A rendered frame: its JSON summary, whether Ctrl-C cut it short, and the milliseconds
/// per stage for the human line (VPL frames; empty otherwise).
struct Rendered {
    summary: serde_json::Value,
    output: PathBuf,
    cancelled: bool,
    note: String,
    stages: String,
}

impl Engine<'_> {
    fn renderer_mut(&mut self) -> &mut filtrace_render::Renderer {
        match self {
            Engine::Plain(_, r) => r,
            Engine::Filtered(_, p) => p.source_mut().renderer_mut(),
            Engine::Vpl(_, r) => r,
        }
    }

    /// Renders and writes one frame; `None` when Ctrl-C stopped it before it could be written.
    fn render(
        &mut self,
        out: &Path,
        stamp: &FrameStamp,
        bar: &indicatif::ProgressBar,
    ) -> anyhow::Result<Option<Rendered>> {
        let attributes = stamp.attributes();
        Ok(match self {
            Engine::Plain(run, renderer) => {
                run.render_frame(renderer, out, &attributes, bar)?.map(|s| Rendered {
                    note: super::render_plain::cancelled_note(&s),
                    output: out.to_path_buf(),
                    cancelled: s.cancelled,
                    summary: serde_json::to_value(&s).unwrap_or_default(),
                    stages: String::new(),
                })
            }
            Engine::Filtered(run, pipeline) => {
                run.render_frame(pipeline, out, &attributes)?.map(|s| Rendered {
                    note: super::render_filtered::cancelled_note(&s),
                    output: out.to_path_buf(),
                    cancelled: s.cancelled,
                    summary: serde_json::to_value(&s).unwrap_or_default(),
                    stages: String::new(),
                })
            }
            Engine::Vpl(run, renderer) => {
                // The bar counts samples; until they start it says what the frame is doing.
                let label = bar.message();
                bar.set_message(format!("{label}: {}", run.preparing_message()));
                bar.tick();
                run.prepare(renderer, stamp.frame as i64)?;
                bar.set_message(label);
                let summary = run.render_frame(renderer, out, &attributes, bar)?;
                let finished = summary.as_ref().is_some_and(|s| !s.cancelled);
                if let Some(state) = finished.then(|| run.state(renderer)).flatten() {
                    stamp.write_state(&state_path(out), &state).with_context(|| {
                        format!(
                            "frame {}: cannot write the state the next frame continues from; the frames \
                             written so far stay and --resume continues from the last state on disk",
                            stamp.frame
                        )
                    })?;
                }
                summary.map(|s| Rendered {
                    note: super::render_vpl::cancelled_note(&s),
                    output: out.to_path_buf(),
                    cancelled: s.cancelled,
                    summary: serde_json::to_value(&s).unwrap_or_default(),
                    stages: s.stages(),
                })
            }
        })
    }
}

/// The line `--json` prints at the end of a sequence (after one line per frame).
#[derive(Serialize)]
struct SequenceSummary {
    kind: &'static str,
    scene: String,
    first: u64,
    last: u64,
    rendered: Vec<u64>,
    resumed: Vec<u64>,
    preview: Option<PathBuf>,
    seconds: f64,
    cancelled: bool,
}

/// Everything the frame loop reads.
struct Sequence<'a> {
    common: &'a CommonArgs,
    source: FrameSource,
    out: PathBuf,
    /// The frames asked for, each with its stamp and whether `--resume` keeps it.
    frames: Vec<(FrameStamp, bool)>,
    ctrlc: CtrlC,
    pool: rayon::ThreadPool,
}

/// What the loop did.
#[derive(Default)]
struct Done {
    rendered: Vec<u64>,
    resumed: Vec<u64>,
    /// The frames on disk, in order: the preview's.
    on_disk: Vec<PathBuf>,
    cancelled: bool,
}

pub fn run(
    common: &CommonArgs,
    filter: &FilterArgs,
    adaptive: &AdaptiveArgs,
    vpl: &VplArgs,
    seq: &SequenceArgs,
) -> anyhow::Result<()> {
    let start = Instant::now();
    let method = Method::choose(common, filter, adaptive, vpl)?;
    let stamp = method.stamp(common, filter, adaptive);
    let (sequence, load, carried) = prepare(common, seq, &stamp, &method)?;
    let first = sequence.frames.iter().find(|(_, keep)| !keep).map(|(s, _)| s.frame as i64);
    let mut engine = match first {
        None => None,
        Some(f) => Some(sequence.engine(method, f, adaptive, &load, carried)?),
    };
    test_hook("built", sequence.ctrlc.flag());
    sequence.ctrlc.arm();
    test_hook("rendering", sequence.ctrlc.flag());
    let done = sequence.render_all(engine.as_mut())?;
    drop(engine);
    sequence.finish(done, start)
}

/// Everything before the first frame: load the scene, resolve the frames against its
/// animation, check the outputs, look at what `--resume` can keep (and, for a method that
/// carries state, the state the first frame to render continues from).
fn prepare<'a>(
    common: &'a CommonArgs,
    seq: &SequenceArgs,
    stamp: &str,
    method: &Method,
) -> anyhow::Result<(Sequence<'a>, LoadReport, Option<VplState>)> {
    let (vpl, carries) = (matches!(method, Method::Vpl(_)), method.carries_state());
    // First: until the render starts, Ctrl-C exits at once and writes nothing.
    let ctrlc = CtrlC::install();
    let t0 = Instant::now();
    let scene = common.load_scene().with_context(|| format!("cannot load scene '{}'", common.scene))?;
    let load = LoadReport::of(&scene, t0.elapsed().as_secs_f64());
    test_hook("loaded", ctrlc.flag());
    let source = FrameSource::new(scene);
    let numbers = seq.frame_numbers(&common.scene, source.clock())?;
    let out = common.prepare_output()?;
    let first = frame_path(&out, numbers[0]);
    let state = carries.then(|| state_path(&first));
    for path in [first.clone(), first.with_extension("png"), preview_path(&out)].into_iter().chain(state) {
        filtrace_io::check_writable(&path).context("the output cannot be written (see --out)")?;
    }
    if !common.json {
        load.load_warnings.iter().for_each(|w| eprintln!("warning: {w}"));
        match (source.clock(), vpl) {
            (Some(_), _) => {}
            (None, false) => {
                eprintln!("note: scene '{}' has no animation: every frame is the same image", common.scene)
            }
            (None, true) => eprintln!(
                "note: scene '{}' has no animation: every frame is the same world, lit by VPLs drawn anew each frame",
                common.scene
            ),
        }
    }
    let mut settings = format!(
        "scene={} spp={:?} max_depth={} seed={} exposure={} filmic={} render={stamp}",
        common.scene, common.spp, common.max_depth, common.seed, common.exposure, common.filmic
    );
    // A frame that continues the frames before it depends on where the sequence started.
    if carries {
        settings.push_str(&format!(" carried_from={}", numbers[0]));
    }
    let stamps: Vec<FrameStamp> = numbers
        .into_iter()
        .map(|frame| FrameStamp {
            frame,
            time_s: source.time_of(frame as i64),
            width: common.res.width,
            height: common.res.height,
            settings: settings.clone(),
        })
        .collect();
    let (frames, carried) = keep_on_resume(stamps, &out, seq.resume, carries);
    let pool = common.thread_pool()?;
    Ok((Sequence { common, source, out, frames, ctrlc, pool }, load, carried))
}

impl Sequence<'_> {
    /// The engine that renders the frames, built for the scene posed at `first`.
    fn engine<'s>(
        &'s self,
        method: Method,
        first: i64,
        adaptive: &'s AdaptiveArgs,
        load: &'s LoadReport,
        carried: Option<VplState>,
    ) -> anyhow::Result<Engine<'s>> {
        let (common, pool, flag) = (self.common, &self.pool, self.ctrlc.flag());
        let scene = self.source.scene_at(first)?;
        Ok(match method {
            Method::Plain => Engine::Plain(
                PlainRun { c: common, pool, cancel: flag, load },
                Box::new(build_renderer(scene, common, pool)?),
            ),
            Method::Filtered(settings, choice) => {
                let trace = common.trace.map(|t| t.mode());
                let mut p = pool
                    .install(|| build_pipeline_traced(scene, settings, common.max_depth, &choice, trace))?;
                p.set_cancel(Some(flag.clone()));
                let run = FilteredRun { common, adaptive, pool, cancel: flag, load_s: load.load_s };
                Engine::Filtered(run, Box::new(p))
            }
            Method::Vpl(v) => {
                let renderer = build_renderer(scene, common, pool)?;
                let settings = v.settings(renderer.lights().scene_radius())?;
                Engine::Vpl(VplRun { c: common, settings, pool, cancel: flag, carried }, Box::new(renderer))
            }
        })
    }

    /// The frame loop: each frame kept by `--resume` or moved to, rendered and written,
    /// until the last or Ctrl-C. `first` is the frame `engine` was built for.
    fn render_all(&self, mut engine: Option<&mut Engine>) -> anyhow::Result<Done> {
        let multi = multi_progress();
        let frames_bar = multi
            .add(progress_bar(self.frames.len() as u64, &format!("{} frames", self.common.scene_name())));
        let mut done = Done::default();
        for (stamp, keep) in &self.frames {
            let exr = frame_path(&self.out, stamp.frame);
            if *keep {
                self.report(stamp, None, &exr)?;
                done.resumed.push(stamp.frame);
                done.on_disk.push(exr.with_extension("png"));
                frames_bar.inc(1);
                continue;
            }
            let Some(engine) = engine.as_deref_mut() else { break };
            self.source.move_to(engine.renderer_mut(), stamp.frame as i64)?;
            if self.ctrlc.is_set() {
                done.cancelled = true;
                break;
            }
            // The pipeline does not count its samples: a bar of frames only.
            let bar = match engine {
                Engine::Plain(..) | Engine::Vpl(..) => {
                    multi.add(progress_bar(0, &format!("frame {}", stamp.frame)))
                }
                Engine::Filtered(..) => indicatif::ProgressBar::hidden(),
            };
            let rendered = engine.render(&exr, stamp, &bar)?;
            multi.remove(&bar);
            let Some(rendered) = rendered else {
                eprintln!(
                    "frame {}: cancelled before it could be written: nothing written for it",
                    stamp.frame
                );
                done.cancelled = true;
                break;
            };
            self.report(stamp, Some(&rendered), &exr)?;
            done.on_disk.push(exr.with_extension("png"));
            done.rendered.push(stamp.frame);
            frames_bar.inc(1);
            test_hook(&format!("frame {} written", stamp.frame), self.ctrlc.flag());
            if rendered.cancelled {
                eprintln!("frame {}: {}", stamp.frame, rendered.note);
                done.cancelled = true;
                break;
            }
        }
        frames_bar.finish_and_clear();
        done.cancelled |= self.ctrlc.is_set();
        Ok(done)
    }

    /// One line per frame on stdout: JSON (`kind` "frame", the frame, its time, whether it
    /// was kept from an earlier run, and the still render's summary) or a human line.
    fn report(&self, stamp: &FrameStamp, rendered: Option<&Rendered>, exr: &Path) -> anyhow::Result<()> {
        let mut stdout = super::output::stdout();
        let png = exr.with_extension("png");
        if self.common.json {
            let mut line = match rendered {
                Some(r) => r.summary.clone(),
                None => serde_json::json!({ "output": exr, "png": png }),
            };
            if let Some(map) = line.as_object_mut() {
                map.insert("kind".into(), "frame".into());
                map.insert("frame".into(), stamp.frame.into());
                map.insert("time_s".into(), stamp.time_s.into());
                map.insert("resumed".into(), rendered.is_none().into());
                map.insert("png".into(), serde_json::to_value(&png)?);
            }
            writeln!(stdout, "{}", serde_json::to_string(&line)?)?;
        } else {
            match rendered {
                Some(r) => writeln!(
                    stdout,
                    "frame {} (t = {:.3} s): {}{}wrote {} and {}{}",
                    stamp.frame,
                    stamp.time_s,
                    r.stages,
                    if r.stages.is_empty() { "" } else { "; " },
                    r.output.display(),
                    png.display(),
                    if r.cancelled { " (cut short by Ctrl-C)" } else { "" }
                )?,
                None => writeln!(stdout, "frame {}: kept {} (already rendered)", stamp.frame, exr.display())?,
            }
        }
        stdout.flush()?;
        Ok(())
    }

    /// The preview of the frames on disk, the closing summary, and exit code 130 after
    /// Ctrl-C.
    fn finish(self, done: Done, start: Instant) -> anyhow::Result<()> {
        let preview = preview_path(&self.out);
        let fps = self.source.clock().map_or(STILL_FPS, |c| c.fps);
        let wrote_preview = !done.on_disk.is_empty();
        if wrote_preview {
            write_preview(&preview, &done.on_disk, fps)
                .with_context(|| format!("cannot write the preview {}", preview.display()))?;
        }
        let (first, last) = (self.frames[0].0.frame, self.frames[self.frames.len() - 1].0.frame);
        let summary = SequenceSummary {
            kind: "sequence",
            scene: self.common.scene.clone(),
            first,
            last,
            rendered: done.rendered,
            resumed: done.resumed,
            preview: wrote_preview.then(|| preview.clone()),
            seconds: start.elapsed().as_secs_f64(),
            cancelled: done.cancelled,
        };
        let mut stdout = super::output::stdout();
        if self.common.json {
            writeln!(stdout, "{}", serde_json::to_string(&summary)?)?;
        } else {
            writeln!(
                stdout,
                "{}: frames {first}..{last}: {} rendered, {} kept from an earlier run, in {:.1} s",
                summary.scene,
                summary.rendered.len(),
                summary.resumed.len(),
                summary.seconds
            )?;
            if wrote_preview {
                writeln!(stdout, "  preview animation {}", preview.display())?;
            }
        }
        stdout.flush()?;
        if done.cancelled {
            let kept = summary.rendered.len() + summary.resumed.len();
            eprintln!(
                "cancelled: {kept} finished frame(s) kept in {}",
                self.out.parent().map_or(".".into(), |p| p.display().to_string())
            );
            return Err(Interrupted.into());
        }
        Ok(())
    }
}
