//! Many-light experiment specs (issue 14, item 6): the new fields parse, bad ones are
//! errors naming their line, and the runner judges each sample count against its own
//! ground truth and reports the three clocks, plots and equal-time tables.

use std::path::Path;

use filtrace_core::Image;
use filtrace_eval::experiment::*;

const SPEC: &str = r#"# a many-light spec
name = "vpl-tiny"
width = 8
height = 4
spp = [1, 2, 4]
equal_time = "alpha-max"

[reference]
ground_truth = "vpl"

[vpl]
vpls = 64
cache_points = 16
neighbours = 2
distributions = 3

[[scenes]]
name = "cornell"

[[methods]]
name = "alpha-max"
sampler = "alpha-max"

[[methods]]
name = "balance-cv-M3"
sampler = "balance-cv"
neighbours = 3
distributions = 4
cache_points = 32
faint_share = 0.1

[[methods]]
name = "uniform"
sampler = "uniform"
"#;

#[test]
fn vpl_fields_parse_with_their_defaults() {
    let spec = ExperimentSpec::from_toml(SPEC).unwrap();
    assert!(spec.is_vpl_ground_truth());
    assert_eq!(spec.metric(), Metric::RelMseClamped);
    assert_eq!(spec.reference.spp, 0);
    let m = |i: usize| spec.vpl_method(&spec.methods[i]).unwrap();
    assert_eq!(
        m(0),
        VplMethod {
            sampler: VplSampler::AlphaMax,
            vpls: 64,
            clamp: None,
            cache_points: 16,
            neighbours: 2,
            distributions: 3,
            faint_share: DEFAULT_FAINT_SHARE,
        }
    );
    assert_eq!(
        (m(1).sampler, m(1).neighbours, m(1).distributions, m(1).cache_points, m(1).faint_share),
        (VplSampler::BalanceCv, 3, 4, 32, 0.1)
    );
    assert_eq!(spec.methods[2].kind_label(), "vpl-uniform");
    // Without `[vpl]` the renderer's defaults.
    let bare = SPEC.replace("[vpl]\nvpls = 64\ncache_points = 16\nneighbours = 2\ndistributions = 3\n", "");
    let spec = ExperimentSpec::from_toml(&bare).unwrap();
    let d = spec.vpl_method(&spec.methods[0]).unwrap();
    assert_eq!((d.vpls, d.cache_points, d.neighbours, d.distributions), (2048, 2048, 2, 4));
    // Every sampler name and an explicit metric.
    for s in VplSampler::ALL {
        let t = SPEC.replace("sampler = \"uniform\"", &format!("sampler = \"{}\"", s.name()));
        assert_eq!(ExperimentSpec::from_toml(&t).unwrap().methods[2].sampler, Some(s));
    }
    let t = SPEC.replace("equal_time = \"alpha-max\"", "metric = \"relmse\"\n[vpl.x]");
    assert!(ExperimentSpec::from_toml(&t).is_err());
    let t = SPEC.replace("equal_time = \"alpha-max\"", "metric = \"relmse\"");
    assert_eq!(ExperimentSpec::from_toml(&t).unwrap().metric(), Metric::RelMse);
}

/// The line of `needle`'s first occurrence in `text` (1-based).
fn line_of(text: &str, needle: &str) -> usize {
    text.lines().position(|l| l.contains(needle)).expect(needle) + 1
}

#[test]
fn bad_vpl_fields_are_errors_naming_their_line() {
    let cases: [(&str, &str, &str, &str); 13] = [
        // (what, replace, by, text on the line the error must name)
        ("unknown sampler", "sampler = \"uniform\"", "sampler = \"lightcuts\"", "lightcuts"),
        ("M = 0", "neighbours = 3", "neighbours = 0", "neighbours = 0"),
        ("M = 5", "neighbours = 3", "neighbours = 5", "neighbours = 5"),
        ("no distributions", "distributions = 4", "distributions = 0", "distributions = 0"),
        ("five distributions", "distributions = 3", "distributions = 5", "distributions = 5"),
        ("no VPLs", "vpls = 64", "vpls = 0", "vpls = 0"),
        ("faint share 1", "faint_share = 0.1", "faint_share = 1.0", "faint_share = 1.0"),
        ("negative faint share", "faint_share = 0.1", "faint_share = -0.5", "faint_share = -0.5"),
        ("unknown key in [vpl]", "vpls = 64", "vpls = 64\nlights = 3", "lights = 3"),
        (
            "a reference spp with the ground truth",
            "ground_truth = \"vpl\"",
            "ground_truth = \"vpl\"\nspp = 64",
            "spp = 64",
        ),
        ("unknown ground truth", "ground_truth = \"vpl\"", "ground_truth = \"path\"", "ground_truth"),
        (
            "a filter on a VPL method",
            "sampler = \"alpha-max\"",
            "sampler = \"alpha-max\"\nfilter = \"guided\"",
            "filter = \"guided\"",
        ),
        (
            "equal_time names no method",
            "equal_time = \"alpha-max\"",
            "equal_time = \"optimised\"",
            "equal_time",
        ),
    ];
    for (what, from, to, on_line) in cases {
        assert!(SPEC.contains(from), "{what}");
        let text = SPEC.replacen(from, to, 1);
        let err = ExperimentSpec::from_toml(&text).expect_err(what);
        let want = format!("line {}:", line_of(&text, on_line));
        assert!(err.starts_with(&want), "{what}: {err:?} should start with {want:?}");
    }
    // A path-traced method against the VPL ground truth, and VPL keys without a sampler.
    let text = SPEC.replace("name = \"uniform\"\nsampler = \"uniform\"", "name = \"pt\"\nfilter = \"none\"");
    let err = ExperimentSpec::from_toml(&text).unwrap_err();
    assert!(err.starts_with(&format!("line {}:", line_of(&text, "filter = \"none\""))), "{err}");
    let text = SPEC
        .replace(
            "name = \"uniform\"\nsampler = \"uniform\"",
            "name = \"pt\"\nfilter = \"none\"\nneighbours = 2",
        )
        .replace("ground_truth = \"vpl\"", "spp = 4");
    let err = ExperimentSpec::from_toml(&text).unwrap_err();
    let last = text.lines().collect::<Vec<_>>().iter().rposition(|l| *l == "neighbours = 2").unwrap() + 1;
    assert!(last > line_of(&text, "neighbours = 2"), "the method's, not [vpl]'s");
    assert!(err.starts_with(&format!("line {last}:")), "{err}");
}

#[test]
fn load_names_the_file_and_line() {
    let dir = std::env::temp_dir().join(format!("filtrace-vplspec-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let p = dir.join("bad.toml");
    std::fs::write(&p, SPEC.replace("neighbours = 3", "neighbours = 9")).unwrap();
    let err = ExperimentSpec::load(&p).unwrap_err();
    let want = format!("{}:{}:", p.display(), line_of(SPEC, "neighbours = 3"));
    assert!(err.starts_with(&want), "{err:?} should start with {want:?}");
    std::fs::remove_dir_all(&dir).ok();
}

/// A backend whose methods are the ground truth plus noise `a / sqrt(spp)`, `a` per
/// sampler, with a ray clock proportional to spp.
struct Fake {
    truths: Vec<u32>,
}

fn truth(w: u32, h: u32, spp: u32) -> Image {
    let mut im = Image::new(w as usize, h as usize, 3);
    for (i, v) in im.data_mut().iter_mut().enumerate() {
        *v = 0.25 + 0.5 * ((i as u32 * 7 + spp) % 5) as f32 / 5.0;
    }
    im
}

impl Backend for Fake {
    fn tag(&self) -> String {
        "fake-vpl".into()
    }
    fn scene_fingerprint(&mut self, s: &SceneSpec) -> Result<String, String> {
        Ok(s.name.clone())
    }
    fn render_reference(&mut self, _: &ExperimentSpec, _: &SceneSpec) -> Result<Image, String> {
        Err("the VPL experiment asks for no path-traced reference".into())
    }
    fn load_reference(&mut self, p: &Path) -> Result<Image, String> {
        Err(p.display().to_string())
    }
    fn render_ground_truth(
        &mut self,
        spec: &ExperimentSpec,
        _: &SceneSpec,
        spp: u32,
        previous: Option<(u32, &Image)>,
    ) -> Result<Image, String> {
        // The runner hands over the ground truth of the count before.
        let want = self.truths.last().map(|&k| (k, truth(spec.width, spec.height, k)));
        assert_eq!(previous.map(|(k, i)| (k, i.clone())), want);
        self.truths.push(spp);
        Ok(truth(spec.width, spec.height, spp))
    }
    fn run(
        &mut self,
        spec: &ExperimentSpec,
        _: &SceneSpec,
        m: &MethodSpec,
        spp: u32,
    ) -> Result<MethodRun, String> {
        let vm = spec.vpl_method(m).expect("a VPL method");
        let a = match vm.sampler {
            VplSampler::AlphaMax => 0.02,
            VplSampler::BalanceCv => 0.04,
            _ => 0.08,
        } / (spp as f32).sqrt();
        let mut image = truth(spec.width, spec.height, spp);
        for (i, v) in image.data_mut().iter_mut().enumerate() {
            *v += if i % 2 == 0 { a } else { -a };
        }
        let per_sample = if vm.sampler == VplSampler::AlphaMax { 3.0 } else { 1.0 };
        let ms = per_sample * spp as f64;
        Ok(MethodRun {
            image,
            noisy: None,
            albedo: None,
            normal: None,
            stages: vec![("cache".into(), 1.0), ("shading".into(), ms)],
            rays: Some(RayClock { rays: (per_sample as u64) * 32 * spp as u64, ray_ms: ms / 2.0 }),
        })
    }
}

#[test]
fn each_sample_count_is_judged_against_its_own_ground_truth() {
    let spec = ExperimentSpec::from_toml(SPEC).unwrap();
    let out = std::env::temp_dir().join(format!("filtrace-vplexp-test-{}", std::process::id()));
    std::fs::remove_dir_all(&out).ok();
    let mut backend = Fake { truths: vec![] };
    let r = run_experiment(&spec, Path::new("."), &out, &mut backend, &mut |_| {}).unwrap();
    assert_eq!(backend.truths, [1, 2, 4], "one ground truth per spp, increasing");
    assert_eq!(r.entries.len(), 9);
    for e in &r.entries {
        // Noise ±a on values in [0.25, 0.75): relMSE (clamped) = a² · n / Σ ref².
        let a = [("alpha-max", 0.02), ("balance-cv-M3", 0.04), ("uniform", 0.08)]
            .iter()
            .find(|m| m.0 == e.method)
            .unwrap()
            .1
            / (e.spp as f64).sqrt();
        let t = truth(8, 4, e.spp);
        let energy: f64 = t.data().iter().map(|v| (*v as f64).powi(2)).sum();
        let want = a * a * t.data().len() as f64 / energy;
        assert!(
            (e.errors.rel_mse_clamped - want).abs() < 1e-4 * want,
            "{}: {} vs {want}",
            e.method,
            e.errors.rel_mse_clamped
        );
        let rays = e.rays.unwrap();
        assert_eq!(e.clock(Clock::WithoutRays), Some(e.total_ms - rays.ray_ms));
        assert_eq!(e.clock(Clock::Rays), Some(rays.rays as f64));
    }
    assert_eq!(r.scenes[0].references_by_spp.len(), 3);
    assert_eq!(r.scenes[0].reference_at(2).0, "cornell-2spp-reference.png");
    filtrace_eval::report::write_all(&out, &r).unwrap();
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    // Four plots (spp and the three clocks), equal-time tables on the three clocks.
    assert_eq!(html.matches("<svg").count(), 4, "one plot per clock");
    for label in ["ms per frame (all time)", "ms without ray queries", "rays traced", "samples per pixel"] {
        assert!(html.contains(label), "{label}");
    }
    assert_eq!(html.matches("Equal ").count(), 3);
    assert!(html.contains("cornell-4spp-reference.png"));
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert!(csv.lines().next().unwrap().contains("rel_mse_clamped") && csv.contains(",vpl-alpha-max,"));
    // Cached on the second run: no ground truth rendered again.
    let again = run_experiment(&spec, Path::new("."), &out, &mut backend, &mut |_| {}).unwrap();
    assert_eq!(backend.truths.len(), 3);
    assert_eq!(again.entries, r.entries);
    std::fs::remove_dir_all(&out).ok();
}
