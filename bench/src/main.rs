//! Throughput of the skinning kernels in million vertices per second, beside a memory-bandwidth
//! reference measured in the same run: a pass that reads exactly the bytes a kernel reads
//! (positions, the lane-ordered influences and, for the centers of rotation, the centers) and
//! writes exactly the bytes it writes (positions out), doing nothing else.
//!
//! Sizes: 100k and 1M vertices (4 and 8 influences), and [`BEYOND_CACHES`] (4 influences): 1M
//! vertices are 56 MB, which some CPUs' last-level cache holds (then the reference measures the
//! cache, not memory); 16M are 0.9 GB, which none does.
//!
//! Also times the precompute of the centers of rotation on the procedural creature
//! (`rigs::Creature`, 40 bones, 4 smooth influences per vertex) at about 50k and 250k vertices.
//!
//! Usage: `dqskin-bench [--quick] [--json FILE] [--only LBS-rigid|DQS-rigid|DQS-scaled|Blend-rigid|CoR-rigid|CoR-scaled|precompute]
//! [--vertices N] [--influences K] [--threads T] [--rounds R]`. The last four narrow the grid to one
//! size, influence count or thread count and set the number of timed rounds (for profiling: under
//! `valgrind --tool=callgrind`, `--rounds 1` skins each case twice, the warm-up and one round);
//! with any of them the precompute runs only if `--only precompute` asks for it. `--copies` runs
//! each kernel on every compiled copy with fused multiply-adds the CPU has, the copies alternated
//! round by round in this one process (rows name the copy): processes on a shared machine can
//! differ from each other by 2x, so copies are compared within one.

use std::hint::black_box;
use std::time::Instant;

use dqskin_core::glam::{Mat4, Quat, Vec3};
use dqskin_core::rigs::Creature;
use dqskin_core::{
    centers_of_rotation, kernel_copies, pool, set_kernel_copy, skin, Influences, Method, Pose, SkinOptions,
};
use rayon::prelude::*;

mod rng;
use rng::Rng;

const BONES: usize = 64;
/// A mesh larger than any CPU's caches, so that kernels and reference stream from memory.
const BEYOND_CACHES: usize = 16_000_000;

struct Scene {
    positions: Vec<[f32; 3]>,
    /// Stand-in centers of rotation (their values do not change the kernel's work).
    centers: Vec<[f32; 3]>,
    influences: Influences,
    rigid: Pose,
    scaled: Pose,
}

fn scene(vertices: usize, per_vertex: usize) -> Scene {
    let mut rng = Rng(0x9E37_79B9_7F4A_7C15 ^ (vertices as u64 * 31 + per_vertex as u64));
    let positions: Vec<[f32; 3]> =
        (0..vertices).map(|_| [rng.range(-1.0, 1.0), rng.range(0.0, 2.0), rng.range(-1.0, 1.0)]).collect();
    let mut offsets = Vec::with_capacity(vertices + 1);
    let mut bones = Vec::with_capacity(vertices * per_vertex);
    let mut weights = Vec::with_capacity(vertices * per_vertex);
    offsets.push(0u32);
    for v in 0..vertices {
        // Neighbouring bones, as on a real mesh, with weights that sum to one.
        let base = (v * BONES / vertices) as u32;
        let raw: Vec<f32> = (0..per_vertex).map(|_| rng.range(0.05, 1.0)).collect();
        let sum: f32 = raw.iter().sum();
        for (k, w) in raw.iter().enumerate() {
            bones.push((base + k as u32 * 3) % BONES as u32);
            weights.push(w / sum);
        }
        offsets.push(bones.len() as u32);
    }
    let influences = Influences::from_csr(&offsets, &bones, &weights, BONES).expect("valid CSR");
    let rest: Vec<Mat4> =
        (0..BONES).map(|b| Mat4::from_translation(Vec3::new(0.0, 2.0 * b as f32 / BONES as f32, 0.0))).collect();
    let pose_with = |scale: bool, rng: &mut Rng| -> Pose {
        let deform: Vec<Mat4> = rest
            .iter()
            .map(|r| {
                let q = Quat::from_euler(
                    dqskin_core::glam::EulerRot::XYZ,
                    rng.range(-2.0, 2.0),
                    rng.range(-2.0, 2.0),
                    rng.range(-2.0, 2.0),
                );
                let s = if scale { Vec3::new(1.0, rng.range(0.5, 1.5), 1.0) } else { Vec3::ONE };
                let t = Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), rng.range(-0.5, 0.5));
                Mat4::from_scale_rotation_translation(s, q, t) * r.inverse()
            })
            .collect();
        Pose::new(&deform, Some(&rest)).expect("valid pose")
    };
    let rigid = pose_with(false, &mut rng);
    let scaled = pose_with(true, &mut rng);
    let centers = positions.iter().map(|p| [0.9 * p[0], p[1], 0.9 * p[2]]).collect();
    Scene { positions, centers, influences, rigid, scaled }
}

/// Seconds one call of `f` takes.
fn once(f: &mut dyn FnMut()) -> f64 {
    let s = Instant::now();
    f();
    s.elapsed().as_secs_f64()
}

/// Reads the positions and the influences' lane-ordered slots (and the centers, for the kernels
/// that read them) and writes the output, as a kernel does, with no math: the same bytes in, the
/// same bytes out.
fn bandwidth_reference(s: &Scene, out: &mut [[f32; 3]], with_centers: bool) {
    const CHUNK: usize = 4096;
    const LANES: usize = 16;
    let (starts, words, words_per_slot) = s.influences.kernel_words();
    let sink = pool::run(|| {
        out.par_chunks_mut(CHUNK)
            .enumerate()
            .map(|(c, dst)| {
                let start = c * CHUNK;
                let end = start + dst.len();
                dst.copy_from_slice(&s.positions[start..end]);
                let (b0, b1) = (start / LANES, end.div_ceil(LANES));
                let slots = &words[starts[b0] as usize * words_per_slot..starts[b1] as usize * words_per_slot];
                let centers: &[[f32; 3]] = if with_centers { &s.centers[start..end] } else { &[] };
                // Two plain folds (one over a chain of both would not vectorize).
                let centers = centers.as_flattened().iter().fold(0u32, |x, w| x ^ w.to_bits());
                starts[b0..=b1].iter().chain(slots).fold(centers, |x, w| x ^ w)
            })
            .reduce(|| 0, |a, b| a ^ b)
    });
    black_box(sink);
}

struct Row {
    vertices: usize,
    per_vertex: usize,
    threads: usize,
    method: &'static str,
    pose: &'static str,
    /// The copy that ran: named with `--copies`, else `DQSKIN_SIMD`'s, else "chosen".
    copy: &'static str,
    seconds: f64,
    reference_seconds: f64,
    bytes: usize,
}

/// The narrowings `--only` takes: a kernel case (method and pose) or the precompute.
const ONLY: [&str; 7] =
    ["LBS-rigid", "DQS-rigid", "DQS-scaled", "Blend-rigid", "CoR-rigid", "CoR-scaled", "precompute"];
/// The options that take a value, and the flags that take none.
const VALUED: [&str; 6] = ["--json", "--only", "--vertices", "--influences", "--threads", "--rounds"];
const FLAGS: [&str; 2] = ["--quick", "--copies"];

fn usage() -> String {
    format!(
        "usage: dqskin-bench [--quick] [--copies] [--json FILE] [--only {}] [--vertices N] [--influences K] [--threads T] [--rounds R]",
        ONLY.join("|")
    )
}

/// Checks the command line before anything runs (a misspelt option would otherwise time the
/// whole grid, minutes of a shared machine): `Err` names the first problem.
fn check_args(args: &[String]) -> Result<(), String> {
    let mut i = 1;
    while i < args.len() {
        let a = args[i].as_str();
        if FLAGS.contains(&a) {
            i += 1;
            continue;
        }
        if !VALUED.contains(&a) {
            return Err(format!("unknown argument {a:?}"));
        }
        let Some(v) = args.get(i + 1) else { return Err(format!("{a} needs a value")) };
        match a {
            "--only" if !ONLY.contains(&v.as_str()) => {
                return Err(format!("--only takes one of {}, got {v:?}", ONLY.join(", ")));
            }
            "--vertices" | "--influences" | "--threads" | "--rounds" if v.parse::<usize>().map_or(true, |n| n == 0) => {
                return Err(format!("{a} needs a positive whole number, got {v:?}"));
            }
            _ => {}
        }
        i += 2;
    }
    Ok(())
}

fn main() {
    let args: Vec<String> = std::env::args().collect();
    if args.iter().any(|a| a == "--help" || a == "-h") {
        println!("{}", usage());
        return;
    }
    if let Err(problem) = check_args(&args) {
        eprintln!("dqskin-bench: {problem}\n{}", usage());
        std::process::exit(2);
    }
    let quick = args.iter().any(|a| a == "--quick");
    let json = args.iter().position(|a| a == "--json").and_then(|i| args.get(i + 1).cloned());
    let value = |name: &str| args.iter().position(|a| a == name).and_then(|i| args.get(i + 1).cloned());
    // Checked above: every number given parses.
    let number = |name: &str| value(name).and_then(|v| v.parse::<usize>().ok());
    let only = value("--only");
    let all = std::thread::available_parallelism().map_or(1, |n| n.get());
    let sizes: Vec<usize> = match number("--vertices") {
        Some(n) => vec![n],
        None if quick => vec![100_000],
        None => vec![100_000, 1_000_000, BEYOND_CACHES],
    };
    let influence_counts: Vec<usize> = number("--influences").map_or(vec![4, 8], |k| vec![k]);
    let influences_given = number("--influences").is_some();
    let thread_counts: Vec<usize> = number("--threads").map_or(vec![1, all], |t| vec![t]);
    let rounds = number("--rounds");
    // The copies each case runs on: with --copies every one with fused multiply-adds here, each
    // named to set_kernel_copy in turn; else the one the process runs ("chosen", or DQSKIN_SIMD's).
    let copies_asked = args.iter().any(|a| a == "--copies");
    let fused: Vec<&'static str> = if copies_asked {
        let named = ["avx2-noprefetch", "avx2", "avx512-noprefetch", "avx512", "neon"];
        let here = named.into_iter().filter(|c| set_kernel_copy(Some(c)).is_ok()).collect();
        set_kernel_copy(None).expect("back to the measured copies");
        here
    } else {
        Vec::new()
    };
    let compare_copies = !fused.is_empty();
    let copies: Vec<&'static str> = if compare_copies {
        fused
    } else {
        if copies_asked {
            println!("--copies: no copy with fused multiply-adds here, only the baseline runs");
        }
        vec![std::env::var("DQSKIN_SIMD").ok().map_or("chosen", |c| &*c.leak())]
    };
    let mut rows = Vec::new();
    // DQSKIN_SIMD=avx2 measures the AVX2 copy on a CPU that has AVX-512 (make bench runs both);
    // without it each kernel runs the copy its first calls measured fastest (printed at the end).
    println!(
        "{:>9} {:>3} {:>3} {:<6} {:<6} {:>9} {:>10} {:>8} {:>10} {:>7} copy",
        "vertices", "inf", "thr", "method", "pose", "ms", "Mverts/s", "GB/s", "ref Mv/s", "of ref"
    );
    for &vertices in &sizes {
        for &per_vertex in &influence_counts {
            if vertices == BEYOND_CACHES && per_vertex != 4 && !influences_given {
                continue; // 8 influences there would need 2.5 GB
            }
            let s = scene(vertices, per_vertex);
            let mut out = vec![[0.0f32; 3]; vertices];
            let bytes = vertices * 12 * 2 + s.influences.byte_size();
            for &threads in &thread_counts {
                pool::set_num_threads(threads).expect("threads");
                let runs = rounds.unwrap_or(if quick || vertices >= BEYOND_CACHES {
                    5
                } else if vertices >= 1_000_000 {
                    25
                } else {
                    60
                });
                let cases: Vec<(&str, Method, &str, &Pose, &str)> = [
                    ("LBS", Method::Linear, "rigid", &s.rigid),
                    ("DQS", Method::DualQuaternion, "rigid", &s.rigid),
                    ("DQS", Method::DualQuaternion, "scaled", &s.scaled),
                    ("Blend", Method::Blend { amount: None, factor: 0.5 }, "rigid", &s.rigid),
                    ("CoR", Method::CentersOfRotation { centers: &s.centers }, "rigid", &s.rigid),
                    ("CoR", Method::CentersOfRotation { centers: &s.centers }, "scaled", &s.scaled),
                ]
                .into_iter()
                .filter(|(name, _, pose_name, _)| only.as_ref().is_none_or(|o| *o == format!("{name}-{pose_name}")))
                .flat_map(|(name, method, pose_name, pose)| {
                    copies.iter().map(move |&c| (name, method, pose_name, pose, c))
                })
                .collect();
                // Rounds alternate the reference and the kernels so that both see the same
                // conditions on a shared machine; each keeps its best time (after a warm-up round).
                // [without, with] the centers.
                let mut reference = [f64::INFINITY; 2];
                let mut best = vec![f64::INFINITY; cases.len()];
                let space = glam::Mat4::from_rotation_translation(
                    glam::Quat::from_rotation_z(0.3),
                    glam::Vec3::new(0.5, -1.0, 2.0),
                );
                for round in 0..=runs {
                    let r = [false, true].map(|c| once(&mut || bandwidth_reference(&s, &mut out, c)));
                    for (k, (_, method, _, pose, copy)) in cases.iter().enumerate() {
                        if compare_copies {
                            set_kernel_copy(Some(copy)).expect("a copy this CPU has");
                        }
                        // The object and armature spaces every Blender job has (the modifier's
                        // premat and postmat): the Python module once ran them 3x slower than this
                        // binary did without them (intrinsics left uninlined).
                        let opts = SkinOptions { premat: Some(space), postmat: Some(space.inverse()), mask: None };
                        let t = once(&mut || {
                            skin(*method, &s.positions, &s.influences, pose, &opts, &mut out).expect("skin")
                        });
                        if round > 0 {
                            best[k] = best[k].min(t);
                        }
                    }
                    if round > 0 {
                        reference = [reference[0].min(r[0]), reference[1].min(r[1])];
                    }
                }
                if compare_copies {
                    set_kernel_copy(None).expect("back to the measured copies");
                }
                for ((name, method, pose_name, _, copy), secs) in cases.iter().zip(best) {
                    let centers = matches!(method, Method::CentersOfRotation { .. });
                    let reference = reference[centers as usize];
                    let bytes = bytes + if centers { vertices * 12 } else { 0 };
                    println!(
                        "{:>9} {:>3} {:>3} {:<6} {:<6} {:>9.3} {:>10.1} {:>8.2} {:>10.1} {:>6.0}% {}",
                        vertices,
                        per_vertex,
                        threads,
                        name,
                        pose_name,
                        secs * 1e3,
                        vertices as f64 / secs / 1e6,
                        bytes as f64 / secs / 1e9,
                        vertices as f64 / reference / 1e6,
                        100.0 * reference / secs,
                        copy
                    );
                    rows.push(Row {
                        vertices,
                        per_vertex,
                        threads,
                        method: name,
                        pose: pose_name,
                        copy,
                        seconds: secs,
                        reference_seconds: reference,
                        bytes,
                    });
                }
            }
        }
    }
    // Which copy each variant's trial chose, per size of job (none where no call of it ran).
    let chosen: Vec<String> = kernel_copies()
        .into_iter()
        .filter_map(|(variant, size, copy)| copy.map(|c| format!("\"{variant}/{size}\":\"{c}\"")))
        .collect();
    println!("kernel copies: {{{}}}", chosen.join(", "));
    let narrowed = ["--vertices", "--influences", "--threads", "--rounds"].iter().any(|f| value(f).is_some());
    let precompute = match only.as_deref() {
        Some("precompute") => precompute_rows(quick, all),
        None if !narrowed => precompute_rows(quick, all),
        _ => Vec::new(),
    };
    if let Some(path) = json {
        let body: Vec<String> = rows
            .iter()
            .map(|r| {
                format!(
                    "{{\"vertices\":{},\"influences\":{},\"threads\":{},\"method\":\"{}\",\"pose\":\"{}\",\"copy\":\"{}\",\"seconds\":{:.6e},\"mverts_per_s\":{:.2},\"reference_seconds\":{:.6e},\"fraction_of_reference\":{:.4},\"bytes\":{}}}",
                    r.vertices,
                    r.per_vertex,
                    r.threads,
                    r.method,
                    r.pose,
                    r.copy,
                    r.seconds,
                    r.vertices as f64 / r.seconds / 1e6,
                    r.reference_seconds,
                    r.reference_seconds / r.seconds,
                    r.bytes
                )
            })
            .collect();
        let pre: Vec<String> = precompute
            .iter()
            .map(|p| {
                format!(
                    "{{\"vertices\":{},\"triangles\":{},\"bones\":{},\"unique_weight_vectors\":{},\"with_center\":{},\"threads\":{},\"seconds\":{:.6e}}}",
                    p.vertices, p.triangles, p.bones, p.unique, p.with_center, p.threads, p.seconds
                )
            })
            .collect();
        let text = format!(
            "{{\"copy\":\"{}\",\"chosen\":{{{}}},\"bones\":{BONES},\"threads_available\":{all},\"rows\":[\n{}\n],\"centers_precompute\":[\n{}\n]}}\n",
            copies.join("+"),
            chosen.join(","),
            body.join(",\n"),
            pre.join(",\n")
        );
        std::fs::write(&path, text).unwrap_or_else(|e| panic!("cannot write {path}: {e}"));
        println!("wrote {path}");
    }
}

struct PrecomputeRow {
    vertices: usize,
    triangles: usize,
    bones: usize,
    unique: usize,
    with_center: usize,
    threads: usize,
    seconds: f64,
}

/// Times `centers_of_rotation` (σ = 0.1) on the creature at about 50k and 250k vertices, on one
/// thread and on all (best of a few runs).
fn precompute_rows(quick: bool, all: usize) -> Vec<PrecomputeRow> {
    let sizes: &[usize] = if quick { &[50_000] } else { &[50_000, 250_000] };
    let mut rows = Vec::new();
    println!();
    println!(
        "{:>9} {:>9} {:>5} {:>8} {:>8} {:>3} {:>9}",
        "vertices", "triangles", "bones", "unique", "centers", "thr", "precompute s"
    );
    for &target in sizes {
        let c = Creature::new(target).expect("creature");
        let unique: std::collections::HashSet<Vec<u32>> = (0..c.positions.len())
            .map(|v| c.influences.of_vertex(v).flat_map(|i| [i.bone, i.weight.to_bits()]).collect())
            .collect();
        for threads in [1, all] {
            pool::set_num_threads(threads).expect("threads");
            let runs = if quick || target > 100_000 { 1 } else { 3 };
            let mut best = f64::INFINITY;
            let mut with_center = 0;
            for _ in 0..runs {
                let start = Instant::now();
                let centers = centers_of_rotation(&c.positions, &c.triangles, &c.influences, 0.1).expect("centers");
                best = best.min(start.elapsed().as_secs_f64());
                with_center = centers.has_center.iter().filter(|&&h| h).count();
                black_box(centers);
            }
            println!(
                "{:>9} {:>9} {:>5} {:>8} {:>8} {:>3} {:>9.3}",
                c.positions.len(),
                c.triangles.len(),
                c.rest.len(),
                unique.len(),
                with_center,
                threads,
                best
            );
            rows.push(PrecomputeRow {
                vertices: c.positions.len(),
                triangles: c.triangles.len(),
                bones: c.rest.len(),
                unique: unique.len(),
                with_center,
                threads,
                seconds: best,
            });
        }
    }
    rows
}

#[cfg(test)]
mod tests {
    use super::check_args;

    fn check(line: &str) -> Result<(), String> {
        let args: Vec<String> =
            std::iter::once("dqskin-bench").chain(line.split_whitespace()).map(String::from).collect();
        check_args(&args)
    }

    #[test]
    fn the_documented_options_pass() {
        assert_eq!(check(""), Ok(()));
        assert_eq!(
            check("--quick --json out.json --only CoR-scaled --vertices 1000 --influences 4 --threads 2 --rounds 3"),
            Ok(())
        );
        assert_eq!(check("--only precompute"), Ok(()));
    }

    #[test]
    fn a_bad_option_is_named_before_anything_runs() {
        assert_eq!(check("--verbose"), Err("unknown argument \"--verbose\"".into()));
        assert_eq!(check("--json"), Err("--json needs a value".into()));
        assert!(check("--only LBS").unwrap_err().contains("--only takes one of LBS-rigid"));
        assert!(check("--threads 0").unwrap_err().contains("positive whole number"));
        assert!(check("--vertices 1e6").unwrap_err().contains("got \"1e6\""));
    }
}
