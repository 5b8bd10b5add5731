//! CPU time of the eight-wide path kernel on one scene, tracing packets or single rays (or
//! the scalar tracer), one thread: for comparisons of the kernel's tracers on a shared machine
//! (run the modes alternately, or under `valgrind --tool=callgrind` for instruction counts).
//!
//! `repeat`: three renders of the scene through `path` in one process, each timed (the first
//! unpacks the triangles and builds the packet tree, the others take what the scene keeps);
//! `repeat-scalar` the same through the scalar tracer.
//!
//! cargo run --release --example path_kernel_bench -- SCENE.xml packets|single|scalar|repeat|repeat-scalar [SPP] [SIZE] [OUT.exr]

use svetlo::integrator::path_simd::SimdKernel;
use svetlo::integrator::{Progress, RenderSettings};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let (Some(path), Some(mode)) = (args.get(1), args.get(2)) else {
        return Err("usage: path_kernel_bench SCENE.xml packets|single|scalar|repeat|repeat-scalar [SPP] [SIZE] [OUT.exr]".into());
    };
    let spp: u32 = args.get(3).map_or(Ok(64), |s| s.parse())?;
    let size: u32 = args.get(4).map_or(Ok(64), |s| s.parse())?;
    let mut scene = svetlo::io::load_scene(std::path::Path::new(path), &[])?;
    scene.camera.width = size;
    scene.camera.height = size;
    let mut s = RenderSettings::from_scene(&scene);
    s.spp = spp;
    s.threads = 1;
    let start = std::time::Instant::now();
    let film = match mode.as_str() {
        "scalar" => svetlo::methods::by_name("path:simd=false")?.render(&scene, &s, &Progress::new())?,
        "repeat" | "repeat-scalar" => {
            let path = svetlo::methods::by_name(if mode == "repeat" { "path" } else { "path:simd=false" })?;
            let mut film = None;
            for i in 0..3 {
                let t = std::time::Instant::now();
                film = Some(path.render(&scene, &s, &Progress::new())?);
                println!("render {i}: {:.4} s", t.elapsed().as_secs_f64());
            }
            film.ok_or("no render")?
        }
        "packets" | "single" => {
            let mut k = SimdKernel::new(&scene, &s).ok_or("the scene does not qualify for the kernel")?;
            if mode == "single" {
                k.use_single_rays(&scene);
            }
            println!("packets: {}", k.uses_packets());
            k.render(&scene, &s, &Progress::new())?
        }
        m => return Err(format!("unknown mode '{m}' (packets, single, scalar, repeat or repeat-scalar)").into()),
    };
    let img = film.image();
    println!("{mode}: {:.3} s, mean {:?}", start.elapsed().as_secs_f64(), img.mean());
    if let Some(out) = args.get(5) {
        svetlo::io::image_io::write_exr(std::path::Path::new(out), &img)?;
    }
    Ok(())
}
