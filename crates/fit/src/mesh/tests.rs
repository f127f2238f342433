//! Meshes of models: marching cubes closes every case of its table, a ball of known radius
//! comes out closed, on its sphere and in its colour, dense and sparse grids of the same values
//! give the same mesh, levels outside the density's range are refused, and the PLY reads back
//! bit for bit through a parser written here from the format's description.

use std::collections::HashMap;

use crate::dense::DenseGrid;
use crate::mesh::{extract, march, Lattice, Level, Mesh, MeshError, MeshOptions};
use crate::model::RadianceField;
use crate::settings::SceneBox;
use crate::shading::Shading;
use crate::sparse::SparseGrid;
use crate::FitError;
use fogray_ops::grid::NodeIndex;
use fogray_ops::rays::Aabb;
use ndarray::{Array2, Array4};
use rand::{Rng, SeedableRng};

/// Checks that `triangles` form a closed, consistently oriented surface: every directed edge
/// is used by exactly one triangle and its reverse by exactly one other (so every undirected
/// edge is shared by exactly two triangles, facing the same way); no triangle repeats an index.
fn assert_closed(triangles: &[[u32; 3]], what: &str) {
    let mut directed: HashMap<(u32, u32), usize> = HashMap::new();
    for t in triangles {
        assert!(t[0] != t[1] && t[1] != t[2] && t[2] != t[0], "{what}: triangle {t:?}");
        for e in 0..3 {
            *directed.entry((t[e], t[(e + 1) % 3])).or_default() += 1;
        }
    }
    for (&(a, b), &n) in &directed {
        assert_eq!(n, 1, "{what}: edge {a}->{b} used {n} times");
        assert_eq!(directed.get(&(b, a)), Some(&1), "{what}: edge {a}->{b} has no twin");
    }
}

/// The volume a closed mesh encloses, positive when its triangles face outwards
/// (counter-clockwise seen from outside): the divergence theorem over the triangles.
fn signed_volume(positions: &[[f32; 3]], triangles: &[[u32; 3]]) -> f64 {
    let p = |i: u32| positions[i as usize].map(f64::from);
    triangles
        .iter()
        .map(|t| {
            let (a, b, c) = (p(t[0]), p(t[1]), p(t[2]));
            let cross = [
                b[1] * c[2] - b[2] * c[1],
                b[2] * c[0] - b[0] * c[2],
                b[0] * c[1] - b[1] * c[0],
            ];
            (a[0] * cross[0] + a[1] * cross[1] + a[2] * cross[2]) / 6.0
        })
        .sum()
}

fn unit_box() -> Aabb {
    Aabb::new([0.0; 3], [1.0; 3]).unwrap()
}

#[test]
fn every_case_of_the_table_gives_a_closed_outward_surface() {
    // A 2^3 lattice is one cube: its 256 inside/outside patterns are the table's cases, each
    // closed by the empty padding around the lattice.
    for case in 0..256usize {
        let values: Vec<f32> = (0..8)
            .map(|l| {
                // Node (i, j, k) at l = 4i + 2j + k; the table's corner numbering.
                let (i, j, k) = (l / 4, l / 2 % 2, l % 2);
                let corner = match (i, j, k) {
                    (0, 0, 0) => 0,
                    (1, 0, 0) => 1,
                    (1, 1, 0) => 2,
                    (0, 1, 0) => 3,
                    (0, 0, 1) => 4,
                    (1, 0, 1) => 5,
                    (1, 1, 1) => 6,
                    _ => 7,
                };
                if case >> corner & 1 == 1 {
                    0.5
                } else {
                    1.5
                }
            })
            .collect();
        let lattice = Lattice::new(2, unit_box(), values).unwrap();
        let surface = march(&lattice, 1.0).unwrap();
        if case == 255 {
            assert!(surface.triangles.is_empty());
            continue;
        }
        assert_closed(&surface.triangles, &format!("case {case}"));
        let volume = signed_volume(&surface.positions, &surface.triangles);
        assert!(volume > 0.0, "case {case}: volume {volume}");
        // Every vertex is on an edge between an inside and an outside node, at the midpoint
        // (the level is halfway between the densities; the padding's are 0, a third of the
        // way from 1.5 to 0 then): within the unit box grown by one spacing.
        for p in &surface.positions {
            assert!(p.iter().all(|&x| (-1.0..=2.0).contains(&x)), "case {case}: {p:?}");
        }
    }
}

#[test]
fn random_lattices_give_closed_surfaces_whose_vertices_sit_where_the_density_crosses() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(42);
    for trial in 0..20 {
        let n = 3 + trial % 5;
        let values: Vec<f32> = (0..n * n * n).map(|_| rng.gen_range(0.0..2.0)).collect();
        let lattice = Lattice::new(n, unit_box(), values.clone()).unwrap();
        let level = 1.0;
        let surface = march(&lattice, level).unwrap();
        assert_closed(&surface.triangles, &format!("trial {trial}"));
        assert!(signed_volume(&surface.positions, &surface.triangles) > 0.0);
        // A vertex inside the box lies on a lattice edge, where the linear interpolation of
        // the two nodes' densities is the level (within the margin kept from the nodes).
        let h = 1.0 / (n - 1) as f64;
        let value = |i: [usize; 3]| f64::from(values[(i[0] * n + i[1]) * n + i[2]]);
        for p in &surface.positions {
            let p = p.map(f64::from);
            if p.iter().any(|&x| !(0.0..=1.0).contains(&x)) {
                continue; // a cap's, towards the empty padding
            }
            let axis = (0..3)
                .max_by(|&a, &b| {
                    let frac = |x: f64| ((x / h) - (x / h).round()).abs();
                    frac(p[a]).total_cmp(&frac(p[b]))
                })
                .unwrap();
            let lo: [usize; 3] = std::array::from_fn(|a| {
                if a == axis {
                    ((p[a] / h).floor() as usize).min(n - 2)
                } else {
                    (p[a] / h).round() as usize
                }
            });
            let mut hi = lo;
            hi[axis] += 1;
            let mu = p[axis] / h - lo[axis] as f64;
            let interpolated = value(lo) + mu * (value(hi) - value(lo));
            let slope = (value(hi) - value(lo)).abs();
            assert!(
                (interpolated - level).abs() <= 1e-3 * slope + 1e-5,
                "trial {trial}: vertex {p:?} reads {interpolated}"
            );
        }
    }
}

/// The ball of the mesh tests: its centre (off the lattice's symmetry) and radius.
const CENTRE: [f64; 3] = [0.05, -0.03, 0.02];
const RADIUS: f64 = 0.6;
/// Raw colour channels everywhere; the density's inside and outside the ball.
const RAW_COLOR: [f64; 3] = [0.3, -1.2, 2.0];
const RAW_INSIDE: f64 = 200.0;
const RAW_OUTSIDE: f64 = -10.0;
const NODES: usize = 32;

fn scene_box() -> SceneBox {
    SceneBox {
        min: [-1.0; 3],
        max: [1.0; 3],
    }
}

/// The raw values of the ball on `NODES^3` nodes over [`scene_box`], `channels` a node: the
/// density, then `color(c)` for the others.
fn ball_raw(channels: usize, color: impl Fn(usize) -> f64) -> Array4<f32> {
    Array4::from_shape_fn((NODES, NODES, NODES, channels), |(i, j, k, c)| {
        if c > 0 {
            return color(c) as f32;
        }
        let r2: f64 = [i, j, k]
            .iter()
            .zip(CENTRE)
            .map(|(&x, o)| (-1.0 + 2.0 * x as f64 / (NODES - 1) as f64 - o).powi(2))
            .sum();
        (if r2 < RADIUS * RADIUS { RAW_INSIDE } else { RAW_OUTSIDE }) as f32
    })
}

fn dense_ball() -> DenseGrid<f32> {
    let mut model = DenseGrid::<f32>::new(scene_box(), NODES, 0.0, 0.0).unwrap();
    let id = model.grid_id();
    model
        .params_mut()
        .get_mut(id)
        .unwrap()
        .assign(&ball_raw(4, |c| RAW_COLOR[c - 1]));
    model
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

fn to_u8(x: f64) -> u8 {
    (x * 255.0).round() as u8
}

/// Half the density inside: the surface halfway along each edge that leaves the ball.
fn half_inside() -> MeshOptions {
    let softplus = |x: f64| x.exp().ln_1p();
    MeshOptions {
        level: Level::Density(0.5 * softplus(RAW_INSIDE)),
        resolution: None,
    }
}

#[test]
fn a_ball_of_constant_density_gives_a_closed_mesh_on_its_sphere_in_its_colour() {
    let model = dense_ball();
    let extracted = extract(&model, &half_inside()).unwrap();
    let mesh = &extracted.mesh;
    assert_eq!(extracted.resolution, NODES);
    assert!(mesh.triangles.len() > 1000, "{} triangles", mesh.triangles.len());
    assert_closed(&mesh.triangles, "ball");
    // Each vertex is at the middle of a lattice edge from a node inside the sphere to one
    // outside it: within half an edge of the sphere.
    let h = 2.0 / (NODES - 1) as f64;
    let worst = mesh
        .positions
        .iter()
        .map(|p| {
            let r: f64 = p.iter().zip(CENTRE).map(|(&x, o)| (f64::from(x) - o).powi(2)).sum();
            (r.sqrt() - RADIUS).abs()
        })
        .fold(0.0, f64::max);
    assert!(worst <= 0.5 * h + 1e-5, "a vertex {worst} from the sphere (h = {h})");
    // The enclosed volume is the ball's, within the lattice's resolution (measured 0.6 %
    // below it), and positive: the triangles face outwards.
    let volume = signed_volume(&mesh.positions, &mesh.triangles);
    let ball = 4.0 / 3.0 * std::f64::consts::PI * RADIUS.powi(3);
    assert!((volume / ball - 1.0).abs() < 0.03, "volume {volume}, the ball's {ball}");
    // The colour is the constant one, through the sigmoid, rounded once to 8 bits.
    let want = RAW_COLOR.map(|x| to_u8(sigmoid(x)));
    assert_eq!(mesh.colors.len(), mesh.positions.len());
    assert!(
        mesh.colors.iter().all(|&c| c == want),
        "{:?} != {want:?}",
        mesh.colors[0]
    );
}

#[test]
fn a_sparse_grid_of_the_same_values_gives_the_same_mesh() {
    let dense = dense_ball();
    let shading = Shading::new(0.0, 0).unwrap();
    let index = NodeIndex::full([NODES; 3]).unwrap();
    let mut sparse = SparseGrid::<f32>::new(scene_box(), NODES, index, shading, 0.0).unwrap();
    let raw = ball_raw(4, |c| RAW_COLOR[c - 1]);
    let rows = raw.into_shape_with_order((NODES * NODES * NODES, 4)).unwrap();
    let id = sparse.params().id(crate::sparse::DATA).unwrap();
    sparse.params_mut().get_mut(id).unwrap().assign(&rows);
    let a = extract(&dense, &half_inside()).unwrap();
    let b = extract(&sparse, &half_inside()).unwrap();
    assert_eq!(a, b);
}

#[test]
fn a_view_dependent_colour_gives_its_degree_0_term_through_the_sigmoid() {
    // Degree 1: 4 coefficients a channel; the degree-0 ones carry the colour, the others
    // vary with the direction and must not reach the vertex colour.
    let mut model = DenseGrid::<f32>::view_dependent(scene_box(), NODES, 0.0, 0.0, 1).unwrap();
    let dc = [1.5, -0.4, 0.8];
    let raw = ball_raw(13, |c| {
        let (channel, basis) = ((c - 1) / 4, (c - 1) % 4);
        if basis == 0 {
            dc[channel]
        } else {
            0.7 * basis as f64 - channel as f64
        }
    });
    let id = model.grid_id();
    model.params_mut().get_mut(id).unwrap().assign(&raw);
    let mesh = extract(&model, &half_inside()).unwrap().mesh;
    assert_closed(&mesh.triangles, "view-dependent ball");
    // Y_0 = 1 / (2 sqrt(pi)).
    let y0 = 0.5 / std::f64::consts::PI.sqrt();
    let want = dc.map(|k| to_u8(sigmoid(y0 * k)));
    assert!(
        mesh.colors.iter().all(|&c| c == want),
        "{:?} != {want:?}",
        mesh.colors[0]
    );
    // And the same through the model's method, unrounded.
    let at = Array2::from_shape_vec((1, 3), vec![0.1f32, 0.2, 0.3]).unwrap();
    let colors = model.base_colors(at.view()).unwrap();
    for (c, k) in dc.iter().enumerate() {
        assert!((f64::from(colors[[0, c]]) - sigmoid(y0 * k)).abs() < 1e-6);
    }
}

#[test]
fn a_finer_lattice_still_closes_the_ball_within_a_grid_voxel() {
    let model = dense_ball();
    let options = MeshOptions {
        resolution: Some(45),
        ..half_inside()
    };
    let extracted = extract(&model, &options).unwrap();
    assert_eq!(extracted.resolution, 45);
    assert_closed(&extracted.mesh.triangles, "ball at 45^3");
    let h = 2.0 / (NODES - 1) as f64;
    for p in &extracted.mesh.positions {
        let r: f64 = p.iter().zip(CENTRE).map(|(&x, o)| (f64::from(x) - o).powi(2)).sum();
        assert!((r.sqrt() - RADIUS).abs() <= h, "{p:?}");
    }
}

#[test]
fn an_opacity_is_the_density_that_absorbs_it_over_one_step() {
    let model = dense_ball();
    let step = model.sample_step();
    for a in [0.01, 0.5, 0.99] {
        let sigma = Level::Opacity(a).density(step).unwrap();
        assert!((1.0 - (-sigma * step).exp() - a).abs() < 1e-12, "{a}: {sigma}");
        let extracted = extract(
            &model,
            &MeshOptions {
                level: Level::Opacity(a),
                resolution: None,
            },
        )
        .unwrap();
        assert_eq!(extracted.level.to_bits(), sigma.to_bits());
    }
    assert_eq!(Level::default(), Level::Opacity(0.1));
}

#[test]
fn levels_resolutions_and_opacities_outside_their_range_are_refused() {
    let model = dense_ball();
    let options = |level, resolution| MeshOptions { level, resolution };
    let refused = |o: MeshOptions| match extract(&model, &o) {
        Err(FitError::Mesh(e)) => e,
        other => panic!("{o:?}: {other:?}"),
    };
    for level in [1e9, 1e-9, -1.0, f64::NAN] {
        match refused(options(Level::Density(level), None)) {
            MeshError::Level {
                range: Some((lo, hi)),
                opacity: None,
                ..
            } => {
                // The range is the lattice's: softplus of the raw inside and outside.
                assert!((lo - (-10f64).exp().ln_1p()).abs() < 1e-9, "{lo}");
                assert!((hi / RAW_INSIDE - 1.0).abs() < 1e-6, "{hi}");
            }
            e => panic!("{level}: {e:?}"),
        }
    }
    let message = refused(options(Level::Density(1e9), None)).to_string();
    assert!(message.contains("range") && message.contains("1000000000"), "{message}");
    for a in [0.0, 1.0, -0.5, 2.0, f64::NAN] {
        assert!(matches!(
            refused(options(Level::Opacity(a), None)),
            MeshError::Opacity(_)
        ));
    }
    for n in [0, 1] {
        assert_eq!(refused(options(Level::default(), Some(n))), MeshError::Resolution(n));
    }
    assert_eq!(
        refused(options(Level::default(), Some(usize::MAX / 2))),
        MeshError::Resolution(usize::MAX / 2)
    );
}

/// What a PLY file holds, parsed from its description alone.
struct Ply {
    header: Vec<String>,
    positions: Vec<[f32; 3]>,
    colors: Vec<[u8; 3]>,
    faces: Vec<Vec<i32>>,
}

fn parse_ply(bytes: &[u8]) -> Ply {
    let end = b"end_header\n";
    let at = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
    let header: Vec<String> = std::str::from_utf8(&bytes[..at])
        .unwrap()
        .lines()
        .map(str::to_string)
        .collect();
    let count = |element: &str| -> usize {
        let line = header
            .iter()
            .find(|l| l.starts_with(&format!("element {element} ")))
            .unwrap();
        line.rsplit(' ').next().unwrap().parse().unwrap()
    };
    let (vertices, faces) = (count("vertex"), count("face"));
    let mut body = &bytes[at..];
    let mut take = |n: usize| {
        let (head, rest) = body.split_at(n);
        body = rest;
        head.to_vec()
    };
    let mut ply = Ply {
        header: header.clone(),
        positions: Vec::new(),
        colors: Vec::new(),
        faces: Vec::new(),
    };
    for _ in 0..vertices {
        let b = take(15);
        ply.positions.push(std::array::from_fn(|a| {
            f32::from_le_bytes(b[4 * a..4 * a + 4].try_into().unwrap())
        }));
        ply.colors.push([b[12], b[13], b[14]]);
    }
    for _ in 0..faces {
        let n = take(1)[0] as usize;
        let b = take(4 * n);
        ply.faces.push(
            b.chunks_exact(4)
                .map(|c| i32::from_le_bytes(c.try_into().unwrap()))
                .collect(),
        );
    }
    assert!(body.is_empty(), "{} bytes after the faces", body.len());
    ply
}

#[test]
fn the_ply_reads_back_bit_for_bit() {
    let mesh = extract(&dense_ball(), &half_inside()).unwrap().mesh;
    let mut bytes = Vec::new();
    mesh.write_ply("a ball", &mut bytes).unwrap();
    let ply = parse_ply(&bytes);
    assert_eq!(
        ply.header,
        [
            "ply",
            "format binary_little_endian 1.0",
            "comment a ball",
            &format!("element vertex {}", mesh.positions.len()),
            "property float x",
            "property float y",
            "property float z",
            "property uchar red",
            "property uchar green",
            "property uchar blue",
            &format!("element face {}", mesh.triangles.len()),
            "property list uchar int vertex_indices",
            "end_header",
        ]
    );
    let bits = |p: &[[f32; 3]]| -> Vec<u32> { p.iter().flatten().map(|x| x.to_bits()).collect() };
    assert_eq!(bits(&ply.positions), bits(&mesh.positions));
    assert_eq!(ply.colors, mesh.colors);
    let faces: Vec<Vec<i32>> = mesh
        .triangles
        .iter()
        .map(|t| t.iter().map(|&i| i as i32).collect())
        .collect();
    assert_eq!(ply.faces, faces);
    // A few values by hand, against the mesh itself: the first vertex and the last face.
    assert_eq!(
        &bytes[ply.header.iter().map(|l| l.len() + 1).sum::<usize>()..][..4],
        &mesh.positions[0][0].to_le_bytes()
    );
    assert_eq!(&bytes[bytes.len() - 13..], {
        let t = mesh.triangles.last().unwrap();
        let mut want = vec![3u8];
        for i in t {
            want.extend((*i as i32).to_le_bytes());
        }
        want
    });
}

#[test]
fn a_mesh_that_does_not_hold_together_is_not_written() {
    let bad = [
        Mesh {
            positions: vec![[0.0; 3]; 3],
            colors: vec![[0; 3]; 2],
            triangles: vec![[0, 1, 2]],
        },
        Mesh {
            positions: vec![[0.0; 3]; 3],
            colors: vec![[0; 3]; 3],
            triangles: vec![[0, 1, 3]],
        },
    ];
    for mesh in &bad {
        let mut bytes = Vec::new();
        let e = mesh.write_ply("", &mut bytes).unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
        assert!(bytes.is_empty());
    }
    let e = Mesh::default().write_ply("two\nlines", &mut Vec::new()).unwrap_err();
    assert_eq!(e.kind(), std::io::ErrorKind::InvalidInput);
}
