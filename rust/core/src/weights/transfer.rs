//! Weight transfer from a skinned body to clothing (Abdrashitov et al. 2023): closest-point
//! matching with distance and normal tests, then inpainting of the unmatched vertices.

use std::collections::VecDeque;

use glam::Vec3;
use rayon::prelude::*;

use super::closest::Bvh;
use super::envelope::Envelope;
use super::laplacian::{q_row, stiffness_and_mass, Csr};
use super::mesh::{diagonal, parts, vertex_normals, Neighbours};
use super::solve::conjugate_gradients;
use super::sparse::{self, Pair};
use super::{check_points, check_range, check_triangles, smooth, Progress, WeightsError, MAX_WEIGHT_INFLUENCES};
use crate::skin::Influences;

/// One row of a sparse matrix: (column, value) pairs.
type SparseRow = Vec<(u32, f64)>;
/// A solved unknown: its vertex and weights.
type Solved = (u32, Vec<Pair>);

/// The paper's distance threshold: this fraction of the clothing's bounding-box diagonal.
pub const DEFAULT_DISTANCE_FRACTION: f32 = 0.05;
/// The paper's normal threshold, in degrees.
pub const DEFAULT_MAX_ANGLE: f32 = 30.0;
/// Residual of the inpainting solve relative to its right-hand side, per bone.
const TOLERANCE: f64 = 1e-6;
const MAX_ITERATIONS: usize = 5000;
/// The most multiply-adds a direct solve of one group may take (a few tenths of a second).
const DIRECT_BUDGET: f64 = 2e8;

/// How weights are transferred.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferOptions {
    /// How far a clothing vertex may be from the body's surface to take its weights there
    /// (`None`: [`DEFAULT_DISTANCE_FRACTION`] of the clothing's bounding-box diagonal).
    pub max_distance: Option<f32>,
    /// The largest angle between the clothing's and the body's normals, in degrees.
    pub max_angle: f32,
    /// Also match where the normals point opposite ways (clothing modelled inside out).
    pub flipped_normals: bool,
    /// Smoothing passes over the filled vertices and their neighbours (0: none).
    pub smoothing: u32,
    /// The most bones per vertex.
    pub max_influences: usize,
}

impl Default for TransferOptions {
    fn default() -> Self {
        TransferOptions {
            max_distance: None,
            max_angle: DEFAULT_MAX_ANGLE,
            flipped_normals: false,
            smoothing: 0,
            max_influences: 4,
        }
    }
}

/// Transferred weights and how each vertex got them.
#[derive(Clone, Debug)]
pub struct Transferred {
    /// At most `max_influences` bones per vertex, weights summing to one, for every vertex.
    pub influences: Influences,
    /// Whether each vertex matched a point of the body.
    pub matched: Vec<bool>,
    /// Unmatched vertices filled by the inpainting solve.
    pub inpainted: usize,
    /// Vertices of loose parts with no match, which took the weights of the nearest matched
    /// vertex (or, when nothing matched at all, of their closest body point).
    pub from_nearest: usize,
    /// The distance threshold used.
    pub max_distance: f32,
    /// The most conjugate-gradient iterations any part of the solve took.
    pub iterations: usize,
}

/// Transfers `body` weights (of the vertices at `body_positions`) to the clothing.
pub fn transfer_weights(
    body_positions: &[[f32; 3]],
    body_triangles: &[[u32; 3]],
    body: &Influences,
    cloth_positions: &[[f32; 3]],
    cloth_triangles: &[[u32; 3]],
    options: &TransferOptions,
    progress: Progress<'_>,
) -> Result<Transferred, WeightsError> {
    check_points("body_positions", body_positions)?;
    check_points("cloth_positions", cloth_positions)?;
    check_triangles("body_triangles", body_triangles, body_positions.len())?;
    check_triangles("cloth_triangles", cloth_triangles, cloth_positions.len())?;
    if body.vertex_count() != body_positions.len() {
        return Err(WeightsError::LengthMismatch {
            what: "body weights",
            expected: body_positions.len(),
            got: body.vertex_count(),
        });
    }
    check_range("max_angle", f64::from(options.max_angle), 0.0, 180.0)?;
    check_range("max_influences", options.max_influences as f64, 1.0, MAX_WEIGHT_INFLUENCES as f64)?;
    check_range("smoothing", f64::from(options.smoothing), 0.0, 1000.0)?;
    if let Some(d) = options.max_distance {
        check_range("max_distance", f64::from(d), 0.0, f64::from(f32::MAX))?;
    }
    if body_triangles.is_empty() {
        return Err(WeightsError::NoSurface);
    }
    let source: Vec<Vec<Pair>> = (0..body.vertex_count())
        .map(|v| {
            let mut pairs: Vec<Pair> = body.of_vertex(v).map(|i| (i.bone, i.weight)).collect();
            sparse::merge_repeated(&mut pairs);
            sparse::normalize(&mut pairs);
            pairs
        })
        .collect();
    if source.iter().all(Vec::is_empty) {
        return Err(WeightsError::NoSourceWeights);
    }
    let k = options.max_influences;
    let n = cloth_positions.len();
    let max_distance = options.max_distance.unwrap_or_else(|| {
        let d = diagonal(cloth_positions);
        DEFAULT_DISTANCE_FRACTION * if d > 0.0 { d } else { diagonal(body_positions) }
    });
    let min_cos = options.max_angle.to_radians().cos();
    let body_normals = vertex_normals(body_positions, body_triangles);
    let cloth_normals = vertex_normals(cloth_positions, cloth_triangles);
    let bvh = Bvh::new(body_positions, body_triangles);
    // The body's weights at the closest point of its surface within `radius`, if any (and if
    // the normals agree, when `check_normal`).
    let weights_at = |v: usize, radius: f32, check_normal: bool| -> Option<Vec<Pair>> {
        let p = Vec3::from_array(cloth_positions[v]);
        let hit = bvh.closest(p, radius)?;
        let corners = body_triangles[hit.triangle as usize];
        if check_normal && cloth_normals[v] != Vec3::ZERO {
            let normal: Vec3 = (0..3).map(|c| body_normals[corners[c] as usize] * hit.bary[c]).sum();
            let cos = normal.normalize_or_zero().dot(cloth_normals[v]);
            let cos = if options.flipped_normals { cos.abs() } else { cos };
            if cos < min_cos - 1e-6 {
                return None;
            }
        }
        let mut mixed: Vec<Pair> = Vec::new();
        for c in 0..3 {
            mixed.extend(source[corners[c] as usize].iter().map(|&(b, w)| (b, w * hit.bary[c])));
        }
        sparse::merge_repeated(&mut mixed);
        sparse::normalize(&mut mixed).then_some(mixed)
    };
    if !progress(0, 4) {
        return Err(WeightsError::Cancelled);
    }
    let found: Vec<Option<Vec<Pair>>> = crate::pool::run(|| {
        (0..n).into_par_iter().with_min_len(256).map(|v| weights_at(v, max_distance, true)).collect()
    });
    let matched: Vec<bool> = found.iter().map(Option::is_some).collect();
    let mut lists: Vec<Vec<Pair>> = found.into_iter().map(Option::unwrap_or_default).collect();
    if !progress(1, 4) {
        return Err(WeightsError::Cancelled);
    }
    let neighbours = Neighbours::of_triangles(n, cloth_triangles);
    let (part, part_count) = parts(n, &neighbours);
    let mut part_matched = vec![false; part_count];
    for v in 0..n {
        part_matched[part[v] as usize] |= matched[v];
    }
    // Loose parts with no match.
    let loose: Vec<usize> = (0..n).filter(|&v| !part_matched[part[v] as usize]).collect();
    let from_nearest = loose.len();
    if !matched.iter().any(|&m| m) {
        let nearest: Vec<Vec<Pair>> = crate::pool::run(|| {
            loose.par_iter().map(|&v| weights_at(v, f32::INFINITY, false).unwrap_or_default()).collect()
        });
        for (&v, w) in loose.iter().zip(nearest) {
            lists[v] = w;
        }
    } else if !loose.is_empty() {
        fill_loose_parts(&mut lists, &loose, &part, &matched, cloth_positions);
    }
    // Inpainting: the unmatched vertices of parts that have a match.
    let unknown: Vec<usize> = (0..n).filter(|&v| !matched[v] && part_matched[part[v] as usize]).collect();
    let guess = nearest_matched(&lists, &matched, &neighbours);
    let mut iterations = 0;
    if !unknown.is_empty() {
        let (k_matrix, mass) = stiffness_and_mass(cloth_positions, cloth_triangles);
        if !progress(2, 4) {
            return Err(WeightsError::Cancelled);
        }
        let (filled, its) = inpaint(&k_matrix, &mass, &unknown, &lists, &guess);
        iterations = its;
        for (&v, mut w) in unknown.iter().zip(filled) {
            if !sparse::limit_and_normalize(&mut w, k) {
                w = guess[v].clone();
            }
            lists[v] = w;
        }
    }
    if !progress(3, 4) {
        return Err(WeightsError::Cancelled);
    }
    if options.smoothing > 0 && !unknown.is_empty() {
        let mut chosen = vec![false; n];
        for &v in &unknown {
            chosen[v] = true;
            for &u in neighbours.of(v) {
                chosen[u as usize] = true;
            }
        }
        smooth::smooth(&mut lists, &neighbours, options.smoothing, k, Some(&chosen));
    }
    for (v, list) in lists.iter_mut().enumerate() {
        if !sparse::limit_and_normalize(list, k) {
            // A vertex the solve left with nothing (all of it clamped away).
            *list = guess[v].clone();
            sparse::limit_and_normalize(list, k);
        }
    }
    if !progress(4, 4) {
        return Err(WeightsError::Cancelled);
    }
    Ok(Transferred {
        influences: sparse::to_influences(&lists, body.bone_count()),
        inpainted: unknown.len(),
        matched,
        from_nearest,
        max_distance,
        iterations,
    })
}

/// Each loose part with no match takes, as a whole, the weights of the matched vertex nearest
/// to it (so a button or an eye moves rigidly with the point it sits on).
fn fill_loose_parts(lists: &mut [Vec<Pair>], loose: &[usize], part: &[u32], matched: &[bool], positions: &[[f32; 3]]) {
    let sources: Vec<usize> = (0..matched.len()).filter(|&v| matched[v]).collect();
    let nearest: Vec<(f32, usize)> = crate::pool::run(|| {
        loose
            .par_iter()
            .map(|&v| {
                let p = Vec3::from_array(positions[v]);
                sources
                    .iter()
                    .map(|&s| (Vec3::from_array(positions[s]).distance_squared(p), s))
                    .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
                    .expect("some vertex matched")
            })
            .collect()
    });
    let mut best: std::collections::HashMap<u32, (f32, usize)> = std::collections::HashMap::new();
    for (&v, &(d, s)) in loose.iter().zip(&nearest) {
        let entry = best.entry(part[v]).or_insert((d, s));
        if d < entry.0 || (d == entry.0 && s < entry.1) {
            *entry = (d, s);
        }
    }
    for &v in loose {
        lists[v] = lists[best[&part[v]].1].clone();
    }
}

/// For every vertex, the weights of the matched vertex fewest edges away (its own if matched;
/// empty where none is connected): the solve's first guess and its fallback.
fn nearest_matched(lists: &[Vec<Pair>], matched: &[bool], neighbours: &Neighbours) -> Vec<Vec<Pair>> {
    let n = lists.len();
    let mut from = vec![usize::MAX; n];
    let mut queue = VecDeque::new();
    for v in 0..n {
        if matched[v] {
            from[v] = v;
            queue.push_back(v);
        }
    }
    while let Some(v) = queue.pop_front() {
        for &u in neighbours.of(v) {
            if from[u as usize] == usize::MAX {
                from[u as usize] = from[v];
                queue.push_back(u as usize);
            }
        }
    }
    (0..n).map(|v| if from[v] == usize::MAX { lists[v].clone() } else { lists[from[v]].clone() }).collect()
}

/// Minimizes `wᵀ·Q·w` over the `unknown` vertices with the others fixed at `lists`, per group
/// of unknowns that `Q` couples, each with the bones that reach it. Returns the unknowns'
/// weights (unclamped) and the most iterations a group took.
fn inpaint(
    k_matrix: &Csr,
    mass: &[f64],
    unknown: &[usize],
    lists: &[Vec<Pair>],
    guess: &[Vec<Pair>],
) -> (Vec<Vec<Pair>>, usize) {
    let n = lists.len();
    let mut local = vec![u32::MAX; n];
    for (i, &v) in unknown.iter().enumerate() {
        local[v] = i as u32;
    }
    // Rows of Q among the unknowns, and the right-hand side −Q_uk·w_k per unknown.
    let rows: Vec<(SparseRow, SparseRow)> = crate::pool::run(|| {
        unknown
            .par_iter()
            .map_init(
                || (vec![0.0f64; n], vec![false; n], Vec::new()),
                |(dense, seen, touched), &v| {
                    q_row(k_matrix, mass, v, dense, seen, touched);
                    let mut row = Vec::new();
                    let mut rhs: Vec<(u32, f64)> = Vec::new();
                    for &c in touched.iter() {
                        let c = c as usize;
                        let q = dense[c];
                        dense[c] = 0.0;
                        seen[c] = false;
                        if local[c] != u32::MAX {
                            row.push((local[c], q));
                        } else {
                            for &(b, w) in &lists[c] {
                                match rhs.iter_mut().find(|e| e.0 == b) {
                                    Some(e) => e.1 -= q * f64::from(w),
                                    None => rhs.push((b, -q * f64::from(w))),
                                }
                            }
                        }
                    }
                    touched.clear();
                    row.sort_unstable_by_key(|e| e.0);
                    (row, rhs)
                },
            )
            .collect()
    });
    // Groups of unknowns coupled through Q.
    let mut group: Vec<u32> = (0..unknown.len() as u32).collect();
    fn find(group: &mut [u32], mut i: u32) -> u32 {
        while group[i as usize] != i {
            group[i as usize] = group[group[i as usize] as usize];
            i = group[i as usize];
        }
        i
    }
    for (i, (row, _)) in rows.iter().enumerate() {
        for &(j, _) in row {
            let (a, b) = (find(&mut group, i as u32), find(&mut group, j));
            if a != b {
                group[a.max(b) as usize] = a.min(b);
            }
        }
    }
    let mut members: std::collections::BTreeMap<u32, Vec<u32>> = std::collections::BTreeMap::new();
    for i in 0..unknown.len() as u32 {
        let root = find(&mut group, i);
        members.entry(root).or_default().push(i);
    }
    let groups: Vec<Vec<u32>> = members.into_values().collect();
    let solved: Vec<(Vec<Solved>, usize)> = crate::pool::run(|| {
        groups
            .par_iter()
            .map(|ids| {
                // The bones this group needs: those of its right-hand side and of its guess.
                let mut bones: Vec<u32> = ids
                    .iter()
                    .flat_map(|&i| {
                        rows[i as usize].1.iter().map(|p| p.0).chain(guess[unknown[i as usize]].iter().map(|p| p.0))
                    })
                    .collect();
                bones.sort_unstable();
                bones.dedup();
                let c = bones.len();
                let column = |b: u32| bones.binary_search(&b).expect("a bone of this group");
                let mut position = std::collections::HashMap::with_capacity(ids.len());
                for (r, &i) in ids.iter().enumerate() {
                    position.insert(i, r as u32);
                }
                let mut triplets = Vec::new();
                let mut rhs = vec![0.0f64; ids.len() * c];
                let mut x = vec![0.0f64; ids.len() * c];
                for (r, &i) in ids.iter().enumerate() {
                    let (row, b) = &rows[i as usize];
                    for &(j, q) in row {
                        triplets.push((r as u32, position[&j], q));
                    }
                    for &(bone, w) in b {
                        rhs[r * c + column(bone)] += w;
                    }
                    for &(bone, w) in &guess[unknown[i as usize]] {
                        x[r * c + column(bone)] = f64::from(w);
                    }
                }
                let a = Csr::from_triplets(ids.len(), triplets);
                // Directly where the envelope is cheap; conjugate gradients then only check the
                // residual (or iterate, from the guess, where it is not).
                if let Some(factor) = Envelope::factor(&a, DIRECT_BUDGET) {
                    factor.solve(&rhs, &mut x, c);
                }
                let its = conjugate_gradients(&a, &rhs, &mut x, c, TOLERANCE, MAX_ITERATIONS);
                let out = ids
                    .iter()
                    .enumerate()
                    .map(|(r, &i)| {
                        let pairs: Vec<Pair> =
                            (0..c).map(|col| (bones[col], x[r * c + col] as f32)).filter(|p| p.1 > 0.0).collect();
                        (i, pairs)
                    })
                    .collect();
                (out, its)
            })
            .collect()
    });
    let mut result = vec![Vec::new(); unknown.len()];
    let mut iterations = 0;
    for (out, its) in solved {
        iterations = iterations.max(its);
        for (i, pairs) in out {
            result[i as usize] = pairs;
        }
    }
    (result, iterations)
}
