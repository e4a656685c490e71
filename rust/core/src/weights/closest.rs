//! The closest point of a triangle mesh to a query point within a radius: a bounding-volume
//! hierarchy over the triangles (split at the median of the longest axis) and the closest point
//! on a triangle with its barycentric coordinates (Ericson, *Real-Time Collision Detection*,
//! 5.1.5).

use glam::Vec3;

/// Triangles per leaf at most.
const LEAF: usize = 4;

struct Node {
    lo: Vec3,
    hi: Vec3,
    /// Leaf: first triangle in `order` and count; inner: index of the first child (the second
    /// follows it) and 0.
    first: u32,
    count: u32,
}

/// A closest point: the triangle, the barycentric weights of its corners, the distance.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Hit {
    pub triangle: u32,
    pub bary: [f32; 3],
    pub distance: f32,
}

pub(crate) struct Bvh<'a> {
    positions: &'a [[f32; 3]],
    triangles: &'a [[u32; 3]],
    order: Vec<u32>,
    nodes: Vec<Node>,
}

impl<'a> Bvh<'a> {
    pub fn new(positions: &'a [[f32; 3]], triangles: &'a [[u32; 3]]) -> Bvh<'a> {
        let corners = |t: u32| triangles[t as usize].map(|i| Vec3::from_array(positions[i as usize]));
        let centers: Vec<Vec3> = (0..triangles.len() as u32).map(|t| corners(t).iter().sum::<Vec3>() / 3.0).collect();
        let mut bvh = Bvh { positions, triangles, order: (0..triangles.len() as u32).collect(), nodes: Vec::new() };
        if !triangles.is_empty() {
            bvh.nodes.push(Node { lo: Vec3::ZERO, hi: Vec3::ZERO, first: 0, count: 0 });
            let mut stack = vec![(0usize, 0usize, triangles.len())];
            while let Some((node, start, end)) = stack.pop() {
                let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
                for &t in &bvh.order[start..end] {
                    for c in corners(t) {
                        lo = lo.min(c);
                        hi = hi.max(c);
                    }
                }
                if end - start <= LEAF {
                    bvh.nodes[node] = Node { lo, hi, first: start as u32, count: (end - start) as u32 };
                    continue;
                }
                let axis = (hi - lo).max_position();
                let mid = (start + end) / 2;
                bvh.order[start..end].select_nth_unstable_by(mid - start, |&a, &b| {
                    centers[a as usize][axis].total_cmp(&centers[b as usize][axis])
                });
                let child = bvh.nodes.len();
                bvh.nodes.push(Node { lo: Vec3::ZERO, hi: Vec3::ZERO, first: 0, count: 0 });
                bvh.nodes.push(Node { lo: Vec3::ZERO, hi: Vec3::ZERO, first: 0, count: 0 });
                bvh.nodes[node] = Node { lo, hi, first: child as u32, count: 0 };
                stack.push((child, start, mid));
                stack.push((child + 1, mid, end));
            }
        }
        bvh
    }

    /// The closest point of the mesh to `p` no farther than `radius`, if any (ties: the lower
    /// triangle index).
    pub fn closest(&self, p: Vec3, radius: f32) -> Option<Hit> {
        if self.nodes.is_empty() {
            return None;
        }
        let mut best: Option<Hit> = None;
        let mut limit = radius * radius;
        let mut stack: Vec<u32> = vec![0];
        while let Some(n) = stack.pop() {
            let node = &self.nodes[n as usize];
            let gap = (node.lo - p).max(p - node.hi).max(Vec3::ZERO);
            if gap.length_squared() > limit {
                continue;
            }
            if node.count > 0 {
                for &t in &self.order[node.first as usize..(node.first + node.count) as usize] {
                    let tri = self.triangles[t as usize].map(|i| Vec3::from_array(self.positions[i as usize]));
                    let (q, bary) = closest_on_triangle(p, tri);
                    let d2 = q.distance_squared(p);
                    let better = match best {
                        None => d2 <= limit,
                        Some(h) => d2 < limit || (d2 == limit && t < h.triangle),
                    };
                    if better {
                        limit = d2;
                        best = Some(Hit { triangle: t, bary, distance: d2.sqrt() });
                    }
                }
            } else {
                // Nearer child last, so it is searched first.
                let (a, b) = (node.first, node.first + 1);
                let da = self.box_gap(a, p);
                let db = self.box_gap(b, p);
                if da < db {
                    stack.push(b);
                    stack.push(a);
                } else {
                    stack.push(a);
                    stack.push(b);
                }
            }
        }
        best
    }

    fn box_gap(&self, n: u32, p: Vec3) -> f32 {
        let node = &self.nodes[n as usize];
        (node.lo - p).max(p - node.hi).max(Vec3::ZERO).length_squared()
    }
}

/// The point of triangle `t` closest to `p` and its barycentric coordinates.
pub(crate) fn closest_on_triangle(p: Vec3, t: [Vec3; 3]) -> (Vec3, [f32; 3]) {
    let [a, b, c] = t;
    let (ab, ac, ap) = (b - a, c - a, p - a);
    let (d1, d2) = (ab.dot(ap), ac.dot(ap));
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0]);
    }
    let bp = p - b;
    let (d3, d4) = (ab.dot(bp), ac.dot(bp));
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0]);
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0]);
    }
    let cp = p - c;
    let (d5, d6) = (ab.dot(cp), ac.dot(cp));
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0]);
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w]);
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w]);
    }
    let denom = va + vb + vc;
    if !(denom.abs() > 0.0) || !denom.is_finite() {
        // A degenerate triangle: its nearest corner.
        let ds = [a, b, c].map(|x| x.distance_squared(p));
        let i = (0..3).min_by(|&i, &j| ds[i].total_cmp(&ds[j])).unwrap_or(0);
        let mut bary = [0.0; 3];
        bary[i] = 1.0;
        return (t[i], bary);
    }
    let v = vb / denom;
    let w = vc / denom;
    (a + ab * v + ac * w, [1.0 - v - w, v, w])
}
