//! AVX-512 versions of the dual quaternion accumulation: all sixteen lanes of a slot at once.
//!
//! Lane `l` and lane `l + 8` share a 512-bit row (their two bone records side by side); the
//! same in-lane shuffles as the AVX2 transpose then work on both halves together, and a
//! two-source permute finishes it. Arithmetic as in `portable.rs`.

use core::arch::x86_64::*;

use super::batch::BatchJob;
use super::influences::{lane_record, Slot, LANES};
use super::job::{DUAL_QUATERNION, LINEAR};
use super::pose::{CorBone, DqBone, LinearBone, PivotBone};

const _: () = assert!(LANES == 16);

/// `[a | b]` from two 256-bit halves.
#[inline]
#[target_feature(enable = "avx512f")]
fn join(a: __m256, b: __m256) -> __m512 {
    _mm512_castpd_ps(_mm512_insertf64x4::<1>(_mm512_castps_pd(_mm512_castps256_ps512(a)), _mm256_castps_pd(b)))
}

/// Loads 8 floats at float offset `offset` of each lane's bone record and transposes them into
/// eight 16-lane component vectors.
///
/// # Safety
/// Every bone index must index `table`, and `offset + 8` floats must lie inside a record.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn load_columns<T>(table: &[T], records: &[u32; LANES], offset: usize) -> [__m512; 8] {
    let row = |l: usize| {
        // SAFETY: the caller guarantees the record and the offset are in range.
        unsafe { _mm256_loadu_ps(lane_record(table, records[l]).add(offset)) }
    };
    transpose(core::array::from_fn(|i| join(row(i), row(i + 8))))
}

/// The 4×4 transposes within each 128-bit block of four rows: block `b` of output `e` holds
/// float `e` of block `b` of rows 0–3.
#[inline]
#[target_feature(enable = "avx512f")]
fn transpose_blocks(r: [__m512; 4]) -> [__m512; 4] {
    let t0 = _mm512_unpacklo_ps(r[0], r[1]);
    let t1 = _mm512_unpackhi_ps(r[0], r[1]);
    let t2 = _mm512_unpacklo_ps(r[2], r[3]);
    let t3 = _mm512_unpackhi_ps(r[2], r[3]);
    [
        _mm512_shuffle_ps::<0x44>(t0, t2),
        _mm512_shuffle_ps::<0xEE>(t0, t2),
        _mm512_shuffle_ps::<0x44>(t1, t3),
        _mm512_shuffle_ps::<0xEE>(t1, t3),
    ]
}

/// Transposes eight rows `[record l | record l + 8]` (8 floats each) into eight 16-lane
/// component vectors.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
fn transpose(r: [__m512; 8]) -> [__m512; 8] {
    let [u0, u1, u2, u3] = transpose_blocks([r[0], r[1], r[2], r[3]]);
    let [u4, u5, u6, u7] = transpose_blocks([r[4], r[5], r[6], r[7]]);
    // 128-bit blocks: low components from blocks 0 and 2, high ones from blocks 1 and 3.
    let lo = _mm512_setr_epi32(0, 1, 2, 3, 16, 17, 18, 19, 8, 9, 10, 11, 24, 25, 26, 27);
    let hi = _mm512_setr_epi32(4, 5, 6, 7, 20, 21, 22, 23, 12, 13, 14, 15, 28, 29, 30, 31);
    [
        _mm512_permutex2var_ps(u0, lo, u4),
        _mm512_permutex2var_ps(u1, lo, u5),
        _mm512_permutex2var_ps(u2, lo, u6),
        _mm512_permutex2var_ps(u3, lo, u7),
        _mm512_permutex2var_ps(u0, hi, u4),
        _mm512_permutex2var_ps(u1, hi, u5),
        _mm512_permutex2var_ps(u2, hi, u6),
        _mm512_permutex2var_ps(u3, hi, u7),
    ]
}

/// `w·b + v × b` for the quaternion sums `(v, w)` (see `turn` in `batch.rs`).
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
fn turn([x, y, z, w]: &[__m512; 4], b: [__m512; 3]) -> [__m512; 3] {
    let (x, y, z, w) = (*x, *y, *z, *w);
    [
        _mm512_fnmadd_ps(z, b[1], _mm512_fmadd_ps(y, b[2], _mm512_mul_ps(w, b[0]))),
        _mm512_fnmadd_ps(x, b[2], _mm512_fmadd_ps(z, b[0], _mm512_mul_ps(w, b[1]))),
        _mm512_fnmadd_ps(y, b[0], _mm512_fmadd_ps(x, b[1], _mm512_mul_ps(w, b[2]))),
    ]
}

/// `|q|²` of quaternion sums `(x, y, z, w)`, in the other copies' order.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
fn length_squared([x, y, z, w]: &[__m512; 4]) -> __m512 {
    _mm512_fmadd_ps(*z, *z, _mm512_fmadd_ps(*y, *y, _mm512_fmadd_ps(*x, *x, _mm512_mul_ps(*w, *w))))
}

/// `a·b` of quaternions per lane, in two independent halves: the sign choice that waits on it is
/// the serial chain, so keep it short.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
fn dot4(a: &[__m512], b: &[__m512]) -> __m512 {
    _mm512_add_ps(
        _mm512_fmadd_ps(a[1], b[1], _mm512_mul_ps(a[0], b[0])),
        _mm512_fmadd_ps(a[3], b[3], _mm512_mul_ps(a[2], b[2])),
    )
}

/// `w`, negated in the lanes where `dot < 0`: a quaternion's sign chosen against the running sum.
#[inline]
#[target_feature(enable = "avx512f")]
fn signed_weight(dot: __m512, w: __m512) -> __m512 {
    let negative = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(dot, _mm512_setzero_ps());
    _mm512_mask_sub_ps(w, negative, _mm512_setzero_ps(), w)
}

/// Adds `±w·(q, d)` to the sums, the sign chosen by `q·sum < 0` per lane.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
fn add_signed(real: &mut [__m512; 4], dual: &mut [__m512; 4], q: &[__m512], d: &[__m512], w: __m512) {
    let ws = signed_weight(dot4(q, real), w);
    for c in 0..4 {
        real[c] = _mm512_fmadd_ps(q[c], ws, real[c]);
        dual[c] = _mm512_fmadd_ps(d[c], ws, dual[c]);
    }
}

/// The sums in registers: real (x, y, z, w), dual (x, y, z, w), total weight.
type Sums = ([__m512; 4], [__m512; 4], __m512);

/// DQS sums for rigid bones.
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA, and every bone index in `slots` must index `dq`.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn rigid_sums(slots: &[Slot], dq: &[DqBone]) -> Sums {
    let mut real = [_mm512_setzero_ps(); 4];
    let mut dual = [_mm512_setzero_ps(); 4];
    let mut contrib = _mm512_setzero_ps();
    for slot in slots {
        // SAFETY: indices are in range (validated); a DqBone is 8 floats.
        let c = unsafe { load_columns(dq, &slot.records, 0) };
        // SAFETY: a slot has 16 weights.
        let w = unsafe { _mm512_loadu_ps(slot.weights.as_ptr()) };
        add_signed(&mut real, &mut dual, &c[0..4], &c[4..8], w);
        contrib = _mm512_add_ps(contrib, w);
    }
    (real, dual, contrib)
}

/// DQS sums when some bone has scale: each bone moves `co` rigidly to where its matrix puts it.
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA, and every bone index in `slots` must index
/// `pivot`.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn scaled_sums([x, y, z]: [__m512; 3], slots: &[Slot], pivot: &[PivotBone]) -> Sums {
    let mut real = [_mm512_setzero_ps(); 4];
    let mut dual = [_mm512_setzero_ps(); 4];
    let mut contrib = _mm512_setzero_ps();
    let half = _mm512_set1_ps(0.5);
    for slot in slots {
        // SAFETY: indices are in range (validated); a PivotBone is 16 floats: rows 0–1, then
        // row 2 and the rotation.
        let a = unsafe { load_columns(pivot, &slot.records, 0) };
        // SAFETY: as above.
        let b = unsafe { load_columns(pivot, &slot.records, 8) };
        let row = |m0: __m512, m1: __m512, m2: __m512, t: __m512| {
            _mm512_fmadd_ps(m0, x, _mm512_fmadd_ps(m1, y, _mm512_fmadd_ps(m2, z, t)))
        };
        let tx = row(a[0], a[1], a[2], a[3]);
        let ty = row(a[4], a[5], a[6], a[7]);
        let tz = row(b[0], b[1], b[2], b[3]);
        let q = [b[4], b[5], b[6], b[7]];
        // ½·(0, t)·q = ½·(w·t + t × v, −t·v), q = (v, w); see avx2.rs for the term order.
        let cross_plus = |p: __m512, r: __m512, s: __m512, u: __m512, tw: __m512| {
            _mm512_mul_ps(half, _mm512_fmsub_ps(p, r, _mm512_fmsub_ps(s, u, _mm512_mul_ps(tw, q[3]))))
        };
        let d = [
            cross_plus(ty, q[2], tz, q[1], tx),
            cross_plus(tz, q[0], tx, q[2], ty),
            cross_plus(tx, q[1], ty, q[0], tz),
            _mm512_mul_ps(
                _mm512_set1_ps(-0.5),
                _mm512_fmadd_ps(tx, q[0], _mm512_fmadd_ps(ty, q[1], _mm512_mul_ps(tz, q[2]))),
            ),
        ];
        // SAFETY: a slot has 16 weights.
        let w = unsafe { _mm512_loadu_ps(slot.weights.as_ptr()) };
        add_signed(&mut real, &mut dual, &q, &d, w);
        contrib = _mm512_add_ps(contrib, w);
    }
    (real, dual, contrib)
}

/// Index vectors that gather every third float of 48 (`a` = floats 0–15, `b` = 16–31,
/// `c` = 32–47): first from `a` and `b`, then the rest from `c`.
const fn deinterleave_indices(axis: i32) -> ([i32; 16], [i32; 16]) {
    let mut first = [0i32; 16];
    let mut second = [0i32; 16];
    let mut l = 0;
    while l < 16 {
        let f = 3 * l as i32 + axis; // position among the 48 floats
        first[l] = if f < 32 { f } else { 0 };
        second[l] = if f < 32 { l as i32 } else { f - 32 + 16 };
        l += 1;
    }
    (first, second)
}

const DEINTERLEAVE: [([i32; 16], [i32; 16]); 3] =
    [deinterleave_indices(0), deinterleave_indices(1), deinterleave_indices(2)];

/// Index vectors that put lane values back as `x0 y0 z0 x1 …`: float `f` of the output comes
/// from lane `f / 3` of axis `f % 3`; three 16-float outputs from three 16-lane axis vectors.
const fn interleave_indices(part: usize) -> ([i32; 16], [i32; 16]) {
    // Step 1 picks from (x, y); step 2 from (step1, z).
    let mut first = [0i32; 16];
    let mut second = [0i32; 16];
    let mut k = 0;
    while k < 16 {
        let f = part * 16 + k;
        let lane = (f / 3) as i32;
        let axis = f % 3;
        first[k] = if axis == 0 {
            lane
        } else if axis == 1 {
            lane + 16
        } else {
            0
        };
        second[k] = if axis == 2 { lane + 16 } else { k as i32 };
        k += 1;
    }
    (first, second)
}

const INTERLEAVE: [([i32; 16], [i32; 16]); 3] = [interleave_indices(0), interleave_indices(1), interleave_indices(2)];

#[inline]
#[target_feature(enable = "avx512f")]
fn idx(v: &[i32; 16]) -> __m512i {
    // SAFETY: 16 i32 are 64 bytes.
    unsafe { _mm512_loadu_si512(v.as_ptr() as *const __m512i) }
}

/// Splits 16 points `x y z x y z …` into coordinate vectors.
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn load_points(points: &[[f32; 3]; LANES]) -> [__m512; 3] {
    let p = points.as_ptr() as *const f32;
    // SAFETY: 16 points are 48 floats.
    let (a, b, c) = unsafe { (_mm512_loadu_ps(p), _mm512_loadu_ps(p.add(16)), _mm512_loadu_ps(p.add(32))) };
    core::array::from_fn(|axis| {
        let (first, second) = &DEINTERLEAVE[axis];
        _mm512_permutex2var_ps(_mm512_permutex2var_ps(a, idx(first), b), idx(second), c)
    })
}

/// Writes coordinate vectors back as 16 points `x y z x y z …`.
///
/// # Safety
/// The CPU must support AVX-512F.
#[inline]
#[target_feature(enable = "avx512f")]
unsafe fn store_points([x, y, z]: [__m512; 3], out: &mut [[f32; 3]; LANES]) {
    let dst = out.as_mut_ptr() as *mut f32;
    for (part, (first, second)) in INTERLEAVE.iter().enumerate() {
        let xy = _mm512_permutex2var_ps(x, idx(first), y);
        // SAFETY: 16 points are 48 floats.
        unsafe { _mm512_storeu_ps(dst.add(16 * part), _mm512_permutex2var_ps(xy, idx(second), z)) };
    }
}

/// A 3×4 affine transform with each entry broadcast to all lanes.
struct Affine {
    m: [[__m512; 4]; 3],
}

impl Affine {
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn new(a: &glam::Affine3A) -> Self {
        let c = [a.matrix3.x_axis, a.matrix3.y_axis, a.matrix3.z_axis, a.translation];
        Affine { m: core::array::from_fn(|r| core::array::from_fn(|k| _mm512_set1_ps(c[k][r]))) }
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn apply(&self, p: [__m512; 3]) -> [__m512; 3] {
        core::array::from_fn(|r| {
            let m = &self.m[r];
            _mm512_fmadd_ps(m[0], p[0], _mm512_fmadd_ps(m[1], p[1], _mm512_fmadd_ps(m[2], p[2], m[3])))
        })
    }
}

/// LBS sums in registers: the weighted rows `Σ wᵢ·Mᵢ` (row-major 3×4) and the total weight.
///
/// Summed per lane: each influence adds its weight (a broadcast load) times its bone's whole
/// 16-float record (one load, folded into the FMA) to its lane's accumulator, and the sixteen
/// accumulators are transposed once per batch. Transposing every slot's records instead cost
/// 48 shuffles and 16 inserts per slot, which bounded LBS on the vector ports. One FMA per float,
/// in slot order.
///
/// # Safety
/// As [`rigid_sums`], for `linear`.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn linear_sums(slots: &[Slot], linear: &[LinearBone]) -> ([__m512; 12], __m512) {
    const { assert!(core::mem::size_of::<LinearBone>() == 64) };
    let mut lanes = [_mm512_setzero_ps(); LANES];
    let mut contrib = _mm512_setzero_ps();
    for slot in slots {
        for (l, lane) in lanes.iter_mut().enumerate() {
            // SAFETY: indices are in range (validated); a LinearBone is 16 floats (rows,
            // zero padding).
            let record = unsafe { _mm512_loadu_ps(scalar_record(linear, &slot.records, l)) };
            *lane = _mm512_fmadd_ps(record, _mm512_set1_ps(slot.weights[l]), *lane);
        }
        // SAFETY: a slot has 16 weights.
        contrib = _mm512_add_ps(contrib, unsafe { _mm512_loadu_ps(slot.weights.as_ptr()) });
    }
    (transpose_rows(&lanes), contrib)
}

/// Floats 0–11 of sixteen lane vectors as twelve 16-lane component vectors (float 12–15, the
/// padding, dropped): the in-block 4×4 transposes of each group of four lanes, then the
/// 128-bit blocks gathered across the groups.
#[inline]
#[target_feature(enable = "avx512f")]
fn transpose_rows(r: &[__m512; LANES]) -> [__m512; 12] {
    // u[g][e]: block b holds float 4b + e of lanes 4g .. 4g + 4.
    let group = |g: usize| transpose_blocks([r[4 * g], r[4 * g + 1], r[4 * g + 2], r[4 * g + 3]]);
    let u = [group(0), group(1), group(2), group(3)];
    let mut out = [_mm512_setzero_ps(); 12];
    for e in 0..4 {
        // Blocks 0–1 (low) and 2–3 (high) of groups 0 and 1, and of groups 2 and 3.
        let lo01 = _mm512_shuffle_f32x4::<0x44>(u[0][e], u[1][e]);
        let hi01 = _mm512_shuffle_f32x4::<0xEE>(u[0][e], u[1][e]);
        let lo23 = _mm512_shuffle_f32x4::<0x44>(u[2][e], u[3][e]);
        let hi23 = _mm512_shuffle_f32x4::<0xEE>(u[2][e], u[3][e]);
        out[e] = _mm512_shuffle_f32x4::<0x88>(lo01, lo23);
        out[4 + e] = _mm512_shuffle_f32x4::<0xDD>(lo01, lo23);
        out[8 + e] = _mm512_shuffle_f32x4::<0x88>(hi01, hi23);
    }
    out
}

/// Everything skinning does to one full batch of 16 vertices, in registers: load, `premat`,
/// LBS and/or DQS (Blender's `mul_v3m3_dq`), blend, strength, `postmat`, mask, store. The same
/// arithmetic as the portable copy (`portable.rs`).
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA; every bone index in `slots` must index the
/// bone tables.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) unsafe fn batch<const KIND: u8>(
    job: &BatchJob<'_>,
    positions: &[[f32; 3]; LANES],
    out: &mut [[f32; 3]; LANES],
    slots: &[Slot],
    strength: Option<&[f32; LANES]>,
    blend_amount: Option<&[f32; LANES]>,
) {
    // SAFETY: 16 points (and below: every array loaded or stored has exactly 16 lanes).
    let o = unsafe { load_points(positions) };
    let p = match job.premat {
        Some(m) => Affine::new(m).apply(o),
        None => o,
    };
    let zero = _mm512_setzero_ps();
    let one = _mm512_set1_ps(1.0);
    let a = match strength {
        // SAFETY: the mask has 16 lanes.
        Some(s) => unsafe { _mm512_loadu_ps(s.as_ptr()) },
        None => one,
    };
    let threshold = _mm512_set1_ps(super::MIN_TOTAL_WEIGHT);
    let lbs = (KIND != DUAL_QUATERNION).then(|| {
        // SAFETY: as this function's own contract.
        let (acc, contrib) = unsafe { linear_sums(slots, job.linear) };
        let valid = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(contrib, threshold);
        let f = _mm512_maskz_div_ps(valid, a, contrib);
        // co + (a/contrib)·(Σ wᵢ·Mᵢ·co − contrib·co)
        let axis = |r: usize| {
            let m = &acc[4 * r..4 * r + 4];
            let moved = _mm512_fmadd_ps(m[0], p[0], _mm512_fmadd_ps(m[1], p[1], _mm512_fmadd_ps(m[2], p[2], m[3])));
            _mm512_fmadd_ps(_mm512_fnmadd_ps(p[r], contrib, moved), f, p[r])
        };
        [axis(0), axis(1), axis(2)]
    });
    let dqs = (KIND != LINEAR).then(|| {
        // SAFETY: as this function's own contract.
        let ([x, y, z, w], [d0, d1, d2, d3], contrib) = unsafe {
            if job.scaled {
                scaled_sums(p, slots, job.pivot)
            } else {
                rigid_sums(slots, job.dq)
            }
        };
        // Blender's `mul_v3m3_dq` as `p + u·(2a/|q|²)` (see `dual_quaternion` in `batch.rs`).
        let ([tx, ty, tz], t0) = ([d0, d1, d2], d3);
        let fma = |a, b, c| _mm512_fmadd_ps(a, b, c);
        let fnma = |a, b, c| _mm512_fnmadd_ps(a, b, c);
        // b = v × p + t⃗, u = w·b + v × b − t₀·v
        let b = [fnma(z, p[1], fma(y, p[2], tx)), fnma(x, p[2], fma(z, p[0], ty)), fnma(y, p[0], fma(x, p[1], tz))];
        let t = turn(&[x, y, z, w], b);
        let u = [fnma(t0, x, t[0]), fnma(t0, y, t[1]), fnma(t0, z, t[2])];
        let len2 = length_squared(&[x, y, z, w]);
        let valid = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(contrib, threshold) & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(len2, zero);
        let g = _mm512_maskz_div_ps(valid, _mm512_add_ps(a, a), len2);
        core::array::from_fn::<__m512, 3, _>(|k| fma(u[k], g, p[k]))
    });
    let moved = match (lbs, dqs) {
        (Some(l), Some(d)) => {
            let mut alpha = _mm512_set1_ps(job.blend_factor);
            if let Some(amount) = blend_amount {
                // SAFETY: the blend amounts have 16 lanes.
                alpha = _mm512_mul_ps(alpha, unsafe { _mm512_loadu_ps(amount.as_ptr()) });
            }
            core::array::from_fn(|k| _mm512_fmadd_ps(alpha, _mm512_sub_ps(d[k], l[k]), l[k]))
        }
        (Some(l), None) => l,
        (None, Some(d)) => d,
        (None, None) => p,
    };
    // SAFETY: as this function's own contract.
    unsafe { write_batch(job, moved, a, o, out) }
}

/// `½·(R·p + t − p)` for the unit quaternions `q = (v, w)` of `R`, given `h = t/2`: `w·a + (v ×
/// a + h)` with `a = v × p` (see `rotation_offset` in `portable.rs`).
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
fn rotation_offset(q: &[__m512], h: &[__m512], p: &[__m512; 3]) -> [__m512; 3] {
    let a = [
        _mm512_fmsub_ps(q[1], p[2], _mm512_mul_ps(q[2], p[1])),
        _mm512_fmsub_ps(q[2], p[0], _mm512_mul_ps(q[0], p[2])),
        _mm512_fmsub_ps(q[0], p[1], _mm512_mul_ps(q[1], p[0])),
    ];
    let b = [
        _mm512_fmsub_ps(q[1], a[2], _mm512_fmsub_ps(q[2], a[1], h[0])),
        _mm512_fmsub_ps(q[2], a[0], _mm512_fmsub_ps(q[0], a[2], h[1])),
        _mm512_fmsub_ps(q[0], a[1], _mm512_fmsub_ps(q[1], a[0], h[2])),
    ];
    core::array::from_fn(|k| _mm512_fmadd_ps(q[3], a[k], b[k]))
}

/// Lane `l`'s bone record in `table`. The slot entry is read as a scalar (a volatile read keeps
/// the compiler from loading all sixteen as a vector and extracting each lane, two shuffles a
/// lane on the vector ports the transposes need) right where the record is loaded, so that no
/// entry waits in a register (or a spill slot) for its turn.
///
/// # Safety
/// `records[l]` must name a record of `table` (see [`lane_record`]).
#[inline(always)]
unsafe fn scalar_record<T>(table: &[T], records: &[u32; LANES], l: usize) -> *const f32 {
    // SAFETY: a valid reference to an initialized u32.
    let r = unsafe { core::ptr::read_volatile(&records[l]) };
    // SAFETY: the caller's contract.
    unsafe { lane_record(table, r) }
}

/// [`load_columns`] with the indices read as scalars (see [`scalar_record`]).
///
/// # Safety
/// As [`load_columns`].
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn load_columns_scalar<T>(table: &[T], records: &[u32; LANES], offset: usize) -> [__m512; 8] {
    // SAFETY: the caller guarantees the records and the offset are in range.
    let row = |l: usize| unsafe { _mm256_loadu_ps(scalar_record(table, records, l).add(offset)) };
    transpose(core::array::from_fn(|i| join(row(i), row(i + 8))))
}

/// The last entry `s22` of each lane's scale/shear part (float 24 of its `CorBone`, after the
/// three windows), by scalar loads through a small buffer: all on the load/store side, none on
/// the vector ports that the transposes fill (faster here than the gather; a fourth window
/// would cost a whole transpose).
///
/// # Safety
/// Every record must be one of `cor`.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn load_s22(cor: &[CorBone], records: &[u32; LANES]) -> __m512 {
    const { assert!(core::mem::offset_of!(CorBone, s22) == 24 * 4) };
    // SAFETY: the caller guarantees the records are in range.
    let values: [f32; LANES] = core::array::from_fn(|l| unsafe { *scalar_record(cor, records, l).add(24) });
    // SAFETY: 16 floats.
    unsafe { _mm512_loadu_ps(values.as_ptr()) }
}

/// The end of every batch: `postmat`, the lanes with strength `a = 0` left bit-identical to the
/// originals `o` (no space round trip), store.
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA.
#[inline]
#[target_feature(enable = "avx512f,avx2,fma")]
unsafe fn write_batch(job: &BatchJob<'_>, moved: [__m512; 3], a: __m512, o: [__m512; 3], out: &mut [[f32; 3]; LANES]) {
    let mut r = match job.postmat {
        Some(m) => Affine::new(m).apply(moved),
        None => moved,
    };
    let untouched = _mm512_cmp_ps_mask::<_CMP_EQ_OQ>(a, _mm512_setzero_ps());
    for k in 0..3 {
        r[k] = _mm512_mask_mov_ps(r[k], untouched, o[k]);
    }
    // SAFETY: the CPU has AVX-512F (this function's contract).
    unsafe { store_points(r, out) };
}

/// Everything skinning with centers of rotation does to one full batch of 16 vertices, in
/// registers: load the points and their centers, `premat` on both, the sums (where each bone
/// puts the center, the sign-aligned rotations, with `SCALED` the blended scale/shear of the
/// offset), the rotation of the offset, strength, `postmat`, mask, store. The same arithmetic as
/// the portable copy (`portable.rs`).
///
/// # Safety
/// The CPU must support AVX-512F, AVX2 and FMA; every bone index in `slots` must index `cor`
/// and `cor_rigid`.
#[target_feature(enable = "avx512f,avx2,fma")]
pub(super) unsafe fn batch_centers<const SCALED: bool>(
    job: &BatchJob<'_>,
    positions: &[[f32; 3]; LANES],
    centers: &[[f32; 3]; LANES],
    out: &mut [[f32; 3]; LANES],
    slots: &[Slot],
    strength: Option<&[f32; LANES]>,
) {
    // SAFETY: 16 points; 16 centers.
    let (o, c) = unsafe { (load_points(positions), load_points(centers)) };
    let (p, c) = match job.premat {
        Some(m) => {
            let m = Affine::new(m);
            (m.apply(o), m.apply(c))
        }
        None => (o, c),
    };
    let d: [__m512; 3] = core::array::from_fn(|k| _mm512_sub_ps(p[k], c[k]));
    let mut anchor = [_mm512_setzero_ps(); 3];
    let mut offset = [_mm512_setzero_ps(); 3];
    let mut real = [_mm512_setzero_ps(); 4];
    let (mut q_prev, mut ws_prev) = ([_mm512_setzero_ps(); 4], _mm512_setzero_ps());
    let mut contrib = _mm512_setzero_ps();
    for slot in slots {
        // SAFETY: a slot has 16 weights.
        let w = unsafe { _mm512_loadu_ps(slot.weights.as_ptr()) };
        let q = if SCALED {
            // SAFETY: indices are in range (validated); a CorBone's first 24 floats are matrix
            // rows 0–1, the rotation and row 2, and the first 8 entries of its scale/shear part.
            let a = unsafe { load_columns_scalar(job.cor, &slot.records, 0) };
            // SAFETY: as above.
            let b = unsafe { load_columns_scalar(job.cor, &slot.records, 8) };
            let rows = [[a[0], a[1], a[2], a[3]], [a[4], a[5], a[6], a[7]], [b[4], b[5], b[6], b[7]]];
            for r in 0..3 {
                let m = rows[r];
                let moved = _mm512_fmadd_ps(m[0], c[0], _mm512_fmadd_ps(m[1], c[1], _mm512_fmadd_ps(m[2], c[2], m[3])));
                anchor[r] = _mm512_fmadd_ps(w, moved, anchor[r]);
            }
            // SAFETY: as above.
            let s = unsafe { load_columns_scalar(job.cor, &slot.records, 16) };
            // SAFETY: as above.
            let s22 = unsafe { load_s22(job.cor, &slot.records) };
            let rows = [[s[0], s[1], s[2]], [s[3], s[4], s[5]], [s[6], s[7], s22]];
            for r in 0..3 {
                let m = rows[r];
                let stretched = _mm512_fmadd_ps(m[0], d[0], _mm512_fmadd_ps(m[1], d[1], _mm512_mul_ps(m[2], d[2])));
                offset[r] = _mm512_fmadd_ps(w, stretched, offset[r]);
            }
            [b[0], b[1], b[2], b[3]]
        } else {
            // SAFETY: indices are in range (validated); a CorRigidBone is 8 floats: the
            // rotation, half the translation and a zero.
            let r = unsafe { load_columns_scalar(job.cor_rigid, &slot.records, 0) };
            let moved = rotation_offset(&r[0..4], &r[4..7], &c);
            let w2 = _mm512_add_ps(w, w);
            for k in 0..3 {
                anchor[k] = _mm512_fmadd_ps(w2, moved[k], anchor[k]);
            }
            [r[0], r[1], r[2], r[3]]
        };
        // The sign chain, shortened: the running sum is `real + ws_prev·q_prev` (the previous
        // term not added yet), so `q·sum = q·real + ws_prev·(q·q_prev)` where both dot products
        // are off the chain and only one FMA waits for `ws_prev`.
        // Worth it where the slot's other work is long (scaled poses); rigid poses are bound by
        // throughput, and the extra products cost more than the shorter chain saves.
        if SCALED {
            let ws = signed_weight(_mm512_fmadd_ps(ws_prev, dot4(&q, &q_prev), dot4(&q, &real)), w);
            for k in 0..4 {
                real[k] = _mm512_fmadd_ps(q_prev[k], ws_prev, real[k]);
            }
            (q_prev, ws_prev) = (q, ws);
        } else {
            let ws = signed_weight(dot4(&q, &real), w);
            for k in 0..4 {
                real[k] = _mm512_fmadd_ps(q[k], ws, real[k]);
            }
        }
        contrib = _mm512_add_ps(contrib, w);
    }
    for k in 0..4 {
        // Adds the last term (scaled poses; zero otherwise).
        real[k] = _mm512_fmadd_ps(q_prev[k], ws_prev, real[k]);
    }
    let zero = _mm512_setzero_ps();
    let a = match strength {
        // SAFETY: the mask has 16 lanes.
        Some(s) => unsafe { _mm512_loadu_ps(s.as_ptr()) },
        None => _mm512_set1_ps(1.0),
    };
    // The rotation through `u` (see `rotation_terms` in `batch.rs`), then the strength, as the
    // portable `finish_centers` (`portable.rs`).
    let [x, y, z, _] = real;
    let fma = |a, b, c| _mm512_fmadd_ps(a, b, c);
    let fnma = |a, b, c| _mm512_fnmadd_ps(a, b, c);
    let mul = |a, b| _mm512_mul_ps(a, b);
    let dd = if SCALED { offset } else { d };
    let b = [fnma(z, dd[1], mul(y, dd[2])), fnma(x, dd[2], mul(z, dd[0])), fnma(y, dd[0], mul(x, dd[1]))];
    let u = turn(&real, b);
    let len2 = length_squared(&real);
    let valid = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(contrib, _mm512_set1_ps(super::MIN_TOTAL_WEIGHT))
        & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(len2, zero);
    // One division serves both factors: a/contrib = inv·|q|², 2a/|q|² = 2·inv·contrib.
    let inv = _mm512_maskz_div_ps(valid, a, mul(len2, contrib));
    let fa = mul(inv, len2);
    let inv2 = _mm512_add_ps(inv, inv);
    let fr = if SCALED { inv2 } else { mul(inv2, contrib) };
    // The rigid anchor is Σ wᵢ·(Mᵢ·c − c); the scaled one Σ wᵢ·Mᵢ·c, whose share is taken
    // as (anchor + o − contrib·co).
    let anchor: [__m512; 3] = if SCALED {
        core::array::from_fn(|k| fnma(p[k], contrib, _mm512_add_ps(anchor[k], offset[k])))
    } else {
        anchor
    };
    let moved: [__m512; 3] = core::array::from_fn(|k| fma(anchor[k], fa, fma(u[k], fr, p[k])));
    // SAFETY: as this function's own contract.
    unsafe { write_batch(job, moved, a, o, out) }
}
