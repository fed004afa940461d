//! A bare mesh file renders lit (issue 17, defect 8): the meshes of ../shared/scenes have no
//! lights and rendered black with exit 0. They now get the default sky and sun (with a
//! warning); `--no-default-light` gives the black image back, with a warning saying why.

use std::path::PathBuf;
use std::process::Command;

#[path = "support/shared.rs"]
mod support_shared;
use support_shared::shared;

/// Renders `scene` at 24x24, 2 spp with `extra` flags; returns the JSON summary.
fn render_json(scene: &PathBuf, tag: &str, extra: &[&str]) -> serde_json::Value {
    let dir = std::env::temp_dir().join(format!("filtrace-cli-defaultlight-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let o = Command::new(env!("CARGO_BIN_EXE_filtrace"))
        .arg("render")
        .arg(scene)
        .args(["--res", "24x24", "--spp", "2", "--threads", "2", "--json", "--out"])
        .arg(dir.join("out.exr"))
        .args(extra)
        .output()
        .expect("the filtrace binary runs");
    assert!(o.status.success(), "render failed: {}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("stdout is one JSON object")
}

fn mean(json: &serde_json::Value) -> f64 {
    let m = json["mean_rgb"].as_array().expect("mean_rgb is an array");
    m.iter().map(|v| v.as_f64().expect("a number")).sum::<f64>() / 3.0
}

fn warnings(json: &serde_json::Value) -> Vec<String> {
    let w = json["load_warnings"].as_array().expect("load_warnings is an array");
    w.iter().map(|v| v.as_str().unwrap_or_default().to_string()).collect()
}

#[test]
fn bare_meshes_render_lit_by_default_and_black_without_the_default_light() {
    for rel in ["scenes/teapot/teapot.obj", "scenes/bunny/bunny_lowres.obj"] {
        let Some(p) = shared(rel) else { continue };
        let tag = rel.rsplit('/').next().unwrap_or("mesh");
        let lit = render_json(&p, tag, &[]);
        assert!(mean(&lit) > 0.01, "{rel}: mean {} with the default light", mean(&lit));
        assert!(warnings(&lit).iter().any(|w| w.contains("default sky")), "{rel}: {:?}", warnings(&lit));
        let dark = render_json(&p, &format!("{tag}-off"), &["--no-default-light"]);
        assert_eq!(mean(&dark), 0.0, "{rel}: no light, no radiance");
        assert!(
            warnings(&dark).iter().any(|w| w.contains("no lights") && w.contains("black")),
            "{rel}: {:?}",
            warnings(&dark)
        );
    }
}
