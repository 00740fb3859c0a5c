//! The BVH2 as the cache stores it (format 9): each node's box as six 16-bit steps of a grid
//! over the root's box, and its link, in 16 bytes, half of what f32 boxes take. The tracer
//! widens the nodes on the GPU (crates/render's `shaders/widen.wgsl`), which decodes a box
//! exactly as [`BvhGrid::decode`] does; the CPU walks the same decoded boxes.
//!
//! The grid steps are powers of two, so `origin + q × step` has one rounding (the sum), the
//! same with or without a fused multiply-add. Encoding rounds outwards and checks the decoded
//! box: a stored box always holds the box the bake built, so it holds every item the bake
//! put under it.

use bytemuck::{Pod, Zeroable};
use serde::{Deserialize, Serialize};

use crate::bvh::{Bvh, BvhNode, MAX_LEAF_RANGE};

/// The largest grid coordinate.
const GRID_MAX: u32 = u16::MAX as u32;

/// Bits of a link below its leaf count: a leaf's first item, or an inner node's first
/// child. The trace walk stacks links packed the same way (crates/render's `MAX_LINK_FIRST`).
pub const LINK_FIRST_BITS: u32 = 28;

// A leaf's count fits above the link's first item.
const _: () = assert!(MAX_LEAF_RANGE < 1 << (32 - LINK_FIRST_BITS));

/// `struct BvhNode { bounds: vec3<u32>, link: u32 }` in widen.wgsl: grid coordinates of the
/// box, two to a word (lo x | lo y << 16, lo z | hi x << 16, hi y | hi z << 16), and the link:
/// `first | count << 28`, count 0 for an inner node whose children are `first` and
/// `first + 1`, else a leaf over items `first .. first + count`.
#[repr(C)]
#[derive(Debug, Clone, Copy, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuBvhNode {
    pub bounds: [u32; 3],
    pub link: u32,
}

impl GpuBvhNode {
    pub fn count(&self) -> u32 {
        self.link >> LINK_FIRST_BITS
    }

    pub fn first(&self) -> u32 {
        self.link & ((1 << LINK_FIRST_BITS) - 1)
    }

    /// The six grid coordinates: lo x, y, z, hi x, y, z.
    fn coordinates(&self) -> [u32; 6] {
        let [a, b, c] = self.bounds;
        [
            a & 0xffff,
            a >> 16,
            b & 0xffff,
            b >> 16,
            c & 0xffff,
            c >> 16,
        ]
    }
}

/// The grid the boxes are stored on: `origin + q × step` per axis, q in 0..=65535, each step
/// a power of two. In the header (format 9).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct BvhGrid {
    pub origin: [f32; 3],
    pub step: [f32; 3],
}

impl Default for BvhGrid {
    fn default() -> BvhGrid {
        BvhGrid {
            origin: [0.0; 3],
            step: [1.0; 3],
        }
    }
}

/// The smallest power of two at or above `x` (≥ the smallest normal f32).
fn power_of_two_at_or_above(x: f64) -> f32 {
    let mut p = f32::MIN_POSITIVE;
    while f64::from(p) < x && p.is_finite() {
        p *= 2.0;
    }
    p
}

impl BvhGrid {
    /// A grid over `lo ..= hi` (the root's box), with room for the outward rounding.
    pub fn covering(lo: [f32; 3], hi: [f32; 3]) -> BvhGrid {
        BvhGrid {
            origin: lo,
            step: std::array::from_fn(|a| {
                power_of_two_at_or_above((f64::from(hi[a]) - f64::from(lo[a])) / 65_000.0)
            }),
        }
    }

    /// Whether the grid is one: a finite origin, and steps that are finite powers of two
    /// (normal f32s with no mantissa bits), so that decoding has one rounding.
    pub fn is_valid(&self) -> bool {
        let power_of_two = |s: f32| s.is_normal() && s > 0.0 && s.to_bits() & 0x007f_ffff == 0;
        self.origin.iter().all(|c| c.is_finite()) && self.step.iter().all(|&s| power_of_two(s))
    }

    /// Grid coordinate `q` of axis `a` (what widen.wgsl computes).
    fn at(&self, a: usize, q: u32) -> f32 {
        self.origin[a] + q as f32 * self.step[a]
    }

    /// The largest coordinate whose value is at or below `x`, or the smallest at or above.
    fn coordinate(&self, a: usize, x: f32, upward: bool) -> Option<u32> {
        let guess = (f64::from(x) - f64::from(self.origin[a])) / f64::from(self.step[a]);
        let mut q = if upward { guess.ceil() } else { guess.floor() }
            .clamp(0.0, f64::from(GRID_MAX)) as u32;
        // The sum's rounding may land either side of x: step until the bound holds.
        if upward {
            while self.at(a, q) < x {
                q = (q < GRID_MAX).then_some(q + 1)?;
            }
        } else {
            while self.at(a, q) > x {
                q = q.checked_sub(1)?;
            }
        }
        Some(q)
    }

    /// The stored node of `node`: its box rounded outwards onto the grid; `None` where the
    /// box is not finite or not on the grid, or the link does not fit.
    pub fn encode(&self, node: &BvhNode) -> Option<GpuBvhNode> {
        if node.count > MAX_LEAF_RANGE || node.first >= 1 << LINK_FIRST_BITS {
            return None;
        }
        let mut q = [0u32; 6];
        for a in 0..3 {
            if !(node.lo[a].is_finite() && node.hi[a].is_finite()) {
                return None;
            }
            q[a] = self.coordinate(a, node.lo[a], false)?;
            q[a + 3] = self.coordinate(a, node.hi[a], true)?;
        }
        Some(GpuBvhNode {
            bounds: [q[0] | q[1] << 16, q[2] | q[3] << 16, q[4] | q[5] << 16],
            link: node.first | node.count << LINK_FIRST_BITS,
        })
    }

    /// The box and link `node` stands for, as the tracer decodes it.
    pub fn decode(&self, node: &GpuBvhNode) -> BvhNode {
        let q = node.coordinates();
        BvhNode {
            lo: std::array::from_fn(|a| self.at(a, q[a])),
            count: node.count(),
            hi: std::array::from_fn(|a| self.at(a, q[a + 3])),
            first: node.first(),
        }
    }
}

impl Bvh {
    /// The tree as the cache stores it: a grid over the root's box and every node on it
    /// (boxes rounded outwards); `None` where a node cannot be stored.
    pub fn stored(&self) -> Option<(BvhGrid, Vec<GpuBvhNode>)> {
        let grid = self
            .nodes
            .first()
            .map_or_else(BvhGrid::default, |root| BvhGrid::covering(root.lo, root.hi));
        let nodes = self
            .nodes
            .iter()
            .map(|n| grid.encode(n))
            .collect::<Option<Vec<_>>>()?;
        Some((grid, nodes))
    }

    /// The tree the stored `nodes` on `grid` stand for.
    pub fn from_stored(grid: &BvhGrid, nodes: &[GpuBvhNode]) -> Bvh {
        Bvh {
            nodes: nodes.iter().map(|n| grid.decode(n)).collect(),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stored_boxes_hold_the_built_ones_within_a_grid_step() {
        let (lo, hi) = ([-3.5f32, 1e5, 0.0], [2.25f32, 1e5 + 7.0, 0.0]);
        let grid = BvhGrid::covering(lo, hi);
        assert!(grid.step.iter().all(|s| s.log2().fract() == 0.0));
        assert!(grid.is_valid() && BvhGrid::default().is_valid());
        for bad in [0.0, 3.0, f32::NAN, f32::INFINITY, -0.5] {
            let step = [grid.step[0], bad, grid.step[2]];
            assert!(!BvhGrid { step, ..grid }.is_valid(), "{bad}");
        }
        // Boxes spread over the root's by a Weyl sequence (multiples of irrationals, mod 1).
        let weyl = |k: u32, a: f64| ((f64::from(k) + 1.0) * a).fract() as f32;
        for k in 0..2000u32 {
            let t: [[f32; 2]; 3] = std::array::from_fn(|axis| {
                let (u, v) = (
                    weyl(k, 0.618_033_988_7 + axis as f64 * 0.1),
                    weyl(k, 0.414_213_562_3 + axis as f64 * 0.2),
                );
                [u.min(v), u.max(v)]
            });
            let node = BvhNode {
                lo: std::array::from_fn(|a| lo[a] + t[a][0] * (hi[a] - lo[a])),
                count: k % 16,
                hi: std::array::from_fn(|a| lo[a] + t[a][1] * (hi[a] - lo[a])),
                first: k * 7919,
            };
            let back = grid.decode(&grid.encode(&node).unwrap());
            assert_eq!((back.count, back.first), (node.count, node.first));
            for a in 0..3 {
                assert!(
                    back.lo[a] <= node.lo[a] && back.hi[a] >= node.hi[a],
                    "{node:?} {back:?}"
                );
                assert!(node.lo[a] - back.lo[a] <= grid.step[a], "{node:?} {back:?}");
                assert!(back.hi[a] - node.hi[a] <= grid.step[a], "{node:?} {back:?}");
            }
        }
        // The root's own box, the flat axis, and what the grid cannot hold.
        let root = BvhNode {
            lo,
            count: 0,
            hi,
            first: 1,
        };
        let back = grid.decode(&grid.encode(&root).unwrap());
        assert!((0..3).all(|a| back.lo[a] <= lo[a] && back.hi[a] >= hi[a]));
        let outside = BvhNode {
            lo: [lo[0] - 1.0, lo[1], lo[2]],
            ..root
        };
        assert_eq!(grid.encode(&outside), None);
        let nan = BvhNode {
            hi: [f32::NAN, hi[1], hi[2]],
            ..root
        };
        assert_eq!(grid.encode(&nan), None);
        let wide = BvhNode {
            count: MAX_LEAF_RANGE + 1,
            ..root
        };
        assert_eq!(grid.encode(&wide), None);
    }
}
