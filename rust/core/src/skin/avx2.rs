//! AVX2+FMA versions of the dual quaternion accumulation, the hot loop of DQS, and of the
//! sums of skinning with centers of rotation.
//!
//! A slot's lanes are handled in two halves of eight. For each half, the eight lanes' bone
//! records (8 floats each) are loaded as eight rows and transposed with shuffles into eight
//! component vectors, which is much cheaper than gathering each component; the running-sum sign
//! choice then runs on eight lanes at once. The arithmetic is the same as the portable code in
//! `kernels.rs`.

use core::arch::x86_64::*;

use super::influences::{Slot, LANES};

const HALF: usize = LANES / 2;
const _: () = assert!(HALF == 8);
use super::kernels::{CorSum, DqSum, Points};
use super::pose::{CorBone, CorRigidBone, DqBone, PivotBone};

/// Transposes eight rows of eight floats into eight columns.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn transpose8(r: [__m256; 8]) -> [__m256; 8] {
    let t0 = _mm256_unpacklo_ps(r[0], r[1]);
    let t1 = _mm256_unpackhi_ps(r[0], r[1]);
    let t2 = _mm256_unpacklo_ps(r[2], r[3]);
    let t3 = _mm256_unpackhi_ps(r[2], r[3]);
    let t4 = _mm256_unpacklo_ps(r[4], r[5]);
    let t5 = _mm256_unpackhi_ps(r[4], r[5]);
    let t6 = _mm256_unpacklo_ps(r[6], r[7]);
    let t7 = _mm256_unpackhi_ps(r[6], r[7]);
    let u0 = _mm256_shuffle_ps::<0x44>(t0, t2);
    let u1 = _mm256_shuffle_ps::<0xEE>(t0, t2);
    let u2 = _mm256_shuffle_ps::<0x44>(t1, t3);
    let u3 = _mm256_shuffle_ps::<0xEE>(t1, t3);
    let u4 = _mm256_shuffle_ps::<0x44>(t4, t6);
    let u5 = _mm256_shuffle_ps::<0xEE>(t4, t6);
    let u6 = _mm256_shuffle_ps::<0x44>(t5, t7);
    let u7 = _mm256_shuffle_ps::<0xEE>(t5, t7);
    [
        _mm256_permute2f128_ps::<0x20>(u0, u4),
        _mm256_permute2f128_ps::<0x20>(u1, u5),
        _mm256_permute2f128_ps::<0x20>(u2, u6),
        _mm256_permute2f128_ps::<0x20>(u3, u7),
        _mm256_permute2f128_ps::<0x31>(u0, u4),
        _mm256_permute2f128_ps::<0x31>(u1, u5),
        _mm256_permute2f128_ps::<0x31>(u2, u6),
        _mm256_permute2f128_ps::<0x31>(u3, u7),
    ]
}

/// Loads 8 floats at float offset `offset` of each lane's bone record and transposes them.
///
/// # Safety
/// Every `bones[l]` must index `table`, and `offset + 8` floats must lie inside a record.
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn load_columns<T>(table: &[T], bones: &[u32], offset: usize) -> [__m256; 8] {
    let base = table.as_ptr() as *const f32;
    let stride = core::mem::size_of::<T>() / 4;
    let row = |l: usize| {
        debug_assert!((bones[l] as usize) < table.len());
        // SAFETY: the caller guarantees the index and the offset are in range.
        unsafe { _mm256_loadu_ps(base.add(bones[l] as usize * stride + offset)) }
    };
    transpose8([row(0), row(1), row(2), row(3), row(4), row(5), row(6), row(7)])
}

/// `w`, negated in the lanes where `q·sum < 0`: a quaternion's sign chosen against the running
/// sum. The dot product in two independent halves: the sign choice is the serial chain, so keep
/// it short.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn signed_weight(q: &[__m256], sum: &[__m256; 4], w: __m256) -> __m256 {
    let dot = _mm256_add_ps(
        _mm256_fmadd_ps(q[1], sum[1], _mm256_mul_ps(q[0], sum[0])),
        _mm256_fmadd_ps(q[3], sum[3], _mm256_mul_ps(q[2], sum[2])),
    );
    let negative = _mm256_cmp_ps::<_CMP_LT_OQ>(dot, _mm256_setzero_ps());
    _mm256_xor_ps(w, _mm256_and_ps(negative, _mm256_set1_ps(-0.0)))
}

/// Adds `±w·(q, d)` to the sums, the sign chosen by `q·sum < 0` per lane.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn add_signed(real: &mut [__m256; 4], dual: &mut [__m256; 4], q: &[__m256], d: &[__m256], w: __m256) {
    let ws = signed_weight(q, real, w);
    for c in 0..4 {
        real[c] = _mm256_fmadd_ps(q[c], ws, real[c]);
        dual[c] = _mm256_fmadd_ps(d[c], ws, dual[c]);
    }
}

/// Writes one half's sums into lanes `8·half ..` of `s`.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn store(s: &mut DqSum, half: usize, real: [__m256; 4], dual: [__m256; 4], contrib: __m256) {
    let at = half * HALF;
    for c in 0..4 {
        // SAFETY: each destination has 8 floats from `at` (LANES = 2·HALF).
        unsafe {
            _mm256_storeu_ps(s.real[c][at..].as_mut_ptr(), real[c]);
            _mm256_storeu_ps(s.dual[c][at..].as_mut_ptr(), dual[c]);
        }
    }
    unsafe { _mm256_storeu_ps(s.contrib[at..].as_mut_ptr(), contrib) };
}

fn empty_sum() -> DqSum {
    DqSum { real: [[0.0; LANES]; 4], dual: [[0.0; LANES]; 4], contrib: [0.0; LANES] }
}

/// DQS sums for rigid bones.
///
/// # Safety
/// The CPU must support AVX2 and FMA, and every bone index in `slots` must index `dq`.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn accumulate_rigid(slots: &[Slot], dq: &[DqBone]) -> DqSum {
    let mut sum = empty_sum();
    for half in 0..2 {
        let lanes = half * HALF..(half + 1) * HALF;
        let mut real = [_mm256_setzero_ps(); 4];
        let mut dual = [_mm256_setzero_ps(); 4];
        let mut contrib = _mm256_setzero_ps();
        for slot in slots {
            // SAFETY: indices are in range (validated); a DqBone is 8 floats.
            let c = unsafe { load_columns(dq, &slot.bones[lanes.clone()], 0) };
            let w = unsafe { _mm256_loadu_ps(slot.weights[lanes.clone()].as_ptr()) };
            add_signed(&mut real, &mut dual, &c[0..4], &c[4..8], w);
            contrib = _mm256_add_ps(contrib, w);
        }
        store(&mut sum, half, real, dual, contrib);
    }
    sum
}

/// DQS sums when some bone has scale: each bone moves `co` rigidly to where its matrix puts it.
///
/// # Safety
/// The CPU must support AVX2 and FMA, and every bone index in `slots` must index `pivot`.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn accumulate_scaled(co: &Points, slots: &[Slot], pivot: &[PivotBone]) -> DqSum {
    let mut sum = empty_sum();
    for h in 0..2 {
        let lanes = h * HALF..(h + 1) * HALF;
        let (x, y, z) = unsafe {
            (
                _mm256_loadu_ps(co.x[lanes.clone()].as_ptr()),
                _mm256_loadu_ps(co.y[lanes.clone()].as_ptr()),
                _mm256_loadu_ps(co.z[lanes.clone()].as_ptr()),
            )
        };
        let (real, dual, contrib) = unsafe { scaled_half(x, y, z, slots, pivot, lanes) };
        store(&mut sum, h, real, dual, contrib);
    }
    sum
}

/// One half of [`accumulate_scaled`].
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn scaled_half(
    x: __m256,
    y: __m256,
    z: __m256,
    slots: &[Slot],
    pivot: &[PivotBone],
    lanes: core::ops::Range<usize>,
) -> ([__m256; 4], [__m256; 4], __m256) {
    let mut real = [_mm256_setzero_ps(); 4];
    let mut dual = [_mm256_setzero_ps(); 4];
    let mut contrib = _mm256_setzero_ps();
    let half = _mm256_set1_ps(0.5);
    for slot in slots {
        let bones = &slot.bones[lanes.clone()];
        // SAFETY: indices are in range (validated); a PivotBone is 16 floats: rows 0–1, then
        // row 2 and the rotation.
        let a = unsafe { load_columns(pivot, bones, 0) };
        let b = unsafe { load_columns(pivot, bones, 8) };
        let row = |m0: __m256, m1: __m256, m2: __m256, t: __m256| {
            _mm256_fmadd_ps(m0, x, _mm256_fmadd_ps(m1, y, _mm256_fmadd_ps(m2, z, t)))
        };
        let tx = row(a[0], a[1], a[2], a[3]);
        let ty = row(a[4], a[5], a[6], a[7]);
        let tz = row(b[0], b[1], b[2], b[3]);
        let q = [b[4], b[5], b[6], b[7]];
        // ½·(0, t)·q = ½·(w·t + t × v, −t·v), q = (v, w)
        let cross_plus = |p: __m256, r: __m256, s: __m256, u: __m256, tw: __m256| {
            _mm256_mul_ps(half, _mm256_fmsub_ps(p, r, _mm256_fmsub_ps(s, u, _mm256_mul_ps(tw, q[3]))))
        };
        let d = [
            // 0.5·(tx·w + ty·vz − tz·vy)
            cross_plus(ty, q[2], tz, q[1], tx),
            // 0.5·(ty·w + tz·vx − tx·vz)
            cross_plus(tz, q[0], tx, q[2], ty),
            // 0.5·(tz·w + tx·vy − ty·vx)
            cross_plus(tx, q[1], ty, q[0], tz),
            _mm256_mul_ps(
                _mm256_set1_ps(-0.5),
                _mm256_fmadd_ps(tx, q[0], _mm256_fmadd_ps(ty, q[1], _mm256_mul_ps(tz, q[2]))),
            ),
        ];
        let w = unsafe { _mm256_loadu_ps(slot.weights[lanes.clone()].as_ptr()) };
        add_signed(&mut real, &mut dual, &q, &d, w);
        contrib = _mm256_add_ps(contrib, w);
    }
    (real, dual, contrib)
}

/// Adds `±w·q` to the quaternion sum, the sign chosen by `q·sum < 0` per lane.
#[inline]
#[target_feature(enable = "avx2,fma")]
fn add_signed_rotation(real: &mut [__m256; 4], q: &[__m256], w: __m256) {
    let ws = signed_weight(q, real, w);
    for c in 0..4 {
        real[c] = _mm256_fmadd_ps(q[c], ws, real[c]);
    }
}

/// `½·(R·p + t − p)` for the unit quaternions `q = (v, w)` of `R`, given `h = t/2`: `w·a + (v ×
/// a + h)` with `a = v × p` (see `rotation_offset` in `kernels.rs`).
#[inline]
#[target_feature(enable = "avx2,fma")]
fn rotation_offset(q: &[__m256], h: &[__m256], p: &[__m256; 3]) -> [__m256; 3] {
    let a = [
        _mm256_fmsub_ps(q[1], p[2], _mm256_mul_ps(q[2], p[1])),
        _mm256_fmsub_ps(q[2], p[0], _mm256_mul_ps(q[0], p[2])),
        _mm256_fmsub_ps(q[0], p[1], _mm256_mul_ps(q[1], p[0])),
    ];
    let b = [
        _mm256_fmsub_ps(q[1], a[2], _mm256_fmsub_ps(q[2], a[1], h[0])),
        _mm256_fmsub_ps(q[2], a[0], _mm256_fmsub_ps(q[0], a[2], h[1])),
        _mm256_fmsub_ps(q[0], a[1], _mm256_fmsub_ps(q[1], a[0], h[2])),
    ];
    core::array::from_fn(|k| _mm256_fmadd_ps(q[3], a[k], b[k]))
}

/// Float offset of lane `l`'s bone record in `table`. The index is read as a scalar (a
/// volatile read keeps the compiler from loading the eight as a vector and extracting each
/// lane) right where the record is loaded, so that no index waits in a register for its turn.
///
/// # Safety
/// `bones[l]` must index `table`.
#[inline(always)]
unsafe fn record_offset<T>(table: &[T], bones: &[u32], l: usize) -> usize {
    // SAFETY: a valid reference to an initialized u32.
    let b = unsafe { core::ptr::read_volatile(&bones[l]) } as usize;
    debug_assert!(b < table.len());
    b * (core::mem::size_of::<T>() / 4)
}

/// The last entry `s22` of each lane's scale/shear part (see `CorBone`), by scalar loads
/// through a small buffer: all on the load/store side, none on the vector ports that the
/// transposes fill (faster here than the gather).
///
/// # Safety
/// Every `bones[l]` must index `cor`.
#[inline]
#[target_feature(enable = "avx2,fma")]
unsafe fn load_s22(cor: &[CorBone], bones: &[u32]) -> __m256 {
    const { assert!(core::mem::offset_of!(CorBone, s22) == 24 * 4) };
    debug_assert!(bones.len() >= HALF);
    let base = cor.as_ptr() as *const f32;
    // SAFETY: the caller guarantees the indices are in range.
    let values: [f32; HALF] = core::array::from_fn(|l| unsafe { *base.add(record_offset(cor, bones, l) + 24) });
    // SAFETY: 8 floats.
    unsafe { _mm256_loadu_ps(values.as_ptr()) }
}

/// Sums for skinning with centers of rotation (see `kernels.rs`): where each bone puts the
/// center (rigid: how far it moves it), the sign-aligned rotations, and with `scaled` the
/// blended scale/shear of `co − c`.
///
/// # Safety
/// The CPU must support AVX2 and FMA, and every bone index in `slots` must index `cor` and
/// `cor_rigid`.
#[target_feature(enable = "avx2,fma")]
pub(super) unsafe fn accumulate_centers(
    co: &Points,
    center: &Points,
    slots: &[Slot],
    cor: &[CorBone],
    cor_rigid: &[CorRigidBone],
    scaled: bool,
) -> CorSum {
    let z = [[0.0; LANES]; 3];
    let mut sum = CorSum { anchor: z, real: [[0.0; LANES]; 4], offset: z, contrib: [0.0; LANES] };
    for h in 0..2 {
        let lanes = h * HALF..(h + 1) * HALF;
        let load = |a: &[f32; LANES]| unsafe { _mm256_loadu_ps(a[lanes.clone()].as_ptr()) };
        let c = [load(&center.x), load(&center.y), load(&center.z)];
        let d = [
            _mm256_sub_ps(load(&co.x), c[0]),
            _mm256_sub_ps(load(&co.y), c[1]),
            _mm256_sub_ps(load(&co.z), c[2]),
        ];
        let mut anchor = [_mm256_setzero_ps(); 3];
        let mut offset = [_mm256_setzero_ps(); 3];
        let mut real = [_mm256_setzero_ps(); 4];
        let mut contrib = _mm256_setzero_ps();
        for slot in slots {
            let bones = &slot.bones[lanes.clone()];
            let w = unsafe { _mm256_loadu_ps(slot.weights[lanes.clone()].as_ptr()) };
            if !scaled {
                // SAFETY: indices are in range (validated); a CorRigidBone is 8 floats: the
                // rotation, half the translation and a zero.
                let r = unsafe { load_columns(cor_rigid, bones, 0) };
                let moved = rotation_offset(&r[0..4], &r[4..7], &c);
                let w2 = _mm256_add_ps(w, w);
                for k in 0..3 {
                    anchor[k] = _mm256_fmadd_ps(w2, moved[k], anchor[k]);
                }
                add_signed_rotation(&mut real, &r[0..4], w);
                contrib = _mm256_add_ps(contrib, w);
                continue;
            }
            // SAFETY: indices are in range (validated); a CorBone's first 24 floats are matrix
            // rows 0–1, row 2 and the rotation, and the first 8 entries of its scale/shear part.
            let a = unsafe { load_columns(cor, bones, 0) };
            let b = unsafe { load_columns(cor, bones, 8) };
            let rows = [[a[0], a[1], a[2], a[3]], [a[4], a[5], a[6], a[7]], [b[0], b[1], b[2], b[3]]];
            for r in 0..3 {
                let m = rows[r];
                let moved = _mm256_fmadd_ps(m[0], c[0], _mm256_fmadd_ps(m[1], c[1], _mm256_fmadd_ps(m[2], c[2], m[3])));
                anchor[r] = _mm256_fmadd_ps(w, moved, anchor[r]);
            }
            {
                let s = unsafe { load_columns(cor, bones, 16) };
                // SAFETY: as above.
                let s22 = unsafe { load_s22(cor, bones) };
                let rows = [[s[0], s[1], s[2]], [s[3], s[4], s[5]], [s[6], s[7], s22]];
                for r in 0..3 {
                    let m = rows[r];
                    let stretched = _mm256_fmadd_ps(m[0], d[0], _mm256_fmadd_ps(m[1], d[1], _mm256_mul_ps(m[2], d[2])));
                    offset[r] = _mm256_fmadd_ps(w, stretched, offset[r]);
                }
            }
            add_signed_rotation(&mut real, &[b[4], b[5], b[6], b[7]], w);
            contrib = _mm256_add_ps(contrib, w);
        }
        let at = h * HALF;
        // SAFETY: each destination has 8 floats from `at` (LANES = 2·HALF).
        unsafe {
            for r in 0..3 {
                _mm256_storeu_ps(sum.anchor[r][at..].as_mut_ptr(), anchor[r]);
                _mm256_storeu_ps(sum.offset[r][at..].as_mut_ptr(), offset[r]);
            }
            for c in 0..4 {
                _mm256_storeu_ps(sum.real[c][at..].as_mut_ptr(), real[c]);
            }
            _mm256_storeu_ps(sum.contrib[at..].as_mut_ptr(), contrib);
        }
    }
    sum
}
