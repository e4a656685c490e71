use glam::Vec3;
use proptest::prelude::*;

use super::closest::{closest_on_triangle, Bvh};
use super::envelope::Envelope;
use super::laplacian::Csr;
use super::solve::conjugate_gradients;
use super::voxels::{Grid, Solid};
use super::*;
use crate::skin::Influences;

/// A closed tube along +X from `x0` to `x1` (radius `r`, `rings × segments` side vertices and two
/// cap centres), offset by `at`.
fn tube(x0: f32, x1: f32, r: f32, rings: usize, segments: usize, at: Vec3) -> (Vec<[f32; 3]>, Vec<[u32; 3]>) {
    let mut p = Vec::new();
    let mut t = Vec::new();
    for i in 0..rings {
        let x = x0 + (x1 - x0) * i as f32 / (rings - 1) as f32;
        for k in 0..segments {
            let a = core::f32::consts::TAU * k as f32 / segments as f32;
            p.push((at + Vec3::new(x, r * a.cos(), r * a.sin())).to_array());
        }
    }
    let at_ = |i: usize, k: usize| (i * segments + k % segments) as u32;
    for i in 0..rings - 1 {
        for k in 0..segments {
            t.push([at_(i, k), at_(i + 1, k), at_(i + 1, k + 1)]);
            t.push([at_(i, k), at_(i + 1, k + 1), at_(i, k + 1)]);
        }
    }
    let (c0, c1) = (p.len() as u32, p.len() as u32 + 1);
    p.push((at + Vec3::new(x0, 0.0, 0.0)).to_array());
    p.push((at + Vec3::new(x1, 0.0, 0.0)).to_array());
    for k in 0..segments {
        t.push([c0, at_(0, k + 1), at_(0, k)]);
        t.push([c1, at_(rings - 1, k), at_(rings - 1, k + 1)]);
    }
    (p, t)
}

/// `count` bones of length 1 along +X from the origin.
fn chain(count: usize) -> Vec<Bone> {
    (0..count).map(|i| Bone { head: [i as f32, 0.0, 0.0], tail: [i as f32 + 1.0, 0.0, 0.0] }).collect()
}

fn run(p: &[[f32; 3]], t: &[[u32; 3]], bones: &[Bone], o: &AutoOptions) -> AutoWeights {
    automatic_weights(p, t, bones, o, &mut |_, _| true).expect("weights")
}

fn check_valid(inf: &Influences, vertices: usize, k: usize) {
    assert_eq!(inf.vertex_count(), vertices);
    for v in 0..vertices {
        let pairs: Vec<_> = inf.of_vertex(v).collect();
        assert!(!pairs.is_empty() && pairs.len() <= k, "vertex {v}: {} influences", pairs.len());
        let sum: f32 = pairs.iter().map(|i| i.weight).sum();
        assert!((sum - 1.0).abs() < 1e-5, "vertex {v}: sum {sum}");
        assert!(pairs.iter().all(|i| i.weight > 0.0));
    }
}

fn dense(inf: &Influences, v: usize) -> Vec<f32> {
    let mut w = vec![0.0; inf.bone_count()];
    for i in inf.of_vertex(v) {
        w[i.bone as usize] += i.weight;
    }
    w
}

fn strongest(inf: &Influences, v: usize) -> u32 {
    inf.of_vertex(v).max_by(|a, b| a.weight.total_cmp(&b.weight)).unwrap().bone
}

#[test]
fn a_closed_tube_is_solid_inside_and_a_sheet_is_only_its_surface() {
    let (p, t) = tube(0.0, 4.0, 0.5, 20, 24, Vec3::ZERO);
    let solid = Solid::build(Grid::around(&p, 64), &p, &t);
    let g = solid.grid.to_grid(Vec3::new(2.0, 0.0, 0.0));
    assert!(solid.id(solid.grid.cell_at(g).unwrap()).is_some(), "the axis is inside");
    // The inside is about π·r²·L of 64 cells per unit: far more than a shell.
    let cell = solid.grid.cell;
    let volume = core::f32::consts::PI * 0.25 * 4.0 / (cell * cell * cell);
    assert!(solid.len() as f32 > 0.9 * volume, "{} solid cells, volume {volume}", solid.len());
    // An open sheet: one layer of cells (two where it lies on a cell boundary).
    let sheet = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let tris = vec![[0, 1, 2], [0, 2, 3]];
    let solid = Solid::build(Grid::around(&sheet, 32), &sheet, &tris);
    assert!(solid.len() >= 32 * 32 && solid.len() <= 2 * 34 * 34, "{}", solid.len());
}

#[test]
fn every_vertex_of_an_intersecting_open_multi_part_mesh_is_weighted() {
    let creature = crate::rigs::Creature::new(6000).unwrap();
    let heads: Vec<Vec3> = creature.rest.iter().map(|m| m.w_axis.truncate()).collect();
    let bones: Vec<Bone> = (0..heads.len())
        .map(|b| {
            let child = creature.parents.iter().position(|&p| p == Some(b));
            let tail = child.map_or(heads[b] + creature.rest[b].y_axis.truncate() * 0.2, |c| heads[c]);
            Bone { head: heads[b].to_array(), tail: tail.to_array() }
        })
        .collect();
    let w = run(&creature.positions, &creature.triangles, &bones, &AutoOptions::default());
    check_valid(&w.influences, creature.positions.len(), 4);
}

#[test]
fn the_strongest_bone_is_the_nearest_and_far_bones_get_nothing() {
    let (p, t) = tube(0.0, 8.0, 0.3, 81, 16, Vec3::ZERO);
    let bones = chain(8);
    let w = run(&p, &t, &bones, &AutoOptions::default());
    check_valid(&w.influences, p.len(), 4);
    let mut right = 0;
    for (v, q) in p.iter().enumerate() {
        let nearest = (q[0].floor() as u32).min(7);
        right += usize::from(strongest(&w.influences, v) == nearest);
        for i in w.influences.of_vertex(v) {
            // The falloff is broad (inverse square near the bones): bones two lengths away keep
            // a little, farther ones almost nothing (below 1 %: at the chain's end, the fourth
            // nearest bone, 2.7 lengths away, keeps 0.52 %).
            let gap = (q[0] - (i.bone as f32 + 0.5)).abs() - 0.5;
            let most = if gap < 1.5 {
                1.0
            } else if gap < 2.5 {
                0.03
            } else {
                0.01
            };
            assert!(i.weight <= most, "vertex {v} at x = {} has bone {} ({})", q[0], i.bone, i.weight);
        }
    }
    assert!(right as f32 >= 0.95 * p.len() as f32, "{right} of {}", p.len());
    assert_eq!(w.unreached, 0);
}

#[test]
fn weights_do_not_depend_on_scale_or_offset() {
    let (p, t) = tube(0.0, 4.0, 0.4, 41, 12, Vec3::ZERO);
    let bones = chain(4);
    let base = run(&p, &t, &bones, &AutoOptions::default());
    for (s, off) in [(0.01f32, Vec3::new(0.3, -2.0, 1.0)), (100.0, Vec3::new(50.0, 0.0, 0.0))] {
        let q: Vec<[f32; 3]> = p.iter().map(|x| (Vec3::from_array(*x) * s + off).to_array()).collect();
        let scaled: Vec<Bone> = bones
            .iter()
            .map(|b| Bone {
                head: (Vec3::from_array(b.head) * s + off).to_array(),
                tail: (Vec3::from_array(b.tail) * s + off).to_array(),
            })
            .collect();
        let w = run(&q, &t, &scaled, &AutoOptions::default());
        for v in 0..p.len() {
            let (a, b) = (dense(&base.influences, v), dense(&w.influences, v));
            for (x, y) in a.iter().zip(&b) {
                assert!((x - y).abs() < 2e-3, "vertex {v} at scale {s}: {a:?} {b:?}");
            }
        }
    }
}

#[test]
fn a_part_no_bone_reaches_takes_its_nearest_bones_and_outside_bones_are_reported() {
    let (mut p, mut t) = tube(0.0, 4.0, 0.4, 41, 12, Vec3::ZERO);
    // A floating "eye" far from the body, and a bone outside the mesh.
    let (ep, et) = tube(0.0, 0.3, 0.1, 4, 8, Vec3::new(2.0, 2.0, 0.0));
    let base = p.len() as u32;
    p.extend(ep);
    t.extend(et.iter().map(|x| x.map(|i| i + base)));
    let mut bones = chain(4);
    bones.push(Bone { head: [2.0, -3.0, 0.0], tail: [2.5, -3.0, 0.0] });
    let w = run(&p, &t, &bones, &AutoOptions::default());
    check_valid(&w.influences, p.len(), 4);
    assert_eq!(w.unreached, p.len() - base as usize);
    assert_eq!(w.outside_bones, vec![4]);
}

#[test]
fn bone_names_mirror_as_blender_names_sides() {
    assert_eq!(mirrored_name("hand.L").as_deref(), Some("hand.R"));
    assert_eq!(mirrored_name("DEF-thigh.R.001").as_deref(), Some("DEF-thigh.L.001"));
    assert_eq!(mirrored_name("L_arm").as_deref(), Some("R_arm"));
    assert_eq!(mirrored_name("arm_l").as_deref(), Some("arm_r"));
    assert_eq!(mirrored_name("LeftHand").as_deref(), Some("RightHand"));
    assert_eq!(mirrored_name("spine.001"), None);
    assert_eq!(mirror_bone_map(&["a.L", "spine", "a.R", "b.L"]), vec![2, 1, 0, 3]);
}

#[test]
fn mirrored_weights_are_symmetric() {
    // Two arms along ±X, bones arm.L (+X) and arm.R (−X) and a middle one.
    let (p, t) = tube(-3.0, 3.0, 0.3, 61, 12, Vec3::ZERO);
    let bones = vec![
        Bone { head: [0.5, 0.0, 0.0], tail: [3.0, 0.0, 0.0] },
        Bone { head: [-0.5, 0.0, 0.0], tail: [0.5, 0.0, 0.0] },
        Bone { head: [-0.5, 0.0, 0.0], tail: [-2.9, 0.0, 0.0] },
    ];
    let map = mirror_bone_map(&["arm.L", "chest", "arm.R"]);
    let w = run(&p, &t, &bones, &AutoOptions { mirror: Some(map.clone()), ..AutoOptions::default() });
    check_valid(&w.influences, p.len(), 4);
    let find = |q: [f32; 3]| p.iter().position(|x| Vec3::from_array(*x).distance(Vec3::from_array(q)) < 1e-5).unwrap();
    for (v, q) in p.iter().enumerate() {
        let m = find([-q[0], q[1], q[2]]);
        let mut a: Vec<(u32, f32)> = w.influences.of_vertex(v).map(|i| (map[i.bone as usize], i.weight)).collect();
        let mut b: Vec<(u32, f32)> = w.influences.of_vertex(m).map(|i| (i.bone, i.weight)).collect();
        a.sort_by_key(|x| x.0);
        b.sort_by_key(|x| x.0);
        assert_eq!(a.len(), b.len(), "vertex {v}");
        for (x, y) in a.iter().zip(&b) {
            assert_eq!(x.0, y.0);
            assert!((x.1 - y.1).abs() < 1e-5, "vertex {v}: {x:?} {y:?}");
        }
    }
}

#[test]
fn resolutions_beyond_the_memory_budget_are_refused_and_bad_options_named() {
    let (p, t) = tube(0.0, 1.0, 0.5, 10, 12, Vec3::ZERO);
    let bones = chain(1);
    let err = |o: AutoOptions| automatic_weights(&p, &t, &bones, &o, &mut |_, _| true).unwrap_err().to_string();
    assert!(err(AutoOptions { resolution: 8, ..Default::default() }).contains("resolution"));
    assert!(err(AutoOptions { falloff: 1.5, ..Default::default() }).contains("falloff"));
    assert!(err(AutoOptions { max_influences: 0, ..Default::default() }).contains("max_influences"));
    assert!(automatic_weights(&p, &t, &[], &AutoOptions::default(), &mut |_, _| true).is_err());
    let cancelled = automatic_weights(&p, &t, &bones, &AutoOptions::default(), &mut |_, _| false);
    assert_eq!(cancelled.unwrap_err(), WeightsError::Cancelled);
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(24))]

    /// Random tubes and bone chains, with random options: every vertex has 1..=K bones whose
    /// weights sum to one, and a second run gives the same bits.
    #[test]
    fn weights_are_normalized_limited_and_deterministic(
        length in 1.0f32..6.0,
        radius in 0.05f32..1.0,
        bones in 1usize..7,
        k in 1usize..6,
        falloff in 0.0f32..1.0,
        smoothing in 0u32..3,
        resolution in 16usize..80,
        shift in -1.0f32..1.0,
    ) {
        let (p, t) = tube(0.0, length, radius, 12, 10, Vec3::ZERO);
        let chain: Vec<Bone> = (0..bones)
            .map(|i| {
                let a = length * i as f32 / bones as f32;
                let b = length * (i + 1) as f32 / bones as f32;
                Bone { head: [a, shift * radius, 0.0], tail: [b, 0.0, shift * radius] }
            })
            .collect();
        let o = AutoOptions { resolution, falloff, max_influences: k, smoothing, mirror: None };
        let a = run(&p, &t, &chain, &o);
        check_valid(&a.influences, p.len(), k);
        let b = run(&p, &t, &chain, &o);
        prop_assert_eq!(a.influences, b.influences);
    }
}

#[test]
fn closest_points_match_brute_force() {
    let (p, t) = tube(0.0, 2.0, 0.5, 9, 10, Vec3::ZERO);
    let bvh = Bvh::new(&p, &t);
    let mut seed = 7u64;
    let mut next = || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed >> 40) as f32 / (1u64 << 24) as f32
    };
    for _ in 0..300 {
        let q = Vec3::new(next() * 3.0 - 0.5, next() * 2.0 - 1.0, next() * 2.0 - 1.0);
        let brute = t
            .iter()
            .map(|tri| closest_on_triangle(q, tri.map(|i| Vec3::from_array(p[i as usize]))).0.distance(q))
            .fold(f32::INFINITY, f32::min);
        let hit = bvh.closest(q, f32::INFINITY).unwrap();
        assert!((hit.distance - brute).abs() < 1e-5);
        assert!(bvh.closest(q, brute * 0.99).is_none());
    }
}

#[test]
fn conjugate_gradients_solve_a_small_spd_system() {
    // The 1D Laplacian plus the identity, two right-hand sides.
    let n = 30;
    let mut trip = Vec::new();
    for i in 0..n {
        trip.push((i as u32, i as u32, 3.0));
        if i > 0 {
            trip.push((i as u32, i as u32 - 1, -1.0));
            trip.push((i as u32 - 1, i as u32, -1.0));
        }
    }
    let a = Csr::from_triplets(n, trip);
    let b: Vec<f64> = (0..2 * n).map(|i| (i as f64 * 0.37).sin()).collect();
    let mut x = vec![0.0; 2 * n];
    conjugate_gradients(&a, &b, &mut x, 2, 1e-12, 1000);
    for i in 0..n {
        for c in 0..2 {
            let ax: f64 = a.row(i).map(|(j, v)| v * x[j * 2 + c]).sum();
            assert!((ax - b[i * 2 + c]).abs() < 1e-9);
        }
    }
}

/// A body tube skinned smoothly along X with 4 bones.
fn skinned_body() -> (Vec<[f32; 3]>, Vec<[u32; 3]>, Influences) {
    let (p, t) = tube(0.0, 4.0, 0.5, 41, 24, Vec3::ZERO);
    let lists: Vec<Vec<(u32, f32)>> = p
        .iter()
        .map(|q| {
            let s = (q[0] - 0.5).clamp(0.0, 2.999);
            let b = s.floor();
            vec![(b as u32, 1.0 - (s - b)), (b as u32 + 1, s - b)]
        })
        .collect();
    let inf = Influences::from_lists(&lists, 4).unwrap();
    (p, t, inf)
}

fn body_weights_at(p: &[[f32; 3]], t: &[[u32; 3]], inf: &Influences, q: Vec3) -> Vec<f32> {
    let bvh = Bvh::new(p, t);
    let hit = bvh.closest(q, f32::INFINITY).unwrap();
    let mut w = vec![0.0; inf.bone_count()];
    for c in 0..3 {
        for i in inf.of_vertex(t[hit.triangle as usize][c] as usize) {
            w[i.bone as usize] += hit.bary[c] * i.weight;
        }
    }
    w
}

#[test]
fn transferred_weights_equal_the_bodys_where_matched_and_fill_the_rest() {
    let (bp, bt, inf) = skinned_body();
    // A sleeve a little outside the body from x = 0.5 to 3, flaring away from it past x = 3.
    let (mut cp, ct) = tube(0.5, 4.5, 0.52, 41, 24, Vec3::ZERO);
    for q in &mut cp {
        if q[0] > 3.0 {
            let grow = 1.0 + 0.8 * (q[0] - 3.0);
            q[1] *= grow;
            q[2] *= grow;
        }
    }
    let o = TransferOptions { max_distance: Some(0.05), ..Default::default() };
    let r = transfer_weights(&bp, &bt, &inf, &cp, &ct, &o, &mut |_, _| true).unwrap();
    check_valid(&r.influences, cp.len(), 4);
    let matched = r.matched.iter().filter(|&&m| m).count();
    assert!(matched > cp.len() / 2 && r.inpainted > 0, "{matched} matched, {} inpainted", r.inpainted);
    for (v, q) in cp.iter().enumerate() {
        let mut got = vec![0.0; 4];
        for i in r.influences.of_vertex(v) {
            got[i.bone as usize] = i.weight;
        }
        if r.matched[v] {
            let want = body_weights_at(&bp, &bt, &inf, Vec3::from_array(*q));
            for b in 0..4 {
                assert!((got[b] - want[b]).abs() < 1e-5, "vertex {v}: {got:?} {want:?}");
            }
        } else if q[0] > 3.5 {
            // The flare hangs past the last bone: it follows bones 2 and 3.
            assert!(got[2] + got[3] > 0.99, "vertex {v} at {q:?}: {got:?}");
        }
    }
}

#[test]
fn a_loose_part_without_a_match_moves_with_the_nearest_matched_point() {
    let (bp, bt, inf) = skinned_body();
    let (mut cp, mut ct) = tube(0.5, 3.5, 0.52, 31, 24, Vec3::ZERO);
    // A button floating 0.3 off the sleeve at x = 2.2, facing away.
    let (bpts, btris) = tube(2.15, 2.25, 0.05, 2, 6, Vec3::new(0.0, 0.9, 0.0));
    let base = cp.len() as u32;
    cp.extend(bpts);
    ct.extend(btris.iter().map(|x| x.map(|i| i + base)));
    let r = transfer_weights(&bp, &bt, &inf, &cp, &ct, &TransferOptions::default(), &mut |_, _| true).unwrap();
    check_valid(&r.influences, cp.len(), 4);
    assert_eq!(r.from_nearest, cp.len() - base as usize);
    let first = r.influences.of_vertex(base as usize).collect::<Vec<_>>();
    for v in base as usize..cp.len() {
        assert_eq!(r.influences.of_vertex(v).collect::<Vec<_>>(), first);
    }
}

#[test]
fn a_huge_bone_costs_no_more_than_one_across_the_grid() {
    let (p, t) = tube(0.0, 4.0, 0.4, 41, 12, Vec3::ZERO);
    let mut bones = chain(4);
    bones.push(Bone { head: [2.0, 0.0, 0.0], tail: [1e30, 0.0, 0.0] });
    bones.push(Bone { head: [-1e30, 5.0, 0.0], tail: [1e30, 5.0, 0.0] });
    // (Unclipped, the second bone alone took ~10^30 steps: the test would never end.)
    let w = run(&p, &t, &bones, &AutoOptions::default());
    check_valid(&w.influences, p.len(), 4);
    assert_eq!(w.outside_bones, vec![5]); // the first crosses the tube, the second misses it
}

/// A `w`×`h` grid's Laplacian plus `shift` times the identity (5-point stencil).
fn grid_system(w: usize, h: usize, shift: f64) -> Csr {
    let mut trip = Vec::new();
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as u32;
            trip.push((i, i, 4.0 + shift));
            for (dx, dy) in [(1i64, 0i64), (0, 1)] {
                let (nx, ny) = (x as i64 + dx, y as i64 + dy);
                if nx < w as i64 && ny < h as i64 {
                    let j = (ny as usize * w + nx as usize) as u32;
                    trip.push((i, j, -1.0));
                    trip.push((j, i, -1.0));
                }
            }
        }
    }
    Csr::from_triplets(w * h, trip)
}

#[test]
fn the_envelope_solve_is_exact_on_a_grid_system() {
    let a = grid_system(37, 23, 0.01);
    let (n, c) = (a.rows(), 3);
    let b: Vec<f64> = (0..n * c).map(|i| (i as f64 * 0.731).sin()).collect();
    let factor = Envelope::factor(&a, f64::INFINITY).expect("positive definite");
    let mut x = vec![0.0; n * c];
    factor.solve(&b, &mut x, c);
    for i in 0..n {
        for k in 0..c {
            let ax: f64 = a.row(i).map(|(j, v)| v * x[j * c + k]).sum();
            assert!((ax - b[i * c + k]).abs() < 1e-10, "row {i} column {k}: {ax} vs {}", b[i * c + k]);
        }
    }
    // Conjugate gradients from there have nothing left to do.
    assert_eq!(conjugate_gradients(&a, &b, &mut x, c, 1e-9, 100), 0);
}

#[test]
fn the_envelope_solve_refuses_what_it_cannot_do() {
    // Not positive definite (a shift below the Laplacian's smallest eigenvalue's negative).
    assert!(Envelope::factor(&grid_system(10, 10, -1.0), f64::INFINITY).is_none());
    // Beyond the budget: a 40×40 grid's envelope is about 40 wide.
    assert!(Envelope::factor(&grid_system(40, 40, 0.1), 1000.0).is_none());
    assert!(Envelope::factor(&grid_system(40, 40, 0.1), 1e7).is_some());
}

#[test]
fn a_zero_right_hand_side_column_ends_with_the_others() {
    // The solution of the zero column is zero; starting away from it, the solve stops once it
    // is small against the other column's scale instead of running to the iteration limit.
    let a = grid_system(20, 20, 0.0);
    let (n, c) = (a.rows(), 2);
    let b: Vec<f64> = (0..n * c).map(|i| if i % 2 == 0 { 1.0 } else { 0.0 }).collect();
    let mut x: Vec<f64> = (0..n * c).map(|i| if i % 2 == 1 { 0.5 } else { 0.0 }).collect();
    let its = conjugate_gradients(&a, &b, &mut x, c, 1e-8, 5000);
    assert!(its < 1000, "{its} iterations");
    assert!(x.iter().skip(1).step_by(2).all(|v| v.abs() < 1e-5));
}
