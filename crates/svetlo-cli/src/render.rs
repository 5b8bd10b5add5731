//! `svetlo render`: load, apply the command line's overrides, render with a progress bar and
//! Ctrl-C cancellation, write the images, print a summary.

use crate::{parse_define, Usage, EXIT_INTERRUPTED};
use anyhow::{Context, Result};
use clap::{value_parser, Args, ValueEnum};
use indicatif::{ProgressBar, ProgressStyle};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::atomic::Ordering;
use std::sync::Arc;
use std::time::{Duration, Instant};
use svetlo::film::{Film, Filter};
use svetlo::integrator::{Integrator, Progress, RenderSettings};
use svetlo::io::image_io::{write_exr, write_pfm, write_png};
use svetlo::sampling::SamplerKind;
use svetlo::scene::Scene;

/// The spp of a render bounded by `--time` alone: large enough never to be reached.
const TIME_ONLY_SPP: u32 = 1 << 24;

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum FilterArg {
    Box,
    Tent,
    Gaussian,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SamplerArg {
    Independent,
    Sobol,
}

#[derive(Args, Debug)]
pub struct RenderArgs {
    /// Scene file (Mitsuba XML, or pbrt-v4 `.pbrt` / `.pbrt.gz`).
    pub scene: PathBuf,
    /// Output image; OUT.png is written beside it. Default: <scene name>.exr in the current directory.
    #[arg(short, long, value_name = "OUT.exr")]
    pub output: Option<PathBuf>,
    /// Samples per pixel (the maximum when --time is given).
    #[arg(long, value_name = "N", allow_negative_numbers = true, value_parser = value_parser!(u32).range(1..))]
    pub spp: Option<u32>,
    /// Stop after this many seconds, keeping whole passes.
    #[arg(long, value_name = "SECONDS", allow_negative_numbers = true, value_parser = parse_seconds)]
    pub time: Option<f64>,
    /// Random seed.
    #[arg(long, value_name = "S")]
    pub seed: Option<u64>,
    /// Path segments from the camera (Mitsuba's meaning: 2 = direct light only, -1 = unbounded).
    #[arg(long, value_name = "D", allow_negative_numbers = true, value_parser = value_parser!(i32).range(-1..))]
    pub max_depth: Option<i32>,
    /// Light transport method (path, direct, ...); default: the scene's.
    #[arg(long, value_name = "NAME")]
    pub integrator: Option<String>,
    /// Image width in pixels; alone, the height follows the scene's aspect ratio.
    #[arg(long, value_name = "W", allow_negative_numbers = true, value_parser = value_parser!(u32).range(1..=65536))]
    pub width: Option<u32>,
    /// Image height in pixels; alone, the width follows the scene's aspect ratio.
    #[arg(long, value_name = "H", allow_negative_numbers = true, value_parser = value_parser!(u32).range(1..=65536))]
    pub height: Option<u32>,
    /// Pixel reconstruction filter (tent radius 1, Gaussian sigma 0.5).
    #[arg(long, value_enum)]
    pub filter: Option<FilterArg>,
    /// Worker threads (0: all cores; at most 1024).
    #[arg(long, value_name = "N", default_value_t = 0, allow_negative_numbers = true, value_parser = value_parser!(u16).range(0..=1024))]
    pub threads: u16,
    /// Sample generator (default: the scene's `<sampler>`, else sobol).
    #[arg(long, value_enum)]
    pub sampler: Option<SamplerArg>,
    /// Scene parameter for <default> / $name substitution (repeatable).
    #[arg(short = 'D', value_name = "NAME=VALUE", value_parser = parse_define)]
    pub define: Vec<(String, String)>,
    /// Also write the per-sample variance image OUT_var.exr.
    #[arg(long)]
    pub variance: bool,
    /// Skip hits closer than D scene units to a ray's origin, on every ray (default 0: none).
    /// Tungsten skips 5e-4: its references of thin-walled glass need --ray-epsilon 5e-4.
    #[arg(long, value_name = "D", value_parser = parse_ray_epsilon)]
    pub ray_epsilon: Option<f32>,
    /// Scene format (default: from the extension, `.pbrt` and `.pbrt.gz` are pbrt-v4).
    #[arg(long, value_enum)]
    pub format: Option<crate::FormatArg>,
    /// BDPT only: also write one image per (s, t) strategy into DIR, MIS-weighted
    /// (s<S>_t<T>_weighted.exr, they sum to the image) and unweighted (s<S>_t<T>_unweighted.exr).
    #[arg(long, value_name = "DIR")]
    pub strategies: Option<PathBuf>,
    /// An AOV: the paths a light path expression matches, as its own layer NAME.R/G/B of
    /// the EXR and OUT_NAME.png (repeatable; e.g. --aov caustic='C D S+ L').
    #[arg(long, value_name = "NAME=EXPR", value_parser = parse_aov)]
    pub aov: Vec<(String, String)>,
    /// Restrict the beauty to the paths a light path expression matches (e.g. 'L D* E').
    #[arg(long, value_name = "EXPR")]
    pub lpe: Option<String>,
    /// Add a preset of AOVs: `lecture` writes one per method class of the lecture (local,
    /// whitted, cook, radiosity, rest).
    #[arg(long, value_name = "NAME", value_parser = ["lecture"])]
    pub aov_preset: Option<String>,
    /// With --strategies: the longest paths (in segments) that get their own images.
    #[arg(long, value_name = "N", default_value_t = 5, value_parser = value_parser!(u32).range(1..=32))]
    pub strategy_depth: u32,
    /// Live preview in a browser, and tev streaming.
    #[command(flatten)]
    pub live: crate::preview::PreviewArgs,
    /// Also write OUT_falsecolour.png: the image's luminance in cd/m² (683 lm/W) in false
    /// colour with a legend, as Radiance's falsecolor.
    #[arg(long, value_name = "QUANTITY", value_parser = ["luminance"])]
    pub false_colour: Option<String>,
    /// The false-colour scale 'lo:hi' in cd/m² (default: 0 to the image's maximum).
    #[arg(long, value_name = "LO:HI", requires = "false_colour")]
    pub scale: Option<String>,
    /// Logarithmic false-colour scale.
    #[arg(long, requires = "false_colour")]
    pub log: bool,
    /// Render on a Dask cluster: a scheduler's ADDRESS (tcp://host:8786) or local:N for N local
    /// worker processes. Runs `python3 -m svetlo.distributed` (the Python package, with
    /// dask[distributed]; SVETLO_PYTHON names another Python); the image is the local one, bit for bit.
    #[arg(long, value_name = "ADDRESS")]
    pub dask: Option<String>,
    /// With --dask: the number of render tasks (default: 4 per worker).
    #[arg(long, value_name = "N", requires = "dask", value_parser = value_parser!(u32).range(1..))]
    pub chunks: Option<u32>,
}

fn parse_aov(s: &str) -> std::result::Result<(String, String), String> {
    match s.split_once('=') {
        Some((n, e)) if !n.trim().is_empty() => Ok((n.trim().to_string(), e.to_string())),
        _ => Err(format!("'{s}' is not NAME=EXPRESSION")),
    }
}

fn parse_ray_epsilon(s: &str) -> std::result::Result<f32, String> {
    match s.parse::<f32>() {
        Ok(d) if (0.0..1e30).contains(&d) => Ok(d),
        Ok(d) => Err(format!("{d} is not a distance of 0 or more")),
        Err(_) => Err(format!("'{s}' is not a distance")),
    }
}

fn parse_seconds(s: &str) -> std::result::Result<f64, String> {
    match s.parse::<f64>() {
        Ok(t) if t > 0.0 && t.is_finite() && t < 1e9 => Ok(t),
        Ok(t) => Err(format!("{t} is not a positive number of seconds")),
        Err(_) => Err(format!("'{s}' is not a number of seconds")),
    }
}

/// Where a render's images go: `<base>.exr`, `<base>.png`, `<base>_var.exr`, and
/// `<base>.pfm` when the output was named `.pfm`.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputPaths {
    pub exr: PathBuf,
    pub png: PathBuf,
    pub var: PathBuf,
    pub pfm: Option<PathBuf>,
}

fn with_suffix(base: &Path, suffix: &str) -> PathBuf {
    let mut s = base.as_os_str().to_os_string();
    s.push(suffix);
    PathBuf::from(s)
}

impl OutputPaths {
    pub fn new(scene: &Path, output: Option<&Path>) -> Result<Self> {
        let (base, pfm) = match output {
            None => {
                let stem = scene.file_stem().ok_or_else(|| Usage(format!("scene path '{}' has no file name", scene.display())))?;
                (PathBuf::from(stem), false)
            }
            Some(o) if o.is_dir() => {
                return Err(Usage(format!("output '{}' is a folder; name a file in it (e.g. {}/image.exr)", o.display(), o.display())).into());
            }
            Some(o) => {
                let ext = o.extension().map(|e| e.to_string_lossy().to_ascii_lowercase());
                match ext.as_deref() {
                    None => (o.to_path_buf(), false),
                    Some("exr") | Some("png") => (o.with_extension(""), false),
                    Some("pfm") => (o.with_extension(""), true),
                    Some(e) => return Err(Usage(format!("output '{}': unsupported extension '.{e}' (use .exr)", o.display())).into()),
                }
            }
        };
        if base.file_name().is_none() {
            return Err(Usage(format!("output '{}' names no file", base.display())).into());
        }
        let paths = OutputPaths {
            exr: with_suffix(&base, ".exr"),
            png: with_suffix(&base, ".png"),
            var: with_suffix(&base, "_var.exr"),
            pfm: pfm.then(|| with_suffix(&base, ".pfm")),
        };
        // Fail before a long render, not after it.
        let dir = paths.exr.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
        if !dir.is_dir() {
            return Err(Usage(format!("output directory '{}' does not exist", dir.display())).into());
        }
        Ok(paths)
    }
}

/// A scene with the command line's overrides applied, ready to render.
pub struct Job {
    pub scene: Scene,
    pub settings: RenderSettings,
    pub integrator_name: String,
    pub integrator: Box<dyn Integrator>,
}

/// Apply the command line over the scene file's settings.
pub fn configure(mut scene: Scene, a: &RenderArgs) -> Result<Job> {
    let integrator_name = a.integrator.clone().unwrap_or_else(|| scene.settings.integrator.clone());
    let integrator = svetlo::methods::by_name(&integrator_name).map_err(|e| {
        if a.integrator.is_some() {
            anyhow::Error::new(Usage(e.to_string()))
        } else {
            anyhow::Error::new(crate::SceneError(e)).context(format!("the scene asks for integrator '{integrator_name}'; choose another with --integrator"))
        }
    })?;
    if a.strategies.is_some() && integrator_name != "bdpt" {
        return Err(Usage(format!("--strategies needs --integrator bdpt (the render would use '{integrator_name}')")).into());
    }
    let mut s = RenderSettings::from_scene(&scene);
    if let Some(spp) = a.spp {
        s.spp = spp;
    } else if a.time.is_some() {
        s.spp = TIME_ONLY_SPP;
    }
    s.time_limit = a.time.map(Duration::from_secs_f64);
    if let Some(seed) = a.seed {
        s.seed = seed;
    }
    if let Some(d) = a.max_depth {
        s.max_depth = d;
    }
    s.threads = a.threads as usize;
    if let Some(d) = a.ray_epsilon {
        scene.settings.ray_epsilon = d;
    }
    if let Some(f) = a.filter {
        s.filter = match f {
            FilterArg::Box => Filter::Box,
            FilterArg::Tent => Filter::Tent { radius: 1.0 },
            FilterArg::Gaussian => Filter::Gaussian { stddev: 0.5 },
        };
    }
    if let Some(k) = a.sampler {
        s.sampler = match k {
            SamplerArg::Independent => SamplerKind::Independent,
            SamplerArg::Sobol => SamplerKind::Sobol,
        };
    }
    let cam = &mut scene.camera;
    let aspect = cam.width as f64 / cam.height as f64;
    match (a.width, a.height) {
        (Some(w), Some(h)) => (cam.width, cam.height) = (w, h),
        (Some(w), None) => (cam.width, cam.height) = (w, ((w as f64 / aspect).round() as u32).max(1)),
        (None, Some(h)) => (cam.width, cam.height) = (((h as f64 * aspect).round() as u32).max(1), h),
        (None, None) => {}
    }
    s.validate().context("render settings")?;
    svetlo::limits::check_film(cam.width, cam.height).map_err(|e| Usage(e.to_string()))?;
    if scene.lights.is_empty() {
        tell!("warning: the scene has no emitter: the image is black");
    } else if matches!(integrator_name.as_str(), "light" | "ptracer") && !scene.environment_lights.is_empty() {
        tell!(
            "warning: light tracing does not see environment emitters (envmap, constant) from the camera; they are missing from the image (use path or bdpt)"
        );
    }
    let request = svetlo::lpe::AovSet::request(&scene, &a.aov, a.aov_preset.as_deref(), a.lpe.as_deref());
    if let Some((set, warnings)) = request.map_err(|e| Usage(format!("light path expression: {e}")))? {
        for w in warnings {
            tell!("warning: {w}");
        }
        s.lpe = Some(Arc::new(set));
    }
    Ok(Job { scene, settings: s, integrator_name, integrator })
}

/// Render with a progress bar (drawn only on a terminal) fed from `progress` by a second thread.
pub fn execute(job: &Job, progress: &Progress) -> Result<(Film, Duration)> {
    let (film, (), elapsed) = execute_with(job, progress, || Ok((job.integrator.render(&job.scene, &job.settings, progress)?, ())))?;
    Ok((film, elapsed))
}

/// `execute` for any render function that also returns something besides the film.
fn execute_with<T>(job: &Job, progress: &Progress, render: impl FnOnce() -> svetlo::Result<(Film, T)>) -> Result<(Film, T, Duration)> {
    let start = Instant::now();
    let pixels = job.scene.camera.width as u64 * job.scene.camera.height as u64;
    let (film, extra) = with_progress_bar(progress, start, job.settings.time_limit, pixels, render)?;
    Ok((film, extra, start.elapsed()))
}

/// Runs `work` while a second thread draws the progress bar. The bar's thread is told to end
/// however `work` ends, a panic included (dropping the sender it waits on wakes it at once):
/// the panic then reaches the caller (and the process exits with it) instead of leaving the
/// scope waiting for the bar forever, and a short render does not wait out the bar's period.
fn with_progress_bar<R>(progress: &Progress, start: Instant, time_limit: Option<Duration>, pixels: u64, work: impl FnOnce() -> R) -> R {
    let (finish, finished) = std::sync::mpsc::channel::<()>();
    std::thread::scope(|s| {
        s.spawn(move || drive_bar(progress, finished, start, time_limit, pixels));
        let _finish = finish;
        work()
    })
}

/// BDPT with one image per strategy, written into `dir` (created if missing).
fn execute_strategies(job: &Job, progress: &Progress, dir: &Path, depth: u32) -> Result<(Film, Duration, Vec<PathBuf>)> {
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create the strategies folder '{}'", dir.display()))?;
    let (film, images, elapsed) =
        execute_with(job, progress, || svetlo::integrator::bdpt::Bdpt.render_with_strategies(&job.scene, &job.settings, progress, depth as usize))?;
    let mut written = Vec::new();
    for im in &images {
        for (img, kind) in [(&im.weighted, "weighted"), (&im.unweighted, "unweighted")] {
            let p = dir.join(format!("s{}_t{}_{kind}.exr", im.s, im.t));
            write_exr(&p, img)?;
            written.push(p);
        }
    }
    Ok((film, elapsed, written))
}

const BAR_UNITS: u64 = 10_000;

/// Redraws the bar every 50 ms until `finished`'s sender is dropped.
fn drive_bar(progress: &Progress, finished: std::sync::mpsc::Receiver<()>, start: Instant, time_limit: Option<Duration>, pixels: u64) {
    let bar = ProgressBar::new(BAR_UNITS);
    let style = ProgressStyle::with_template("{spinner} [{elapsed_precise}] [{wide_bar}] {percent:>3}% {msg} ETA {eta}")
        .map(|s| s.progress_chars("=> "))
        .unwrap_or_else(|_| ProgressStyle::default_bar());
    bar.set_style(style);
    loop {
        let elapsed = start.elapsed();
        // The render ends at whichever comes first: all samples, or the time budget.
        let mut frac = progress.fraction();
        if let Some(t) = time_limit {
            frac = frac.max(elapsed.as_secs_f64() / t.as_secs_f64());
        }
        bar.set_position((frac.clamp(0.0, 1.0) * BAR_UNITS as f64) as u64);
        let done = progress.done.load(Ordering::Relaxed);
        let rate = done as f64 / elapsed.as_secs_f64().max(1e-9);
        bar.set_message(format!("{:.1} spp, {}samples/s", done as f64 / pixels.max(1) as f64, si(rate)));
        // Only a timeout goes on: the sender is dropped (never used) when the render ends.
        if !matches!(finished.recv_timeout(Duration::from_millis(50)), Err(std::sync::mpsc::RecvTimeoutError::Timeout)) {
            break;
        }
    }
    bar.finish_and_clear();
}

/// CPU time (user + system, all threads) this process has used, where the OS tells it.
fn process_cpu_seconds() -> Option<f64> {
    #[cfg(unix)]
    {
        let mut u = std::mem::MaybeUninit::<libc::rusage>::zeroed();
        // SAFETY: getrusage fills the struct it is given and touches nothing else.
        if unsafe { libc::getrusage(libc::RUSAGE_SELF, u.as_mut_ptr()) } != 0 {
            return None;
        }
        // SAFETY: initialised by the successful call above (and zeroed before).
        let u = unsafe { u.assume_init() };
        let tv = |t: libc::timeval| t.tv_sec as f64 + t.tv_usec as f64 * 1e-6;
        Some(tv(u.ru_utime) + tv(u.ru_stime))
    }
    #[cfg(not(unix))]
    {
        None
    }
}

/// A number with an SI prefix: 1234567 -> "1.23 M".
pub fn si(x: f64) -> String {
    let (v, p) = if x >= 1e9 {
        (x / 1e9, "G")
    } else if x >= 1e6 {
        (x / 1e6, "M")
    } else if x >= 1e3 {
        (x / 1e3, "k")
    } else {
        (x, "")
    };
    format!("{v:.2} {p}")
}

/// OUT_falsecolour.png: luminance (cd/m²) in false colour with its legend.
fn write_false_colour(img: &svetlo::film::Image, exr: &Path, scale: Option<&str>, log: bool) -> Result<PathBuf> {
    use svetlo::photometry::false_colour::{picture, Scale};
    let cd: Vec<f64> = img.data.iter().map(|c| c.luminance() as f64 * svetlo::photometry::LM_PER_W).collect();
    let sc = match scale {
        Some(s) => Scale::parse(s, log).map_err(|e| crate::Usage(format!("--scale: {e}")))?,
        None => Scale::auto(&cd, log),
    };
    let p = with_suffix(&exr.with_extension(""), "_falsecolour.png");
    write_png(&p, &picture(&cd, img.width, img.height, &sc, "cd/m2", false))?;
    Ok(p)
}

/// Write the images; returns the paths written.
pub fn write_outputs(film: &Film, out: &OutputPaths, variance: bool) -> Result<Vec<PathBuf>> {
    let img = film.image();
    let layers = film.layer_images();
    if layers.is_empty() {
        write_exr(&out.exr, &img)?;
    } else {
        svetlo::io::image_io::write_exr_layers(&out.exr, &img, &layers)?;
    }
    write_png(&out.png, &img)?;
    let mut written = vec![out.exr.clone(), out.png.clone()];
    // One PNG per AOV beside the beauty's: OUT_NAME.png.
    for (name, layer) in &layers {
        let p = with_suffix(&out.exr.with_extension(""), &format!("_{name}.png"));
        write_png(&p, layer)?;
        written.push(p);
    }
    if let Some(p) = &out.pfm {
        write_pfm(p, &img)?;
        written.push(p.clone());
    }
    if variance {
        write_exr(&out.var, &film.variance_image())?;
        written.push(out.var.clone());
    }
    Ok(written)
}

/// Everything after loading: configure, render, write, report. Returns the exit code.
pub fn render_loaded(scene: Scene, a: &RenderArgs, out: &OutputPaths, progress: &Progress) -> Result<ExitCode> {
    let job = configure(scene, a)?;
    if a.variance && matches!(job.integrator_name.as_str(), "light" | "ptracer" | "bdpt") {
        tell!("warning: --variance counts only what each pixel's own samples add; the {} integrator's splats (light paths) are not in it", job.integrator_name);
    }
    let (w, h) = (job.scene.camera.width, job.scene.camera.height);
    // The method's scene set-up (acceleration structures) belongs to loading: the render
    // call's time and CPU below count the render alone.
    job.integrator.prepare(&job.scene, &job.settings);
    let cpu0 = process_cpu_seconds();
    let (film, elapsed, strategy_files) = match &a.strategies {
        Some(dir) => execute_strategies(&job, progress, dir, a.strategy_depth)?,
        None => {
            let (film, elapsed) = execute(&job, progress)?;
            (film, elapsed, Vec::new())
        }
    };
    let cpu = process_cpu_seconds().zip(cpu0).map(|(b, a)| b - a);
    let mut written = write_outputs(&film, out, a.variance)?;
    if a.false_colour.is_some() {
        written.push(write_false_colour(&film.image(), &out.exr, a.scale.as_deref(), a.log)?);
    }
    let secs = elapsed.as_secs_f64();
    let samples = film.spp_done as f64 * w as f64 * h as f64;
    say!("integrator  {}", job.integrator_name);
    say!("resolution  {w}x{h}");
    let planned = if a.spp.is_none() && a.time.is_some() { "time-limited".to_string() } else { format!("of {}", job.settings.spp) };
    say!("spp         {} ({planned})", film.spp_done);
    // Milliseconds: renders of a tenth of a second are compared to a few percent.
    say!("time        {secs:.3} s");
    if let Some(c) = cpu {
        // All threads' CPU time in the render call: what benchmarks on a busy machine compare.
        say!("cpu         {c:.3} s");
    }
    say!("samples/s   {}", si(samples / secs.max(1e-9)));
    for p in &written {
        say!("wrote       {}", p.display());
    }
    if let (Some(dir), false) = (&a.strategies, strategy_files.is_empty()) {
        say!("strategies  {} images in {}", strategy_files.len(), dir.display());
    }
    if let Some(r) = job.integrator.report() {
        {
            use std::io::Write as _;
            let _ = write!(std::io::stderr(), "{r}");
        }
    }
    if progress.cancelled() {
        tell!("interrupted after {} spp", film.spp_done);
        return Ok(ExitCode::from(EXIT_INTERRUPTED));
    }
    if film.spp_done == 0 {
        anyhow::bail!("no sample pass finished within the time limit; the image is empty");
    }
    Ok(ExitCode::SUCCESS)
}

/// `--threads N` holds for the whole process: loading, the BVH build and tables built on
/// first use run on rayon's global pool, which gets N threads (the render makes its own pool
/// of N). Only the first call in a process can size it; later ones keep that size.
pub fn limit_global_threads(threads: usize) {
    if threads > 0 {
        let _ = rayon::ThreadPoolBuilder::new().num_threads(threads).build_global();
    }
}

pub fn run(a: &RenderArgs) -> Result<ExitCode> {
    // Check what can be checked before a possibly slow scene load.
    if let Some(name) = &a.integrator {
        svetlo::methods::by_name(name).map_err(|e| Usage(e.to_string()))?;
        if a.strategies.is_some() && name != "bdpt" {
            return Err(Usage(format!("--strategies needs --integrator bdpt, not '{name}'")).into());
        }
    }
    let out = OutputPaths::new(&a.scene, a.output.as_deref())?;
    if let Some(address) = &a.dask {
        return crate::dask::run(a, address);
    }
    limit_global_threads(a.threads as usize);
    let scene = crate::load_scene(&a.scene, a.format, &a.define)?;
    for w in &scene.warnings {
        tell!("warning: {w}");
    }
    let live = crate::preview::Live::start(a, &scene)?;
    let progress = live.as_ref().map_or_else(|| Arc::new(Progress::new()), |l| l.progress());
    for sig in crate::signals::install(progress.clone()) {
        tell!("warning: {sig} is ignored (as the parent process set it): it will not stop the render");
    }
    let outcome = render_loaded(scene, a, &out, &progress);
    if let Some(l) = live {
        l.finish(&outcome, &out);
    }
    outcome
}

#[cfg(test)]
pub mod tests {
    use super::*;
    use crate::{Cli, Command};
    use clap::Parser;
    use glam::{Mat4, Vec3};
    use svetlo::bsdf::Material;
    use svetlo::camera::{Camera, Projection};
    use svetlo::geometry::{Geometry, Sphere};
    use svetlo::io::image_io::read_image;
    use svetlo::light::Light;
    use svetlo::scene::SceneBuilder;
    use svetlo::texture::Texture;
    use svetlo::Rgb;

    /// A render that panics (a bug) ends the process with the panic, not in a hang: the
    /// progress bar's thread is told to stop however the render ends.
    #[test]
    fn a_panicking_render_does_not_hang() {
        let progress = Progress::new();
        let (tx, rx) = std::sync::mpsc::channel();
        std::thread::spawn(move || {
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                with_progress_bar(&progress, Instant::now(), None, 1, || -> u32 { panic!("a bug in a render") })
            }));
            let _ = tx.send(r.is_err());
        });
        assert_eq!(rx.recv_timeout(Duration::from_secs(30)), Ok(true), "the panic must reach the caller");
    }

    /// A lit diffuse sphere seen by a 32x24 pinhole camera.
    pub fn tiny_scene() -> Scene {
        let mut b = SceneBuilder::new();
        let m = b.add_material(Material::Diffuse { reflectance: Texture::Constant(Rgb::splat(0.6)) });
        b.add_shape(Geometry::Sphere(Sphere { center: Vec3::new(0.0, 0.0, 4.0), radius: 1.0, flip_normals: false }), m, None, "ball").unwrap();
        b.add_light(Light::Point { position: Vec3::new(1.0, 2.0, 0.0), intensity: Rgb::splat(10.0) });
        b.set_camera(Camera {
            to_world: Mat4::IDENTITY,
            projection: Projection::Perspective { fov_x_deg: 40.0, aperture_radius: 0.0, focus_distance: 1.0 },
            width: 32,
            height: 24,
            near_clip: 0.01,
            far_clip: 100.0,
            shutter_open: 0.0,
            shutter_close: 0.0,
        });
        b.settings.spp = 3;
        b.build().unwrap()
    }

    pub fn args(extra: &[&str]) -> RenderArgs {
        let mut v = vec!["svetlo", "render", "scene.xml"];
        v.extend_from_slice(extra);
        match Cli::try_parse_from(v).unwrap().command {
            Command::Render(a) => a,
            _ => unreachable!(),
        }
    }

    fn tmp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("svetlo-cli-render-{}-{name}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn overrides_apply() {
        let a = args(&[
            "--spp",
            "5",
            "--max-depth",
            "-1",
            "--seed",
            "7",
            "--filter",
            "box",
            "--sampler",
            "sobol",
            "--width",
            "20",
            "--height",
            "10",
            "--threads",
            "2",
            "--integrator",
            "direct",
        ]);
        let job = configure(tiny_scene(), &a).unwrap();
        assert_eq!(job.settings.spp, 5);
        assert_eq!(job.settings.max_depth, -1);
        assert_eq!(job.settings.seed, 7);
        assert_eq!(job.settings.filter, Filter::Box);
        assert_eq!(job.settings.sampler, SamplerKind::Sobol);
        assert_eq!(job.settings.threads, 2);
        assert_eq!((job.scene.camera.width, job.scene.camera.height), (20, 10));
        assert_eq!(job.integrator_name, "direct");
        assert_eq!(job.scene.settings.ray_epsilon, 0.0);
        let job = configure(tiny_scene(), &args(&["--ray-epsilon", "5e-4"])).unwrap();
        assert_eq!(job.scene.settings.ray_epsilon, 5e-4);
        for bad in ["-1", "nan", "inf", "x"] {
            assert!(Cli::try_parse_from(["svetlo", "render", "scene.xml", "--ray-epsilon", bad]).is_err(), "{bad}");
        }
        // Without options the scene's own settings stand.
        let job = configure(tiny_scene(), &args(&[])).unwrap();
        assert_eq!(job.settings.spp, 3);
        assert_eq!(job.integrator_name, "path");
        assert_eq!((job.scene.camera.width, job.scene.camera.height), (32, 24));
        // Width alone keeps the aspect ratio.
        let job = configure(tiny_scene(), &args(&["--width", "64"])).unwrap();
        assert_eq!((job.scene.camera.width, job.scene.camera.height), (64, 48));
        // Time alone: spp is only a bound.
        let job = configure(tiny_scene(), &args(&["--time", "2.5"])).unwrap();
        assert_eq!(job.settings.spp, TIME_ONLY_SPP);
        assert_eq!(job.settings.time_limit, Some(Duration::from_millis(2500)));
        // Unknown integrator from the command line is a usage error.
        let e = configure(tiny_scene(), &args(&["--integrator", "nope"])).err().unwrap();
        assert!(e.downcast_ref::<Usage>().is_some(), "{e:#}");
    }

    #[test]
    fn strategies_need_bdpt() {
        let e = configure(tiny_scene(), &args(&["--strategies", "dir", "--integrator", "path"])).err().unwrap();
        assert!(e.downcast_ref::<Usage>().is_some() && e.to_string().contains("bdpt"), "{e:#}");
        // Without --integrator the scene's (path) is used: still an error.
        let e = configure(tiny_scene(), &args(&["--strategies", "dir"])).err().unwrap();
        assert!(e.downcast_ref::<Usage>().is_some(), "{e:#}");
        assert!(configure(tiny_scene(), &args(&["--strategies", "dir", "--integrator", "bdpt"])).is_ok());
    }

    #[test]
    fn strategies_written() {
        let d = tmp("strategies");
        let a = args(&[
            "--spp",
            "2",
            "--integrator",
            "bdpt",
            "--strategies",
            d.join("st").to_str().unwrap(),
            "--strategy-depth",
            "2",
            "-o",
            d.join("b.exr").to_str().unwrap(),
        ]);
        let paths = OutputPaths::new(&a.scene, a.output.as_deref()).unwrap();
        assert_eq!(render_loaded(tiny_scene(), &a, &paths, &Progress::new()).unwrap(), ExitCode::SUCCESS);
        // Depth 2: (1,1), (0,2), (2,1), (1,2), (0,3), weighted and unweighted.
        let n = std::fs::read_dir(d.join("st")).unwrap().count();
        assert_eq!(n, 10);
        assert!(d.join("st/s1_t2_weighted.exr").is_file() && d.join("st/s2_t1_unweighted.exr").is_file());
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn output_paths() {
        let o = OutputPaths::new(Path::new("dir/cbox.v2.xml"), None).unwrap();
        assert_eq!(o.exr, PathBuf::from("cbox.v2.exr"));
        assert_eq!(o.png, PathBuf::from("cbox.v2.png"));
        assert_eq!(o.var, PathBuf::from("cbox.v2_var.exr"));
        let d = tmp("paths");
        let o = OutputPaths::new(Path::new("s.xml"), Some(&d.join("a.png"))).unwrap();
        assert_eq!(o.exr, d.join("a.exr"));
        let o = OutputPaths::new(Path::new("s.xml"), Some(&d.join("a.pfm"))).unwrap();
        assert_eq!(o.pfm, Some(d.join("a.pfm")));
        assert!(OutputPaths::new(Path::new("s.xml"), Some(Path::new("a.tga"))).is_err());
        let e = OutputPaths::new(Path::new("s.xml"), Some(&d.join("missing/a.exr"))).unwrap_err();
        assert!(e.downcast_ref::<Usage>().is_some() && e.to_string().contains("does not exist"), "{e:#}");
    }

    #[test]
    fn render_writes_exr_png_and_variance() {
        let d = tmp("write");
        let out = d.join("img.exr");
        let a = args(&["--spp", "4", "--variance", "--width", "16", "--height", "12", "-o", out.to_str().unwrap()]);
        let paths = OutputPaths::new(&a.scene, a.output.as_deref()).unwrap();
        let code = render_loaded(tiny_scene(), &a, &paths, &Progress::new()).unwrap();
        assert_eq!(code, ExitCode::SUCCESS);
        let img = read_image(&d.join("img.exr")).unwrap();
        let png = read_image(&d.join("img.png")).unwrap();
        let var = read_image(&d.join("img_var.exr")).unwrap();
        for i in [&img, &png, &var] {
            assert_eq!((i.width, i.height), (16, 12));
        }
        assert!(img.mean().max_component() > 0.0, "the sphere is lit");
        assert!(var.data.iter().all(|c| c.is_finite() && c.min_component() >= 0.0));
    }

    #[test]
    fn cancelled_render_still_writes_and_exits_130() {
        let d = tmp("cancel");
        let a = args(&["--spp", "1000", "-o", d.join("c.exr").to_str().unwrap()]);
        let paths = OutputPaths::new(&a.scene, a.output.as_deref()).unwrap();
        let progress = Progress::new();
        progress.cancel.store(true, Ordering::Relaxed);
        let code = render_loaded(tiny_scene(), &a, &paths, &progress).unwrap();
        assert_eq!(code, ExitCode::from(EXIT_INTERRUPTED));
        assert!(d.join("c.exr").is_file() && d.join("c.png").is_file());
    }

    #[test]
    fn time_limited_render_stops() {
        let d = tmp("time");
        let a = args(&["--time", "0.3", "-o", d.join("t.exr").to_str().unwrap()]);
        let paths = OutputPaths::new(&a.scene, a.output.as_deref()).unwrap();
        let t0 = Instant::now();
        let code = render_loaded(tiny_scene(), &a, &paths, &Progress::new()).unwrap();
        assert_eq!(code, ExitCode::SUCCESS);
        assert!(t0.elapsed() < Duration::from_secs(10));
    }

    #[test]
    fn si_prefixes() {
        assert_eq!(si(1_234_567.0), "1.23 M");
        assert_eq!(si(12.0), "12.00 ");
        assert_eq!(si(2.5e9), "2.50 G");
    }
}
