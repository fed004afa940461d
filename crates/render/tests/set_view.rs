//! `Renderer::set_camera` / `set_view` (the viewer's camera moves): a renderer moved and
//! resized in place renders the same film, bit for bit, as one built for that camera and
//! resolution, so the BVH need not be rebuilt when the camera moves.

use filtrace_render::{RenderSettings, Renderer};
use filtrace_scene::Camera;
use std::sync::atomic::AtomicBool;

fn moved_camera() -> Camera {
    let c = Camera::cornell();
    Camera { eye: c.eye + filtrace_core::Vec3::new(60.0, -20.0, 100.0), vfov_deg: 30.0, ..c }
}

fn film_of(r: &Renderer) -> Vec<filtrace_render::film::FilmPixel> {
    let mut film = r.new_film();
    r.render_pass(&mut film, 0, 2, &AtomicBool::new(false));
    film.pixels().to_vec()
}

#[test]
fn a_moved_renderer_renders_what_a_new_one_renders() {
    let scene = filtrace_scene::builtin("cornell").unwrap();
    let small = RenderSettings { width: 12, height: 8, spp: 2, max_depth: 4, seed: 5 };
    let big = RenderSettings { width: 20, height: 10, ..small.clone() };

    let mut moved = Renderer::new(scene.clone(), small.clone()).unwrap();
    moved.set_camera(&moved_camera());
    let mut want = scene.clone();
    want.camera = Some(moved_camera());
    assert_eq!(film_of(&moved), film_of(&Renderer::new(want.clone(), small).unwrap()));

    moved.set_view(&moved_camera(), big.clone()).unwrap();
    assert_eq!(moved.settings(), &big);
    assert_eq!(film_of(&moved), film_of(&Renderer::new(want, big.clone()).unwrap()));

    // Bad settings are refused and change nothing.
    let bad = RenderSettings { width: 0, ..big.clone() };
    assert!(moved.set_view(&Camera::cornell(), bad).is_err());
    assert_eq!(moved.settings(), &big);
}
