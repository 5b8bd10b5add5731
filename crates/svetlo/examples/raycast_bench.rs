//! Ray casting throughput of svetlo's accelerator on a generated 1M-triangle mesh.
//! Writes the mesh, the rays and svetlo's hits to `--out` (bench/out by default) so
//! that bench/raycast/embree_compare.py can run Embree on exactly the same input.
//!
//! cargo run --release --example raycast_bench -- [--out DIR] [--repeat N] [--threads 1,2] [--subdiv N] [--no-write] [--sets coherent,incoherent,segments] [--lanes] [--serve]
//!
//! Prints one JSON object per line: the build, then one per (ray set, query, threads).
//! With `--serve`, prints `ready` after the build and then answers lines
//! `SET closest|occluded THREADS` on stdin with one cast each, until stdin closes:
//! embree_compare.py uses it to alternate svetlo and Embree runs in time, so that
//! both see the same load on a shared machine.

use std::io::Write;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;
use svetlo::accel::{Accel, RAY_LANES};
use svetlo::geometry::{Geometry, Ray, TriangleMesh};
use svetlo::math::Vec3;
use svetlo::sampling::rng::Pcg32;

struct Args {
    out: std::path::PathBuf,
    repeat: usize,
    threads: Vec<usize>,
    subdiv: usize,
    write: bool,
    /// Only these ray sets (all when empty).
    sets: Vec<String>,
    /// Cast eight rays at a time (`Accel::intersect_lanes`, `occluded_lanes`), as the path kernel does.
    lanes: bool,
    /// Answer `SET QUERY THREADS` lines from stdin, one cast each (lets a driver interleave runs).
    serve: bool,
}

fn parse_args() -> Args {
    let mut a = Args { out: "bench/out".into(), repeat: 3, threads: vec![1, 2], subdiv: 289, write: true, sets: Vec::new(), serve: false, lanes: false };
    let mut it = std::env::args().skip(1);
    while let Some(k) = it.next() {
        let mut val = || it.next().unwrap_or_else(|| panic!("{k} needs a value"));
        match k.as_str() {
            "--out" => a.out = val().into(),
            "--repeat" => a.repeat = val().parse().expect("--repeat N"),
            "--threads" => a.threads = val().split(',').map(|s| s.parse().expect("--threads 1,2")).collect(),
            "--subdiv" => a.subdiv = val().parse().expect("--subdiv N"),
            "--no-write" => a.write = false,
            "--serve" => a.serve = true,
            "--lanes" => a.lanes = true,
            "--sets" => a.sets = val().split(',').map(str::to_string).collect(),
            _ => panic!("unknown argument {k}"),
        }
    }
    a
}

/// Smooth pseudo-random bumps on the unit sphere: a few octaves of products of sines.
fn displacement(p: Vec3) -> f32 {
    let mut h = 0.0;
    let mut f = 3.0;
    let mut a = 0.12;
    for o in 0..5 {
        let s = o as f32 * 1.7;
        h += a * (f * p.x + s).sin() * (f * 1.3 * p.y + 2.0 * s).sin() * (f * 0.9 * p.z + 0.5 * s).cos();
        f *= 2.3;
        a *= 0.5;
    }
    h
}

/// A cube sphere (6 faces of n x n quads, 12 n^2 triangles) displaced along the normal.
/// Face edges duplicate their vertices, as a mesh exported per face would.
fn bumpy_planet(n: usize) -> TriangleMesh {
    let mut m = TriangleMesh::default();
    let faces = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (Vec3::NEG_Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (Vec3::NEG_Z, Vec3::Y, Vec3::X),
    ];
    for (normal, u, v) in faces {
        let base = m.positions.len() as u32;
        for i in 0..=n {
            for j in 0..=n {
                let (s, t) = (2.0 * i as f32 / n as f32 - 1.0, 2.0 * j as f32 / n as f32 - 1.0);
                let p = (normal + s * u + t * v).normalize();
                m.positions.push(p * (1.0 + displacement(p)));
            }
        }
        let idx = |i: usize, j: usize| base + (i * (n + 1) + j) as u32;
        for i in 0..n {
            for j in 0..n {
                m.indices.push([idx(i, j), idx(i + 1, j), idx(i + 1, j + 1)]);
                m.indices.push([idx(i, j), idx(i + 1, j + 1), idx(i, j + 1)]);
            }
        }
    }
    m
}

fn uniform_dir(rng: &mut Pcg32) -> Vec3 {
    let z = 1.0 - 2.0 * rng.next_f32();
    let r = (1.0 - z * z).max(0.0).sqrt();
    let phi = 2.0 * std::f32::consts::PI * rng.next_f32();
    Vec3::new(r * phi.cos(), r * phi.sin(), z)
}

/// Ray sets: (name, rays).
fn ray_sets(mesh: &TriangleMesh) -> Vec<(&'static str, Vec<Ray>)> {
    let b = mesh.bounds();
    let mut rng = Pcg32::new(2024, 1);
    let in_box = |rng: &mut Pcg32| b.min + Vec3::new(rng.next_f32(), rng.next_f32(), rng.next_f32()) * (b.max - b.min);
    // Coherent: a 1024 x 1024 pinhole camera looking at the planet from outside.
    let res = 1024;
    let eye = Vec3::new(1.2, -3.4, 1.6);
    let fwd = (Vec3::ZERO - eye).normalize();
    let right = fwd.cross(Vec3::Z).normalize();
    let up = right.cross(fwd);
    let tan = (0.5 * 40f32.to_radians()).tan();
    let mut coherent = Vec::with_capacity(res * res);
    for y in 0..res {
        for x in 0..res {
            let sx = (2.0 * (x as f32 + 0.5) / res as f32 - 1.0) * tan;
            let sy = (1.0 - 2.0 * (y as f32 + 0.5) / res as f32) * tan;
            coherent.push(Ray::new(eye, (fwd + sx * right + sy * up).normalize()));
        }
    }
    // Incoherent: random origins inside the bounds, random directions.
    let incoherent: Vec<Ray> = (0..1 << 20).map(|_| Ray::new(in_box(&mut rng), uniform_dir(&mut rng))).collect();
    // Shadow-like: segments between two random points inside the bounds.
    let segments: Vec<Ray> = (0..1 << 20)
        .map(|_| {
            let (p, q) = (in_box(&mut rng), in_box(&mut rng));
            let len = (q - p).length();
            Ray::with_max(p, (q - p) / len, len)
        })
        .collect();
    vec![("coherent", coherent), ("incoherent", incoherent), ("segments", segments)]
}

fn write_mesh(path: &std::path::Path, m: &TriangleMesh) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    f.write_all(&(m.positions.len() as u32).to_le_bytes())?;
    f.write_all(&(m.indices.len() as u32).to_le_bytes())?;
    for p in &m.positions {
        for c in p.to_array() {
            f.write_all(&c.to_le_bytes())?;
        }
    }
    for t in &m.indices {
        for i in t {
            f.write_all(&i.to_le_bytes())?;
        }
    }
    f.flush()
}

/// u32 count, then per ray o.xyz, d.xyz, t_max as f32.
fn write_rays(path: &std::path::Path, rays: &[Ray]) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    f.write_all(&(rays.len() as u32).to_le_bytes())?;
    for r in rays {
        for c in [r.o.x, r.o.y, r.o.z, r.d.x, r.d.y, r.d.z, r.t_max] {
            f.write_all(&c.to_le_bytes())?;
        }
    }
    f.flush()
}

/// Per ray the hit triangle (-1 for none) and t (inf for none).
fn write_hits(path: &std::path::Path, accel: &Accel, rays: &[Ray]) -> std::io::Result<()> {
    let mut f = std::io::BufWriter::new(std::fs::File::create(path)?);
    for r in rays {
        let (prim, t) = accel.intersect(r).map_or((-1i32, f32::INFINITY), |h| (h.prim as i32, h.t));
        f.write_all(&prim.to_le_bytes())?;
        f.write_all(&t.to_le_bytes())?;
    }
    f.flush()
}

/// CPU time this thread has run, in ns (Linux; 0 elsewhere). Unlike wall time it
/// does not count the time the thread waited for a core on a loaded machine.
fn thread_cpu_ns() -> u64 {
    std::fs::read_to_string("/proc/thread-self/schedstat").ok().and_then(|s| s.split_whitespace().next().and_then(|v| v.parse().ok())).unwrap_or(0)
}

/// CPU time all of this process's living threads have run, in ns (Linux; 0 elsewhere): a build's
/// CPU time on rayon's threads, which a loaded machine's wall clock overstates.
fn process_cpu_ns() -> u64 {
    let Ok(tasks) = std::fs::read_dir("/proc/self/task") else { return 0 };
    let stat = |p: std::path::PathBuf| std::fs::read_to_string(p).ok()?.split_whitespace().next()?.parse::<u64>().ok();
    tasks.filter_map(|t| stat(t.ok()?.path().join("schedstat"))).sum()
}

/// Casts all rays on `threads` threads (dynamic chunks); returns (wall seconds,
/// CPU seconds summed over the threads, number of hits).
fn cast(accel: &Accel, rays: &[Ray], threads: usize, occlusion: bool, lanes: bool) -> (f64, f64, usize) {
    const CHUNK: usize = 4096;
    let next = AtomicUsize::new(0);
    let hits = AtomicUsize::new(0);
    let cpu_ns = AtomicUsize::new(0);
    let t0 = Instant::now();
    std::thread::scope(|s| {
        for _ in 0..threads {
            s.spawn(|| {
                let c0 = thread_cpu_ns();
                let mut h = 0;
                loop {
                    let start = next.fetch_add(CHUNK, Ordering::Relaxed);
                    if start >= rays.len() {
                        break;
                    }
                    let chunk = &rays[start..(start + CHUNK).min(rays.len())];
                    if lanes {
                        for group in chunk.chunks(RAY_LANES) {
                            let mut eight = [group[0]; RAY_LANES];
                            eight[..group.len()].copy_from_slice(group);
                            let active = ((1u32 << group.len()) - 1) as u8;
                            h += if occlusion {
                                accel.occluded_lanes(&eight, active).count_ones() as usize
                            } else {
                                accel.intersect_lanes(&eight, active).iter().flatten().count()
                            };
                        }
                    } else {
                        for r in chunk {
                            h += if occlusion { accel.occluded(r) as usize } else { accel.intersect(r).is_some() as usize };
                        }
                    }
                }
                hits.fetch_add(h, Ordering::Relaxed);
                cpu_ns.fetch_add((thread_cpu_ns() - c0) as usize, Ordering::Relaxed);
            });
        }
    });
    (t0.elapsed().as_secs_f64(), cpu_ns.into_inner() as f64 * 1e-9, hits.into_inner())
}

/// One JSON line: throughput of each run by wall clock and per CPU-second of a thread.
fn report(name: &str, rays: &[Ray], occlusion: bool, threads: usize, runs: &[(f64, f64, usize)]) {
    let n = rays.len() as f64;
    let list = |f: &dyn Fn(&(f64, f64, usize)) -> f64| runs.iter().map(|r| format!("{:.3}", n / f(r) / 1e6)).collect::<Vec<_>>().join(",");
    let query = if occlusion { "occluded" } else { "closest" };
    println!(
        "{{\"kind\":\"cast\",\"set\":\"{name}\",\"query\":\"{query}\",\"threads\":{threads},\"rays\":{},\"hits\":{},\"mrays\":[{}],\"cpu_mrays_per_thread\":[{}]}}",
        rays.len(),
        runs[0].2,
        list(&|r| r.0),
        list(&|r| r.1)
    );
    std::io::stdout().flush().expect("stdout");
}

fn main() -> std::io::Result<()> {
    let args = parse_args();
    let t0 = Instant::now();
    let mesh = bumpy_planet(args.subdiv);
    let gen_s = t0.elapsed().as_secs_f64();
    let geom = Geometry::Mesh(mesh);
    let Geometry::Mesh(mesh) = &geom else { unreachable!() };
    // Build timing on the threads rayon has (RAYON_NUM_THREADS), then on one.
    let (t0, c0) = (Instant::now(), process_cpu_ns());
    let accel = Accel::build(&[&geom]);
    let (build_s, build_cpu_s) = (t0.elapsed().as_secs_f64(), (process_cpu_ns() - c0) as f64 * 1e-9);
    let pool1 = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("rayon pool");
    let (t0, c0) = (Instant::now(), process_cpu_ns());
    drop(pool1.install(|| Accel::build(&[&geom])));
    let (build1_s, build1_cpu_s) = (t0.elapsed().as_secs_f64(), (process_cpu_ns() - c0) as f64 * 1e-9);
    println!(
        "{{\"kind\":\"build\",\"triangles\":{},\"build_s\":{build_s:.3},\"build_1thread_s\":{build1_s:.3},\"build_cpu_s\":{build_cpu_s:.3},\"build_1thread_cpu_s\":{build1_cpu_s:.3},\"rayon_threads\":{},\"mesh_gen_s\":{gen_s:.3}}}",
        mesh.triangle_count(),
        rayon::current_num_threads()
    );
    let mut sets = ray_sets(mesh);
    if !args.sets.is_empty() {
        sets.retain(|(name, _)| args.sets.iter().any(|s| s == name));
    }
    if args.write {
        std::fs::create_dir_all(&args.out)?;
        write_mesh(&args.out.join("mesh.bin"), mesh)?;
        for (name, rays) in &sets {
            write_rays(&args.out.join(format!("rays_{name}.bin")), rays)?;
            write_hits(&args.out.join(format!("hits_{name}.bin")), &accel, rays)?;
        }
    }
    if args.serve {
        println!("ready");
        for line in std::io::stdin().lines() {
            let line = line?;
            let w: Vec<&str> = line.split_whitespace().collect();
            let [set, query, threads] = w[..] else { break };
            let rays = &sets.iter().find(|(n, _)| *n == set).unwrap_or_else(|| panic!("no ray set {set}")).1;
            let threads = threads.parse().expect("thread count");
            report(set, rays, query == "occluded", threads, &[cast(&accel, rays, threads, query == "occluded", args.lanes)]);
        }
        return Ok(());
    }
    for (name, rays) in &sets {
        for occlusion in [false, true] {
            for &threads in &args.threads {
                let runs: Vec<_> = (0..args.repeat).map(|_| cast(&accel, rays, threads, occlusion, args.lanes)).collect();
                report(name, rays, occlusion, threads, &runs);
            }
        }
    }
    Ok(())
}
