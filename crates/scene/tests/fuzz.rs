//! Property tests: the text parsers never panic, whatever they are fed, and what they accept
//! is well formed (indices in range, material ids valid, everything finite).

use std::path::Path;

use filtrace_scene::obj::parse_obj;
use filtrace_scene::ply::parse_ply;
use filtrace_scene::Scene;
use proptest::prelude::*;

fn well_formed(s: &Scene) {
    for m in &s.meshes {
        assert_eq!(m.indices.len(), m.material_ids.len());
        for (k, t) in m.indices.iter().enumerate() {
            assert!(t.iter().all(|&i| (i as usize) < m.positions.len()));
            let [a, b, c] = m.triangle(k);
            assert!(a.is_finite() && b.is_finite() && c.is_finite());
            assert!((b - a).cross(c - a).length_squared() > 0.0, "degenerate triangle kept");
        }
        assert!(m.material_ids.iter().all(|&id| (id as usize) < s.materials.len()));
    }
}

/// Lines that look like OBJ: mostly valid statements with random numbers and indices.
fn obj_line() -> impl Strategy<Value = String> {
    let num = prop_oneof![
        (-5.0f32..5.0).prop_map(|x| x.to_string()),
        Just("nan".into()),
        Just("x".into()),
        Just("1e40".into())
    ];
    let idx = prop_oneof![(-6i32..8).prop_map(|i| i.to_string()), Just("".into()), Just("a".into())];
    let vert =
        (idx.clone(), prop::option::of(idx.clone()), prop::option::of(idx)).prop_map(|(v, t, n)| {
            match (t, n) {
                (None, None) => v,
                (Some(t), None) => format!("{v}/{t}"),
                (t, Some(n)) => format!("{v}/{}/{n}", t.unwrap_or_default()),
            }
        });
    prop_oneof![
        4 => prop::collection::vec(num.clone(), 0..5).prop_map(|v| format!("v {}", v.join(" "))),
        1 => prop::collection::vec(num.clone(), 0..3).prop_map(|v| format!("vt {}", v.join(" "))),
        1 => prop::collection::vec(num, 0..4).prop_map(|v| format!("vn {}", v.join(" "))),
        4 => prop::collection::vec(vert, 0..6).prop_map(|v| format!("f {}", v.join(" "))),
        1 => Just("g group".to_string()),
        1 => Just("usemtl nothing".to_string()),
        1 => Just("mtllib missing.mtl".to_string()),
        1 => "[ -~]{0,20}",
    ]
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 256, ..ProptestConfig::default() })]

    #[test]
    fn obj_parser_never_panics(lines in prop::collection::vec(obj_line(), 0..40)) {
        let src = lines.join("\n");
        if let Ok(s) = parse_obj(&src, Path::new("/nonexistent/fuzz.obj")) {
            well_formed(&s);
        }
    }

    #[test]
    fn ply_parser_never_panics(body in prop::collection::vec(any::<u8>(), 0..200), ascii in any::<bool>()) {
        let header = format!(
            "ply\nformat {} 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\n\
             element face 3\nproperty list uchar int vertex_indices\nend_header\n",
            if ascii { "ascii" } else { "binary_little_endian" }
        );
        let mut bytes = header.into_bytes();
        bytes.extend_from_slice(&body);
        if let Ok(s) = parse_ply(&bytes, Path::new("fuzz.ply")) {
            well_formed(&s);
        }
    }

    #[test]
    fn ply_header_garbage_never_panics(text in "[a-z0-9 \n]{0,200}") {
        let _ = parse_ply(format!("ply\n{text}").as_bytes(), Path::new("fuzz.ply"));
    }
}
