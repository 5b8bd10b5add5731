//! `svetlo compare IMAGE REF [--ref-var VAR --spp N]`: relMSE, and Mitsuba's Z-test when the
//! reference's per-sample variance is given.

use crate::{Usage, EXIT_FAIL};
use anyhow::Result;
use clap::{value_parser, Args};
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use svetlo::film::compare::{rel_mse, z_test, MIN_PASS_FRACTION};
use svetlo::film::Image;
use svetlo::io::read_image;
use svetlo::Rgb;

#[derive(Args, Debug)]
pub struct CompareArgs {
    /// The image to test (EXR, PFM, PNG).
    pub image: PathBuf,
    /// The reference image.
    pub reference: PathBuf,
    /// The reference's per-sample variance image: enables the Z-test.
    #[arg(long, value_name = "VAR", requires = "spp")]
    pub ref_var: Option<PathBuf>,
    /// Samples per pixel of IMAGE (for the Z-test).
    #[arg(long, value_name = "N", requires = "ref_var", allow_negative_numbers = true, value_parser = value_parser!(u32).range(1..))]
    pub spp: Option<u32>,
}

/// Unreadable or mismatched input is the user's to fix: exit code 2.
fn load(path: &Path) -> Result<Image> {
    read_image(path).map_err(|e| Usage(e.to_string()).into())
}

fn fmt_rgb(c: Rgb) -> String {
    format!("({:.6}, {:.6}, {:.6})", c.r, c.g, c.b)
}

pub fn run(a: &CompareArgs) -> Result<ExitCode> {
    let img = load(&a.image)?;
    let reference = load(&a.reference)?;
    let relmse = rel_mse(&img, &reference).map_err(|e| Usage(e.to_string()))?;
    say!("image       {} {}x{} mean {}", a.image.display(), img.width, img.height, fmt_rgb(img.mean()));
    say!("reference   {} {}x{} mean {}", a.reference.display(), reference.width, reference.height, fmt_rgb(reference.mean()));
    say!("relMSE      {relmse:.6e}");
    let (Some(var_path), Some(spp)) = (&a.ref_var, a.spp) else {
        return Ok(ExitCode::SUCCESS);
    };
    let var = load(var_path)?;
    let t = z_test(&img, &reference, &var, spp).map_err(|e| Usage(e.to_string()))?;
    say!(
        "Z-test      {}: {:.4} % of {} pixel channels pass (need {:.2} %), {} fail; alpha {:.3e}, min p {:.3e}, {} spp",
        if t.pass { "PASS" } else { "FAIL" },
        100.0 * t.fraction_passing,
        t.channels,
        100.0 * MIN_PASS_FRACTION,
        t.failed,
        t.alpha,
        t.min_p,
        t.spp
    );
    Ok(if t.pass { ExitCode::SUCCESS } else { ExitCode::from(EXIT_FAIL) })
}
