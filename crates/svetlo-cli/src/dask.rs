//! `svetlo render --dask ADDRESS`: the render spread over a Dask cluster by the Python
//! package's driver (`python -m svetlo.distributed`), the options passed through. Dask is
//! Python's, so this runs a Python: `$SVETLO_PYTHON`, or `python3` on the PATH.

use crate::render::{FilterArg, RenderArgs, SamplerArg};
use crate::Usage;
use anyhow::{bail, Context, Result};
use std::ffi::OsString;
use std::process::{Command, ExitCode};

/// The environment variable naming the Python that has svetlo and dask[distributed].
pub const PYTHON_VAR: &str = "SVETLO_PYTHON";

fn python() -> OsString {
    std::env::var_os(PYTHON_VAR).filter(|p| !p.is_empty()).unwrap_or_else(|| "python3".into())
}

/// The options of `svetlo render` that a distributed render does not take.
fn refused(a: &RenderArgs) -> Option<&'static str> {
    [
        (a.time.is_some(), "--time (a distributed render is planned by spp)"),
        (a.strategies.is_some(), "--strategies"),
        (!a.aov.is_empty() || a.aov_preset.is_some(), "--aov"),
        (a.lpe.is_some(), "--lpe"),
        (a.variance, "--variance"),
        (a.format.is_some(), "--format"),
        (a.ray_epsilon.is_some(), "--ray-epsilon"),
        (a.false_colour.is_some(), "--false-colour"),
        (a.live.preview || a.live.tev.is_some(), "--preview and --tev"),
    ]
    .into_iter()
    .find_map(|(given, name)| given.then_some(name))
}

/// The arguments of `python -m svetlo.distributed` for `a` on `address`: a scheduler's
/// address, or `local:N` for a local cluster of N worker processes.
pub fn module_args(a: &RenderArgs, address: &str) -> Result<Vec<OsString>> {
    if let Some(name) = refused(a) {
        return Err(Usage(format!("--dask does not take {name}")).into());
    }
    let mut v: Vec<OsString> = vec!["-m".into(), "svetlo.distributed".into(), a.scene.clone().into_os_string()];
    let mut opt = |k: &str, val: String| {
        v.push(k.into());
        v.push(val.into());
    };
    match address.strip_prefix("local:") {
        Some(n) => match n.parse::<u32>() {
            Ok(n) if n >= 1 => opt("--workers", n.to_string()),
            _ => return Err(Usage(format!("--dask local:N needs N >= 1 worker processes, got '{address}'")).into()),
        },
        None if address.trim().is_empty() => return Err(Usage("--dask needs a scheduler address (tcp://host:8786) or local:N".into()).into()),
        None => opt("--scheduler", address.to_string()),
    }
    if let Some(i) = &a.integrator {
        opt("--integrator", i.clone());
    }
    if let Some(x) = a.spp {
        opt("--spp", x.to_string());
    }
    if let Some(x) = a.seed {
        opt("--seed", x.to_string());
    }
    if let Some(x) = a.max_depth {
        opt("--max-depth", x.to_string());
    }
    if let Some(x) = a.width {
        opt("--width", x.to_string());
    }
    if let Some(x) = a.height {
        opt("--height", x.to_string());
    }
    if let Some(f) = a.filter {
        opt(
            "--filter",
            match f {
                FilterArg::Box => "box",
                FilterArg::Tent => "tent",
                FilterArg::Gaussian => "gaussian",
            }
            .into(),
        );
    }
    if let Some(s) = a.sampler {
        opt(
            "--sampler",
            match s {
                SamplerArg::Independent => "independent",
                SamplerArg::Sobol => "sobol",
            }
            .into(),
        );
    }
    if let Some(c) = a.chunks {
        opt("--chunks", c.to_string());
    }
    if a.threads > 0 {
        opt("--threads", a.threads.to_string());
    }
    for (k, val) in &a.define {
        opt("-D", format!("{k}={val}"));
    }
    if let Some(o) = &a.output {
        v.push("-o".into());
        v.push(o.clone().into_os_string());
    }
    Ok(v)
}

/// Run the render through the Python driver; its exit status is ours.
pub fn run(a: &RenderArgs, address: &str) -> Result<ExitCode> {
    let args = module_args(a, address)?;
    let py = python();
    let shown = py.to_string_lossy().into_owned();
    let hint = format!(
        "install the svetlo Python package and dask[distributed] (pip install svetlo 'dask[distributed]'), or set {PYTHON_VAR} to a Python that has them"
    );
    // Ask first, so that a missing package is named rather than shown as a traceback.
    let probe = match Command::new(&py).args(["-c", "import svetlo.distributed, distributed"]).output() {
        Ok(o) => o,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            bail!("--dask runs '{shown} -m svetlo.distributed', but there is no Python at '{shown}': {hint}")
        }
        Err(e) => return Err(e).with_context(|| format!("--dask: cannot run '{shown}'")),
    };
    if !probe.status.success() {
        let err = String::from_utf8_lossy(&probe.stderr);
        let last = err.lines().rev().find(|l| !l.trim().is_empty()).unwrap_or("it exited with an error");
        bail!("--dask: the Python at '{shown}' cannot import svetlo.distributed and dask's distributed ({}): {hint}", last.trim());
    }
    let status = Command::new(&py).args(&args).status().with_context(|| format!("--dask: cannot run '{shown}'"))?;
    Ok(match status.code() {
        Some(c) => ExitCode::from(c.clamp(0, 255) as u8),
        None => ExitCode::from(crate::EXIT_INTERRUPTED),
    })
}
