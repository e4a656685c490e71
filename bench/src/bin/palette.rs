//! An experiment, not a kernel the library runs: Linear skinning of 16-vertex batches summed in
//! two designs, timed side by side in one process (AVX-512), so that a CPU's choice between them
//! is measured on that CPU (docs/performance.md, "An alternative measured: a palette of bones per
//! batch").
//!
//! - **Per lane** (the shipped kernels' sums): each lane adds its weight times its bone's whole
//!   16-float record (rows of a 3×4 matrix, zero padding), one fused multiply-add a lane and
//!   influence, the record's load indexed by the lane's bone; here the sixteen lane vectors are
//!   transposed once a batch, as the one body's AVX-512 sums are (the shipped Linear applies each
//!   lane's sum to its point in place instead, `avx512/kept.rs`, a little faster).
//! - **Palette**: each batch keeps the distinct bones its lanes use (at most 16) and, per slot,
//!   each lane's position among them (made once, as influences are); the kernel loads the
//!   palette's records, transposes them, and sums component by component, each lane's component
//!   picked from the transposed palette by `vpermps`.
//!
//! Both add the same products in the same order and share the finish, so they give the same bits
//! (checked). Meshes: `bench`, dqskin-bench's (every lane of a slot on one bone), `mixed` (each
//! vertex 4 of the 8 bones from its place, in random order: about 8 distinct bones a batch) and
//! `wide` (4 of the 16: 9 to 16 a batch, the palette's largest tables).
//!
//! Usage: `palette [--method linear|dq] [--vertices N] [--rounds R] [--mesh bench|mixed|wide]`.

#[cfg(target_arch = "x86_64")]
#[path = "../rng.rs"]
mod rng;

#[cfg(target_arch = "x86_64")]
mod x86 {
    use core::arch::x86_64::*;
    use std::time::Instant;

    use super::rng::Rng;

    const LANES: usize = 16;
    const SLOTS: usize = 4;
    const BONES: usize = 64;

    /// A bone's move: rows of a 3×4 matrix, then four zeros (one cache line).
    #[repr(C, align(64))]
    #[derive(Clone, Copy)]
    struct Record([f32; 16]);

    /// A bone's rigid dual quaternion: the rotation, then the dual part (x, y, z, w each).
    #[repr(C, align(32))]
    #[derive(Clone, Copy)]
    struct DqRecord([f32; 8]);

    #[derive(Clone, Copy)]
    struct Slot {
        bones: [u8; LANES],
        weights: [f32; LANES],
    }

    /// A batch's distinct bones and, per slot, where each lane's bone is in the transposed palette.
    #[derive(Clone, Copy)]
    struct Palette {
        bones: [u8; LANES],
        /// Groups of four records transposed: 1 to 4.
        groups: usize,
        at: [[u8; LANES]; SLOTS],
        /// Each lane's bone's index in `bones` (the order of the 16-entry tables DQS transposes).
        index: [[u8; LANES]; SLOTS],
    }

    struct Mesh {
        records: Vec<Record>,
        dq: Vec<DqRecord>,
        points: Vec<[f32; 3]>,
        slots: Vec<Slot>,
        palettes: Vec<Palette>,
        distinct: f64,
    }

    /// A mesh whose vertices take 4 bones: `spread` 0, those of dqskin-bench's mesh; else 4 of
    /// the `spread` bones from each vertex's place, in random order.
    fn mesh(vertices: usize, spread: u64) -> Mesh {
        let mut rng = Rng(0x9E37_79B9_7F4A_7C15);
        let records = (0..BONES)
            .map(|_| {
                let mut r = [0.0; 16];
                r[..12].iter_mut().for_each(|x| *x = rng.range(-0.5, 0.5));
                Record(r)
            })
            .collect();
        // Unit rotations in both signs (so the sign chain flips some weights) and translations.
        let dq = (0..BONES)
            .map(|_| {
                let q: [f32; 4] = core::array::from_fn(|_| rng.range(-1.0, 1.0));
                let n = q.iter().map(|x| x * x).sum::<f32>().sqrt();
                let t: [f32; 3] = core::array::from_fn(|_| rng.range(-0.5, 0.5));
                let [x, y, z, w] = q.map(|c| c / n);
                // dual = ½·(t, 0)·q
                let dual = [
                    0.5 * (t[0] * w + t[1] * z - t[2] * y),
                    0.5 * (-t[0] * z + t[1] * w + t[2] * x),
                    0.5 * (t[0] * y - t[1] * x + t[2] * w),
                    -0.5 * (t[0] * x + t[1] * y + t[2] * z),
                ];
                DqRecord([x, y, z, w, dual[0], dual[1], dual[2], dual[3]])
            })
            .collect();
        let points = (0..vertices).map(|_| [rng.unit(), rng.unit(), rng.unit()]).collect();
        let mut bones = vec![[0u8; SLOTS]; vertices];
        let mut weights = vec![[0f32; SLOTS]; vertices];
        for v in 0..vertices {
            let base = v * BONES / vertices;
            let raw: [f32; SLOTS] = core::array::from_fn(|_| rng.range(0.05, 1.0));
            let sum: f32 = raw.iter().sum();
            for k in 0..SLOTS {
                let bone = if spread > 0 {
                    // From the batch's place, so that a batch draws from `spread` bones at most.
                    let base = v / LANES * LANES * BONES / vertices;
                    loop {
                        let b = ((base + (rng.next_u64() % spread) as usize) % BONES) as u8;
                        if !bones[v][..k].contains(&b) {
                            break b;
                        }
                    }
                } else {
                    ((base + 3 * k) % BONES) as u8
                };
                bones[v][k] = bone;
                weights[v][k] = raw[k] / sum;
            }
        }
        let (mut slots, mut palettes, mut distinct) = (Vec::new(), Vec::new(), 0);
        for b in 0..vertices / LANES {
            let lane = |l: usize| b * LANES + l;
            let mut used: Vec<u8> = Vec::new();
            for k in 0..SLOTS {
                for l in 0..LANES {
                    if !used.contains(&bones[lane(l)][k]) {
                        used.push(bones[lane(l)][k]);
                    }
                }
                slots.push(Slot {
                    bones: core::array::from_fn(|l| bones[lane(l)][k]),
                    weights: core::array::from_fn(|l| weights[lane(l)][k]),
                });
            }
            distinct += used.len();
            assert!(used.len() <= LANES, "a batch uses more bones than a palette holds");
            let groups = used.len().div_ceil(4);
            // Two groups sit in blocks 0 and 2 of the transposed vectors, more in blocks 0-3.
            let place = |j: usize| if groups <= 2 { 8 * (j / 4) + j % 4 } else { j };
            let mut palette =
                Palette { bones: [used[0]; LANES], groups, at: [[0; LANES]; SLOTS], index: [[0; LANES]; SLOTS] };
            palette.bones[..used.len()].copy_from_slice(&used);
            for (k, (at, index)) in palette.at.iter_mut().zip(&mut palette.index).enumerate() {
                for (l, (at, index)) in at.iter_mut().zip(index).enumerate() {
                    let j = used.iter().position(|&u| u == bones[lane(l)][k]).expect("listed");
                    (*at, *index) = (place(j) as u8, j as u8);
                }
            }
            palettes.push(palette);
        }
        let distinct = distinct as f64 / palettes.len().max(1) as f64;
        Mesh { records, dq, points, slots, palettes, distinct }
    }

    /// The 4×4 transposes within each 128-bit block of four vectors.
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

    /// Block `c` of each of `u` (records 4g..4g+4 transposed within blocks) into block g.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn gather_block<const SEL: i32>(u: &[[__m512; 4]; 4], k: usize) -> __m512 {
        let a = _mm512_shuffle_f32x4::<SEL>(u[0][k], u[1][k]);
        let b = _mm512_shuffle_f32x4::<SEL>(u[2][k], u[3][k]);
        _mm512_shuffle_f32x4::<0x88>(a, b)
    }

    /// The twelve components (rows 0-2, columns 0-3) of sixteen entries, from four groups of
    /// four transposed within their blocks (`transpose_blocks`): entry `4g + k` of component
    /// `e` is float `e` of group `g`'s entry `k`.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn components(u: &[[__m512; 4]; 4]) -> [__m512; 12] {
        core::array::from_fn(|e| match e / 4 {
            0 => gather_block::<0x00>(u, e % 4),
            1 => gather_block::<0x55>(u, e % 4),
            _ => gather_block::<0xAA>(u, e % 4),
        })
    }

    /// The sums' finish, shared: `p + (1/Σw)·(M·p − Σw·p)` per lane, from the twelve summed
    /// components (row-major), written back as points.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn finish(m: &[__m512; 12], contrib: __m512, p: [__m512; 3]) -> [__m512; 3] {
        let f = _mm512_div_ps(_mm512_set1_ps(1.0), contrib);
        core::array::from_fn(|r| {
            let row = _mm512_add_ps(
                _mm512_add_ps(_mm512_mul_ps(m[4 * r], p[0]), _mm512_mul_ps(m[4 * r + 2], p[2])),
                _mm512_add_ps(_mm512_mul_ps(m[4 * r + 1], p[1]), m[4 * r + 3]),
            );
            _mm512_fmadd_ps(_mm512_fnmadd_ps(p[r], contrib, row), f, p[r])
        })
    }

    const fn split_index(axis: usize) -> ([i32; 16], [i32; 16]) {
        let (mut first, mut second, mut l) = ([0; 16], [0; 16], 0);
        while l < 16 {
            let f = 3 * l + axis;
            first[l] = if f < 32 { f as i32 } else { 0 };
            second[l] = if f < 32 { l as i32 } else { (f - 16) as i32 };
            l += 1;
        }
        (first, second)
    }

    const fn join_index(part: usize) -> ([i32; 16], [i32; 16]) {
        let (mut first, mut second, mut e) = ([0; 16], [0; 16], 0);
        while e < 16 {
            let g = 16 * part + e;
            let (lane, axis) = ((g / 3) as i32, g % 3);
            first[e] = if axis == 0 { lane } else { 16 + lane };
            second[e] = if axis == 2 { 16 + lane } else { e as i32 };
            e += 1;
        }
        (first, second)
    }

    const SPLIT: [([i32; 16], [i32; 16]); 3] = [split_index(0), split_index(1), split_index(2)];
    const JOIN: [([i32; 16], [i32; 16]); 3] = [join_index(0), join_index(1), join_index(2)];

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn index(i: &[i32; 16]) -> __m512i {
        // SAFETY: sixteen i32 are 64 readable bytes.
        unsafe { _mm512_loadu_si512(i.as_ptr().cast()) }
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn load_points(p: &[[f32; 3]; LANES]) -> [__m512; 3] {
        let f = p.as_flattened();
        // SAFETY: 48 floats, read 16 at a time.
        let (a, b, c) = unsafe {
            (_mm512_loadu_ps(f.as_ptr()), _mm512_loadu_ps(f[16..].as_ptr()), _mm512_loadu_ps(f[32..].as_ptr()))
        };
        core::array::from_fn(|k| {
            let ab = _mm512_permutex2var_ps(a, index(&SPLIT[k].0), b);
            _mm512_permutex2var_ps(ab, index(&SPLIT[k].1), c)
        })
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn store_points(o: [__m512; 3], out: &mut [[f32; 3]; LANES]) {
        let f = out.as_flattened_mut();
        for (part, chunk) in f.chunks_exact_mut(16).enumerate() {
            let xy = _mm512_permutex2var_ps(o[0], index(&JOIN[part].0), o[1]);
            // SAFETY: sixteen writable floats.
            unsafe { _mm512_storeu_ps(chunk.as_mut_ptr(), _mm512_permutex2var_ps(xy, index(&JOIN[part].1), o[2])) };
        }
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn record(records: &[Record], bone: u8) -> __m512 {
        let r = &records[usize::from(bone)];
        // SAFETY: a record is 16 aligned floats.
        unsafe { _mm512_load_ps(r.0.as_ptr()) }
    }

    #[inline]
    #[target_feature(enable = "avx512f")]
    fn weights(w: &[f32; LANES]) -> __m512 {
        // SAFETY: sixteen floats.
        unsafe { _mm512_loadu_ps(w.as_ptr()) }
    }

    /// Prefetches the inputs of batch `b + 8` (as the shipped kernels do, `prefetch_ahead`):
    /// without it either design waits on memory.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn prefetch_ahead(m: &Mesh, b: usize) {
        let ahead = (b + 8).min(m.palettes.len() - 1);
        let lines = |start: *const u8, bytes: usize| {
            for offset in (0..bytes).step_by(64) {
                _mm_prefetch::<_MM_HINT_T0>(start.wrapping_add(offset).cast());
            }
        };
        lines((&m.palettes[ahead] as *const Palette).cast(), size_of::<Palette>());
        lines(m.slots[ahead * SLOTS..].as_ptr().cast(), SLOTS * size_of::<Slot>());
        lines(m.points[ahead * LANES..].as_ptr().cast(), LANES * 12);
    }

    #[target_feature(enable = "avx512f,avx2,fma")]
    fn per_lane(m: &Mesh, out: &mut [[f32; 3]]) {
        for (b, ((slots, p), o)) in m
            .slots
            .chunks_exact(SLOTS)
            .zip(m.points.as_chunks::<LANES>().0)
            .zip(out.as_chunks_mut::<LANES>().0)
            .enumerate()
        {
            prefetch_ahead(m, b);
            let mut lanes = [_mm512_setzero_ps(); LANES];
            let mut contrib = _mm512_setzero_ps();
            for s in slots {
                for (l, lane) in lanes.iter_mut().enumerate() {
                    *lane = _mm512_fmadd_ps(record(&m.records, s.bones[l]), _mm512_set1_ps(s.weights[l]), *lane);
                }
                contrib = _mm512_add_ps(contrib, weights(&s.weights));
            }
            // Lane vectors to component vectors: the 4×4 transposes in each group of four lanes,
            // then component c of block g from group g.
            let u: [[__m512; 4]; 4] = core::array::from_fn(|g| {
                transpose_blocks([lanes[4 * g], lanes[4 * g + 1], lanes[4 * g + 2], lanes[4 * g + 3]])
            });
            let sums = components(&u);
            store_points(finish(&sums, contrib, load_points(p)), o);
        }
    }

    #[target_feature(enable = "avx512f,avx2,fma")]
    fn palette(m: &Mesh, out: &mut [[f32; 3]]) {
        for (b, ((pal, p), o)) in
            m.palettes.iter().zip(m.points.as_chunks::<LANES>().0).zip(out.as_chunks_mut::<LANES>().0).enumerate()
        {
            prefetch_ahead(m, b);
            let zero = [_mm512_setzero_ps(); 4];
            let mut u = [zero; 4];
            for (g, group) in u.iter_mut().enumerate().take(pal.groups) {
                *group = transpose_blocks(core::array::from_fn(|k| record(&m.records, pal.bones[4 * g + k])));
            }
            // Component e of every palette record: two groups in blocks 0 and 2, else in 0-3.
            let table: [__m512; 12] = if pal.groups <= 2 {
                core::array::from_fn(|e| match e / 4 {
                    0 => _mm512_shuffle_f32x4::<0x00>(u[0][e % 4], u[1][e % 4]),
                    1 => _mm512_shuffle_f32x4::<0x55>(u[0][e % 4], u[1][e % 4]),
                    _ => _mm512_shuffle_f32x4::<0xAA>(u[0][e % 4], u[1][e % 4]),
                })
            } else {
                components(&u)
            };
            let mut sums = [_mm512_setzero_ps(); 12];
            let mut contrib = _mm512_setzero_ps();
            for (k, s) in m.slots[b * SLOTS..(b + 1) * SLOTS].iter().enumerate() {
                // SAFETY: sixteen bytes.
                let at = _mm512_cvtepu8_epi32(unsafe { _mm_loadu_si128(pal.at[k].as_ptr().cast()) });
                let w = weights(&s.weights);
                for (sum, t) in sums.iter_mut().zip(&table) {
                    *sum = _mm512_fmadd_ps(_mm512_permutexvar_ps(at, *t), w, *sum);
                }
                contrib = _mm512_add_ps(contrib, w);
            }
            store_points(finish(&sums, contrib, load_points(p)), o);
        }
    }

    /// Four floats from `offset` of the 16 records `bones` names, transposed: vector `c` holds
    /// float `offset + c` of each (as the shipped AVX-512 copy loads them, `avx512.rs` `columns4`).
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn columns4(dq: &[DqRecord], bones: &[u8; LANES], offset: usize) -> [__m512; 4] {
        let at = |l: usize| {
            let r = &dq[usize::from(bones[l])].0[offset..offset + 4];
            // SAFETY: four floats.
            unsafe { _mm_loadu_ps(r.as_ptr()) }
        };
        transpose_blocks(core::array::from_fn(|k| {
            let v = _mm512_castps128_ps512(at(k));
            let v = _mm512_insertf32x4::<1>(v, at(k + 4));
            let v = _mm512_insertf32x4::<2>(v, at(k + 8));
            _mm512_insertf32x4::<3>(v, at(k + 12))
        }))
    }

    /// The sign chain's step for one slot, shared: `±w` against the running sum, then the sums.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn add_dq(first: bool, q: [__m512; 4], d: [__m512; 4], w: __m512, real: &mut [__m512; 4], dual: &mut [__m512; 4]) {
        let ws = if first {
            w
        } else {
            let dot = _mm512_add_ps(
                _mm512_fmadd_ps(q[1], real[1], _mm512_mul_ps(q[0], real[0])),
                _mm512_fmadd_ps(q[3], real[3], _mm512_mul_ps(q[2], real[2])),
            );
            let negative = _mm512_cmp_ps_mask::<_CMP_LT_OQ>(dot, _mm512_setzero_ps());
            let bits = _mm512_castps_si512(w);
            _mm512_castsi512_ps(_mm512_mask_xor_epi32(bits, negative, bits, _mm512_set1_epi32(i32::MIN)))
        };
        for c in 0..4 {
            real[c] = _mm512_fmadd_ps(q[c], ws, real[c]);
            dual[c] = _mm512_fmadd_ps(d[c], ws, dual[c]);
        }
    }

    /// The dual quaternion sums applied to the points, shared (the library's `dual_quaternion`,
    /// full strength): `p + u·(2/|q|²)`.
    #[inline]
    #[target_feature(enable = "avx512f")]
    fn finish_dq(real: [__m512; 4], dual: [__m512; 4], contrib: __m512, p: [__m512; 3]) -> [__m512; 3] {
        let [x, y, z, w] = real;
        let [tx, ty, tz, t0] = dual;
        let b = [
            _mm512_fnmadd_ps(z, p[1], _mm512_fmadd_ps(y, p[2], tx)),
            _mm512_fnmadd_ps(x, p[2], _mm512_fmadd_ps(z, p[0], ty)),
            _mm512_fnmadd_ps(y, p[0], _mm512_fmadd_ps(x, p[1], tz)),
        ];
        let t = [
            _mm512_fnmadd_ps(z, b[1], _mm512_fmadd_ps(y, b[2], _mm512_mul_ps(w, b[0]))),
            _mm512_fnmadd_ps(x, b[2], _mm512_fmadd_ps(z, b[0], _mm512_mul_ps(w, b[1]))),
            _mm512_fnmadd_ps(y, b[0], _mm512_fmadd_ps(x, b[1], _mm512_mul_ps(w, b[2]))),
        ];
        let u = [_mm512_fnmadd_ps(t0, x, t[0]), _mm512_fnmadd_ps(t0, y, t[1]), _mm512_fnmadd_ps(t0, z, t[2])];
        let len2 = _mm512_fmadd_ps(z, z, _mm512_fmadd_ps(y, y, _mm512_fmadd_ps(x, x, _mm512_mul_ps(w, w))));
        let valid = _mm512_cmp_ps_mask::<_CMP_GT_OQ>(contrib, _mm512_set1_ps(1e-4))
            & _mm512_cmp_ps_mask::<_CMP_GT_OQ>(len2, _mm512_setzero_ps());
        let g = _mm512_maskz_div_ps(valid, _mm512_set1_ps(2.0), len2);
        core::array::from_fn(|k| _mm512_fmadd_ps(u[k], g, p[k]))
    }

    #[target_feature(enable = "avx512f,avx2,fma")]
    fn per_lane_dq(m: &Mesh, out: &mut [[f32; 3]]) {
        let batches =
            m.slots.chunks_exact(SLOTS).zip(m.points.as_chunks::<LANES>().0).zip(out.as_chunks_mut::<LANES>().0);
        for (b, ((slots, p), o)) in batches.enumerate() {
            prefetch_ahead(m, b);
            let zero = [_mm512_setzero_ps(); 4];
            let (mut real, mut dual, mut contrib) = (zero, zero, _mm512_setzero_ps());
            for (k, s) in slots.iter().enumerate() {
                let (q, d) = (columns4(&m.dq, &s.bones, 0), columns4(&m.dq, &s.bones, 4));
                let w = weights(&s.weights);
                add_dq(k == 0, q, d, w, &mut real, &mut dual);
                contrib = _mm512_add_ps(contrib, w);
            }
            store_points(finish_dq(real, dual, contrib, load_points(p)), o);
        }
    }

    #[target_feature(enable = "avx512f,avx2,fma")]
    fn palette_dq(m: &Mesh, out: &mut [[f32; 3]]) {
        let batches = m.palettes.iter().zip(m.points.as_chunks::<LANES>().0).zip(out.as_chunks_mut::<LANES>().0);
        for (b, ((pal, p), o)) in batches.enumerate() {
            prefetch_ahead(m, b);
            // The palette's rotations and dual parts as 16-entry tables, once a batch.
            let (tq, td) = (columns4(&m.dq, &pal.bones, 0), columns4(&m.dq, &pal.bones, 4));
            let zero = [_mm512_setzero_ps(); 4];
            let (mut real, mut dual, mut contrib) = (zero, zero, _mm512_setzero_ps());
            for (k, s) in m.slots[b * SLOTS..(b + 1) * SLOTS].iter().enumerate() {
                // SAFETY: sixteen bytes.
                let at = _mm512_cvtepu8_epi32(unsafe { _mm_loadu_si128(pal.index[k].as_ptr().cast()) });
                let pick =
                    |t: &[__m512; 4]| -> [__m512; 4] { core::array::from_fn(|c| _mm512_permutexvar_ps(at, t[c])) };
                let w = weights(&s.weights);
                add_dq(k == 0, pick(&tq), pick(&td), w, &mut real, &mut dual);
                contrib = _mm512_add_ps(contrib, w);
            }
            store_points(finish_dq(real, dual, contrib, load_points(p)), o);
        }
    }

    /// One design's kernel over a whole mesh (needs AVX-512F, AVX2 and FMA).
    type Design = unsafe fn(&Mesh, &mut [[f32; 3]]);

    /// Which sums the two designs compute.
    #[derive(Clone, Copy, PartialEq, Debug)]
    enum Method {
        Linear,
        DualQuaternion,
    }

    /// Both designs of `method` over `m`: whether they give the same bits, and each one's best
    /// time.
    fn compare(m: &Mesh, method: Method, rounds: usize) -> (bool, f64, f64) {
        let vertices = m.points.len();
        let (mut a, mut b) = (vec![[0f32; 3]; vertices], vec![[0f32; 3]; vertices]);
        let (lane_design, palette_design): (Design, Design) = match method {
            Method::Linear => (per_lane, palette),
            Method::DualQuaternion => (per_lane_dq, palette_dq),
        };
        let time = |f: Design, out: &mut [[f32; 3]]| {
            let start = Instant::now();
            // SAFETY: the callers checked that the CPU has AVX-512F, AVX2 and FMA.
            unsafe { f(m, out) };
            start.elapsed().as_secs_f64()
        };
        let (mut lane, mut palette_time) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..=rounds {
            lane = lane.min(time(lane_design, &mut a));
            palette_time = palette_time.min(time(palette_design, &mut b));
        }
        let same = a.iter().zip(&b).all(|(x, y)| x.map(f32::to_bits) == y.map(f32::to_bits));
        (same, lane, palette_time)
    }

    fn avx512() -> bool {
        is_x86_feature_detected!("avx512f") && is_x86_feature_detected!("avx2") && is_x86_feature_detected!("fma")
    }

    #[test]
    fn both_designs_give_the_same_bits() {
        if !avx512() {
            return; // (nothing to compare on this CPU)
        }
        for spread in [0, 8, 16] {
            let m = mesh(4096, spread);
            for method in [Method::Linear, Method::DualQuaternion] {
                assert!(compare(&m, method, 0).0, "spread {spread}, {method:?}");
            }
        }
        // The wide mesh reaches the palettes of three and four groups of records.
        assert!(mesh(4096, 16).palettes.iter().any(|p| p.groups > 2));
    }

    fn arg(name: &str) -> Option<String> {
        let args: Vec<String> = std::env::args().collect();
        args.iter().position(|a| a == name).and_then(|i| args.get(i + 1).cloned())
    }

    pub fn main() -> Result<(), String> {
        if !avx512() {
            return Err("this experiment needs AVX-512F".into());
        }
        let number = |name: &str, default: usize| -> Result<usize, String> {
            arg(name).map_or(Ok(default), |v| v.parse().map_err(|_| format!("{name} takes a whole number, not {v:?}")))
        };
        let vertices = number("--vertices", 1_000_000)? / LANES * LANES;
        let rounds = number("--rounds", 5)?.max(1);
        let (name, spread) = match arg("--mesh").as_deref() {
            None | Some("bench") => ("bench", 0),
            Some("mixed") => ("mixed", 8),
            Some("wide") => ("wide", 16),
            Some(other) => return Err(format!("--mesh is bench, mixed or wide, not {other:?}")),
        };
        let method = match arg("--method").as_deref() {
            None | Some("linear") => Method::Linear,
            Some("dq") => Method::DualQuaternion,
            Some(other) => return Err(format!("--method is linear or dq, not {other:?}")),
        };
        if vertices == 0 {
            return Err("--vertices must be at least 16".into());
        }
        let m = mesh(vertices, spread);
        let (same, best_lane, best_palette) = compare(&m, method, rounds);
        let rate = |s: f64| vertices as f64 / s / 1e6;
        println!("{method:?}, mesh {name}: {vertices} vertices, {:.2} distinct bones a batch", m.distinct);
        println!(
            "per lane {:.3} ms ({:.0} Mverts/s), palette {:.3} ms ({:.0} Mverts/s), the same bits: {same}",
            best_lane * 1e3,
            rate(best_lane),
            best_palette * 1e3,
            rate(best_palette)
        );
        if same {
            Ok(())
        } else {
            Err("the two designs' results differ".into())
        }
    }
}

fn main() -> std::process::ExitCode {
    #[cfg(target_arch = "x86_64")]
    let result = x86::main();
    #[cfg(not(target_arch = "x86_64"))]
    let result: Result<(), String> = Err("this experiment is written for x86-64 with AVX-512".into());
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("palette: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}
