//! The scenes shipped in `examples/grid/scenes` (drawn at random to check the defaults on scenes
//! no one tuned for, four over light and four over dark backgrounds, and the built-in scene
//! over a dark one) read as valid scenes, each with matter inside the box.

use fogray_grid::scene::Scene;

#[test]
fn the_shipped_scenes_read_and_hold_matter() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("scenes");
    let mut read = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "json") {
            let scene = Scene::read(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            let inside = (0..1000).any(|i| {
                let f = |k: u32| -0.9 + 1.8 * (((i * k) % 997) as f64 / 997.0);
                scene.density_at([f(7), f(13), f(29)]) > 0.0
            });
            assert!(inside, "{}: no matter found", path.display());
            read += 1;
        }
    }
    assert_eq!(read, 9);
}
