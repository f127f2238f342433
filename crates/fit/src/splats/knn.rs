//! The mean distance from each point to its 3 nearest others, by bucketing the points into a
//! uniform grid of about one point per cell and searching rings of cells outwards: expected
//! O(N) for points spread through a volume, where the naive pairwise search is O(N²).

use std::collections::HashMap;

/// How many neighbours the initial scale averages over (3DGS's choice).
pub(crate) const NEIGHBOURS: usize = 3;

/// For each point, the mean distance to its [`NEIGHBOURS`] nearest other points (fewer where
/// there are fewer others; 0 for a lone point). Expects finite coordinates.
pub(crate) fn mean_neighbour_distance(points: &[[f64; 3]]) -> Vec<f64> {
    let n = points.len();
    if n < 2 {
        return vec![0.0; n];
    }
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        for a in 0..3 {
            lo[a] = lo[a].min(p[a]);
            hi[a] = hi[a].max(p[a]);
        }
    }
    let volume: f64 = (0..3).map(|a| (hi[a] - lo[a]).max(1e-12)).product();
    let widest = (0..3).map(|a| hi[a] - lo[a]).fold(0.0, f64::max);
    // About one point per cell, so that a ring of cells holds a few points; but never finer
    // than the widest extent over the cube root of the count, or points on a plane or a line
    // (a flat volume) would be cells apart by the millions and the rings would never end:
    // with this floor, at most cbrt(n) + 1 rings span every point.
    let cell = (volume / n as f64).cbrt().max(widest / (n as f64).cbrt()).max(1e-9);
    let key = |p: &[f64; 3]| -> [i64; 3] { [0, 1, 2].map(|a| ((p[a] - lo[a]) / cell).floor() as i64) };
    let mut buckets: HashMap<[i64; 3], Vec<usize>> = HashMap::new();
    for (i, p) in points.iter().enumerate() {
        buckets.entry(key(p)).or_default().push(i);
    }
    let want = NEIGHBOURS.min(n - 1);
    points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = key(p);
            let mut best: Vec<f64> = Vec::with_capacity(want + 1);
            let mut ring = 0i64;
            loop {
                for dx in -ring..=ring {
                    for dy in -ring..=ring {
                        for dz in -ring..=ring {
                            // Only the shell of this ring: inner cells were searched before.
                            if dx.abs().max(dy.abs()).max(dz.abs()) != ring {
                                continue;
                            }
                            let Some(list) = buckets.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                                continue;
                            };
                            for &j in list.iter().filter(|&&j| j != i) {
                                let q = points[j];
                                let d = ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt();
                                best.push(d);
                                best.sort_by(f64::total_cmp);
                                best.truncate(want);
                            }
                        }
                    }
                }
                // Every point beyond this ring is at least `ring * cell` away: once the
                // kept ones are closer, no later ring can displace them.
                if best.len() == want && best[want - 1] <= ring as f64 * cell {
                    break;
                }
                ring += 1;
            }
            best.iter().sum::<f64>() / want as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn agrees_with_the_pairwise_search() {
        // A jittered lattice plus a far outlier, against the O(N²) definition.
        let mut points: Vec<[f64; 3]> = (0..125)
            .map(|i| {
                let (a, b, c) = ((i % 5) as f64, ((i / 5) % 5) as f64, (i / 25) as f64);
                [a + 0.1 * (i as f64).sin(), b * 0.7, c * 1.3 + 0.05 * (i as f64).cos()]
            })
            .collect();
        points.push([40.0, -3.0, 2.0]);
        let fast = mean_neighbour_distance(&points);
        for (i, p) in points.iter().enumerate() {
            let mut d: Vec<f64> = points
                .iter()
                .enumerate()
                .filter(|&(j, _)| j != i)
                .map(|(_, q)| ((p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)).sqrt())
                .collect();
            d.sort_by(f64::total_cmp);
            let slow = d[..3].iter().sum::<f64>() / 3.0;
            assert!((fast[i] - slow).abs() < 1e-12, "{i}: {} vs {slow}", fast[i]);
        }
    }

    #[test]
    fn few_points() {
        assert_eq!(mean_neighbour_distance(&[]), Vec::<f64>::new());
        assert_eq!(mean_neighbour_distance(&[[1.0; 3]]), vec![0.0]);
        assert_eq!(mean_neighbour_distance(&[[0.0; 3], [3.0, 4.0, 0.0]]), vec![5.0, 5.0]);
    }

    #[test]
    fn points_on_a_line_end_the_search() {
        // A flat volume (extent 0 in two axes) once made cells of 1e-9 and rings without end.
        let points: Vec<[f64; 3]> = (0..1000).map(|i| [i as f64, 0.0, 0.0]).collect();
        let d = mean_neighbour_distance(&points);
        // Interior points: neighbours at 1, 1 and 2.
        assert!((d[500] - 4.0 / 3.0).abs() < 1e-12, "{}", d[500]);
        assert!((d[0] - 2.0).abs() < 1e-12, "{}", d[0]);
    }
}
