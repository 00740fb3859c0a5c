//! Spray: components of the particles too small or too scattered to support a surface, drawn
//! as spheres (a blob per compact component, else a sphere per particle).

use rayon::prelude::*;

use crate::real::{Real, V3};
use crate::runs::LIST_BLOCK;

/// A component whose points lie farther apart on average than this many dense spacings is
/// spray, whatever its size.
const SPRAY_GAP: f64 = 1.25;

/// Spray drawn as what it is: a small sphere (a blob or a particle).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Sphere<T> {
    pub centre: V3<T>,
    pub radius: T,
}

/// The spheres that draw spray, and (point, sphere) for each point of it. Spray is a
/// component (points linked where one is in the other's list within its h, the `links` the
/// lists stage found) that cannot support a surface: fewer points than `below`, or no wider
/// than its smoothing length (every fit in it would span it whole), or no wider than that
/// across its second principal axis (a thread: a string of droplets, a jet thinner than a
/// fit, which every fit would span across and draw as an open shell). A
/// compact component of 4 points or more becomes one blob: its centroid, radius the members'
/// RMS distance to it plus half the dense spacing (a particle's radius). Otherwise (fewer
/// points, or a scattered component whose members stand out of that blob by more than a
/// spacing) each point is a sphere of half the dense spacing: never a sphere that bounds
/// particles far apart.
pub(crate) fn droplets<T: Real>(
    points: &[[f64; 3]],
    links: &[Vec<(u32, u32)>],
    components: Option<Vec<u32>>,
    ball_h: &(dyn Fn(usize) -> f64 + Sync),
    nearest: &[f64],
    spacing: f64,
    below: usize,
) -> (Vec<Sphere<T>>, Vec<(u32, u32)>) {
    if below <= 1 {
        return (Vec::new(), Vec::new());
    }
    let n = points.len();
    let d2 = |a: [f64; 3], b: [f64; 3]| {
        (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2) + (a[2] - b[2]).powi(2)
    };
    // Members grouped by component (each root is its component's smallest index), in one
    // array: components in order of their first member, members in index order.
    // Joined by the search where it did (the GPU's), else here.
    let roots = match components {
        Some(roots) if roots.len() == n => roots,
        _ => component_roots(n, links),
    };
    let mut first = vec![0u32; n + 1];
    for &r in &roots {
        first[r as usize + 1] += 1;
    }
    for k in 0..n {
        first[k + 1] += first[k];
    }
    let mut fill = first.clone();
    let mut order = vec![0usize; n];
    for (i, &r) in roots.iter().enumerate() {
        order[fill[r as usize] as usize] = i;
        fill[r as usize] += 1;
    }
    let components: Vec<&[usize]> = (0..n)
        .filter_map(|r| {
            let m = &order[first[r] as usize..first[r + 1] as usize];
            (!m.is_empty()).then_some(m)
        })
        .collect();
    let distance = |p: [f64; 3], c: [f64; 3]| d2(p, c).sqrt();
    let particle = 0.5 * spacing;
    /// What a component is drawn as.
    enum Spray {
        Surface,
        Blob { centre: [f64; 3], radius: f64 },
        Particles,
    }
    // Each component on its own, all at once; a large one's sums by blocks too.
    let kinds: Vec<Spray> = components
        .par_iter()
        .map(|m| {
            let len = m.len() as f64;
            let [sx, sy, sz, gaps] = sum_over(m, |i| {
                let p = points[i];
                [p[0], p[1], p[2], nearest[i]]
            });
            let c = [sx / len, sy / len, sz / len];
            let far = m
                .par_iter()
                .with_min_len(SUM_BLOCK)
                .map(|&i| distance(points[i], c))
                .reduce(|| 0.0, f64::max);
            // A surface: enough points, wider than h, in two directions at least, and
            // sampled about as densely as the fluid (spray spread thin is not a sheet to
            // stretch across its gaps).
            let mean_gap = gaps / len;
            let h = ball_h(m[0]);
            if m.len() >= below
                && far > h
                && mean_gap <= SPRAY_GAP * spacing
                && second_half_width(points, m, c) > h
            {
                return Spray::Surface;
            }
            let [squares] = sum_over(m, |i| [distance(points[i], c).powi(2)]);
            let rms = (squares / len).sqrt();
            // A blob only where the particles fill it: no wider than their own volume's
            // sphere (N particles of radius s / 2 fill one of radius (s / 2)·∛N), with slack.
            let filled = rms <= 1.25 * particle * (m.len() as f64).cbrt();
            if m.len() >= 4 && far <= rms + spacing && filled {
                Spray::Blob {
                    centre: c,
                    radius: rms + particle,
                }
            } else {
                Spray::Particles
            }
        })
        .collect();
    // Spheres numbered in order of their first member, so the result does not depend on threads.
    let mut spheres = Vec::new();
    let mut marks = Vec::new();
    for (m, kind) in components.iter().zip(kinds) {
        match kind {
            Spray::Surface => {}
            Spray::Blob { centre, radius } => {
                let d = spheres.len() as u32;
                marks.extend(m.iter().map(|&i| (i as u32, d)));
                spheres.push(Sphere {
                    centre: V3::from_f64(centre),
                    radius: T::c(radius),
                });
            }
            Spray::Particles => {
                for &i in *m {
                    marks.push((i as u32, spheres.len() as u32));
                    spheres.push(Sphere {
                        centre: V3::from_f64(points[i]),
                        radius: T::c(particle),
                    });
                }
            }
        }
    }
    (spheres, marks)
}

/// The half-width of `members` (centroid `c`) along the second of their principal axes:
/// √3 σ₂, σ₂² the middle eigenvalue of their covariance. A sphere's radius for points on a
/// sphere (σ² = R²/3 along every axis); a thread's thickness for points along a line; a
/// sheet's half-width in its plane.
fn second_half_width(points: &[[f64; 3]], members: &[usize], c: [f64; 3]) -> f64 {
    let len = members.len() as f64;
    let [xx, xy, xz, yy, yz, zz] = sum_over(members, |i| {
        let d = [
            points[i][0] - c[0],
            points[i][1] - c[1],
            points[i][2] - c[2],
        ];
        [
            d[0] * d[0],
            d[0] * d[1],
            d[0] * d[2],
            d[1] * d[1],
            d[1] * d[2],
            d[2] * d[2],
        ]
    });
    let cov = [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]].map(|row| row.map(|v| v / len));
    let (mut values, _) = crate::support::jacobi_eigen(cov);
    values.sort_by(f64::total_cmp);
    (3.0 * values[1].max(0.0)).sqrt()
}

/// Members per block of [`sum_over`].
const SUM_BLOCK: usize = 4096;

/// Σ `term(i)` over `members`, by blocks of [`SUM_BLOCK`] summed in order: the same sum
/// whatever the threads, and a component of a million points (the fluid itself) summed on
/// every core: one thread summing it took most of the stage.
fn sum_over<const K: usize>(
    members: &[usize],
    term: impl Fn(usize) -> [f64; K] + Sync,
) -> [f64; K] {
    let add = |mut s: [f64; K], t: [f64; K]| {
        for (a, b) in s.iter_mut().zip(t) {
            *a += b;
        }
        s
    };
    let block = |c: &[usize]| c.iter().fold([0.0; K], |s, &i| add(s, term(i)));
    if members.len() <= SUM_BLOCK {
        return block(members);
    }
    let blocks: Vec<[f64; K]> = members.par_chunks(SUM_BLOCK).map(block).collect();
    blocks.into_iter().fold([0.0; K], add)
}

/// Each point's component (points joined by `links`), named by its smallest index.
pub fn component_roots(n: usize, links: &[Vec<(u32, u32)>]) -> Vec<u32> {
    // Components by union-find, every root linked to a smaller one, so that each component's
    // root is its smallest index whatever order the links come in. The lists stage gives the
    // links by blocks of consecutive points (in a bake, where points come in spatial order):
    // the links within a block are joined by that block's own task in its own slice of the
    // parents, all blocks at once, and only the links between blocks (a tenth of them), as
    // pairs of block roots, one after another. A concurrent union-find over all links
    // measured slower on 16 threads than this on one: every thread's links led to the same
    // few roots.
    fn root(parent: &mut [u32], offset: u32, mut i: u32) -> u32 {
        while parent[(i - offset) as usize] != i {
            let up = parent[(parent[(i - offset) as usize] - offset) as usize];
            parent[(i - offset) as usize] = up;
            i = up;
        }
        i
    }
    fn join(parent: &mut [u32], offset: u32, i: u32, j: u32) {
        let (ri, rj) = (root(parent, offset, i), root(parent, offset, j));
        if ri != rj {
            parent[(ri.max(rj) - offset) as usize] = ri.min(rj);
        }
    }
    let block = LIST_BLOCK;
    let by_block = links.len() == n.div_ceil(block);
    let local = |b: usize, (i, j): (u32, u32)| {
        by_block && i as usize / block == b && j as usize / block == b
    };
    let mut parent: Vec<u32> = (0..n as u32).collect();
    if by_block {
        parent
            .par_chunks_mut(block)
            .zip(links)
            .enumerate()
            .for_each(|(b, (parent, links))| {
                let offset = (b * block) as u32;
                for &(i, j) in links {
                    if local(b, (i, j)) {
                        join(parent, offset, i, j);
                    }
                }
            });
    }
    // The links between blocks, as pairs of the roots their ends have after the blocks' own
    // joins, each pair once: most join two blocks already joined by another link, and
    // joining all of them one after another took most of the stage at 1M points.
    let parent_ref = &parent;
    let root_of = |i: u32| {
        let mut i = i;
        while parent_ref[i as usize] != i {
            i = parent_ref[i as usize];
        }
        i
    };
    let mut between: Vec<(u32, u32)> = links
        .par_iter()
        .enumerate()
        .flat_map_iter(|(b, links)| {
            let mut pairs: Vec<(u32, u32)> = links
                .iter()
                .filter(|&&l| !local(b, l))
                .map(|&(i, j)| {
                    let (ri, rj) = (root_of(i), root_of(j));
                    (ri.min(rj), ri.max(rj))
                })
                .filter(|(a, b)| a != b)
                .collect();
            pairs.sort_unstable();
            pairs.dedup();
            pairs
        })
        .collect();
    between.par_sort_unstable();
    between.dedup();
    for (i, j) in between {
        join(&mut parent, 0, i, j);
    }
    (0..n)
        .into_par_iter()
        .map(|mut i| {
            while parent[i] as usize != i {
                i = parent[i] as usize;
            }
            i as u32
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Components against a breadth-first search over the same links, given by blocks (as
    /// the lists stage gives them, links within and between blocks) and all in one list.
    #[test]
    fn component_roots_are_each_components_smallest_index() {
        let n = 5 * LIST_BLOCK + 77;
        let mut x = 99u32;
        let mut next = move |m: u32| {
            x ^= x << 13;
            x ^= x >> 17;
            x ^= x << 5;
            x % m
        };
        // Chains within blocks, a few long jumps between them, isolated points.
        let mut all: Vec<(u32, u32)> = Vec::new();
        for i in 0..n as u32 {
            match next(10) {
                0..=6 if i + 1 < n as u32 => all.push((i, i + 1 + next(3).min(n as u32 - i - 2))),
                7 => all.push((i, next(n as u32))),
                _ => {}
            }
        }
        let mut adjacency = vec![Vec::new(); n];
        for &(i, j) in &all {
            adjacency[i as usize].push(j as usize);
            adjacency[j as usize].push(i as usize);
        }
        let mut want = vec![u32::MAX; n];
        for s in 0..n {
            if want[s] != u32::MAX {
                continue;
            }
            let mut stack = vec![s];
            want[s] = s as u32;
            while let Some(i) = stack.pop() {
                for &j in &adjacency[i] {
                    if want[j] == u32::MAX {
                        want[j] = s as u32;
                        stack.push(j);
                    }
                }
            }
        }
        let mut by_block = vec![Vec::new(); n.div_ceil(LIST_BLOCK)];
        for &(i, j) in &all {
            by_block[i as usize / LIST_BLOCK].push((i, j));
        }
        assert_eq!(component_roots(n, &by_block), want, "links by block");
        assert_eq!(component_roots(n, &[all]), want, "links in one list");
    }

    /// A component's sums by blocks are the same on one thread as on several, and the
    /// second half-width of a million points on a sphere of radius 2 (a Fibonacci lattice,
    /// the fluid of a 1M step) is that radius: σ² = R²/3 along every axis.
    #[test]
    fn a_large_components_sums_do_not_depend_on_threads() {
        let n = 1_000_000;
        let golden = std::f64::consts::PI * (3.0 - 5f64.sqrt());
        let points: Vec<[f64; 3]> = (0..n)
            .map(|i| {
                let z = 1.0 - 2.0 * (i as f64 + 0.5) / n as f64;
                let r = (1.0 - z * z).sqrt();
                let a = golden * i as f64;
                [
                    2.0 * r * a.cos() + 0.25,
                    2.0 * r * a.sin() - 1.0,
                    2.0 * z + 3.0,
                ]
            })
            .collect();
        let members: Vec<usize> = (0..n).collect();
        let width_on = |threads: usize| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                let [x, y, z] = sum_over(&members, |i| points[i]);
                let c = [x / n as f64, y / n as f64, z / n as f64];
                (c, second_half_width(&points, &members, c))
            })
        };
        let (one, three) = (width_on(1), width_on(3));
        assert_eq!(one, three, "sums on 1 and 3 threads");
        let (c, width) = one;
        for (got, want) in c.iter().zip([0.25, -1.0, 3.0]) {
            assert!((got - want).abs() < 1e-6, "centroid {c:?}");
        }
        assert!((width - 2.0).abs() < 1e-4, "second half-width {width}");
    }
}
