//! `filtrace bench suite` (issue 13) on tiny settings: it runs, its JSON parses and holds
//! what the driver script reads, the same image comes out at every thread count, the
//! scene dump for the peer scripts is complete, and bad input is an error. Timings are never
//! checked.

use std::process::{Command, Output};

fn suite(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_filtrace"))
        .args(["bench", "suite"])
        .args(args)
        .output()
        .expect("the filtrace binary runs")
}

fn json_of(o: &Output) -> serde_json::Value {
    assert!(o.status.success(), "bench suite failed: {}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("bench suite --json prints one JSON object")
}

#[path = "support/shared.rs"]
mod support_shared;
use support_shared::shared;

#[test]
fn suite_json_has_render_and_ray_rows_and_the_same_image_at_every_thread_count() {
    let v = json_of(&suite(&[
        "--scenes",
        "cornell",
        "--res",
        "16x8",
        "--spp",
        "2",
        "--repeats",
        "2",
        "--rays",
        "512",
        "--threads",
        "1,2",
        "--json",
    ]));
    assert_eq!(v["res"], "16x8");
    assert_eq!(v["spp"], 2);
    let scene = &v["scenes"][0];
    assert_eq!(scene["scene"], "cornell");
    assert_eq!(scene["triangles"], 36);
    let rows = scene["render"].as_array().unwrap();
    assert_eq!(rows.len(), 2);
    for row in rows {
        assert_eq!(row["samples"], 16 * 8 * 2);
        assert_eq!(row["seconds"].as_array().unwrap().len(), 2);
        assert!(row["samples_per_s_best"].as_f64().unwrap() > 0.0);
    }
    assert_eq!(rows[0]["mean_rgb"], rows[1]["mean_rgb"], "1 and 2 threads render the same image");
    let rays = &scene["rays"];
    assert_eq!(rays["threads"], 1);
    assert_eq!(rays["incoherent_rays"], 512);
    for key in ["incoherent_closest_mrays", "incoherent_any_mrays", "incoherent_hit_fraction"] {
        assert!(rays[key].as_f64().is_some(), "rays lack {key}: {rays}");
    }
}

#[test]
fn suite_prints_both_tables_and_skips_what_it_is_told_to() {
    let o = suite(&["--scenes", "cornell", "--res", "8x8", "--spp", "1", "--repeats", "1", "--rays", "64"]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let text = String::from_utf8_lossy(&o.stdout);
    assert!(
        text.contains("## Path tracing")
            && text.contains("## Incoherent rays")
            && text.contains("| cornell | 36 |"),
        "{text}"
    );
    let v =
        json_of(&suite(&["--scenes", "cornell", "--res", "8x8", "--no-render", "--rays", "64", "--json"]));
    assert!(v["scenes"][0]["render"].as_array().unwrap().is_empty());
    assert!(v["scenes"][0]["rays"].is_object());
    let v = json_of(&suite(&["--scenes", "cornell", "--res", "8x8", "--spp", "1", "--no-rays", "--json"]));
    assert!(v["scenes"][0]["rays"].is_null());
}

/// The suite's large scene is over a million triangles (issue 13).
#[test]
fn grass_1m_has_over_a_million_triangles() {
    let v = json_of(&suite(&[
        "--scenes",
        "grass-1m",
        "--res",
        "4x4",
        "--no-render",
        "--rays",
        "64",
        "--repeats",
        "1",
        "--json",
    ]));
    assert!(v["scenes"][0]["triangles"].as_u64().unwrap() > 1_000_000, "{}", v["scenes"][0]["triangles"]);
}

/// The dump holds one PLY per shape and every triangle of the scene, placed by its
/// instances; the engine keeps its instancing.
#[test]
fn scene_dump_covers_every_triangle_with_its_instances() {
    let mut scenes = vec!["cornell", "grass"];
    if shared("scenes/gltf/2CylinderEngine.glb").is_some() {
        scenes.push("engine");
    }
    let dir = std::env::temp_dir().join(format!("filtrace-suite-dump-{}", std::process::id()));
    let list = scenes.join(",");
    let o = suite(&["--scenes", &list, "--dump-scene-json", dir.to_str().unwrap()]);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    for name in scenes {
        let doc: serde_json::Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join(name).join("scene.json")).unwrap())
                .unwrap();
        let mut placed = 0;
        for s in doc["shapes"].as_array().unwrap() {
            assert!(dir.join(name).join(s["file"].as_str().unwrap()).is_file(), "{name}: {s}");
            placed += s["triangles"].as_u64().unwrap() * s["instances"].as_array().unwrap().len() as u64;
        }
        assert_eq!(placed, doc["triangles"].as_u64().unwrap(), "{name}");
        assert!(doc["camera"]["vfov_deg"].as_f64().unwrap() > 0.0, "{name}");
        if name == "engine" {
            let instances: usize = doc["shapes"]
                .as_array()
                .unwrap()
                .iter()
                .map(|s| s["instances"].as_array().unwrap().len())
                .sum();
            assert!(
                instances > doc["shapes"].as_array().unwrap().len(),
                "engine: meshes placed more than once"
            );
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn bad_suite_input_is_an_error_with_a_message() {
    for args in [
        &["--scenes", "no-such-scene"][..],
        &["--scenes", "cornell", "--repeats", "0"],
        &["--scenes", "cornell", "--threads", "0"],
        &["--scenes", "cornell", "--ray-threads", "0"],
        &["--scenes", "cornell", "--spp", "0"],
    ] {
        let o = suite(args);
        let err = String::from_utf8_lossy(&o.stderr);
        assert_eq!(o.status.code(), Some(1), "{args:?}: {err}");
        assert!(err.starts_with("error: ") && !err.contains("panicked"), "{args:?}: {err}");
    }
}
