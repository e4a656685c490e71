//! Centers of rotation: the precompute against the naive formula in f64, and the skinning
//! kernel against a scalar f64 reference and the properties the method promises.

use super::super::isa::Simd;
use super::super::tests::skin_all;
use super::super::{Method, Pose, SkinError, SkinOptions, MIN_TOTAL_WEIGHT};
use super::*;
use crate::rigs::{polygon_area, Creature, TwistCylinder};
use glam::{DMat3, DQuat, DVec3, Mat4, Quat, Vec3};
use proptest::prelude::*;

/// The precompute straight from the formula: every vertex against every triangle, dense weight
/// vectors, the library `exp`, f64 throughout.
fn naive_centers(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f64,
) -> Vec<Option<DVec3>> {
    let all: Vec<usize> = (0..influences.vertex_count()).collect();
    naive_centers_of(positions, triangles, influences, sigma, &all)
}

/// [`naive_centers`] of the given vertices only.
fn naive_centers_of(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f64,
    vertices: &[usize],
) -> Vec<Option<DVec3>> {
    let bones = influences.bone_count();
    let dense: Vec<Vec<f64>> = (0..influences.vertex_count())
        .map(|v| {
            let mut w = vec![0.0; bones];
            for i in influences.of_vertex(v) {
                w[i.bone as usize] += f64::from(i.weight);
            }
            let total: f64 = w.iter().sum();
            if total > f64::from(MIN_TOTAL_WEIGHT) {
                w.iter_mut().for_each(|x| *x /= total);
            } else {
                w.iter_mut().for_each(|x| *x = 0.0);
            }
            w
        })
        .collect();
    let p = |v: u32| Vec3::from_array(positions[v as usize]).as_dvec3();
    let tris: Vec<(f64, DVec3, Vec<f64>)> = triangles
        .iter()
        .map(|t| {
            let area = 0.5 * (p(t[1]) - p(t[0])).cross(p(t[2]) - p(t[0])).length();
            let centroid = (p(t[0]) + p(t[1]) + p(t[2])) / 3.0;
            let w = (0..bones).map(|b| t.iter().map(|&v| dense[v as usize][b]).sum::<f64>() / 3.0).collect();
            (area, centroid, w)
        })
        .collect();
    vertices
        .iter()
        .map(|&v| {
            let a = &dense[v];
            let (mut num, mut den) = (DVec3::ZERO, 0.0);
            // Terms with aⱼ = 0 or aₖ = 0 are 0: skipping them keeps the naive sum exact.
            let support: Vec<usize> = (0..bones).filter(|&j| a[j] != 0.0).collect();
            for (area, centroid, b) in &tris {
                let mut s = 0.0;
                for &j in &support {
                    for &k in &support {
                        if j != k {
                            let u = a[j] * b[k] - a[k] * b[j];
                            s += a[j] * a[k] * b[j] * b[k] * (-(u * u) / (sigma * sigma)).exp();
                        }
                    }
                }
                num += s * area * *centroid;
                den += s * area;
            }
            (den > 0.0).then(|| num / den)
        })
        .collect()
}

fn diagonal(positions: &[[f32; 3]]) -> f64 {
    let (mut lo, mut hi) = (DVec3::splat(f64::INFINITY), DVec3::splat(f64::NEG_INFINITY));
    for p in positions {
        let p = Vec3::from_array(*p).as_dvec3();
        lo = lo.min(p);
        hi = hi.max(p);
    }
    (hi - lo).length()
}

/// Centers with every compiled copy of the inner loop (they must agree to 1e-12 of the
/// diagonal); checks them against the naive formula within `1e-5 × diagonal`.
fn check_against_naive(positions: &[[f32; 3]], triangles: &[[u32; 3]], influences: &Influences, sigma: f32) -> Centers {
    let want = naive_centers(positions, triangles, influences, f64::from(sigma));
    let diag = diagonal(positions).max(1e-30);
    let mut results = Vec::new();
    for simd in Simd::available() {
        let (got, _) = centers_counted(
            simd,
            Some(cells::TOLERANCE),
            positions,
            triangles,
            influences,
            sigma,
            &mut |_, _| true,
            &mut || false,
        )
        .unwrap();
        for (v, (w, (c, has))) in want.iter().zip(got.centers.iter().zip(&got.has_center)).enumerate() {
            match w {
                Some(w) => {
                    assert!(*has, "{simd:?}: vertex {v} should have a center");
                    let err = (Vec3::from_array(*c).as_dvec3() - *w).length();
                    assert!(err <= 1e-5 * diag, "{simd:?}: vertex {v}: {c:?} vs {w} (error {err}, diagonal {diag})");
                }
                None => {
                    assert!(!*has, "{simd:?}: vertex {v} should have no center");
                    assert_eq!(*c, positions[v], "a vertex without a center keeps its position");
                }
            }
        }
        results.push(got);
    }
    let last = results.pop().unwrap();
    for other in &results {
        assert_eq!(other.has_center, last.has_center);
        for (a, b) in other.centers.iter().zip(&last.centers) {
            assert!((Vec3::from_array(*a) - Vec3::from_array(*b)).length() as f64 <= 1e-6 * diag);
        }
    }
    last
}

#[test]
fn precompute_matches_the_naive_formula_on_the_twist_cylinder() {
    let cyl = TwistCylinder::new(21, 24, 4.0, 0.5, 0.5).unwrap();
    let c = check_against_naive(&cyl.positions, &cyl.triangles, &cyl.influences, DEFAULT_SIGMA);
    // Blended rings get a center on the axis (by symmetry); one-bone rings have none.
    for r in 0..cyl.rings {
        let v = cyl.ring(r).start;
        let bones = cyl.influences.of_vertex(v).len();
        assert_eq!(c.has_center[v], bones == 2, "ring {r}");
        if bones == 2 {
            let p = c.centers[v];
            assert!(p[0].abs() < 1e-5 && p[2].abs() < 1e-5, "ring {r}: {p:?}");
        }
    }
}

#[test]
fn precompute_matches_the_naive_formula_on_the_creature() {
    let c = Creature::new(3000).unwrap();
    let centers = check_against_naive(&c.positions, &c.triangles, &c.influences, DEFAULT_SIGMA);
    assert!(centers.has_center.iter().all(|&h| h), "every creature vertex has four bones");
    // A tiny σ goes through the underflow shift.
    check_against_naive(&c.positions, &c.triangles, &c.influences, 0.03);
}

#[test]
fn the_fast_path_is_within_its_certified_bound_where_it_is_used() {
    // Big enough that pair lists fill many cells (about 30 000 triangle weight vectors).
    let c = Creature::new(15_000).unwrap();
    let diag = diagonal(&c.positions);
    let (p, t, i) = (&c.positions, &c.triangles, &c.influences);
    let (exact, none) =
        centers_counted(Simd::detect(), None, p, t, i, DEFAULT_SIGMA, &mut |_, _| true, &mut || false).unwrap();
    assert_eq!(none, 0);
    // The certificate allows 1e-7 × diagonal; f32 rounding of the centers adds ~1e-7 of their size.
    let tolerance = 1e-6 * diag;
    for simd in Simd::available() {
        let (fast, count) =
            centers_counted(simd, Some(cells::TOLERANCE), p, t, i, DEFAULT_SIGMA, &mut |_, _| true, &mut || false)
                .unwrap();
        // Nearly every vertex has its own weights; most should take the fast path.
        assert!(count * 10 >= 8 * p.len(), "{simd:?}: only {count} of {} on the fast path", p.len());
        assert_eq!(fast.has_center, exact.has_center);
        let mut worst = 0.0f64;
        for (a, b) in fast.centers.iter().zip(&exact.centers) {
            worst = worst.max((Vec3::from_array(*a).as_dvec3() - Vec3::from_array(*b).as_dvec3()).length());
        }
        eprintln!(
            "{simd:?}: {count} weight vectors on the fast path, largest difference to the exact sums {:.2e} × diagonal",
            worst / diag
        );
        assert!(worst <= tolerance, "{simd:?}: {worst} > {tolerance}");
    }
    // A tolerance tight enough that some vertices fall back to the exact sums.
    let (mixed, count) =
        centers_counted(Simd::detect(), Some(1e-10), p, t, i, DEFAULT_SIGMA, &mut |_, _| true, &mut || false).unwrap();
    assert!(count > 0 && count * 10 < 9 * p.len(), "{count} of {} on the fast path", p.len());
    for (a, b) in mixed.centers.iter().zip(&exact.centers) {
        assert!((Vec3::from_array(*a).as_dvec3() - Vec3::from_array(*b).as_dvec3()).length() <= tolerance);
    }
    // And the exact sums against the formula itself, on a sample.
    let sample: Vec<usize> = (0..p.len()).step_by(97).collect();
    let want = naive_centers_of(p, t, i, f64::from(DEFAULT_SIGMA), &sample);
    let fast = centers_of_rotation(p, t, i, DEFAULT_SIGMA).unwrap();
    for (&v, w) in sample.iter().zip(&want) {
        let err = (Vec3::from_array(fast.centers[v]).as_dvec3() - w.unwrap()).length();
        assert!(err <= tolerance, "vertex {v}: error {err} > {tolerance}");
    }
}

/// Positions, triangles, influence lists, bone count, σ.
type SmallMesh = (Vec<[f32; 3]>, Vec<[u32; 3]>, Vec<Vec<(u32, f32)>>, usize, f32);

/// A small random mesh: positions, triangles over them, and 0..=5 influences per vertex (zero,
/// repeated and unnormalized weights included).
fn small_mesh() -> impl Strategy<Value = SmallMesh> {
    (3usize..30, 1usize..6).prop_flat_map(|(n, bones)| {
        let entry = (0..bones as u32, prop_oneof![6 => 0.0f32..1.0, 1 => Just(0.0f32), 1 => 1.0f32..3.0]);
        (
            proptest::collection::vec(proptest::array::uniform3(-2.0f32..2.0), n),
            proptest::collection::vec(proptest::array::uniform3(0..n as u32), 0..60),
            proptest::collection::vec(proptest::collection::vec(entry, 0..=5), n),
            Just(bones),
            prop_oneof![Just(0.1f32), 0.02f32..2.0],
        )
    })
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    #[test]
    fn precompute_matches_the_naive_formula_on_random_meshes((positions, triangles, lists, bones, sigma) in small_mesh()) {
        let influences = Influences::from_lists(&lists, bones).unwrap();
        check_against_naive(&positions, &triangles, &influences, sigma);
    }
}

#[test]
fn equal_weight_vectors_share_a_center_and_scaling_weights_changes_nothing() {
    let cyl = TwistCylinder::new(9, 12, 2.0, 0.5, 0.8).unwrap();
    let base = centers_of_rotation(&cyl.positions, &cyl.triangles, &cyl.influences, 0.1).unwrap();
    // The same weights times 3, with a repeated bone split in two.
    let lists: Vec<Vec<(u32, f32)>> = (0..cyl.positions.len())
        .map(|v| {
            cyl.influences.of_vertex(v).flat_map(|i| [(i.bone, 1.5 * i.weight), (i.bone, 1.5 * i.weight)]).collect()
        })
        .collect();
    let scaled = Influences::from_lists(&lists, 2).unwrap();
    let other = centers_of_rotation(&cyl.positions, &cyl.triangles, &scaled, 0.1).unwrap();
    assert_eq!(base.has_center, other.has_center);
    for (a, b) in base.centers.iter().zip(&other.centers) {
        assert!((Vec3::from_array(*a) - Vec3::from_array(*b)).length() < 1e-6);
    }
}

#[test]
fn progress_is_reported_and_cancelling_stops() {
    let c = Creature::new(3000).unwrap();
    let mut calls = Vec::new();
    centers_of_rotation_with_progress(&c.positions, &c.triangles, &c.influences, 0.1, &mut |done, total| {
        calls.push((done, total));
        true
    })
    .unwrap();
    assert!(calls.len() >= 2);
    assert_eq!(calls[0].0, 0);
    assert!(calls.windows(2).all(|w| w[0].0 <= w[1].0 && w[0].1 == w[1].1));
    let last = calls.last().unwrap();
    assert_eq!(last.0, last.1);
    let mut seen = 0;
    let err = centers_of_rotation_with_progress(&c.positions, &c.triangles, &c.influences, 0.1, &mut |_, _| {
        seen += 1;
        seen < 2
    });
    assert_eq!(err, Err(SkinError::Cancelled));
    assert_eq!(seen, 2, "stops at the first refusal");
}

/// The setup (seconds on a mesh of half a million vertices, before `progress`'s total is known)
/// asks `interrupted` between its stages, so Ctrl-C stops it there too; asked to stop at any of
/// them, nothing is reported and the result is `Cancelled`.
#[test]
fn the_setup_can_be_interrupted_at_each_stage() {
    let c = Creature::new(3000).unwrap();
    // (result, checks before the first progress report if there was one, checks in all)
    let run = |stop_at: usize| {
        let asked = std::cell::Cell::new(0usize);
        let mut first = None;
        let result = centers_of_rotation_interruptible(
            &c.positions,
            &c.triangles,
            &c.influences,
            0.1,
            &mut |_, _| {
                first.get_or_insert(asked.get());
                true
            },
            &mut || {
                asked.set(asked.get() + 1);
                asked.get() == stop_at
            },
        );
        (result, first, asked.get())
    };
    let (done, first, all) = run(usize::MAX);
    assert!(done.is_ok());
    let before_work = first.expect("progress was reported");
    assert!(before_work >= 6, "the setup asked {before_work} times");
    assert_eq!(all, before_work, "asked during the setup only (progress covers the rest)");
    for stop_at in 1..=before_work {
        let (result, first, _) = run(stop_at);
        assert_eq!(result.unwrap_err(), SkinError::Cancelled, "stopped at check {stop_at}");
        assert!(first.is_none(), "no progress reported when stopped at check {stop_at}");
    }
}

#[test]
fn bad_precompute_inputs_are_rejected_naming_them() {
    let cyl = TwistCylinder::new(3, 4, 2.0, 0.5, 0.8).unwrap();
    let (p, t, i) = (&cyl.positions, &cyl.triangles, &cyl.influences);
    let n = p.len();
    let run = |p: &[[f32; 3]], t: &[[u32; 3]], s: f32| centers_of_rotation(p, t, i, s).unwrap_err();
    assert_eq!(run(&p[1..], t, 0.1), SkinError::LengthMismatch { what: "positions", expected: n, got: n - 1 });
    for s in [0.0, -1.0, f32::NAN, f32::INFINITY] {
        assert!(matches!(run(p, t, s), SkinError::InvalidSigma(_)));
    }
    let mut bad = t.clone();
    bad[3][1] = n as u32;
    let e = run(p, &bad, 0.1);
    assert_eq!(e, SkinError::InvalidTriangle { index: 3, vertex: n as u32, vertex_count: n });
    assert!(e.to_string().contains("triangles[3]"));
    let mut nan = p.clone();
    nan[5][2] = f32::NAN;
    assert_eq!(run(&nan, t, 0.1), SkinError::NotFinite { what: "positions", index: 5 });
    assert!(run(p, t, -1.0).to_string().contains("sigma"));
}

// ---------------------------------------------------------------------------------------------
// The kernel.

/// The per-frame formula in f64: `v' = Σ wⱼ·Mⱼ·c + R·Σ wⱼ·Sⱼ·(v − c)` in armature space, with
/// `R` from the sign-aligned quaternion sum and `Sⱼ = Rⱼᵀ·M₃ⱼ` (identity for rigid bones).
#[allow(clippy::too_many_arguments)] // the kernel's inputs, one by one
fn reference(
    positions: &[[f32; 3]],
    centers: &[[f32; 3]],
    lists: &[Vec<(u32, f32)>],
    deform: &[Mat4],
    pose: &Pose,
    premat: Mat4,
    postmat: Mat4,
    mask: Option<&[f32]>,
) -> Vec<DVec3> {
    let (pre, post) = (premat.as_dmat4(), postmat.as_dmat4());
    positions
        .iter()
        .enumerate()
        .map(|(v, p)| {
            let p = Vec3::from_array(*p).as_dvec3();
            let a = mask.map_or(1.0, |m| f64::from(m[v]));
            if a == 0.0 {
                return p;
            }
            let co = pre.transform_point3(p);
            let c = pre.transform_point3(Vec3::from_array(centers[v]).as_dvec3());
            let (mut anchor, mut offset, mut q, mut contrib) =
                (DVec3::ZERO, DVec3::ZERO, DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0), 0.0);
            for &(b, w) in &lists[v] {
                let w = f64::from(w);
                let b = b as usize;
                let m = deform[b].as_dmat4();
                let qb = pose.bone_rotation(b).unwrap().as_dquat();
                let stretch = if pose.scaled_bones()[b] {
                    DMat3::from_quat(qb).transpose() * DMat3::from_mat4(m)
                } else {
                    DMat3::IDENTITY
                };
                anchor += w * m.transform_point3(c);
                offset += w * (stretch * (co - c));
                let sign = if qb.dot(q) < 0.0 { -1.0 } else { 1.0 };
                q += qb * (sign * w);
                contrib += w;
            }
            if contrib <= f64::from(MIN_TOTAL_WEIGHT) || q.length_squared() == 0.0 {
                return post.transform_point3(co);
            }
            let r = DMat3::from_quat(q.normalize());
            let moved = anchor / contrib + r * (offset / contrib);
            post.transform_point3(co + (moved - co) * a)
        })
        .collect()
}

fn unit_quat() -> impl Strategy<Value = Quat> {
    proptest::array::uniform4(-1.0f32..1.0).prop_filter_map("non-zero", |a| {
        let q = Quat::from_array(a);
        (q.length() > 0.1).then(|| q.normalize())
    })
}

fn vec3(extent: f32) -> impl Strategy<Value = Vec3> {
    proptest::array::uniform3(-extent..extent).prop_map(Vec3::from_array)
}

/// Rest and deform matrices; with `scaled`, some bones get scale, shear or a mirror.
fn rig(bones: std::ops::Range<usize>, scaled: bool) -> impl Strategy<Value = (Vec<Mat4>, Vec<Mat4>)> {
    let kind = if scaled { 0u8..4 } else { 0u8..1 };
    proptest::collection::vec((unit_quat(), vec3(2.0), unit_quat(), vec3(2.0), kind, vec3(0.6)), bones).prop_map(
        |specs| {
            let mut rest = Vec::new();
            let mut deform = Vec::new();
            for (rq, rt, pq, pt, kind, extra) in specs {
                let b = Mat4::from_rotation_translation(rq, rt);
                let mut posed = Mat4::from_rotation_translation(pq, pt);
                match kind {
                    1 => posed *= Mat4::from_scale(Vec3::ONE + extra.abs() * 2.0),
                    2 => {
                        let mut shear = Mat4::IDENTITY;
                        shear.y_axis.x = extra.x;
                        shear.z_axis.y = extra.y;
                        posed *= shear;
                    }
                    3 => posed *= Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0 + extra.z.abs())),
                    _ => {}
                }
                deform.push(posed * b.inverse());
                rest.push(b);
            }
            (rest, deform)
        },
    )
}

type Case = ((Vec<Mat4>, Vec<Mat4>), Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<Vec<(u32, f32)>>, Vec<f32>, Mat4);

fn case(scaled: bool) -> impl Strategy<Value = Case> {
    rig(1..7, scaled).prop_flat_map(|rig| {
        let b = rig.0.len() as u32;
        let entry = (0..b, prop_oneof![6 => 0.0f32..1.0, 1 => Just(0.0f32), 1 => 1.0f32..3.0]);
        (
            Just(rig),
            proptest::collection::vec(vec3(3.0).prop_map(|v| v.to_array()), 37),
            proptest::collection::vec(vec3(3.0).prop_map(|v| v.to_array()), 37),
            proptest::collection::vec(proptest::collection::vec(entry, 0..=6), 37),
            proptest::collection::vec(prop_oneof![Just(0.0f32), Just(1.0f32), 0.0f32..1.0], 37),
            (unit_quat(), vec3(2.0), 0.5f32..2.0)
                .prop_map(|(q, t, s)| Mat4::from_scale_rotation_translation(Vec3::splat(s), q, t)),
        )
    })
}

fn assert_close(got: &[[f32; 3]], want: &[DVec3], tol: f64) -> Result<(), TestCaseError> {
    for (v, (g, w)) in got.iter().zip(want).enumerate() {
        let g = Vec3::from_array(*g).as_dvec3();
        prop_assert!((g - *w).length() <= tol * (1.0 + w.length()), "vertex {v}: got {g}, want {w}");
    }
    Ok(())
}

/// The kernels against the float64 reference with the spaces `premat` and its inverse and the
/// mask; returns the kernels' result.
fn matches_the_reference(
    rest: &[Mat4],
    deform: &[Mat4],
    positions: &[[f32; 3]],
    centers: &[[f32; 3]],
    lists: &[Vec<(u32, f32)>],
    mask: &[f32],
    premat: Mat4,
) -> Result<Vec<[f32; 3]>, TestCaseError> {
    let influences = Influences::from_lists(lists, rest.len()).unwrap();
    let pose = Pose::new(deform, Some(rest)).unwrap();
    let postmat = premat.inverse();
    let options = SkinOptions { premat: Some(premat), postmat: Some(postmat), mask: Some(mask) };
    let got = skin_all(Method::CentersOfRotation { centers }, positions, &influences, &pose, &options);
    let want = reference(positions, centers, lists, deform, &pose, premat, postmat, Some(mask));
    // Magnitudes reach ~100 units (scaled bones, far centers); f32 round-off is ~1e-6 of that.
    assert_close(&got, &want, 5e-5)?;
    Ok(got)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 150, ..ProptestConfig::default() })]

    /// Rigid spaces on a pose without scale fold into the bones' records (`spaces.rs`): the
    /// kernels then work in mesh space, and must give what they give in armature space.
    #[test]
    fn kernel_matches_the_reference_with_rigid_spaces(((rest, deform), positions, centers, lists, mask, premat) in case(false)) {
        let (_, rotation, translation) = premat.to_scale_rotation_translation();
        let premat = Mat4::from_rotation_translation(rotation, translation);
        matches_the_reference(&rest, &deform, &positions, &centers, &lists, &mask, premat)?;
    }

    #[test]
    fn kernel_matches_the_reference(((rest, deform), positions, centers, lists, mask, premat) in case(true)) {
        let got = matches_the_reference(&rest, &deform, &positions, &centers, &lists, &mask, premat)?;
        for (v, m) in mask.iter().enumerate() {
            if *m == 0.0 {
                prop_assert_eq!(got[v], positions[v]);
            }
        }
        let influences = Influences::from_lists(&lists, rest.len()).unwrap();
        let pose = Pose::new(&deform, Some(&rest)).unwrap();
        let method = Method::CentersOfRotation { centers: &centers };
        let plain = skin_all(method, &positions, &influences, &pose, &SkinOptions::default());
        let want = reference(&positions, &centers, &lists, &deform, &pose, Mat4::IDENTITY, Mat4::IDENTITY, None);
        assert_close(&plain, &want, 5e-5)?;
    }

    #[test]
    fn rows_without_a_center_are_lbs(((rest, deform), positions, _c, lists, mask, premat) in case(true)) {
        let influences = Influences::from_lists(&lists, rest.len()).unwrap();
        let pose = Pose::new(&deform, Some(&rest)).unwrap();
        let options = SkinOptions { premat: Some(premat), postmat: Some(premat.inverse()), mask: Some(&mask) };
        let cor = skin_all(Method::CentersOfRotation { centers: &positions }, &positions, &influences, &pose, &options);
        let lbs = skin_all(Method::Linear, &positions, &influences, &pose, &options);
        for (a, b) in cor.iter().zip(&lbs) {
            let (a, b) = (Vec3::from_array(*a), Vec3::from_array(*b));
            prop_assert!((a - b).length() <= 2e-5 * (1.0 + b.length()), "{a} vs LBS {b}");
        }
    }

    #[test]
    fn bone_translations_alone_give_lbs(((rest, _), positions, centers, lists, _m, _p) in case(false), shifts in proptest::collection::vec(vec3(3.0), 6)) {
        let deform: Vec<Mat4> = (0..rest.len()).map(|b| Mat4::from_translation(shifts[b])).collect();
        let influences = Influences::from_lists(&lists, rest.len()).unwrap();
        let pose = Pose::new(&deform, Some(&rest)).unwrap();
        let cor = skin_all(Method::CentersOfRotation { centers: &centers }, &positions, &influences, &pose, &SkinOptions::default());
        let lbs = skin_all(Method::Linear, &positions, &influences, &pose, &SkinOptions::default());
        for (a, b) in cor.iter().zip(&lbs) {
            let (a, b) = (Vec3::from_array(*a), Vec3::from_array(*b));
            prop_assert!((a - b).length() <= 1e-5 * (1.0 + b.length()), "{a} vs LBS {b}");
        }
    }

    #[test]
    fn one_bone_vertices_move_rigidly_and_the_rest_pose_changes_nothing(((rest, deform), positions, centers, lists, _m, _p) in case(true)) {
        let bones = rest.len() as u32;
        let single: Vec<Vec<(u32, f32)>> = lists.iter().enumerate().map(|(v, _)| vec![(v as u32 % bones, 0.7)]).collect();
        let influences = Influences::from_lists(&single, rest.len()).unwrap();
        let pose = Pose::new(&deform, Some(&rest)).unwrap();
        let got = skin_all(Method::CentersOfRotation { centers: &centers }, &positions, &influences, &pose, &SkinOptions::default());
        for (v, g) in got.iter().enumerate() {
            let want = deform[v % rest.len()].transform_point3(Vec3::from_array(positions[v]));
            prop_assert!((Vec3::from_array(*g) - want).length() <= 2e-5 * (1.0 + want.length()), "vertex {v}: {g:?} vs {want}");
        }
        let influences = Influences::from_lists(&lists, rest.len()).unwrap();
        let still = Pose::new(&vec![Mat4::IDENTITY; rest.len()], Some(&rest)).unwrap();
        let got = skin_all(Method::CentersOfRotation { centers: &centers }, &positions, &influences, &still, &SkinOptions::default());
        for (g, p) in got.iter().zip(&positions) {
            prop_assert!((Vec3::from_array(*g) - Vec3::from_array(*p)).length() <= 1e-5 * (1.0 + Vec3::from_array(*p).length()));
        }
    }

    #[test]
    fn a_uniformly_scaled_rig_is_the_scaled_rigid_result(((rest, deform), positions, centers, lists, _m, _p) in case(false), s in 0.3f32..3.0) {
        // Every bone scaled by s about the armature origin after its rigid motion... i.e. the
        // mesh scaled first: M'ⱼ = Mⱼ·(s·I). Centers of rotation must give OCoR(s·v, s·p*).
        let scaled: Vec<Mat4> = deform.iter().map(|m| *m * Mat4::from_scale(Vec3::splat(s))).collect();
        let influences = Influences::from_lists(&lists, rest.len()).unwrap();
        let got = skin_all(Method::CentersOfRotation { centers: &centers }, &positions, &influences, &Pose::new(&scaled, Some(&rest)).unwrap(), &SkinOptions::default());
        let times = |a: &[[f32; 3]]| -> Vec<[f32; 3]> { a.iter().map(|p| (Vec3::from_array(*p) * s).to_array()).collect() };
        let want = skin_all(Method::CentersOfRotation { centers: &times(&centers) }, &times(&positions), &influences, &Pose::new(&deform, Some(&rest)).unwrap(), &SkinOptions::default());
        for (v, (a, b)) in got.iter().zip(&want).enumerate() {
            // Vertices without weight stay where they are, unscaled.
            if lists[v].iter().map(|e| e.1).sum::<f32>() <= MIN_TOTAL_WEIGHT {
                continue;
            }
            let (a, b) = (Vec3::from_array(*a), Vec3::from_array(*b));
            prop_assert!((a - b).length() <= 3e-5 * (1.0 + b.length()), "{a} vs {b}");
        }
    }
}

#[test]
fn bones_sharing_one_sheared_matrix_move_vertices_by_that_matrix() {
    // Same rest matrices too: a scaled bone's rotation (Blender's) depends on its rest matrix.
    let rest = vec![Mat4::from_rotation_translation(Quat::from_rotation_x(0.5), Vec3::Z); 2];
    let mut shear = Mat4::from_scale_rotation_translation(
        Vec3::new(1.3, 0.7, 2.0),
        Quat::from_rotation_z(0.8),
        Vec3::new(0.2, -1.0, 0.5),
    );
    shear.y_axis.x = 0.4;
    let deform = vec![shear; 2];
    let pose = Pose::new(&deform, Some(&rest)).unwrap();
    assert!(pose.any_scaled());
    let positions = vec![[1.0, 2.0, 3.0], [-0.5, 0.1, 0.9], [2.0, -1.0, 0.0]];
    let centers = vec![[0.0, 1.0, 0.0], [0.3, 0.3, 0.3], [2.0, -1.0, 0.0]];
    let influences =
        Influences::from_lists(&[vec![(0, 0.3), (1, 0.7)], vec![(1, 0.5), (0, 0.5)], vec![(0, 1.0), (1, 1.0)]], 2)
            .unwrap();
    let got = skin_all(
        Method::CentersOfRotation { centers: &centers },
        &positions,
        &influences,
        &pose,
        &SkinOptions::default(),
    );
    for (g, p) in got.iter().zip(&positions) {
        let want = shear.transform_point3(Vec3::from_array(*p));
        assert!((Vec3::from_array(*g) - want).length() < 1e-5, "{g:?} vs {want}");
    }
}

fn twisted_ring_area(cyl: &TwistCylinder, method: Method<'_>, angle: f32) -> f64 {
    let pose = Pose::new(&cyl.twist(angle), Some(&cyl.rest)).unwrap();
    let out = skin_all(method, &cyl.positions, &cyl.influences, &pose, &SkinOptions::default());
    polygon_area(&cyl.ring(cyl.rings / 2).map(|i| out[i]).collect::<Vec<_>>())
}

#[test]
fn twisting_180_degrees_keeps_the_middle_cross_section() {
    let cyl = TwistCylinder::new(21, 48, 4.0, 0.5, 0.5).unwrap();
    let centers = centers_of_rotation(&cyl.positions, &cyl.triangles, &cyl.influences, DEFAULT_SIGMA).unwrap();
    let cor = Method::CentersOfRotation { centers: &centers.centers };
    let rest_area = twisted_ring_area(&cyl, Method::Linear, 0.0);
    let pi = core::f32::consts::PI;
    let lbs = twisted_ring_area(&cyl, Method::Linear, pi) / rest_area;
    let kept = twisted_ring_area(&cyl, cor, pi) / rest_area;
    eprintln!("180° twist, middle ring area kept: LBS {:.1} %, centers of rotation {:.2} %", 100.0 * lbs, 100.0 * kept);
    assert!(lbs < 1e-6);
    assert!(kept >= 0.95, "keeps {kept}");
    assert!((twisted_ring_area(&cyl, cor, 0.0) / rest_area - 1.0).abs() < 1e-6);
}

/// Bends the upper bone of a cylinder by `degrees` about the X axis at the joint and measures
/// the vertices of the blend zone: mean and largest `|distance to the bent axis − radius|`,
/// relative to the radius.
fn elbow_deviation(cyl: &TwistCylinder, method: Method<'_>, degrees: f32) -> (f64, f64) {
    let joint = cyl.rest[1].w_axis.truncate();
    let bend =
        Mat4::from_translation(joint) * Mat4::from_rotation_x(degrees.to_radians()) * Mat4::from_translation(-joint);
    let deform = [Mat4::IDENTITY, bend];
    let pose = Pose::new(&deform, Some(&cyl.rest)).unwrap();
    let out = skin_all(method, &cyl.positions, &cyl.influences, &pose, &SkinOptions::default());
    let upper_dir = bend.transform_vector3(Vec3::Y);
    // Distance to the bent axis: the lower segment below the joint, the upper one above it.
    let distance = |p: Vec3| -> f32 {
        let d = p - joint;
        let along_lower = d.dot(Vec3::Y).min(0.0);
        let along_upper = d.dot(upper_dir).max(0.0);
        let lower = (d - Vec3::Y * along_lower).length();
        let upper = (d - upper_dir * along_upper).length();
        // A point is nearest to whichever segment (or the joint) it is closest to.
        lower.min(upper)
    };
    let mut deviations = Vec::new();
    for v in 0..cyl.rings * cyl.segments {
        if cyl.influences.of_vertex(v).len() == 2 {
            let d = distance(Vec3::from_array(out[v]));
            deviations.push((f64::from(d) - f64::from(cyl.radius)).abs() / f64::from(cyl.radius));
        }
    }
    let mean = deviations.iter().sum::<f64>() / deviations.len() as f64;
    (mean, deviations.iter().cloned().fold(0.0, f64::max))
}

#[test]
fn an_elbow_bend_deviates_less_from_the_rest_radius_than_lbs_and_dqs() {
    let cyl = TwistCylinder::new(41, 48, 4.0, 0.5, 0.5).unwrap();
    let centers = centers_of_rotation(&cyl.positions, &cyl.triangles, &cyl.influences, DEFAULT_SIGMA).unwrap();
    let cor = Method::CentersOfRotation { centers: &centers.centers };
    for degrees in [90.0f32, 120.0, 150.0] {
        let (lbs, lbs_max) = elbow_deviation(&cyl, Method::Linear, degrees);
        let (dqs, dqs_max) = elbow_deviation(&cyl, Method::DualQuaternion, degrees);
        let (ocor, ocor_max) = elbow_deviation(&cyl, cor, degrees);
        eprintln!(
            "elbow {degrees}°: mean |distance − r|/r  LBS {:.2} %  DQS {:.2} %  CoR {:.2} %   (largest {:.1} / {:.1} / {:.1} %)",
            100.0 * lbs, 100.0 * dqs, 100.0 * ocor, 100.0 * lbs_max, 100.0 * dqs_max, 100.0 * ocor_max
        );
        assert!(ocor < lbs && ocor < dqs, "{degrees}°: LBS {lbs}, DQS {dqs}, centers {ocor}");
    }
}

#[test]
fn bad_kernel_inputs_are_rejected_before_anything_is_written() {
    let positions = vec![[0.0f32; 3]; 2];
    let influences = Influences::from_lists(&[vec![(0, 1.0)], vec![(1, 1.0)]], 2).unwrap();
    let pose = Pose::new(&[Mat4::IDENTITY; 2], Some(&[Mat4::IDENTITY; 2])).unwrap();
    let linear_only = Pose::new(&[Mat4::IDENTITY; 2], None).unwrap();
    let mut out = vec![[7.0f32; 3]; 2];
    let opts = SkinOptions::default();
    let centers = [[0.0f32; 3]; 2];
    let err = |c: &[[f32; 3]], pose: &Pose, out: &mut [[f32; 3]]| {
        super::super::skin(Method::CentersOfRotation { centers: c }, &positions, &influences, pose, &opts, out)
            .unwrap_err()
    };
    assert_eq!(err(&centers[..1], &pose, &mut out), SkinError::LengthMismatch { what: "centers", expected: 2, got: 1 });
    assert_eq!(
        err(&[[0.0, f32::NAN, 0.0], [0.0; 3]], &pose, &mut out),
        SkinError::NotFinite { what: "centers", index: 0 }
    );
    assert_eq!(err(&centers, &linear_only, &mut out), SkinError::MissingRestMatrices);
    assert_eq!(out, vec![[7.0f32; 3]; 2]);
}

#[test]
fn skin_many_runs_centers_of_rotation() {
    let c = Creature::new(3000).unwrap();
    let centers = centers_of_rotation(&c.positions, &c.triangles, &c.influences, DEFAULT_SIGMA).unwrap();
    let deform = c.pose(0.4, 0.3);
    let pose = Pose::new(&deform, Some(&c.rest)).unwrap();
    let method = Method::CentersOfRotation { centers: &centers.centers };
    let mut want = vec![[0.0f32; 3]; c.positions.len()];
    super::super::skin(method, &c.positions, &c.influences, &pose, &SkinOptions::default(), &mut want).unwrap();
    let mut out = vec![[0.0f32; 3]; c.positions.len()];
    let mut short = vec![[7.0f32; 3]; 3];
    let mut jobs = vec![
        super::super::ManyJob {
            method,
            positions: &c.positions,
            influences: &c.influences,
            deform: &deform,
            rest: Some(&c.rest),
            options: SkinOptions::default(),
            out: &mut out,
        },
        super::super::ManyJob {
            method,
            positions: &c.positions,
            influences: &c.influences,
            deform: &deform,
            rest: None,
            options: SkinOptions::default(),
            out: &mut short,
        },
    ];
    let results = super::super::skin_many(&mut jobs);
    drop(jobs);
    assert!(results[0].is_ok());
    assert!(results[1].is_err());
    assert_eq!(out, want);
    // The pose moved the creature, and differently from LBS.
    let mut lbs = vec![[0.0f32; 3]; c.positions.len()];
    super::super::skin(Method::Linear, &c.positions, &c.influences, &pose, &SkinOptions::default(), &mut lbs).unwrap();
    assert!(want.iter().zip(&lbs).any(|(a, b)| (Vec3::from_array(*a) - Vec3::from_array(*b)).length() > 1e-3));
}

/// The creature's weights with a stroke painted: the vertices within `radius` of vertex `at`
/// get `weight` more on `bone` (renormalized by the precompute), as a weight brush does.
fn painted(c: &Creature, at: usize, radius: f32, bone: u32, weight: f32) -> (Influences, usize) {
    let centre = Vec3::from_array(c.positions[at]);
    let mut count = 0;
    let lists: Vec<Vec<(u32, f32)>> = (0..c.influences.vertex_count())
        .map(|v| {
            let mut list: Vec<(u32, f32)> = c.influences.of_vertex(v).map(|i| (i.bone, i.weight)).collect();
            if Vec3::from_array(c.positions[v]).distance(centre) < radius {
                count += 1;
                list.push((bone, weight));
            }
            list
        })
        .collect();
    (Influences::from_lists(&lists, c.influences.bone_count()).unwrap(), count)
}

#[test]
fn after_a_stroke_the_update_equals_the_full_precompute_bit_for_bit_and_computes_less() {
    let c = Creature::new(20_000).unwrap();
    let (p, t) = (&c.positions, &c.triangles);
    let before = centers_of_rotation(p, t, &c.influences, DEFAULT_SIGMA).unwrap();
    let mut full_total = 0;
    for (at, radius, bone, weight) in [(1234, 0.3, 5, 0.4), (9000, 0.15, 2, 0.2), (17_000, 0.05, 9, 1.0)] {
        let (after, count) = painted(&c, at, radius, bone, weight);
        assert!(count > 10, "the stroke paints {count} vertices");
        let full = centers_counted(
            Simd::detect(),
            Some(cells::TOLERANCE),
            p,
            t,
            &after,
            DEFAULT_SIGMA,
            &mut |_, total| {
                full_total = total;
                true
            },
            &mut || false,
        )
        .unwrap()
        .0;
        let mut update_total = 0;
        let previous = PreviousCenters { influences: &c.influences, centers: &before };
        let updated = centers_of_rotation_update(
            p,
            t,
            &after,
            DEFAULT_SIGMA,
            previous,
            &mut |_, total| {
                update_total = total;
                true
            },
            &mut || false,
        )
        .unwrap();
        assert_eq!(updated, full, "a stroke of {count} vertices at {at}");
        assert_ne!(updated, before, "the stroke moves centers");
        assert!(update_total * 2 < full_total, "the update does {update_total} of the full {full_total}");
    }
    // Nothing painted: nothing computed, the same centers.
    let mut total = usize::MAX;
    let previous = PreviousCenters { influences: &c.influences, centers: &before };
    let same = centers_of_rotation_update(
        p,
        t,
        &c.influences,
        DEFAULT_SIGMA,
        previous,
        &mut |_, n| {
            total = n;
            true
        },
        &mut || false,
    )
    .unwrap();
    assert_eq!(same, before);
    assert_eq!(total, 0);
}

#[test]
fn the_update_refuses_previous_centers_of_another_mesh() {
    let c = Creature::new(3000).unwrap();
    let other = Creature::new(4000).unwrap();
    let centers = centers_of_rotation(&other.positions, &other.triangles, &other.influences, DEFAULT_SIGMA).unwrap();
    let previous = PreviousCenters { influences: &other.influences, centers: &centers };
    let got = centers_of_rotation_update(
        &c.positions,
        &c.triangles,
        &c.influences,
        DEFAULT_SIGMA,
        previous,
        &mut |_, _| true,
        &mut || false,
    );
    assert!(matches!(got, Err(SkinError::LengthMismatch { .. })), "{got:?}");
}

/// `influences` with `bone`'s weight set to `weight` on the vertices within `radius` of vertex
/// `at` (as a brush paints a group: an existing weight replaced, else added).
fn repainted(
    positions: &[[f32; 3]],
    influences: &Influences,
    at: usize,
    radius: f32,
    bone: u32,
    weight: f32,
) -> Influences {
    let centre = Vec3::from_array(positions[at]);
    let lists: Vec<Vec<(u32, f32)>> = (0..influences.vertex_count())
        .map(|v| {
            let mut list: Vec<(u32, f32)> = influences.of_vertex(v).map(|i| (i.bone, i.weight)).collect();
            if Vec3::from_array(positions[v]).distance(centre) < radius {
                match list.iter_mut().find(|e| e.0 == bone) {
                    Some(e) => e.1 = weight,
                    None => list.push((bone, weight)),
                }
            }
            list
        })
        .collect();
    Influences::from_lists(&lists, influences.bone_count()).unwrap()
}

#[test]
fn strokes_that_follow_one_another_take_the_kept_sums_and_still_equal_the_full_precompute() {
    let c = Creature::new(20_000).unwrap();
    let (p, t) = (&c.positions, &c.triangles);
    let mut weights = c.influences.clone();
    let mut centers = centers_of_rotation(p, t, &weights, DEFAULT_SIGMA).unwrap();
    let mut kept: Option<CenterSums> = None;
    // The same place again, beside it, elsewhere, and back to the first stroke's weights there
    // (weight vectors that existed two strokes ago come back, after lists they read changed).
    let strokes =
        [(1234, 0.3, 5, 0.4), (1234, 0.3, 5, 0.7), (1300, 0.2, 5, 0.2), (9000, 0.15, 2, 0.3), (1234, 0.3, 5, 0.4)];
    for (s, &(at, radius, bone, weight)) in strokes.iter().enumerate() {
        let after = repainted(p, &weights, at, radius, bone, weight);
        let full = centers_of_rotation(p, t, &after, DEFAULT_SIGMA).unwrap();
        let previous = PreviousCenters { influences: &weights, centers: &centers };
        let mut plain_work = 0;
        let plain = centers_of_rotation_update(
            p,
            t,
            &after,
            DEFAULT_SIGMA,
            previous,
            &mut |_, n| {
                plain_work = n;
                true
            },
            &mut || false,
        )
        .unwrap();
        let mut kept_work = 0;
        let (got, next) = centers_of_rotation_update_keeping(
            p,
            t,
            &after,
            DEFAULT_SIGMA,
            previous,
            kept.take(),
            &mut |_, n| {
                kept_work = n;
                true
            },
            &mut || false,
        )
        .unwrap();
        assert_eq!(plain, full, "stroke {s} without kept sums");
        assert_eq!(got, full, "stroke {s} with the kept sums");
        assert!(!next.is_empty(), "stroke {s} kept nothing");
        // At least the fast path's 5 values of one pair for each weight vector kept.
        assert!(
            next.heap_bytes() >= next.len() * 5 * 8,
            "stroke {s}: {} bytes for {} vectors",
            next.heap_bytes(),
            next.len()
        );
        if s > 0 {
            assert!(kept_work < plain_work, "stroke {s}: {kept_work} of work with the kept sums, {plain_work} without");
        }
        kept = Some(next);
        weights = after;
        centers = got;
    }
}

#[test]
fn sums_kept_for_another_sigma_are_not_taken() {
    let c = Creature::new(2000).unwrap();
    let (p, t) = (&c.positions, &c.triangles);
    let first = repainted(p, &c.influences, 1000, 0.3, 3, 0.5);
    let second = repainted(p, &first, 1000, 0.3, 3, 0.9);
    let before = centers_of_rotation(p, t, &c.influences, 0.2).unwrap();
    let previous = PreviousCenters { influences: &c.influences, centers: &before };
    let (mid, kept) = update_keeping(p, t, &first, 0.2, previous, None);
    let mid_default = centers_of_rotation(p, t, &first, DEFAULT_SIGMA).unwrap();
    let previous = PreviousCenters { influences: &first, centers: &mid_default };
    let (got, _) = update_keeping(p, t, &second, DEFAULT_SIGMA, previous, Some(kept));
    assert_ne!(mid, mid_default);
    assert_eq!(got, centers_of_rotation(p, t, &second, DEFAULT_SIGMA).unwrap());
}

#[test]
fn sums_kept_for_another_geometry_are_not_taken() {
    // Two meshes with the same weights, one with moved vertices: what an update of the first
    // kept must not be taken by an update of the second (the values depend on the positions).
    let c = Creature::new(2000).unwrap();
    let t = &c.triangles;
    let a = &c.positions;
    let b: Vec<[f32; 3]> = a.iter().map(|p| [p[0] * 1.1, p[1], p[2] + 0.05 * p[0]]).collect();
    let first = repainted(a, &c.influences, 1000, 0.3, 3, 0.5);
    let second = repainted(a, &first, 1000, 0.3, 3, 0.9);
    let on_a = centers_of_rotation(a, t, &c.influences, DEFAULT_SIGMA).unwrap();
    let previous = PreviousCenters { influences: &c.influences, centers: &on_a };
    let (_, kept) = update_keeping(a, t, &first, DEFAULT_SIGMA, previous, None);
    let mid_b = centers_of_rotation(&b, t, &first, DEFAULT_SIGMA).unwrap();
    let previous = PreviousCenters { influences: &first, centers: &mid_b };
    let (got, _) = update_keeping(&b, t, &second, DEFAULT_SIGMA, previous, Some(kept));
    assert_eq!(got, centers_of_rotation(&b, t, &second, DEFAULT_SIGMA).unwrap());
}

/// An update that keeps its sums (and takes `kept`), with no progress report or cancelling.
fn update_keeping(
    positions: &[[f32; 3]],
    triangles: &[[u32; 3]],
    influences: &Influences,
    sigma: f32,
    previous: PreviousCenters<'_>,
    kept: Option<CenterSums>,
) -> (Centers, CenterSums) {
    centers_of_rotation_update_keeping(
        positions,
        triangles,
        influences,
        sigma,
        previous,
        kept,
        &mut |_, _| true,
        &mut || false,
    )
    .unwrap()
}
