//! Per-bone data computed once per frame from the deform and rest matrices, so that the
//! per-vertex kernels only load, weigh and add.

use glam::{Affine3A, Mat3, Mat4, Quat, Vec3, Vec3A, Vec4};

use super::SkinError;
use crate::dual_quat::{is_orthonormal, rotation_from_mat3};

/// A bone's affine deform matrix as three rows `(m_r0, m_r1, m_r2, t_r)`, so `M·co` is three dot
/// products with `(co, 1)`.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(16))]
pub(crate) struct AffineRows {
    pub rows: [Vec4; 3],
}

impl AffineRows {
    pub(crate) fn from_mat4(m: &Mat4) -> Self {
        Self { rows: [m.row(0), m.row(1), m.row(2)] }
    }

    /// The rows back as an affine transform.
    pub(crate) fn to_affine(self) -> Affine3A {
        let [r0, r1, r2] = self.rows;
        Affine3A::from_cols(
            Vec3A::new(r0.x, r1.x, r2.x),
            Vec3A::new(r0.y, r1.y, r2.y),
            Vec3A::new(r0.z, r1.z, r2.z),
            Vec3A::new(r0.w, r1.w, r2.w),
        )
    }

    #[cfg(test)]
    pub fn transform_point(&self, co: Vec4) -> Vec3 {
        Vec3::new(self.rows[0].dot(co), self.rows[1].dot(co), self.rows[2].dot(co))
    }
}

/// A bone's deform matrix for LBS, padded with zeros to one 64-byte line so that SIMD code can
/// load any 8-float window of it, or all of it as one 16-float vector.
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct LinearBone {
    pub matrix: AffineRows,
    pub padding: [f32; 4],
}

/// A bone's move (`spaces.rs`) by column for the AVX2 LBS (`avx2/kept.rs`): the columns of its
/// 3×4 matrix, each padded with a zero, so that a lane's sum is two vectors `[c₀ | c₁]`,
/// `[c₂ | c₃]` that multiply its point without a transpose.
#[cfg(target_arch = "x86_64")]
#[derive(Clone, Copy, Debug, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct ColumnMove {
    pub columns: [[f32; 4]; 4],
}

#[cfg(target_arch = "x86_64")]
impl ColumnMove {
    pub(crate) fn new(record: &LinearBone) -> Self {
        let rows = record.matrix.rows.map(|r| r.to_array());
        ColumnMove { columns: core::array::from_fn(|c| [rows[0][c], rows[1][c], rows[2][c], 0.0]) }
    }
}

/// A bone as Blender's Preserve Volume sees it: the unit rotation quaternion `real` (x, y, z, w)
/// of its rigid part and the dual part `½·(0, t)·real` of its rigid translation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(32))]
pub(crate) struct DqBone {
    pub real: Vec4,
    pub dual: Vec4,
}

/// How Blender's DQS moves a vertex `co` for a bone with scale or shear: rigidly with the
/// bone's rotation `real` and a per-vertex translation `t(co) = M·co − R·co`, so that the vertex
/// lands exactly where the full affine matrix `M` puts it (the "scale path" with the vertex as
/// pivot, `add_weighted_dq_dq_pivot`). `translation` holds the rows of `(M₃ − R₃ | t_M)`; for
/// rigid bones it is `(0 | t)`. One 64-byte line per bone.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct PivotBone {
    pub translation: AffineRows,
    pub real: Vec4,
}

/// The dual part [`PivotBone`] gives a vertex, as one linear map of it: `½·(0, t(co))·q` with
/// `t(co) = T·(co, 1)` is `P·(co, 1)` for the 4×4 matrix `P = ½·Q·T`, `Q` the 3-to-4 map
/// `t ↦ (w·t + t × v, −t·v)` of `q = (v, w)`. Rows: the dual part's x, y, z, w. Summed with the
/// signed weights per vertex and applied once, it replaces one transform of `co` per influence
/// (the SIMD kernels of `batch.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct PivotDualBone {
    pub rows: [Vec4; 4],
}

impl PivotDualBone {
    fn new(pivot: &PivotBone) -> Self {
        let [vx, vy, vz, w] = pivot.real.to_array();
        let [t0, t1, t2] = pivot.translation.rows;
        let row = |a: f32, b: f32, c: f32| 0.5 * (a * t0 + b * t1 + c * t2);
        PivotDualBone { rows: [row(w, vz, -vy), row(-vz, w, vx), row(vy, -vx, w), row(-vx, -vy, -vz)] }
    }
}

/// A bone for skinning with centers of rotation: its full deform matrix (which moves the
/// center, as LBS would), its scale/shear part `S = Rᵀ·M₃` (exactly the identity for bones that
/// do not take the scale path) and its rotation (the one DQS uses). Laid out for the kernels'
/// loads: floats 0–7 the matrix rows 0 and 1, 8–11 the rotation (x, y, z, w), 12–15 matrix row
/// 2, 16–23 `s00 s01 s02 s10 s11 s12 s20 s21`, 24 `s22`, then zeros. The kernels sum the rows
/// without the rotation (floats 0–7 and 12–27: three pairs of rows).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(64))]
pub(crate) struct CorBone {
    /// Rows 0 and 1 of the deform matrix.
    pub rows01: [Vec4; 2],
    pub real: Vec4,
    /// Row 2 of the deform matrix.
    pub row2: Vec4,
    /// `S` row-major without its last entry: `s00 s01 s02 s10 s11 s12 s20 s21`.
    pub stretch: [f32; 8],
    pub s22: f32,
    /// Zeros, so that the record is two 64-byte lines (and `s22`'s row is `s22 0 0 0`).
    pub padding: [f32; 7],
}

/// A rigid bone for skinning with centers of rotation: its rotation (x, y, z, w) and half its
/// translation (x, y, z, 0). 8 floats, so SIMD code loads a lane's record in one window; the
/// kernels rotate the center by `real` rather than read a 3×3 matrix, and add `t/2` inside the
/// rotation's `½·(R·c − c)` (see `rotation_offset` in `avx512/kept.rs`).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
#[repr(C, align(32))]
pub(crate) struct CorRigidBone {
    pub real: Vec4,
    pub half_translation: Vec4,
}

const _: () = assert!(core::mem::size_of::<CorBone>() == 128 && core::mem::size_of::<CorRigidBone>() == 32);
// The kernels read a CorBone by float offsets (see its layout).
const _: () = assert!(
    core::mem::offset_of!(CorBone, real) == 8 * 4
        && core::mem::offset_of!(CorBone, row2) == 12 * 4
        && core::mem::offset_of!(CorBone, stretch) == 16 * 4
        && core::mem::offset_of!(CorBone, s22) == 24 * 4
);

/// Per-frame bone data for all skinning methods.
#[derive(Clone, Debug)]
pub struct Pose {
    pub(crate) linear: Vec<LinearBone>,
    pub(crate) dq: Vec<DqBone>,
    pub(crate) pivot: Vec<PivotBone>,
    pub(crate) pivot_dual: Vec<PivotDualBone>,
    pub(crate) cor: Vec<CorBone>,
    pub(crate) cor_rigid: Vec<CorRigidBone>,
    scaled: Vec<bool>,
}

/// Which per-bone tables a [`Pose`] holds, each level with those of the levels before it:
/// LBS reads only the matrices, DQS and Blend also the dual quaternions and pivots, Optimized
/// Centers also its own records.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) enum Tables {
    Linear,
    DualQuaternion,
    Centers,
}

/// Tolerance of Blender's `is_orthonormal_m3` (on column dot products and squared lengths).
const ORTHONORMAL_TOLERANCE: f32 = 1e-5;
/// Blender takes the scale path when `|column lengths − 1|² > (1e-4)²`.
const SCALE_TOLERANCE_SQ: f32 = 1e-8;

impl Pose {
    /// From per-bone deform matrices (posed matrix times the inverse rest matrix, in armature
    /// space: Blender's `PoseBone.matrix_channel`) and, for dual quaternion skinning, the rest
    /// matrices (`Bone.matrix_local`). Without rest matrices only linear skinning is available.
    ///
    /// Errors name the first bone whose matrix is not finite, not affine, or (for rest matrices)
    /// not invertible.
    pub fn new(deform: &[Mat4], rest: Option<&[Mat4]>) -> Result<Self, SkinError> {
        Self::with_tables(deform, rest, Tables::Centers)
    }

    /// [`Pose::new`] with only the tables up to `tables` (one skinning computes only what its
    /// method reads: on a Rigify character's 720 expanded bones the dual quaternion and centers
    /// tables cost a Linear frame more than its vertices did). The inputs are checked alike.
    pub(crate) fn with_tables(deform: &[Mat4], rest: Option<&[Mat4]>, tables: Tables) -> Result<Self, SkinError> {
        for (bone, m) in deform.iter().enumerate() {
            check_affine("deform", bone, m)?;
        }
        let linear =
            deform.iter().map(|m| LinearBone { matrix: AffineRows::from_mat4(m), padding: [0.0; 4] }).collect();
        let Some(rest) = rest else {
            return Ok(Self { linear, ..Self::empty_tables() });
        };
        if rest.len() != deform.len() {
            return Err(SkinError::LengthMismatch { what: "rest matrices", expected: deform.len(), got: rest.len() });
        }
        if tables == Tables::Linear {
            for (bone, b) in rest.iter().enumerate() {
                check_rest(bone, b)?;
            }
            return Ok(Self { linear, ..Self::empty_tables() });
        }
        let n = deform.len();
        let centers = tables == Tables::Centers;
        let mut records = Self { linear, ..Self::empty_tables() };
        records.dq = vec![DqBone::default(); n];
        records.pivot = vec![PivotBone::default(); n];
        records.pivot_dual = vec![PivotDualBone::default(); n];
        records.scaled = vec![false; n];
        if centers {
            records.cor = vec![CorBone::default(); n];
            records.cor_rigid = vec![CorRigidBone::default(); n];
        }
        records.fill_rotations(deform, rest)?;
        Ok(records)
    }

    fn empty_tables() -> Self {
        Self {
            linear: Vec::new(),
            dq: Vec::new(),
            pivot: Vec::new(),
            pivot_dual: Vec::new(),
            cor: Vec::new(),
            cor_rigid: Vec::new(),
            scaled: Vec::new(),
        }
    }

    /// Fills the tables sized by [`Pose::with_tables`] (the centers' left empty where not
    /// asked for); for rigs of many bones in chunks shared with the pool, where a bone's rotation
    /// costs about 130 ns on one thread (a Rigify rig's 720 expanded bones: 94 µs, a third of a
    /// DQS call; see docs/performance.md). The first rest matrix that cannot be used is the
    /// error, as a serial check would find it.
    fn fill_rotations(&mut self, deform: &[Mat4], rest: &[Mat4]) -> Result<(), SkinError> {
        let chunks = Chunks {
            dq: &mut self.dq,
            pivot: &mut self.pivot,
            pivot_dual: &mut self.pivot_dual,
            scaled: &mut self.scaled,
            cor: &mut self.cor,
            cor_rigid: &mut self.cor_rigid,
        };
        if deform.len() < PARALLEL_BONES || crate::pool::num_threads() <= 1 {
            return chunks.fill(0, deform, rest);
        }
        chunks.fill_shared(deform, rest)
    }

    /// Number of bones.
    #[inline]
    pub fn bone_count(&self) -> usize {
        self.linear.len()
    }

    /// Whether rest matrices were given, so dual quaternion skinning is available.
    #[inline]
    pub fn has_dual_quaternions(&self) -> bool {
        self.dq.len() == self.linear.len()
    }

    /// Whether the centers of rotation tables were computed (with the rest matrices).
    #[inline]
    pub(crate) fn has_centers(&self) -> bool {
        self.cor.len() == self.linear.len() && self.cor_rigid.len() == self.linear.len()
    }

    /// Whether any bone goes through Blender's scale path (scale, shear or reflection).
    #[inline]
    pub fn any_scaled(&self) -> bool {
        self.scaled.iter().any(|&s| s)
    }

    /// Per bone: whether it goes through the scale path.
    #[inline]
    pub fn scaled_bones(&self) -> &[bool] {
        &self.scaled
    }

    /// The rotation DQS uses for a bone (x, y, z, w), if rest matrices were given.
    pub fn bone_rotation(&self, bone: usize) -> Option<Quat> {
        self.dq.get(bone).map(|b| Quat::from_vec4(b.real))
    }
}

/// Rigs with at least this many bones have their rotation tables filled in chunks of
/// [`BONE_CHUNK`] bones shared with the pool.
const PARALLEL_BONES: usize = 256;
const BONE_CHUNK: usize = 64;

/// One run of bones' records (the centers' empty where not asked for).
struct Chunks<'a> {
    dq: &'a mut [DqBone],
    pivot: &'a mut [PivotBone],
    pivot_dual: &'a mut [PivotDualBone],
    scaled: &'a mut [bool],
    cor: &'a mut [CorBone],
    cor_rigid: &'a mut [CorRigidBone],
}

impl<'a> Chunks<'a> {
    /// [`Chunks::fill`] in chunks of [`BONE_CHUNK`] bones, shared with the pool.
    fn fill_shared(self, deform: &[Mat4], rest: &[Mat4]) -> Result<(), SkinError> {
        let errors = std::sync::Mutex::new(Vec::new());
        crate::pool::share_parts(self.split(BONE_CHUNK), |k, part| {
            let (start, end) = (k * BONE_CHUNK, k * BONE_CHUNK + part.dq.len());
            if let Err(e) = part.fill(start, &deform[start..end], &rest[start..end]) {
                errors.lock().unwrap_or_else(|e| e.into_inner()).push((k, e));
            }
        });
        // (The first chunk's error is the first bone's.)
        let errors = errors.into_inner().unwrap_or_else(|e| e.into_inner());
        errors.into_iter().min_by_key(|&(k, _)| k).map_or(Ok(()), |(_, e)| Err(e))
    }

    /// The records in runs of `c` bones.
    fn split(self, c: usize) -> Vec<Self> {
        let (mut cor, mut cor_rigid) = (self.cor.chunks_mut(c), self.cor_rigid.chunks_mut(c));
        let runs = self.dq.chunks_mut(c).zip(self.pivot.chunks_mut(c)).zip(self.pivot_dual.chunks_mut(c));
        runs.zip(self.scaled.chunks_mut(c))
            .map(|(((dq, pivot), pivot_dual), scaled)| Chunks {
                dq,
                pivot,
                pivot_dual,
                scaled,
                cor: cor.next().unwrap_or_default(),
                cor_rigid: cor_rigid.next().unwrap_or_default(),
            })
            .collect()
    }

    /// The records of bones `first..first + deform.len()`.
    fn fill(self, first: usize, deform: &[Mat4], rest: &[Mat4]) -> Result<(), SkinError> {
        let centers = !self.cor.is_empty();
        for (i, (m, b)) in deform.iter().zip(rest).enumerate() {
            check_rest(first + i, b)?;
            let (q, is_scaled) = blender_bone_rotation(m, b);
            let q = q.normalize();
            let t = m.w_axis.truncate();
            let dual = Quat::from_xyzw(0.5 * t.x, 0.5 * t.y, 0.5 * t.z, 0.0) * q;
            self.dq[i] = DqBone { real: Vec4::from(q), dual: Vec4::from(dual) };
            let delta = Mat3::from_mat4(*m) - Mat3::from_quat(q);
            let p =
                Mat4::from_cols(delta.x_axis.extend(0.0), delta.y_axis.extend(0.0), delta.z_axis.extend(0.0), m.w_axis);
            let pivot = PivotBone { translation: AffineRows::from_mat4(&p), real: Vec4::from(q) };
            self.pivot_dual[i] = PivotDualBone::new(&pivot);
            self.pivot[i] = pivot;
            self.scaled[i] = is_scaled;
            if !centers {
                continue;
            }
            let stretch = if is_scaled { Mat3::from_quat(q).transpose() * Mat3::from_mat4(*m) } else { Mat3::IDENTITY };
            let (s0, s1, s2) = (stretch.row(0), stretch.row(1), stretch.row(2));
            let [r0, r1, r2] = AffineRows::from_mat4(m).rows;
            self.cor[i] = CorBone {
                rows01: [r0, r1],
                real: Vec4::from(q),
                row2: r2,
                stretch: [s0.x, s0.y, s0.z, s1.x, s1.y, s1.z, s2.x, s2.y],
                s22: s2.z,
                padding: [0.0; 7],
            };
            self.cor_rigid[i] = CorRigidBone { real: Vec4::from(q), half_translation: (0.5 * t).extend(0.0) };
        }
        Ok(())
    }
}

/// A rest matrix DQS can use: affine, finite and invertible.
fn check_rest(bone: usize, b: &Mat4) -> Result<(), SkinError> {
    check_affine("rest", bone, b)?;
    if b.determinant().abs() < 1e-12 {
        return Err(SkinError::InvalidMatrix { what: "rest", bone, problem: "is not invertible" });
    }
    Ok(())
}

fn check_affine(what: &'static str, bone: usize, m: &Mat4) -> Result<(), SkinError> {
    match affine_problem(m) {
        Some(problem) => Err(SkinError::InvalidMatrix { what, bone, problem }),
        None => Ok(()),
    }
}

/// What makes `m` unusable as an affine transform, if anything.
pub fn affine_problem(m: &Mat4) -> Option<&'static str> {
    if !m.is_finite() {
        Some("has a NaN or infinite entry")
    } else if (m.row(3) - Vec4::W).abs().max_element() > 1e-6 {
        Some("is not affine (its last row must be 0, 0, 0, 1)")
    } else {
        None
    }
}

/// The rotation Blender's `mat4_to_dquat(basemat = rest, mat = deform)` assigns to a bone, and
/// whether the bone takes the scale path. For a rigid deform matrix this is its own rotation. With
/// scale, shear or a reflection, Blender splits `deform·rest` into a rotation that keeps its Y axis
/// (`orthogonalize_m4(·, Y)`) and a remaining scale, and uses `rotation·rest⁻¹`.
pub(crate) fn blender_bone_rotation(deform: &Mat4, rest: &Mat4) -> (Quat, bool) {
    let m3 = Mat3::from_mat4(*deform);
    let base_rs = *deform * *rest;
    let size = Vec3::new(
        base_rs.x_axis.truncate().length(),
        base_rs.y_axis.truncate().length(),
        base_rs.z_axis.truncate().length(),
    );
    let dscale = size - Vec3::ONE;
    let scaled = !is_orthonormal(&m3, ORTHONORMAL_TOLERANCE)
        || deform.determinant() < 0.0
        || dscale.length_squared() > SCALE_TOLERANCE_SQ;
    if !scaled {
        return (rotation_from_mat3(&m3), false);
    }
    let base_rot = rotation_from_mat3(&orthogonalize_keep_y(&Mat3::from_mat4(base_rs)));
    let rest_rot = rotation_from_mat3(&Mat3::from_mat4(*rest));
    // R = baseR·rest⁻¹; its rotation is baseR's rotation times the inverse of rest's.
    let r = Mat3::from_quat(base_rot) * Mat3::from_quat(rest_rot).transpose();
    (rotation_from_mat3(&r), true)
}

/// Blender's `orthogonalize_m4(m, 1)` (axis Y) without the final rescale, which does not change
/// the rotation extracted from it.
fn orthogonalize_keep_y(m: &Mat3) -> Mat3 {
    let norm = |v: Vec3| {
        let l = v.length();
        if l != 0.0 {
            v / l
        } else {
            v
        }
    };
    let (mut x, y, mut z) = (m.x_axis, norm(m.y_axis), m.z_axis);
    if y.dot(x) < 1.0 {
        z = norm(x.cross(y));
        x = y.cross(z);
    } else if x.dot(z) < 1.0 {
        x = norm(y.cross(z));
        z = x.cross(y);
    } else {
        let v = Vec3::new(y.y, y.z, y.x);
        x = norm(y.cross(v));
        z = x.cross(y);
    }
    Mat3::from_cols(x, y, z)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rigid_bones_keep_their_own_rotation_and_translation() {
        let q = Quat::from_euler(glam::EulerRot::XYZ, 0.3, -1.2, 2.0);
        let m = Mat4::from_rotation_translation(q, Vec3::new(1.0, 2.0, 3.0));
        let rest = Mat4::from_rotation_translation(Quat::from_rotation_x(0.4), Vec3::Y);
        let pose = Pose::new(&[m], Some(&[rest])).unwrap();
        assert!(!pose.any_scaled());
        let r = pose.bone_rotation(0).unwrap();
        assert!(r.dot(q).abs() > 1.0 - 1e-6);
        let dq = crate::DualQuat::from_parts(r, Quat::from_vec4(pose.dq[0].dual));
        assert!(dq.translation().abs_diff_eq(Vec3::new(1.0, 2.0, 3.0), 1e-5));
    }

    #[test]
    fn scaled_bone_pivot_maps_vertices_exactly_like_the_matrix() {
        let rest = Mat4::from_rotation_translation(Quat::from_rotation_z(0.7), Vec3::new(0.0, 1.0, 0.0));
        let posed = Mat4::from_scale_rotation_translation(
            Vec3::new(1.0, 2.5, 0.5),
            Quat::from_rotation_x(0.9),
            Vec3::new(0.3, 1.0, -0.2),
        );
        let deform = posed * rest.inverse();
        let pose = Pose::new(&[deform], Some(&[rest])).unwrap();
        assert!(pose.any_scaled());
        let q = pose.bone_rotation(0).unwrap();
        for co in [Vec3::ZERO, Vec3::new(1.0, -2.0, 0.5), Vec3::new(-3.0, 0.2, 4.0)] {
            let t = pose.pivot[0].translation.transform_point(co.extend(1.0));
            let moved = q * co + t;
            assert!(moved.abs_diff_eq(deform.transform_point3(co), 1e-5));
            // The same dual part as one linear map of the vertex.
            let h = co.extend(1.0);
            let dual = Quat::from_xyzw(0.5 * t.x, 0.5 * t.y, 0.5 * t.z, 0.0) * q;
            let rows = pose.pivot_dual[0].rows;
            let got = Vec4::new(rows[0].dot(h), rows[1].dot(h), rows[2].dot(h), rows[3].dot(h));
            assert!(got.abs_diff_eq(Vec4::from(dual), 1e-5), "{got} vs {dual}");
        }
    }

    /// Rigs of many bones fill their tables in parallel chunks: the same records as bone by
    /// bone, and the first unusable rest matrix is the error.
    #[test]
    fn many_bones_give_the_records_of_each_bone_alone() {
        let n = PARALLEL_BONES + 3 * BONE_CHUNK + 5;
        let bone = |i: usize| {
            let f = i as f32;
            let rest = Mat4::from_rotation_translation(Quat::from_rotation_z(0.01 * f), Vec3::new(0.0, f, 0.0));
            let scale = if i % 3 == 0 { Vec3::new(1.0, 1.5, 0.7) } else { Vec3::ONE };
            let posed = Mat4::from_scale_rotation_translation(
                scale,
                Quat::from_euler(glam::EulerRot::XYZ, 0.1 * f, -0.03 * f, 0.2),
                Vec3::new(0.5, f, -0.1 * f),
            );
            (posed * rest.inverse(), rest)
        };
        let (deform, rest): (Vec<Mat4>, Vec<Mat4>) = (0..n).map(bone).unzip();
        assert!(crate::pool::num_threads() > 1, "the test needs a pool of more than one thread");
        for tables in [Tables::DualQuaternion, Tables::Centers] {
            let pose = Pose::with_tables(&deform, Some(&rest), tables).unwrap();
            for i in 0..n {
                let one = Pose::with_tables(&deform[i..=i], Some(&rest[i..=i]), tables).unwrap();
                assert_eq!(
                    (pose.dq[i], pose.pivot[i], pose.pivot_dual[i], pose.scaled[i]),
                    (one.dq[0], one.pivot[0], one.pivot_dual[0], one.scaled[0])
                );
                if tables == Tables::Centers {
                    assert_eq!((pose.cor[i], pose.cor_rigid[i]), (one.cor[0], one.cor_rigid[0]));
                } else {
                    assert!(pose.cor.is_empty() && pose.cor_rigid.is_empty());
                }
            }
            assert!(pose.any_scaled());
            let mut bad = rest.clone();
            bad[n - 2] = Mat4::ZERO;
            bad[BONE_CHUNK + 7] = Mat4::from_translation(Vec3::new(f32::NAN, 0.0, 0.0));
            assert!(matches!(
                Pose::with_tables(&deform, Some(&bad), tables),
                Err(SkinError::InvalidMatrix { what: "rest", bone, .. }) if bone == BONE_CHUNK + 7
            ));
        }
    }

    #[test]
    fn rejects_bad_matrices_naming_the_bone() {
        let mut bad = Mat4::IDENTITY;
        bad.x_axis.w = 0.5;
        let err = Pose::new(&[Mat4::IDENTITY, bad], None).unwrap_err();
        assert_eq!(
            err,
            SkinError::InvalidMatrix {
                what: "deform",
                bone: 1,
                problem: "is not affine (its last row must be 0, 0, 0, 1)"
            }
        );
        let nan = Mat4::from_translation(Vec3::new(f32::NAN, 0.0, 0.0));
        assert!(matches!(Pose::new(&[nan], None), Err(SkinError::InvalidMatrix { bone: 0, .. })));
        assert!(matches!(
            Pose::new(&[Mat4::IDENTITY], Some(&[Mat4::ZERO])),
            Err(SkinError::InvalidMatrix { what: "rest", .. })
        ));
        assert!(matches!(Pose::new(&[Mat4::IDENTITY], Some(&[])), Err(SkinError::LengthMismatch { .. })));
    }
}
