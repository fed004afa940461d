//! The experiment runner end to end on a tiny spec (16x16), with a backend whose errors are
//! known: "exact" returns the reference, "noisy" adds noise of amplitude 1/sqrt(spp).

use std::path::Path;

use filtrace_core::Image;
use filtrace_eval::experiment::*;

struct Fake {
    reference_renders: usize,
}

fn gradient(w: usize, h: usize) -> Image {
    let mut im = Image::new(w, h, 3);
    for y in 0..h {
        for x in 0..w {
            im.pixel_mut(x, y).copy_from_slice(&[x as f32 / w as f32, y as f32 / h as f32, 0.25]);
        }
    }
    im
}

impl Backend for Fake {
    fn tag(&self) -> String {
        "fake-1".into()
    }
    fn scene_fingerprint(&mut self, s: &SceneSpec) -> Result<String, String> {
        Ok(format!("fake:{}", s.name))
    }
    fn render_reference(&mut self, spec: &ExperimentSpec, _s: &SceneSpec) -> Result<Image, String> {
        self.reference_renders += 1;
        Ok(gradient(spec.width as usize, spec.height as usize))
    }
    fn load_reference(&mut self, p: &Path) -> Result<Image, String> {
        Err(format!("no file {}", p.display()))
    }
    fn run(
        &mut self,
        spec: &ExperimentSpec,
        _s: &SceneSpec,
        m: &MethodSpec,
        spp: u32,
    ) -> Result<MethodRun, String> {
        let mut im = gradient(spec.width as usize, spec.height as usize);
        if m.filter == "noisy" {
            let a = 0.1 / (spp as f32).sqrt();
            for (i, v) in im.data_mut().iter_mut().enumerate() {
                *v += if i % 2 == 0 { a } else { -a };
            }
        }
        Ok(MethodRun {
            image: im,
            noisy: None,
            albedo: None,
            normal: None,
            stages: vec![("trace".into(), 2.0 * spp as f64), ("filter".into(), 1.0)],
            rays: None,
        })
    }
}

const SPEC: &str = r#"
name = "tiny"
width = 16
height = 16
spp = [1, 4]
[reference]
spp = 8
[[scenes]]
name = "cornell"
crop = [4, 4, 8, 8]
[[scenes]]
name = "other"
[[methods]]
name = "exact"
filter = "exact"
[[methods]]
name = "noisy"
filter = "noisy"
indirect_paths = "spp"
"#;

#[test]
fn tiny_spec_end_to_end_with_reference_cache() {
    let spec = ExperimentSpec::from_toml(SPEC).unwrap();
    let out = std::env::temp_dir().join(format!("filtrace-exp-test-{}", std::process::id()));
    std::fs::remove_dir_all(&out).ok();
    std::fs::create_dir_all(&out).unwrap();
    let mut backend = Fake { reference_renders: 0 };
    let mut steps = 0;
    let results = run_experiment(&spec, Path::new("."), &out, &mut backend, &mut |p| {
        assert!(p.done <= p.total);
        steps += 1;
    })
    .unwrap();
    assert_eq!(backend.reference_renders, 2);
    assert!(steps >= 2 * (1 + 2 * 2));
    assert_eq!(results.entries.len(), 2 * 2 * 2);
    for e in &results.entries {
        if e.method == "exact" {
            assert_eq!(e.errors.mse, 0.0);
            assert_eq!(e.errors.psnr, None);
        } else {
            // Noise of amplitude a on every channel: MSE = a^2.
            let a = 0.1 / (e.spp as f64).sqrt();
            assert!((e.errors.mse - a * a).abs() < 1e-6 * a * a + 1e-9, "{} vs {}", e.errors.mse, a * a);
        }
        assert_eq!(e.total_ms, 2.0 * e.spp as f64 + 1.0);
        for f in [&e.image, &e.error_map, &e.crop] {
            assert!(out.join(f).is_file(), "{f} missing");
        }
    }
    filtrace_eval::report::write_all(&out, &results).unwrap();
    let csv = std::fs::read_to_string(out.join("results.csv")).unwrap();
    assert_eq!(csv.lines().count(), 1 + 8);
    assert!(csv.lines().next().unwrap().contains("trace_ms"));
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("results.json")).unwrap()).unwrap();
    assert_eq!(json["entries"].as_array().unwrap().len(), 8);
    let html = std::fs::read_to_string(out.join("report.html")).unwrap();
    assert!(
        html.contains("<svg")
            && html.contains("cornell-noisy-4spp.png")
            && html.contains("cornell-reference-crop.png")
    );
    // Without `oidn = true` the report says how to enable the OIDN comparison.
    assert!(html.contains("oidnDenoise") && html.contains("pyoidn"));

    // Second run: the references come from the cache.
    let again = run_experiment(&spec, Path::new("."), &out, &mut backend, &mut |_| {}).unwrap();
    assert_eq!(backend.reference_renders, 2);
    assert!(again.scenes[0].reference_source.starts_with("cached"));
    assert_eq!(again.entries, results.entries);
    std::fs::remove_dir_all(&out).ok();
}

#[test]
fn cache_key_follows_the_reference_settings() {
    let spec = ExperimentSpec::from_toml(SPEC).unwrap();
    let s = &spec.scenes[0];
    let k = spec.reference_key(s, "a", "f");
    assert_eq!(k, spec.reference_key(s, "a", "f"));
    assert_ne!(k, spec.reference_key(s, "b", "f"));
    assert_ne!(k, spec.reference_key(s, "a", "g"), "an edited scene needs a new reference");
    let mut more = spec.clone();
    more.reference.spp = 16;
    assert_ne!(k, more.reference_key(s, "a", "f"));
    let mut bigger = spec.clone();
    bigger.width = 32;
    assert_ne!(k, bigger.reference_key(s, "a", "f"));
    // Methods do not change the reference.
    let mut fewer = spec.clone();
    fewer.methods.pop();
    assert_eq!(k, fewer.reference_key(s, "a", "f"));
}

#[test]
fn bad_specs_are_clear_errors() {
    let cases = [
        ("width = 0", SPEC.replace("width = 16", "width = 0")),
        ("spp 0", SPEC.replace("spp = [1, 4]", "spp = [0]")),
        ("unknown key", SPEC.replace("name = \"tiny\"", "name = \"tiny\"\ncolour = 3")),
        ("duplicate method", SPEC.replace("name = \"noisy\"", "name = \"exact\"")),
        ("crop outside", SPEC.replace("crop = [4, 4, 8, 8]", "crop = [10, 10, 8, 8]")),
        ("indirect_paths", SPEC.replace("indirect_paths = \"spp\"", "indirect_paths = \"many\"")),
        ("not toml", "name = ".to_string()),
    ];
    for (what, text) in cases {
        let e = ExperimentSpec::from_toml(&text).expect_err(what);
        assert!(!e.is_empty(), "{what}");
    }
}
