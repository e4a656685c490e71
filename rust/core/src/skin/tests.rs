//! Kernels against a straightforward scalar reference written from Blender's
//! `armature_deform.cc` and `math_rotation_c.cc` in f64, with the scale path computed the way
//! Blender does it (full scale matrices, `add_weighted_dq_dq_pivot`), not the shortcut the
//! kernels take.

use super::*;
use crate::rigs::{polygon_area, TwistCylinder};
use glam::{DMat3, DMat4, DQuat, DVec3, Mat4, Quat, Vec3};
use influences::bone_window;
use proptest::prelude::*;

mod reference {
    use super::*;

    /// Blender's `DualQuat`: quat and trans as (w, x, y, z), scale matrix and its weight.
    #[derive(Clone, Copy)]
    pub struct BDq {
        pub quat: [f64; 4],
        pub trans: [f64; 4],
        pub scale: DMat4,
        pub scale_weight: f64,
    }

    fn mat4_to_quat(m: &DMat4) -> [f64; 4] {
        // Normalize columns, negate on negative determinant, then any correct conversion; w ≥ 0.
        let mut m3 = DMat3::from_cols(
            m.x_axis.truncate().normalize_or_zero(),
            m.y_axis.truncate().normalize_or_zero(),
            m.z_axis.truncate().normalize_or_zero(),
        );
        if m3.determinant() < 0.0 {
            m3 = -m3;
        }
        let q = DQuat::from_mat3(&m3).normalize();
        let q = if q.w < 0.0 { -q } else { q };
        [q.w, q.x, q.y, q.z]
    }

    fn orthogonalize_y(m: &DMat4) -> DMat4 {
        let size = DVec3::new(m.x_axis.truncate().length(), m.y_axis.truncate().length(), m.z_axis.truncate().length());
        let y = m.y_axis.truncate().normalize();
        let x0 = m.x_axis.truncate();
        let z = x0.cross(y).normalize();
        let x = y.cross(z);
        DMat4::from_cols((x * size.x).extend(0.0), (y * size.y).extend(0.0), (z * size.z).extend(0.0), m.w_axis)
    }

    fn is_orthonormal(m: &DMat3) -> bool {
        let c = [m.x_axis, m.y_axis, m.z_axis];
        for i in 0..3 {
            for j in 0..i {
                if c[i].dot(c[j]).abs() > 1e-5 {
                    return false;
                }
            }
            if (c[i].dot(c[i]) - 1.0).abs() > 1e-5 {
                return false;
            }
        }
        true
    }

    pub fn mat4_to_dquat(basemat: &DMat4, mat: &DMat4) -> BDq {
        let base_rs = *mat * *basemat;
        let size = DVec3::new(
            base_rs.x_axis.truncate().length(),
            base_rs.y_axis.truncate().length(),
            base_rs.z_axis.truncate().length(),
        );
        let dscale = size - DVec3::ONE;
        let (r, scale, scale_weight);
        if !is_orthonormal(&DMat3::from_mat4(*mat)) || mat.determinant() < 0.0 || dscale.length_squared() > 1e-8 {
            let basequat = mat4_to_quat(&orthogonalize_y(&base_rs));
            let q = DQuat::from_xyzw(basequat[1], basequat[2], basequat[3], basequat[0]);
            let mut base_r = DMat4::from_quat(q);
            base_r.w_axis = base_rs.w_axis;
            let baseinv = basemat.inverse();
            r = base_r * baseinv;
            let s = base_r.inverse() * base_rs;
            scale = *basemat * s * baseinv;
            scale_weight = 1.0;
        } else {
            r = *mat;
            scale = DMat4::ZERO;
            scale_weight = 0.0;
        }
        let q = mat4_to_quat(&r);
        let t = r.w_axis.truncate();
        let trans = [
            -0.5 * (t.x * q[1] + t.y * q[2] + t.z * q[3]),
            0.5 * (t.x * q[0] + t.y * q[3] - t.z * q[2]),
            0.5 * (-t.x * q[3] + t.y * q[0] + t.z * q[1]),
            0.5 * (t.x * q[2] - t.y * q[1] + t.z * q[0]),
        ];
        BDq { quat: q, trans, scale, scale_weight }
    }

    fn add_weighted(sum: &mut BDq, dq: &BDq, weight: f64) {
        let dot: f64 = (0..4).map(|k| dq.quat[k] * sum.quat[k]).sum();
        let w = if dot < 0.0 { -weight } else { weight };
        for k in 0..4 {
            sum.quat[k] += w * dq.quat[k];
            sum.trans[k] += w * dq.trans[k];
        }
        if dq.scale_weight != 0.0 {
            sum.scale += dq.scale * weight;
            sum.scale_weight += weight;
        }
    }

    /// `add_weighted_dq_dq_pivot` with `compute_scale_matrix = false`.
    fn add_weighted_pivot(sum: &mut BDq, dq: &BDq, pivot: DVec3, weight: f64) {
        if dq.scale_weight != 0.0 {
            let mut m = *dq;
            let dst = dq.scale.transform_point3(pivot) - pivot;
            let q = m.quat;
            m.trans[0] -= 0.5 * (q[1] * dst.x + q[2] * dst.y + q[3] * dst.z);
            m.trans[1] += 0.5 * (q[0] * dst.x + q[2] * dst.z - q[3] * dst.y);
            m.trans[2] += 0.5 * (q[0] * dst.y + q[3] * dst.x - q[1] * dst.z);
            m.trans[3] += 0.5 * (q[0] * dst.z + q[1] * dst.y - q[2] * dst.x);
            m.scale_weight = 0.0;
            add_weighted(sum, &m, weight);
        } else {
            add_weighted(sum, dq, weight);
        }
    }

    fn mul_v3m3_dq(co: DVec3, dq: &BDq) -> DVec3 {
        let [w, x, y, z] = dq.quat;
        let [t0, t1, t2, t3] = dq.trans;
        let m = DMat3::from_cols(
            DVec3::new(w * w + x * x - y * y - z * z, 2.0 * (x * y + w * z), 2.0 * (x * z - w * y)),
            DVec3::new(2.0 * (x * y - w * z), w * w + y * y - x * x - z * z, 2.0 * (y * z + w * x)),
            DVec3::new(2.0 * (x * z + w * y), 2.0 * (y * z - w * x), w * w + z * z - x * x - y * y),
        );
        let len2 = w * w + x * x + y * y + z * z;
        let t = DVec3::new(
            2.0 * (-t0 * x + w * t1 - t2 * z + y * t3),
            2.0 * (-t0 * y + t1 * z - x * t3 + w * t2),
            2.0 * (-t0 * z + x * t2 + w * t3 - t1 * y),
        );
        (m * co + t) / len2
    }

    pub struct Inputs<'a> {
        pub positions: &'a [[f32; 3]],
        pub lists: &'a [Vec<(u32, f32)>],
        pub deform: &'a [Mat4],
        pub rest: &'a [Mat4],
        pub premat: Mat4,
        pub postmat: Mat4,
        pub mask: Option<&'a [f32]>,
    }

    fn d(m: &Mat4) -> DMat4 {
        m.as_dmat4()
    }

    /// Blender's `armature_vert_task_with_dvert` for vertex groups only; `dqs` picks Preserve
    /// Volume. Returns mesh-space positions.
    pub fn skin(inputs: &Inputs<'_>, dqs: bool) -> Vec<DVec3> {
        let dqs_bones: Vec<BDq> =
            inputs.deform.iter().zip(inputs.rest).map(|(m, b)| mat4_to_dquat(&d(b), &d(m))).collect();
        inputs
            .positions
            .iter()
            .enumerate()
            .map(|(v, p)| {
                let p = Vec3::from_array(*p).as_dvec3();
                let a = inputs.mask.map_or(1.0, |m| m[v] as f64);
                if a == 0.0 {
                    return p;
                }
                let mut co = d(&inputs.premat).transform_point3(p);
                let mut contrib = 0.0;
                let mut vec = DVec3::ZERO;
                let mut sum = BDq { quat: [0.0; 4], trans: [0.0; 4], scale: DMat4::ZERO, scale_weight: 0.0 };
                for &(bone, w) in &inputs.lists[v] {
                    let w = w as f64;
                    if w == 0.0 {
                        continue;
                    }
                    let b = bone as usize;
                    if dqs {
                        add_weighted_pivot(&mut sum, &dqs_bones[b], co, w);
                    } else {
                        vec += (d(&inputs.deform[b]).transform_point3(co) - co) * w;
                    }
                    contrib += w;
                }
                if contrib > 0.0001 {
                    if dqs {
                        let r = mul_v3m3_dq(co, &sum);
                        co += (r - co) * a;
                    } else {
                        co += vec * (a / contrib);
                    }
                }
                d(&inputs.postmat).transform_point3(co)
            })
            .collect()
    }

    pub fn blend(inputs: &Inputs<'_>, alpha: &[f32]) -> Vec<DVec3> {
        let (l, q) = (skin(inputs, false), skin(inputs, true));
        l.iter().zip(&q).zip(alpha).map(|((l, q), &a)| *l * (1.0 - a as f64) + *q * a as f64).collect()
    }
}

/// A random rig: rest matrices are rigid; deform matrices are rigid, scaled, sheared or mirrored.
#[derive(Debug, Clone)]
struct Rig {
    rest: Vec<Mat4>,
    deform: Vec<Mat4>,
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

#[derive(Debug, Clone, Copy)]
enum BoneKind {
    Rigid,
    Scaled,
    Sheared,
    Mirrored,
    /// The rotation half a turn from the first bone's, so signs must be flipped in the sum.
    Antipodal,
}

fn bone_kind() -> impl Strategy<Value = BoneKind> {
    prop_oneof![
        4 => Just(BoneKind::Rigid),
        1 => Just(BoneKind::Scaled),
        1 => Just(BoneKind::Sheared),
        1 => Just(BoneKind::Mirrored),
        2 => Just(BoneKind::Antipodal),
    ]
}

fn rig(bones: std::ops::Range<usize>) -> impl Strategy<Value = Rig> {
    proptest::collection::vec((unit_quat(), vec3(2.0), unit_quat(), vec3(2.0), bone_kind(), vec3(0.6)), bones).prop_map(
        |specs| {
            let first = specs[0].2;
            let mut rest = Vec::new();
            let mut deform = Vec::new();
            for (rq, rt, pq, pt, kind, extra) in specs {
                let b = Mat4::from_rotation_translation(rq, rt);
                let posed_rot = match kind {
                    BoneKind::Antipodal => Quat::from_axis_angle(Vec3::new(0.3, 1.0, -0.2).normalize(), 3.0) * first,
                    _ => pq,
                };
                let mut posed = Mat4::from_rotation_translation(posed_rot, pt);
                match kind {
                    BoneKind::Scaled => posed *= Mat4::from_scale(Vec3::ONE + extra.abs() * 2.0),
                    BoneKind::Sheared => {
                        let mut shear = Mat4::IDENTITY;
                        shear.y_axis.x = extra.x;
                        shear.z_axis.y = extra.y;
                        posed *= shear;
                    }
                    BoneKind::Mirrored => posed *= Mat4::from_scale(Vec3::new(-1.0, 1.0, 1.0 + extra.z.abs())),
                    _ => {}
                }
                // Blender's matrix_channel: posed (armature space) times inverse rest.
                deform.push(posed * b.inverse());
                rest.push(b);
            }
            Rig { rest, deform }
        },
    )
}

/// Per-vertex influence lists with 0..=8 entries, zero and unnormalized weights, repeated bones.
fn lists(vertices: usize, bones: usize) -> impl Strategy<Value = Vec<Vec<(u32, f32)>>> {
    let entry = (0..bones as u32, prop_oneof![6 => 0.0f32..1.0, 1 => Just(0.0f32), 1 => 1.0f32..3.0]);
    proptest::collection::vec(proptest::collection::vec(entry, 0..=8), vertices)
}

/// A rig, 40 positions, their influence lists and mask weights, and `premat`.
type Case = (Rig, Vec<[f32; 3]>, Vec<Vec<(u32, f32)>>, Vec<f32>, Mat4);

fn case() -> impl Strategy<Value = Case> {
    rig(1..9).prop_flat_map(|rig| {
        let b = rig.rest.len();
        (
            Just(rig),
            proptest::collection::vec(vec3(3.0).prop_map(|v| v.to_array()), 40),
            lists(40, b),
            proptest::collection::vec(prop_oneof![Just(0.0f32), Just(1.0f32), 0.0f32..1.0], 40),
            (unit_quat(), vec3(2.0), 0.5f32..2.0)
                .prop_map(|(q, t, s)| Mat4::from_scale_rotation_translation(Vec3::splat(s), q, t)),
        )
    })
}

/// Skins with every compiled copy of the kernels this CPU can run; they must agree to round-off
/// (FMA contraction differs between copies) and the last one's result is returned.
fn run(
    method: Method<'_>,
    positions: &[[f32; 3]],
    lists: &[Vec<(u32, f32)>],
    rig: &Rig,
    options: &SkinOptions<'_>,
) -> Vec<[f32; 3]> {
    let influences = Influences::from_lists(lists, rig.rest.len()).unwrap();
    let pose = Pose::new(&rig.deform, Some(&rig.rest)).unwrap();
    skin_all(method, positions, &influences, &pose, options)
}

/// Skins with every compiled copy of the kernels; returns the last one's result. The copies with
/// fused multiply-adds (all but the baseline) must give the same bits: which of them runs is
/// chosen by timing (`calibration.rs`), and a result must not depend on it (a farm's chunks
/// baked in different processes, or on different CPUs, join byte for byte). So must each copy's
/// hand-written kernels and its one body ([`isa::Simd::one_body`]): on a CPU with only one copy
/// with fused multiply-adds, that is what holds its hand-written kernels to the others'. The
/// baseline, whose products are rounded before they are added, must agree to round-off.
pub(in crate::skin) fn skin_all(
    method: Method<'_>,
    positions: &[[f32; 3]],
    influences: &Influences,
    pose: &Pose,
    options: &SkinOptions<'_>,
) -> Vec<[f32; 3]> {
    let mut results = Vec::new();
    let mut fused: Option<(isa::Simd, Vec<[f32; 3]>)> = None;
    // (Each copy also without prefetching where it has the hint: a hint changes no bit.)
    let copies = isa::Simd::available()
        .into_iter()
        .flat_map(|simd| [Some(simd.one_body()), simd.without_prefetch(), Some(simd)])
        .flatten();
    for simd in copies {
        let mut out = vec![[f32::NAN; 3]; positions.len()];
        skin_with(Some(simd), method, positions, influences, pose, options, &mut out).unwrap();
        if simd.instruction_set() != isa::InstructionSet::Baseline {
            match &fused {
                Some((first, want)) => {
                    for (v, (a, b)) in out.iter().zip(want).enumerate() {
                        assert!(
                            a.map(f32::to_bits) == b.map(f32::to_bits),
                            "{method:?}: vertex {v} is {a:?} on {simd:?} but {b:?} on {first:?}"
                        );
                    }
                }
                None => fused = Some((simd, out.clone())),
            }
        }
        results.push(out);
    }
    let last = results.pop().unwrap();
    for other in &results {
        for (a, b) in other.iter().zip(&last) {
            let (a, b) = (Vec3::from_array(*a), Vec3::from_array(*b));
            assert!((a - b).length() <= 1e-5 * (1.0 + b.length()), "compiled copies disagree: {a} vs {b}");
        }
    }
    last
}

#[test]
fn every_compiled_copy_is_exercised_here() {
    // Say which copies the reference tests cover; the SIMD copy every CI machine has (AVX2 on
    // x86-64, NEON on aarch64) must be among them.
    use isa::InstructionSet;
    let available: Vec<InstructionSet> = isa::Simd::available().iter().map(|s| s.instruction_set()).collect();
    assert_eq!(available[0], InstructionSet::Baseline);
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") && std::arch::is_x86_feature_detected!("fma") {
        assert!(available.contains(&InstructionSet::Avx2Fma));
    }
    #[cfg(target_arch = "aarch64")]
    assert!(available.contains(&InstructionSet::Neon));
    eprintln!("kernel copies tested: {available:?}");
}

fn assert_close(got: &[[f32; 3]], want: &[DVec3], tol: f64) -> Result<(), TestCaseError> {
    for (v, (g, w)) in got.iter().zip(want).enumerate() {
        let g = Vec3::from_array(*g).as_dvec3();
        let scale = 1.0 + w.length();
        prop_assert!((g - *w).length() <= tol * scale, "vertex {v}: got {g}, want {w}");
    }
    Ok(())
}

/// LBS, DQS and Blend with the spaces `premat`, `postmat` and the mask against the float64
/// reference; returns Blend's result.
fn every_method_matches_the_reference(
    rig: &Rig,
    positions: &[[f32; 3]],
    lists: &[Vec<(u32, f32)>],
    mask: &[f32],
    premat: Mat4,
    postmat: Mat4,
) -> Result<Vec<[f32; 3]>, TestCaseError> {
    let inputs =
        reference::Inputs { positions, lists, deform: &rig.deform, rest: &rig.rest, premat, postmat, mask: Some(mask) };
    let options = SkinOptions { premat: Some(premat), postmat: Some(postmat), mask: Some(mask) };
    // The deformations reach magnitudes of ~50 units; f32 round-off is ~1e-6 of that.
    assert_close(&run(Method::Linear, positions, lists, rig, &options), &reference::skin(&inputs, false), 2e-5)?;
    assert_close(&run(Method::DualQuaternion, positions, lists, rig, &options), &reference::skin(&inputs, true), 2e-5)?;
    let amount: Vec<f32> = mask.iter().rev().copied().collect();
    let blend = run(Method::Blend { amount: Some(&amount), factor: 0.8 }, positions, lists, rig, &options);
    let alpha: Vec<f32> = amount.iter().map(|a| a * 0.8).collect();
    assert_close(&blend, &reference::blend(&inputs, &alpha), 2e-5)?;
    Ok(blend)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

    #[test]
    fn kernels_match_the_reference((rig, positions, lists, mask, premat) in case()) {
        let blend = every_method_matches_the_reference(&rig, &positions, &lists, &mask, premat, premat.inverse())?;
        // Masked-out vertices are copied bit for bit.
        for (v, m) in mask.iter().enumerate() {
            if *m == 0.0 {
                prop_assert_eq!(blend[v], positions[v]);
            }
        }
    }

    /// Rigid spaces (a rotation and a translation, as most objects have) fold into the dual
    /// quaternions too (`spaces.rs`): DQS and Blend in mesh space equal them in armature space.
    #[test]
    fn kernels_match_the_reference_with_rigid_spaces((rig, positions, lists, mask, premat) in case()) {
        let (_, rotation, translation) = premat.to_scale_rotation_translation();
        let premat = Mat4::from_rotation_translation(rotation, translation);
        every_method_matches_the_reference(&rig, &positions, &lists, &mask, premat, premat.inverse())?;
    }

    /// Spaces that are not each other's inverse are applied as they are, not folded into the
    /// bones (`spaces.rs`).
    #[test]
    fn kernels_match_the_reference_with_spaces_that_do_not_undo_each_other((rig, positions, lists, mask, premat) in case()) {
        let postmat = Mat4::from_scale_rotation_translation(Vec3::splat(1.5), Quat::from_rotation_y(0.4), Vec3::new(0.3, -0.2, 1.0)) * premat.inverse();
        every_method_matches_the_reference(&rig, &positions, &lists, &mask, premat, postmat)?;
    }

    #[test]
    fn kernels_match_the_reference_without_spaces_or_mask((rig, positions, lists, _mask, _premat) in case()) {
        let inputs = reference::Inputs {
            positions: &positions, lists: &lists, deform: &rig.deform, rest: &rig.rest,
            premat: Mat4::IDENTITY, postmat: Mat4::IDENTITY, mask: None,
        };
        let options = SkinOptions::default();
        assert_close(&run(Method::Linear, &positions, &lists, &rig, &options), &reference::skin(&inputs, false), 2e-5)?;
        assert_close(&run(Method::DualQuaternion, &positions, &lists, &rig, &options), &reference::skin(&inputs, true), 2e-5)?;
        let lbs = run(Method::Blend { amount: None, factor: 0.0 }, &positions, &lists, &rig, &options);
        assert_close(&lbs, &reference::skin(&inputs, false), 2e-5)?;
        let dqs = run(Method::Blend { amount: None, factor: 1.0 }, &positions, &lists, &rig, &options);
        assert_close(&dqs, &reference::skin(&inputs, true), 2e-5)?;
    }
}

/// Every method of `positions` at once, and each vertex skinned alone (whose influences keep
/// the vertex order: one vertex has nothing to reorder), must give the same bits.
fn each_vertex_as_alone(
    rig: &Rig,
    positions: &[[f32; 3]],
    lists: &[Vec<(u32, f32)>],
    mask: &[f32],
    premat: Mat4,
) -> Result<(), TestCaseError> {
    let influences = Influences::from_lists(lists, rig.rest.len()).unwrap();
    prop_assume!(influences.lane_positions().is_some());
    let pose = Pose::new(&rig.deform, Some(&rig.rest)).unwrap();
    let centers: Vec<[f32; 3]> = positions.iter().rev().copied().collect();
    let amount: Vec<f32> = mask.iter().rev().copied().collect();
    let options = SkinOptions { premat: Some(premat), postmat: Some(premat.inverse()), mask: Some(mask) };
    let methods = |v: Option<usize>| {
        let pick = |a: &[f32]| -> Vec<f32> { v.map_or_else(|| a.to_vec(), |v| vec![a[v]]) };
        (pick(&amount), v.map_or_else(|| centers.clone(), |v| vec![centers[v]]))
    };
    let (all_amount, all_centers) = methods(None);
    let all = [
        skin_all(Method::Linear, positions, &influences, &pose, &options),
        skin_all(Method::DualQuaternion, positions, &influences, &pose, &options),
        skin_all(Method::Blend { amount: Some(&all_amount), factor: 0.7 }, positions, &influences, &pose, &options),
        skin_all(Method::CentersOfRotation { centers: &all_centers }, positions, &influences, &pose, &options),
    ];
    for v in 0..positions.len() {
        let alone = Influences::from_lists(&lists[v..v + 1], rig.rest.len()).unwrap();
        prop_assert!(alone.lane_positions().is_none());
        let (amount, centers) = methods(Some(v));
        let mask = [mask[v]];
        let options = SkinOptions { mask: Some(&mask), ..options };
        let point = &positions[v..v + 1];
        let got = [
            skin_all(Method::Linear, point, &alone, &pose, &options),
            skin_all(Method::DualQuaternion, point, &alone, &pose, &options),
            skin_all(Method::Blend { amount: Some(&amount), factor: 0.7 }, point, &alone, &pose, &options),
            skin_all(Method::CentersOfRotation { centers: &centers }, point, &alone, &pose, &options),
        ];
        for (m, (a, g)) in all.iter().zip(&got).enumerate() {
            prop_assert_eq!(a[v].map(f32::to_bits), g[0].map(f32::to_bits), "method {}, vertex {}", m, v);
        }
    }
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 32, ..ProptestConfig::default() })]

    /// Influences whose vertices take their lanes by decreasing count within windows
    /// (`influences/lane_order.rs`): every vertex's result is the one it has alone, for every
    /// method and compiled copy.
    #[test]
    fn lanes_in_window_order_give_each_vertex_its_own_result((rig, positions, lists, mask, premat) in case()) {
        each_vertex_as_alone(&rig, &positions, &lists, &mask, premat)?;
    }
}

/// The same across windows and the thread pool's chunks: two chunks and a partial window, with
/// counts from 0 to 6 mixed in every batch.
#[test]
fn lanes_in_window_order_hold_across_windows_and_chunks() {
    let n = kernels::CHUNK + 300;
    let (positions, _, deform, rest) = batch_fixture(n, 24, 1);
    let lists: Vec<Vec<(u32, f32)>> = (0..n)
        .map(|v| (0..(v * 7 % 11) % 7).map(|k| (((v * 5 + k * 3) % 24) as u32, 0.1 + (k as f32) * 0.3)).collect())
        .collect();
    let mask: Vec<f32> = (0..n).map(|v| [1.0, 0.0, 0.5, 0.25][v % 4]).collect();
    let rig = Rig { rest, deform };
    let premat = Mat4::from_rotation_translation(Quat::from_rotation_z(0.3), Vec3::new(0.1, 0.2, 0.3));
    each_vertex_as_alone(&rig, &positions, &lists, &mask, premat).unwrap();
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 48, ..ProptestConfig::default() })]

    /// Influences keep their bone indices in 8 bits where the bones number at most 256, else in
    /// 16 (`influences.rs`): the kernels of both widths give the same bits for every method and
    /// scale path, with the 16-bit ones naming bones past 255. The same rig is given once as its
    /// own bones and once reversed at the end of a table of 300 (the others rigid fillers).
    #[test]
    fn both_bone_index_widths_skin_to_the_same_bits((rig, positions, lists, mask, premat) in case()) {
        const WIDE: usize = 300;
        let b = rig.rest.len();
        let wide_of = |bone: u32| (WIDE - 1 - bone as usize) as u32;
        let wide_lists: Vec<Vec<(u32, f32)>> =
            lists.iter().map(|l| l.iter().map(|&(bone, w)| (wide_of(bone), w)).collect()).collect();
        let (mut rest, mut deform) = (vec![Mat4::IDENTITY; WIDE], vec![Mat4::from_translation(Vec3::X); WIDE]);
        for bone in 0..b {
            rest[wide_of(bone as u32) as usize] = rig.rest[bone];
            deform[wide_of(bone as u32) as usize] = rig.deform[bone];
        }
        let narrow = Influences::from_lists(&lists, b).unwrap();
        let wide = Influences::from_lists(&wide_lists, WIDE).unwrap();
        prop_assert!(wide.byte_size() > narrow.byte_size() || narrow.is_empty());
        for (n, w) in (0..positions.len()).map(|v| (narrow.of_vertex(v), wide.of_vertex(v))) {
            prop_assert!(n.map(|i| (wide_of(i.bone), i.weight)).eq(w.map(|i| (i.bone, i.weight))));
        }
        let (narrow_pose, wide_pose) =
            (Pose::new(&rig.deform, Some(&rig.rest)).unwrap(), Pose::new(&deform, Some(&rest)).unwrap());
        let options = SkinOptions { premat: Some(premat), postmat: Some(premat.inverse()), mask: Some(&mask) };
        let centers: Vec<[f32; 3]> = positions.iter().rev().copied().collect();
        let amount: Vec<f32> = mask.iter().rev().copied().collect();
        for method in [
            Method::Linear,
            Method::DualQuaternion,
            Method::Blend { amount: Some(&amount), factor: 0.7 },
            Method::CentersOfRotation { centers: &centers },
        ] {
            let a = skin_all(method, &positions, &narrow, &narrow_pose, &options);
            let z = skin_all(method, &positions, &wide, &wide_pose, &options);
            for (v, (a, z)) in a.iter().zip(&z).enumerate() {
                prop_assert_eq!(a.map(f32::to_bits), z.map(f32::to_bits), "{:?}: vertex {}", method, v);
            }
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 64, ..ProptestConfig::default() })]

    /// A vertex's result does not depend on where it is in the mesh: in a full SIMD batch, in the
    /// partial last one or on another thread's chunk, every copy gives the same bits for the same
    /// inputs (vertices split at one place, at UV seams and sharp edges, must stay together).
    #[test]
    fn equal_vertices_skin_to_equal_bits_wherever_they_are((rig, positions, lists, mask, premat) in case()) {
        let influences_of = |count: usize| {
            let repeated: Vec<Vec<(u32, f32)>> = (0..count).map(|_| lists[0].clone()).collect();
            Influences::from_lists(&repeated, rig.rest.len()).unwrap()
        };
        let pose = Pose::new(&rig.deform, Some(&rig.rest)).unwrap();
        // Two full batches of 16 and a partial one; then more than one parallel chunk.
        for count in [37, kernels::CHUNK + 21] {
            let points = vec![positions[0]; count];
            let masks = vec![mask[0]; count];
            let influences = influences_of(count);
            let options = SkinOptions { premat: Some(premat), postmat: Some(premat.inverse()), mask: Some(&masks) };
            let amount = vec![0.6f32; count];
            for method in [Method::Linear, Method::DualQuaternion, Method::Blend { amount: Some(&amount), factor: 0.7 }] {
                for simd in isa::Simd::available() {
                    let mut out = vec![[f32::NAN; 3]; count];
                    skin_with(Some(simd), method, &points, &influences, &pose, &options, &mut out).unwrap();
                    for (v, p) in out.iter().enumerate() {
                        prop_assert!(p.map(f32::to_bits) == out[0].map(f32::to_bits), "{:?} {:?}: vertex {} gives {:?}, vertex 0 {:?}", simd, method, v, p, out[0]);
                    }
                }
            }
        }
    }
}

#[test]
fn the_order_of_influences_decides_dqs_signs_as_in_blender() {
    // Three bones whose rotations are pairwise more than 90° apart in quaternion space: the sign
    // each gets depends on the running sum, hence on the order.
    let rest = vec![Mat4::IDENTITY; 3];
    let deform = vec![
        Mat4::from_quat(Quat::from_rotation_z(0.0)),
        Mat4::from_quat(Quat::from_rotation_z(2.4)),
        Mat4::from_quat(Quat::from_rotation_z(-2.4)),
    ];
    let rig = Rig { rest: rest.clone(), deform: deform.clone() };
    let positions = vec![[1.0, 0.5, 0.0]; 2];
    let lists = vec![vec![(0, 0.5), (1, 0.3), (2, 0.2)], vec![(0, 0.5), (2, 0.2), (1, 0.3)]];
    let out = run(Method::DualQuaternion, &positions, &lists, &rig, &SkinOptions::default());
    let inputs = reference::Inputs {
        positions: &positions,
        lists: &lists,
        deform: &deform,
        rest: &rest,
        premat: Mat4::IDENTITY,
        postmat: Mat4::IDENTITY,
        mask: None,
    };
    let want = reference::skin(&inputs, true);
    assert_close(&out, &want, 1e-5).unwrap();
    assert!((want[0] - want[1]).length() > 0.1, "orders should differ: {:?}", want);
}

#[test]
fn vertices_with_too_little_weight_stay_put_but_go_through_the_spaces() {
    let rig = Rig { rest: vec![Mat4::IDENTITY], deform: vec![Mat4::from_translation(Vec3::X)] };
    let positions = vec![[1.0, 2.0, 3.0]; 3];
    let lists = vec![vec![], vec![(0, 0.00005), (0, 0.00005)], vec![(0, 0.0)]];
    for method in [Method::Linear, Method::DualQuaternion, Method::Blend { amount: None, factor: 0.5 }] {
        let out = run(method, &positions, &lists, &rig, &SkinOptions::default());
        assert_eq!(out, positions);
        let pre = Mat4::from_translation(Vec3::new(0.0, 0.0, 10.0));
        let options = SkinOptions { premat: Some(pre), postmat: Some(Mat4::from_translation(Vec3::Z)), mask: None };
        let out = run(method, &positions, &lists, &rig, &options);
        assert!(out.iter().all(|p| *p == [1.0, 2.0, 14.0]));
    }
    // Just above the threshold the vertex moves, fully (weights are normalized).
    let lists = vec![vec![(0, 0.00011)]; 3];
    let out = run(Method::Linear, &positions, &lists, &rig, &SkinOptions::default());
    assert!(out.iter().all(|p| (p[0] - 2.0).abs() < 1e-5));
}

/// A vertex LBS leaves still (mask weight 0, too little weight) keeps its point's bits, negative
/// zeros too, on every copy: no `co + 0·offset` (which turns −0 into +0) stands in for keeping
/// it. (DQS keeps a weightless vertex's place but not a −0's sign: `p + 0`.)
#[test]
fn still_vertices_keep_their_bits_in_lbs() {
    let rig = Rig { rest: vec![Mat4::IDENTITY], deform: vec![Mat4::from_translation(Vec3::new(1.0, -1.0, 2.0))] };
    let positions: Vec<[f32; 3]> = (0..37).map(|v| [-0.0, if v % 2 == 0 { -0.0 } else { 0.0 }, v as f32]).collect();
    let lists: Vec<_> = (0..37).map(|v| if v % 3 == 0 { vec![(0, 0.00005)] } else { vec![(0, 1.0)] }).collect();
    let mask: Vec<f32> = (0..37).map(|v| if v % 3 == 1 { 0.0 } else { 1.0 }).collect();
    let options = SkinOptions { mask: Some(&mask), ..SkinOptions::default() };
    let out = run(Method::Linear, &positions, &lists, &rig, &options);
    for (v, (o, p)) in out.iter().zip(&positions).enumerate() {
        let still = v % 3 != 2;
        assert_eq!(still, o.map(f32::to_bits) == p.map(f32::to_bits), "vertex {v} is {o:?}");
    }
}

/// A vertex whose mask weight is 0 keeps its point's bits, negative zeros too, with every
/// method, rigid bones and bones with scale, on every copy (Blender's modifier skips it): the
/// kernels keep the point rather than add `0·offset` to it.
#[test]
fn masked_vertices_keep_their_bits_with_every_method() {
    let turn = Mat4::from_rotation_translation(Quat::from_rotation_z(0.7), Vec3::new(1.0, -1.0, 2.0));
    let rigid = vec![Mat4::IDENTITY, turn];
    let scaled = vec![Mat4::IDENTITY, turn * Mat4::from_scale(Vec3::new(1.5, 1.0, 0.5))];
    let positions: Vec<[f32; 3]> = (0..37).map(|v| [-0.0, if v % 2 == 0 { -0.0 } else { 0.0 }, v as f32]).collect();
    let lists: Vec<_> = (0..37).map(|v| vec![(0, 0.5), ((v % 2) as u32 ^ 1, 0.25 + 0.01 * v as f32)]).collect();
    let mask: Vec<f32> = (0..37).map(|v| if v % 3 == 1 { 0.0 } else { 1.0 }).collect();
    let centers: Vec<[f32; 3]> = (0..37).map(|v| [0.5, 0.0, v as f32]).collect();
    let amount: Vec<f32> = (0..37).map(|v| v as f32 / 36.0).collect();
    let options = SkinOptions { mask: Some(&mask), ..SkinOptions::default() };
    for deform in [rigid, scaled] {
        let rig = Rig { rest: vec![Mat4::IDENTITY; 2], deform };
        for method in [
            Method::Linear,
            Method::DualQuaternion,
            Method::Blend { amount: Some(&amount), factor: 0.7 },
            Method::CentersOfRotation { centers: &centers },
        ] {
            let out = run(method, &positions, &lists, &rig, &options);
            for (v, (o, p)) in out.iter().zip(&positions).enumerate() {
                let still = v % 3 == 1;
                assert_eq!(still, o.map(f32::to_bits) == p.map(f32::to_bits), "{method:?}: vertex {v} is {o:?}");
            }
        }
    }
}

/// The AVX-512 LBS sums a batch whose weighted bones lie within sixteen consecutive indices by
/// picking each component from those sixteen records (`avx512/bone_window.rs`), and a wider one
/// per lane; both must give every copy's bits. Batches of every kind, in both index widths: the
/// lowest bone in lane 0 or elsewhere, exactly sixteen bones wide and seventeen, at the table's
/// end, with padded and weightless lanes (whose records may then be another bone's), zero
/// weights on far bones, nothing weighted at all.
#[test]
fn linear_batches_within_sixteen_bones_give_the_same_bits_as_wider_ones() {
    for bones in [40usize, 300] {
        let n = 16 * 8 * 5;
        let (positions, _, deform, rest) = batch_fixture(n, bones, 1);
        let top = bones as u32 - 1;
        let lists: Vec<Vec<(u32, f32)>> = (0..n)
            .map(|v| {
                let (batch, l) = (v / 16, (v % 16) as u32);
                let b = (batch as u32 * 7) % (top - 20);
                let w = |k: u32| 0.1 + ((v as u32 * 3 + k) % 7) as f32 * 0.15;
                match batch % 8 {
                    0 => vec![(b, w(0)), (b + 4 + l % 3, w(1)), (b + 10 - l % 2, w(2))],
                    1 if l == 0 => vec![(b + 9, w(0)), (b + 12, w(1)), (b + 15, w(2))],
                    1 => vec![(b + l % 16, w(0)), (b + 3, w(1)), (b + 6, w(2))],
                    2 => vec![(b + 15 * (l % 2), w(0)), (b + 7, w(1)), (b + 15, w(2))],
                    3 => vec![(b + 16 * (l % 2), w(0)), (b + 7, w(1)), (b + 1, w(2))],
                    4 => vec![(top - l % 3, w(0)), (top - 2, w(1)), (top, w(2))],
                    5 => (0..l % 4).map(|k| (b + 5 + k, w(k))).collect(),
                    6 => vec![(b + 2, w(0)), (0, 0.0), (top, 0.0)],
                    _ => vec![(b + l, 0.0), (top, 0.0), (3, 0.0)],
                }
            })
            .collect();
        let mask: Vec<f32> = (0..n).map(|v| [1.0, 0.0, 0.5, 0.25, 1.0][v % 5]).collect();
        let premat = Mat4::from_rotation_translation(Quat::from_rotation_z(0.3), Vec3::new(0.1, 0.2, 0.3));
        let rig = Rig { rest, deform };
        // The copies' bits are compared inside `run`; the float64 reference checks the sums.
        for mask in [None, Some(&mask[..])] {
            let options = SkinOptions { premat: Some(premat), postmat: Some(premat.inverse()), mask };
            let inputs = reference::Inputs {
                positions: &positions,
                lists: &lists,
                deform: &rig.deform,
                rest: &rig.rest,
                premat,
                postmat: premat.inverse(),
                mask,
            };
            let got = run(Method::Linear, &positions, &lists, &rig, &options);
            assert_close(&got, &reference::skin(&inputs, false), 2e-5).unwrap();
        }
    }
}

/// Each batch's bone window (the AVX-512 LBS's): the first of sixteen consecutive bones holding
/// all its weighted bones; bones with weight 0 (and padding) do not count.
#[test]
fn each_batch_keeps_the_sixteen_bones_its_weights_lie_in() {
    let batch = |list: &dyn Fn(usize) -> Vec<(u32, f32)>| (0..16).map(list).collect::<Vec<_>>();
    for bones in [64u32, 300] {
        let top = bones - 1;
        let mut lists = Vec::new();
        lists.extend(batch(&|l| vec![(5 + l as u32, 0.5), (0, 0.0), (top, 0.0)]));
        lists.extend(batch(&|l| vec![(5 + 16 * (l as u32 % 2), 0.5), (6, 0.5), (7, 0.0)]));
        lists.extend(batch(&|_| vec![(9, 0.0), (top, 0.0), (1, 0.0)]));
        lists.extend(batch(&|l| vec![(top - l as u32 % 16, 0.5), (top, 0.1), (top - 3, 1.0)]));
        lists.extend((0..3).map(|l| vec![(top - l, 0.5), (top - 2, 0.2), (top - 1, 0.1)]));
        let influences = Influences::from_lists(&lists, bones as usize).unwrap();
        assert!(influences.lane_positions().is_none(), "vertex order, as the lists");
        let (fresh, bytes) = (influences.clone(), influences.heap_bytes());
        let windows: Vec<_> = (0..5).map(|b| bone_window(influences.bone_windows(), b)).collect();
        // Made when first asked for, then kept: two bytes a batch; the influences still equal.
        assert_eq!(influences.heap_bytes(), bytes + 2 * 5);
        assert_eq!(influences, fresh);
        assert_eq!(windows, [Some(5), None, Some(0), Some(top - 15), Some(top - 2)], "{bones} bones");
    }
}

#[test]
fn unnormalized_weights_are_divided_by_their_sum() {
    let rig = Rig {
        rest: vec![Mat4::IDENTITY; 2],
        deform: vec![Mat4::from_translation(Vec3::X), Mat4::from_translation(Vec3::Y)],
    };
    let positions = vec![[0.0; 3]; 2];
    let lists = vec![vec![(0, 3.0), (1, 1.0)], vec![(0, 0.3), (1, 0.1)]];
    for method in [Method::Linear, Method::DualQuaternion] {
        let out = run(method, &positions, &lists, &rig, &SkinOptions::default());
        for p in out {
            assert!(Vec3::from_array(p).abs_diff_eq(Vec3::new(0.75, 0.25, 0.0), 1e-6), "{p:?}");
        }
    }
}

fn twisted_ring_area(cyl: &TwistCylinder, method: Method<'_>, angle: f32) -> f64 {
    let deform = cyl.twist(angle);
    let pose = Pose::new(&deform, Some(&cyl.rest)).unwrap();
    let mut out = vec![[0.0; 3]; cyl.positions.len()];
    skin(method, &cyl.positions, &cyl.influences, &pose, &SkinOptions::default(), &mut out).unwrap();
    let middle: Vec<_> = cyl.ring(cyl.rings / 2).map(|i| out[i]).collect();
    polygon_area(&middle)
}

#[test]
fn twisting_collapses_lbs_but_not_dqs() {
    let cyl = TwistCylinder::new(21, 48, 4.0, 0.5, 0.5).unwrap();
    let rest_area = twisted_ring_area(&cyl, Method::Linear, 0.0);
    assert!((rest_area - twisted_ring_area(&cyl, Method::DualQuaternion, 0.0)).abs() < 1e-6);
    for degrees in [90.0f32, 150.0, 180.0] {
        let angle = degrees.to_radians();
        let lbs = twisted_ring_area(&cyl, Method::Linear, angle) / rest_area;
        let dqs = twisted_ring_area(&cyl, Method::DualQuaternion, angle) / rest_area;
        // The middle ring has weights 0.5/0.5: LBS scales it by cos²(angle/2), DQS rotates it.
        let expected_lbs = (angle / 2.0).cos().powi(2) as f64;
        assert!((lbs - expected_lbs).abs() < 1e-4, "{degrees}°: LBS keeps {lbs}");
        assert!((dqs - 1.0).abs() < 1e-4, "{degrees}°: DQS keeps {dqs}");
        let half = twisted_ring_area(&cyl, Method::Blend { amount: None, factor: 0.5 }, angle) / rest_area;
        assert!(half > lbs && half < dqs, "{degrees}°: blend keeps {half}");
    }
    assert!(twisted_ring_area(&cyl, Method::Linear, core::f32::consts::PI) / rest_area < 1e-6);
}

#[test]
fn bad_inputs_are_rejected_before_anything_is_written() {
    let rig = Rig { rest: vec![Mat4::IDENTITY; 2], deform: vec![Mat4::IDENTITY; 2] };
    let influences = Influences::from_lists(&[vec![(0, 1.0)], vec![(1, 1.0)]], 2).unwrap();
    let pose = Pose::new(&rig.deform, Some(&rig.rest)).unwrap();
    let linear_only = Pose::new(&rig.deform, None).unwrap();
    let positions = vec![[0.0; 3]; 2];
    let mut out = vec![[7.0; 3]; 2];
    let opts = SkinOptions::default();
    let err = |r: Result<(), SkinError>| r.unwrap_err();
    assert_eq!(
        err(skin(Method::Linear, &positions[..1], &influences, &pose, &opts, &mut out)),
        SkinError::LengthMismatch { what: "positions", expected: 2, got: 1 }
    );
    assert_eq!(
        err(skin(Method::Linear, &positions, &influences, &pose, &opts, &mut out[..1])),
        SkinError::LengthMismatch { what: "out", expected: 2, got: 1 }
    );
    assert_eq!(
        err(skin(Method::DualQuaternion, &positions, &influences, &linear_only, &opts, &mut out)),
        SkinError::MissingRestMatrices
    );
    assert!(skin(Method::Linear, &positions, &influences, &linear_only, &opts, &mut out).is_ok());
    out = vec![[7.0; 3]; 2];
    let three = Pose::new(&[Mat4::IDENTITY; 3], None).unwrap();
    assert!(matches!(
        err(skin(Method::Linear, &positions, &influences, &three, &opts, &mut out)),
        SkinError::LengthMismatch { .. }
    ));
    let mask = [0.5, 1.5];
    let masked = SkinOptions { mask: Some(&mask), ..opts };
    assert_eq!(
        err(skin(Method::Linear, &positions, &influences, &pose, &masked, &mut out)),
        SkinError::OutOfRange { what: "mask", index: Some(1), value: 1.5 }
    );
    let amount = [f32::NAN, 0.5];
    assert!(matches!(
        err(skin(
            Method::Blend { amount: Some(&amount), factor: 1.0 },
            &positions,
            &influences,
            &pose,
            &opts,
            &mut out
        )),
        SkinError::OutOfRange { what: "blend amount", index: Some(0), .. }
    ));
    assert!(matches!(
        err(skin(Method::Blend { amount: None, factor: 2.0 }, &positions, &influences, &pose, &opts, &mut out)),
        SkinError::OutOfRange { what: "blend_factor", .. }
    ));
    let mut bad = Mat4::IDENTITY;
    bad.w_axis.w = 2.0;
    let spaces = SkinOptions { premat: Some(bad), ..opts };
    assert!(matches!(
        err(skin(Method::Linear, &positions, &influences, &pose, &spaces, &mut out)),
        SkinError::InvalidSpaceMatrix { what: "premat", .. }
    ));
    assert_eq!(out, vec![[7.0; 3]; 2], "out must be untouched on error");
}

#[test]
fn influences_are_validated() {
    let e = |o: &[u32], b: &[u32], w: &[f32]| Influences::from_csr(o, b, w, 4).unwrap_err().to_string();
    assert!(e(&[], &[], &[]).contains("offsets"));
    assert!(e(&[1, 1], &[0], &[1.0]).contains("offsets[0] must be 0"));
    assert!(e(&[0, 2, 1, 2], &[0, 1], &[1.0, 1.0]).contains("must not decrease"));
    assert!(e(&[0, 1], &[0, 1], &[1.0, 1.0]).contains("offsets[-1]"));
    assert!(e(&[0, 2], &[0, 1], &[1.0]).contains("weights has 1"));
    assert!(e(&[0, 2], &[0, 4], &[1.0, 1.0]).contains("bones[1] = 4 is out of range"));
    assert!(e(&[0, 2], &[0, 1], &[1.0, -0.1]).contains("weights[1]"));
    assert!(e(&[0, 2], &[0, 1], &[f32::INFINITY, 1.0]).contains("weights[0]"));
    // The kernels keep each influence's bone index in 16 bits.
    let too_many = Influences::from_csr(&[0, 1], &[0], &[1.0], crate::MAX_BONES + 1).unwrap_err().to_string();
    assert!(too_many.contains("at most 65536 bones"), "{too_many}");
    let last = Influences::from_csr(&[0, 1], &[(crate::MAX_BONES - 1) as u32], &[1.0], crate::MAX_BONES).unwrap();
    assert_eq!(last.of_vertex(0).next().unwrap().bone as usize, crate::MAX_BONES - 1);
    let ok = Influences::from_csr(&[0, 2, 2, 3], &[3, 1, 0], &[0.5, 0.5, 1.0], 4).unwrap();
    assert_eq!((ok.vertex_count(), ok.len(), ok.max_per_vertex()), (3, 3, 2));
    assert!(ok.of_vertex(1).len() == 0);
}

#[test]
fn dense_influences_drop_zero_weights_and_keep_the_order() {
    // Vertex 1 pads with an out-of-range bone at weight 0 (dropped, so never checked).
    let bones = [2, 0, 1, 9, 3, 3];
    let weights = [0.25, 0.0, 0.5, 0.0, 1.0, 2.0];
    let dense = Influences::from_dense(&bones, &weights, 3, 2, 4).unwrap();
    let csr = Influences::from_csr(&[0, 1, 2, 4], &[2, 1, 3, 3], &[0.25, 0.5, 1.0, 2.0], 4).unwrap();
    assert_eq!(dense, csr);
    let empty = Influences::from_dense(&[], &[], 5, 0, 1).unwrap();
    assert_eq!((empty.vertex_count(), empty.len()), (5, 0));
    let e = |b: &[u32], w: &[f32], v, k| Influences::from_dense(b, w, v, k, 4).unwrap_err().to_string();
    assert!(e(&[0, 1], &[1.0, 1.0], 2, 2).contains("both must have 2 × 2"));
    assert!(e(&[0], &[1.0, 1.0], 1, 2).contains("bones has 1 entries"));
    assert!(e(&[0, 7], &[1.0, 0.5], 1, 2).contains("bones[1] = 7 is out of range"));
    assert!(e(&[0, 1], &[1.0, -0.5], 1, 2).contains("weights[1] = -0.5"));
    assert!(e(&[0, 1], &[f32::NAN, 0.0], 1, 2).contains("weights[0] = NaN"));
    let wide = MAX_INFLUENCES_PER_VERTEX + 1;
    assert!(e(&vec![0; wide], &vec![1.0; wide], 1, wide).contains("at most 4096"));
}

#[test]
fn results_do_not_depend_on_the_thread_count() {
    let cyl = TwistCylinder::new(200, 64, 4.0, 0.5, 0.3).unwrap();
    let deform = cyl.twist(2.0);
    let pose = Pose::new(&deform, Some(&cyl.rest)).unwrap();
    let mut a = vec![[0.0; 3]; cyl.positions.len()];
    let mut b = a.clone();
    crate::pool::set_num_threads(1).unwrap();
    assert_eq!(crate::pool::num_threads(), 1);
    skin(Method::DualQuaternion, &cyl.positions, &cyl.influences, &pose, &SkinOptions::default(), &mut a).unwrap();
    crate::pool::set_num_threads(3).unwrap();
    assert_eq!(crate::pool::num_threads(), 3);
    skin(Method::DualQuaternion, &cyl.positions, &cyl.influences, &pose, &SkinOptions::default(), &mut b).unwrap();
    assert_eq!(crate::pool::set_num_threads(0), Err(crate::pool::PoolError::ZeroThreads));
    assert_eq!(a, b);
}

#[test]
fn skin_many_equals_one_call_per_mesh_and_reports_each_error() {
    use super::{skin_many, ManyJob};
    let (positions, influences, deform, rest) = crate::skin::tests::batch_fixture(300, 5, 3);
    let (p2, i2, d2, r2) = crate::skin::tests::batch_fixture(9000, 7, 4);
    let mut want1 = vec![[0.0f32; 3]; positions.len()];
    let mut want2 = vec![[0.0f32; 3]; p2.len()];
    let pose1 = Pose::new(&deform, Some(&rest)).unwrap();
    let pose2 = Pose::new(&d2, Some(&r2)).unwrap();
    skin(Method::DualQuaternion, &positions, &influences, &pose1, &SkinOptions::default(), &mut want1).unwrap();
    skin(Method::Linear, &p2, &i2, &pose2, &SkinOptions::default(), &mut want2).unwrap();
    let mut out1 = vec![[9.0f32; 3]; positions.len()];
    let mut out2 = vec![[9.0f32; 3]; p2.len()];
    let mut bad_out = vec![[7.0f32; 3]; 4];
    let mut jobs = vec![
        ManyJob {
            method: Method::DualQuaternion,
            positions: &positions,
            influences: &influences,
            deform: &deform,
            rest: Some(&rest),
            options: SkinOptions::default(),
            out: &mut out1,
        },
        ManyJob {
            method: Method::Linear,
            positions: &p2,
            influences: &i2,
            deform: &d2,
            rest: Some(&r2),
            options: SkinOptions::default(),
            out: &mut out2,
        },
        ManyJob {
            method: Method::Linear,
            positions: &p2,
            influences: &i2,
            deform: &d2,
            rest: None,
            options: SkinOptions::default(),
            out: &mut bad_out,
        },
    ];
    let results = skin_many(&mut jobs);
    drop(jobs);
    assert!(results[0].is_ok() && results[1].is_ok());
    assert!(matches!(results[2], Err(SkinError::LengthMismatch { what: "out", .. })));
    assert_eq!(out1, want1);
    assert_eq!(out2, want2);
    assert_eq!(bad_out, vec![[7.0f32; 3]; 4]);
}

#[test]
fn the_trial_of_copies_changes_no_result_and_ends_in_a_choice() {
    // Each size's trial runs on this process's first calls (`calibration.rs`); other tests may
    // share it (the scaled Blend, rarely used elsewhere), which only ends it sooner.
    let samples = |size: calibration::Size| size.samples() as usize * calibration::candidates().len();
    for (vertices, size) in [(500, calibration::Size::Cached), (STREAMED_FROM, calibration::Size::Streamed)] {
        assert_eq!(calibration::Size::of(vertices), size);
        let (positions, influences, mut deform, rest) = batch_fixture(vertices, 6, 4);
        deform[2] *= Mat4::from_scale(Vec3::new(1.0, 1.4, 0.8)); // a scaled bone: the scaled kernels
        let pose = Pose::new(&deform, Some(&rest)).unwrap();
        let method = Method::Blend { amount: None, factor: 0.3 };
        let mut first = vec![[0.0f32; 3]; vertices];
        skin(method, &positions, &influences, &pose, &SkinOptions::default(), &mut first).unwrap();
        for call in 0..samples(size) {
            let mut out = vec![[f32::NAN; 3]; vertices];
            skin(method, &positions, &influences, &pose, &SkinOptions::default(), &mut out).unwrap();
            let same = out.iter().zip(&first).all(|(a, b)| a.map(f32::to_bits) == b.map(f32::to_bits));
            assert!(same, "call {call} of {vertices} vertices differs from the first");
        }
        let chosen = kernel_copies().into_iter().find(|&(v, s, _)| v == "blend_scaled" && s == size.name()).unwrap().2;
        let names: Vec<&str> = calibration::candidates().iter().map(|s| s.name()).collect();
        let requested = std::env::var("DQSKIN_SIMD").ok();
        match chosen {
            Some(name) => {
                assert!(names.contains(&name) || requested.as_deref() == Some(name), "{name} among {names:?}")
            }
            None => panic!("{size:?}: no copy chosen after {} calls", samples(size) + 1),
        }
    }
}

/// Random positions, `bones` bones with random rigid deforms, `k` influences per vertex.
pub(crate) fn batch_fixture(n: usize, bones: usize, k: usize) -> (Vec<[f32; 3]>, Influences, Vec<Mat4>, Vec<Mat4>) {
    let mut seed = 12345u64 + n as u64;
    let mut rnd = move || {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        (seed % 10_000) as f32 / 10_000.0
    };
    let positions: Vec<[f32; 3]> = (0..n).map(|_| [rnd() * 4.0 - 2.0, rnd() * 4.0 - 2.0, rnd() * 4.0]).collect();
    let lists: Vec<Vec<(u32, f32)>> = (0..n)
        .map(|_| (0..k).map(|_| (((rnd() * bones as f32) as u32).min(bones as u32 - 1), rnd())).collect())
        .collect();
    let influences = Influences::from_lists(&lists, bones).unwrap();
    let rest: Vec<Mat4> = (0..bones).map(|b| Mat4::from_translation(glam::Vec3::new(0.0, 0.0, b as f32))).collect();
    let deform: Vec<Mat4> = (0..bones)
        .map(|_| {
            Mat4::from_rotation_translation(
                glam::Quat::from_axis_angle(glam::Vec3::new(rnd(), rnd(), rnd() + 0.1).normalize(), rnd() * 3.0),
                glam::Vec3::new(rnd(), rnd(), rnd()),
            )
        })
        .collect();
    (positions, influences, deform, rest)
}

#[test]
fn the_first_non_finite_center_is_found_in_every_block_and_on_the_pool() {
    for n in [1usize, 17, 1024, 1025, kernels::CHUNK, 3 * kernels::CHUNK + 5] {
        let clean = vec![[1.0f32, -2.0, 3.0e38]; n];
        assert_eq!(first_point_not_finite(&clean), None);
        for bad in [f32::NAN, f32::INFINITY, f32::NEG_INFINITY] {
            for index in [0, n / 2, n - 1] {
                for axis in 0..3 {
                    let mut c = clean.clone();
                    c[index][axis] = bad;
                    // A later one must not hide the first.
                    if index + 1 < n {
                        c[n - 1][2] = f32::NAN;
                    }
                    assert_eq!(first_point_not_finite(&c), Some(index), "n {n}, index {index}, axis {axis}, {bad}");
                    assert_eq!(first_not_finite(c.as_flattened()), Some(3 * index + axis));
                }
            }
        }
    }
}
