//! The planes' geometry against hand-placed points, a fresh model's density, and the
//! occupancy grid's planes drawn the right way up.

use fogray_fit::dense::DenseGrid;
use fogray_fit::images::ImageError;
use fogray_ops::rays::Aabb;
use fogray_ops::sample::{CellPoints, GridAxis, OccupancyConfig, OccupancyGrid};
use ndarray::{Array1, ArrayView2};

use super::*;

#[test]
fn pixel_centres_run_right_along_the_first_axis_and_up_the_second() {
    // 4 x 4 pixels over [-1, 1]: centres at -0.75, -0.25, 0.25, 0.75.
    let unit = SceneBox::UNIT;
    assert_eq!(pixel_point(&unit, GridAxis::Z, 4, 0, 0), [-0.75, 0.75, 0.0]);
    assert_eq!(pixel_point(&unit, GridAxis::Z, 4, 3, 1), [-0.25, -0.75, 0.0]);
    assert_eq!(pixel_point(&unit, GridAxis::X, 4, 0, 3), [0.0, 0.75, 0.75]);
    assert_eq!(pixel_point(&unit, GridAxis::Y, 4, 2, 0), [-0.75, 0.0, -0.25]);
    // [0, 2] x [0, 4] x [0, 8] in 2 x 2 pixels across z: the plane z = 4, the top-left pixel's
    // centre a quarter of the way along x (0.5) and a quarter of the way down y from 4 (3).
    let uneven = SceneBox {
        min: [0.0; 3],
        max: [2.0, 4.0, 8.0],
    };
    assert_eq!(pixel_point(&uneven, GridAxis::Z, 2, 0, 0), [0.5, 3.0, 4.0]);
    assert_eq!(pixel_point(&uneven, GridAxis::X, 2, 1, 1), [1.0, 3.0, 2.0]);
}

#[test]
fn a_fresh_model_has_the_shifted_density_everywhere() {
    let model = DenseGrid::<f32>::new(SceneBox::UNIT, 5, -4.0, 0.0).unwrap();
    let planes = model_density_planes(&model, &SceneBox::UNIT, 6).unwrap();
    assert_eq!(planes.iter().map(|p| p.axis).collect::<Vec<_>>(), AXES.to_vec());
    let want = softplus(-4.0); // 0.01815
    for v in planes.iter().flat_map(|p| p.values.iter()) {
        assert!((v - want).abs() < 1e-6, "{v} vs {want}");
    }
}

#[test]
fn occupancy_planes_are_drawn_right_way_up() {
    // Matter only where x > 0 and z > 0, on a 4^3 grid: every middle plane (index 2, cells
    // 0 .. 0.5) is half or a quarter occupied, and where must match the picture's axes.
    let mut grid = OccupancyGrid::new(
        Aabb::new([-1.0; 3], [1.0; 3]).unwrap(),
        4,
        OccupancyConfig::density(1.0).unwrap(),
    )
    .unwrap();
    let density = |p: ArrayView2<'_, f64>| -> Result<Array1<f64>, String> {
        Ok(p.rows()
            .into_iter()
            .map(|r| if r[0] > 0.0 && r[2] > 0.0 { 10.0 } else { 0.0 })
            .collect())
    };
    grid.update(density, CellPoints::Centre).unwrap();
    let planes = occupancy_planes(&grid).unwrap();
    // Across x at index 2 (x > 0): occupied where z > 0, the top half of the image.
    let x = &planes[0].values;
    assert_eq!(x.column(0).to_vec(), vec![1.0, 1.0, 0.0, 0.0]);
    assert_eq!(x.row(0).to_vec(), vec![1.0; 4]);
    // Across y: x right, z up, so the top right quarter.
    let y = &planes[1].values;
    assert_eq!(y.row(0).to_vec(), vec![0.0, 0.0, 1.0, 1.0]);
    assert_eq!(y.row(3).to_vec(), vec![0.0; 4]);
    // Across z at index 2 (z > 0): x > 0, the right half, all the way up y.
    let z = &planes[2].values;
    assert_eq!(z.column(3).to_vec(), vec![1.0; 4]);
    assert_eq!(z.column(0).to_vec(), vec![0.0; 4]);
}

#[test]
fn plane_pictures_reject_bad_input() {
    let dir = std::env::temp_dir().join(format!("fogray-lab-slices-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("planes.png");
    let small = planes(&SceneBox::UNIT, 4, |p| p[0]);
    let large = planes(&SceneBox::UNIT, 5, |p| p[0]);
    let colouring = Colouring::Map {
        lo: 0.0,
        hi: 60.0,
        label: "density".into(),
    };
    let rows = [
        PlaneRow {
            title: "a",
            planes: &small,
        },
        PlaneRow {
            title: "b",
            planes: &large,
        },
    ];
    assert!(matches!(
        write_planes_png(&path, &rows, &colouring, 2),
        Err(ImageError::Shape { .. })
    ));
    assert!(matches!(
        write_planes_png(&path, &rows[..1], &colouring, 0),
        Err(ImageError::Write { .. })
    ));
    assert!(matches!(
        write_planes_png(&path, &[], &colouring, 2),
        Err(ImageError::Empty)
    ));
    assert!(!path.exists(), "nothing written on error");
    write_planes_png(&path, &rows[..1], &colouring, 2).unwrap();
    assert!(path.exists());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `ln(1 + e^x)` in the stable form, by the standard library.
fn softplus(x: f64) -> f64 {
    x.max(0.0) + (-x.abs()).exp().ln_1p()
}
