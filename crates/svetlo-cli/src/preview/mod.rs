//! The live preview: `svetlo render --preview`, `svetlo serve` and `--tev`.
//!
//! The render thread hands each pass's film to [`state::Session`] through the library's pass
//! observer ([`svetlo::integrator::Progress::observed`]); the page connections
//! ([`server`]) and the tev stream ([`tev`]) read the newest state from there on their own
//! threads, so watching costs the render one development of the film per pass.

pub mod http;
pub mod server;
pub mod state;
pub mod tev;
pub mod websocket;

use crate::render::{self, OutputPaths, RenderArgs};
use crate::{Usage, EXIT_INTERRUPTED};
use anyhow::{Context, Result};
use clap::Args;
use state::{Config, Info, Mode, Session};
use std::net::IpAddr;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::sync::Arc;
use std::time::Duration;
use svetlo::integrator::Progress;
use svetlo::scene::Scene;

/// How long pages get to receive the final state before the process exits.
const GRACE: Duration = Duration::from_secs(2);

/// Watching options shared by `render` and `serve`.
#[derive(Args, Debug, Clone)]
pub struct PreviewArgs {
    /// Show the render in a browser: prints a local address (with its access token) to open.
    #[arg(long)]
    pub preview: bool,
    /// Address the preview listens on (default loopback only; any other lets the network in).
    #[arg(long, value_name = "IP", default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// Port of the preview (0: any free port).
    #[arg(long, value_name = "PORT", default_value_t = 0)]
    pub port: u16,
    /// Stream the render to a running tev image viewer (its default port is 14158).
    #[arg(long, value_name = "HOST:PORT")]
    pub tev: Option<String>,
}

fn scene_name(path: &Path) -> String {
    path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "scene".into())
}

/// Start the server (and the tev stream) for `session` as the options ask.
fn start_watchers(a: &PreviewArgs, session: &Arc<Session>, serve: bool) -> Result<(Option<server::Server>, Option<std::thread::JoinHandle<()>>)> {
    let server = if a.preview || serve {
        if !a.bind.is_loopback() {
            eprintln!("warning: the preview listens on {} (not loopback): whoever can reach it and learns the token can watch the render and stop it", a.bind);
        }
        let s = server::start(a.bind, a.port, session.clone())?;
        // On its own line and flushed: scripts (and the browser test) read it.
        eprintln!("preview: {}", s.url());
        Some(s)
    } else {
        None
    };
    let tev = a.tev.clone().map(|addr| tev::spawn(addr, session.clone()));
    Ok((server, tev))
}

/// The names of the AOV layers a render will have (`--aov`, then `--aov-preset`'s).
fn aov_names(a: &RenderArgs) -> Result<Vec<String>> {
    let aovs = svetlo::lpe::AovSet::requested(&a.aov, a.aov_preset.as_deref()).map_err(|e| Usage(format!("light path expression: {e}")))?;
    Ok(aovs.into_iter().map(|(n, _)| n).collect())
}

/// The preview of one `svetlo render`: the page watches and can stop it.
pub struct Live {
    session: Arc<Session>,
    server: Option<server::Server>,
    tev: Option<std::thread::JoinHandle<()>>,
}

impl Live {
    /// `None` unless `--preview` or `--tev` was given.
    pub fn start(a: &RenderArgs, scene: &Scene) -> Result<Option<Live>> {
        if !a.live.preview && a.live.tev.is_none() {
            return Ok(None);
        }
        let method = a.integrator.clone().unwrap_or_else(|| scene.settings.integrator.clone());
        let config = Config { methods: vec![method], spp: a.spp.unwrap_or(scene.settings.spp), max_depth: a.max_depth.unwrap_or(scene.settings.max_depth) };
        let session = Session::new(Info::new(Mode::Render, scene_name(&a.scene), None, &aov_names(a)?), config);
        let (server, tev) = start_watchers(&a.live, &session, false)?;
        Ok(Some(Live { session, server, tev }))
    }

    /// The render's progress: observed by the preview, cancelled by its stop button.
    pub fn progress(&self) -> Arc<Progress> {
        let (run, spp) = {
            let s = self.session.lock();
            (s.run, s.config.spp)
        };
        let progress = Arc::new(Progress::watched(self.session.observer(run, 0, spp)));
        self.session.start_slot(run, 0, progress.clone(), None);
        progress
    }

    /// The render returned: show its end, let the pages and tev have it, then stop serving.
    pub fn finish(self, outcome: &Result<ExitCode>, out: &OutputPaths) {
        let run = self.session.lock().run;
        let error = outcome.as_ref().err().map(|e| format!("{e:#}"));
        let written = if error.is_none() { vec![out.exr.display().to_string(), out.png.display().to_string()] } else { Vec::new() };
        self.session.finish_slot(run, 0, None, written, error);
        self.session.shut_down();
        if let Some(s) = &self.server {
            s.drain(GRACE);
        }
        if let Some(t) = self.tev {
            let _ = t.join();
        }
    }
}

#[derive(Args, Debug)]
pub struct ServeArgs {
    #[command(flatten)]
    pub render: RenderArgs,
    /// Render these methods in turn and compare them (comma-separated, e.g. path,bdpt).
    #[arg(long, value_name = "A,B")]
    pub compare: Option<String>,
    /// Reference image: the error plot shows relMSE against it (else each method's own
    /// variance estimate).
    #[arg(long, value_name = "REF.exr")]
    pub reference: Option<PathBuf>,
}

/// A method's name as part of a file name (`radiosity:solver=x` -> `radiosity_solver_x`).
fn file_part(method: &str) -> String {
    method.chars().map(|c| if c.is_ascii_alphanumeric() || c == '-' { c } else { '_' }).collect()
}

/// `svetlo serve`: render, show, compare; restart from the page; until Ctrl-C.
pub fn serve(a: &ServeArgs) -> Result<ExitCode> {
    let r = &a.render;
    if r.strategies.is_some() {
        return Err(Usage("--strategies is for 'svetlo render'".into()).into());
    }
    let methods: Option<Vec<String>> = a.compare.as_ref().map(|c| c.split(',').filter(|m| !m.is_empty()).map(str::to_string).collect());
    for m in methods.iter().flatten().chain(r.integrator.as_ref()) {
        svetlo::methods::by_name(m).map_err(|e| Usage(e.to_string()))?;
    }
    if methods.as_ref().is_some_and(|m| m.is_empty() || m.len() > 4) {
        return Err(Usage("--compare takes 1 to 4 methods, e.g. --compare path,bdpt".into()).into());
    }
    let out = OutputPaths::new(&r.scene, r.output.as_deref())?;
    let reference = match &a.reference {
        Some(p) => Some(svetlo::io::image_io::read_image(p).with_context(|| format!("cannot read the reference '{}'", p.display()))?),
        None => None,
    };
    render::limit_global_threads(r.threads as usize);
    let scene = crate::load_scene(&r.scene, r.format, &r.define)?;
    for w in &scene.warnings {
        eprintln!("warning: {w}");
    }
    let job = render::configure(scene, r)?;
    let (w, h) = (job.scene.camera.width as usize, job.scene.camera.height as usize);
    if let Some(img) = &reference {
        if (img.width, img.height) != (w, h) {
            return Err(Usage(format!("the reference is {}x{} but the render is {w}x{h} (set --width/--height)", img.width, img.height)).into());
        }
    }
    let methods = methods.unwrap_or_else(|| vec![job.integrator_name.clone()]);
    let config = Config { methods, spp: job.settings.spp, max_depth: job.settings.max_depth };
    let session = Session::new(Info::new(Mode::Serve, scene_name(&r.scene), reference, &aov_names(r)?), config.clone());
    let (server, tev) = start_watchers(&r.live, &session, true)?;
    {
        let s = session.clone();
        if let Err(e) = ctrlc::try_set_handler(move || {
            eprintln!("\ninterrupt: finishing the current pass, writing its image and exiting");
            s.shut_down();
        }) {
            eprintln!("warning: Ctrl-C will not stop the server cleanly: {e}");
        }
    }
    let mut config = config;
    loop {
        let run = session.begin_run(config.clone());
        for (i, m) in config.methods.iter().enumerate() {
            if session.interrupted() {
                break;
            }
            let mut settings = job.settings.clone();
            settings.spp = config.spp;
            settings.max_depth = config.max_depth;
            let progress = Arc::new(Progress::watched(session.observer(run, i, settings.spp)));
            session.start_slot(run, i, progress.clone(), settings.time_limit);
            let result = svetlo::methods::by_name(m).and_then(|integ| integ.render(&job.scene, &settings, &progress));
            match result {
                Ok(film) if film.spp_done > 0 => {
                    let base = out.exr.with_extension("");
                    let paths = OutputPaths::new(&r.scene, Some(&PathBuf::from(format!("{}-{}.exr", base.display(), file_part(m)))))?;
                    let written = render::write_outputs(&film, &paths, r.variance)?;
                    for p in &written {
                        eprintln!("wrote {} ({m}, {} spp)", p.display(), film.spp_done);
                    }
                    session.finish_slot(run, i, Some(&film), written.iter().map(|p| p.display().to_string()).collect(), None);
                }
                Ok(film) => session.finish_slot(run, i, Some(&film), Vec::new(), None),
                Err(e) => session.finish_slot(run, i, None, Vec::new(), Some(e.to_string())),
            }
        }
        session.update(|_| ());
        // Idle until the page asks for another render or the user presses Ctrl-C.
        let mut seen = 0;
        let next = loop {
            let mut s = session.wait_change(seen, Duration::from_millis(500));
            seen = s.version;
            if s.shutdown {
                break None;
            }
            if let Some(c) = s.pending.take() {
                break Some(c);
            }
        };
        match next {
            Some(c) => config = c,
            None => break,
        }
    }
    if let Some(s) = &server {
        s.drain(GRACE);
    }
    if let Some(t) = tev {
        let _ = t.join();
    }
    Ok(ExitCode::from(EXIT_INTERRUPTED))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn method_file_names() {
        assert_eq!(file_part("path"), "path");
        assert_eq!(file_part("radiosity:solver=hierarchical"), "radiosity_solver_hierarchical");
        assert_eq!(file_part("../x"), "___x");
    }
}
