//! Resource limits that keep hostile input from exhausting the machine: one memory budget,
//! checked against what a file's header (or a film's size) announces *before* anything of
//! that size is allocated, and the structural limits of scene files.
//!
//! The budget defaults to half the machine's physical memory (`/proc/meminfo`; 8 GiB where
//! that cannot be read) and is set process-wide with [`set_max_memory`] (the CLI's
//! `--max-memory`). A request over it is [`Error::TooLarge`], naming what asked.

use crate::error::{Error, Result};
use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

/// Elements may nest this deep in a scene file (Mitsuba scenes use about ten levels).
pub const MAX_ELEMENT_DEPTH: usize = 128;
/// Plugins (BSDFs inside BSDFs, textures, shapes of instanced groups) may nest this deep,
/// counting the levels that `<ref>` adds.
pub const MAX_PLUGIN_DEPTH: usize = 64;
/// At most this many plugin instantiations per scene: a DAG of references that fans out
/// (each BSDF using the next one twice) would otherwise build exponentially many.
pub const MAX_PLUGIN_INSTANCES: usize = 1_000_000;
/// At most this many `<include>` expansions per scene (including repeats of one file).
pub const MAX_INCLUDES: usize = 10_000;
/// At most this many bytes of scene text in all, the main file and every include together.
pub const MAX_SCENE_TEXT: u64 = 1 << 30;

/// Bytes the film of one pixel costs while rendering and writing: the accumulator (filtered
/// sum, weight, two moments), the splat buffer, the developed image and its 8-bit copy.
pub const FILM_BYTES_PER_PIXEL: u64 = 48 + 12 + 12 + 12 + 3;

/// 0: not set, use the default.
static MAX_MEMORY: AtomicU64 = AtomicU64::new(0);

/// The default budget: half the physical memory, or 8 GiB if it is unknown.
pub fn default_max_memory() -> u64 {
    physical_memory().map(|m| m / 2).unwrap_or(8 << 30)
}

fn physical_memory() -> Option<u64> {
    let info = std::fs::read_to_string("/proc/meminfo").ok()?;
    let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
    let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
    Some(kib.saturating_mul(1024))
}

/// The memory budget in bytes.
pub fn max_memory() -> u64 {
    match MAX_MEMORY.load(Ordering::Relaxed) {
        0 => default_max_memory(),
        m => m,
    }
}

/// Set the memory budget for the whole process (bytes; 0 restores the default).
pub fn set_max_memory(bytes: u64) {
    MAX_MEMORY.store(bytes, Ordering::Relaxed);
}

/// Parse a size such as `512M`, `8G`, `1.5GiB` or a plain number of bytes.
pub fn parse_size(s: &str) -> Option<u64> {
    let t = s.trim();
    let split = t.find(|c: char| !(c.is_ascii_digit() || c == '.')).unwrap_or(t.len());
    let (num, unit) = t.split_at(split);
    let v: f64 = num.parse().ok()?;
    let mult = match unit.trim().to_ascii_lowercase().as_str() {
        "" | "b" => 1u64,
        "k" | "kb" | "kib" => 1 << 10,
        "m" | "mb" | "mib" => 1 << 20,
        "g" | "gb" | "gib" => 1 << 30,
        "t" | "tb" | "tib" => 1 << 40,
        _ => return None,
    };
    let bytes = v * mult as f64;
    (1.0..1.8e19).contains(&bytes).then_some(bytes as u64)
}

/// A size for messages: 40000000000 -> "37.3 GiB".
pub fn human(bytes: u64) -> String {
    let b = bytes as f64;
    if b >= (1u64 << 30) as f64 {
        format!("{:.1} GiB", b / (1u64 << 30) as f64)
    } else if b >= (1u64 << 20) as f64 {
        format!("{:.1} MiB", b / (1u64 << 20) as f64)
    } else {
        format!("{bytes} bytes")
    }
}

/// Fail unless `bytes` fit the budget; `what` says what wanted them.
pub fn check(what: impl Into<String>, bytes: u64) -> Result<()> {
    let limit = max_memory();
    if bytes > limit {
        return Err(Error::TooLarge { what: what.into(), bytes, limit });
    }
    Ok(())
}

/// `count` items of `size` bytes each, checked (an overflowing product is over budget).
pub fn check_items(what: impl Into<String>, count: u64, size: u64) -> Result<()> {
    check(what, count.saturating_mul(size))
}

/// The film of a `width` x `height` render.
pub fn check_film(width: u32, height: u32) -> Result<()> {
    check_items(format!("a {width}x{height} film"), width as u64 * height as u64, FILM_BYTES_PER_PIXEL)
}

/// Read a whole file that must be a regular file (not a device, pipe or folder) and fit the
/// budget: `/dev/zero` named as a mesh is an error, not an endless read.
pub fn read_file(path: &Path) -> Result<Vec<u8>> {
    let io = |e| Error::Io { file: path.to_path_buf(), source: e };
    let meta = std::fs::metadata(path).map_err(io)?;
    if !meta.is_file() {
        let kind = if meta.is_dir() { "a folder" } else { "not a regular file (a device, pipe or socket)" };
        return Err(Error::Scene { file: path.to_path_buf(), msg: format!("is {kind}; expected a file") });
    }
    check(format!("reading {}", path.display()), meta.len())?;
    let mut bytes = Vec::new();
    use std::io::Read;
    // Read at most what the metadata announced (plus one byte to notice growth): a file that
    // grows while it is read cannot push past the budget.
    std::fs::File::open(path).map_err(io)?.take(meta.len() + 1).read_to_end(&mut bytes).map_err(io)?;
    check(format!("reading {}", path.display()), bytes.len() as u64)?;
    Ok(bytes)
}

/// [`read_file`] as UTF-8 text.
pub fn read_text(path: &Path) -> Result<String> {
    String::from_utf8(read_file(path)?).map_err(|e| Error::Scene { file: path.to_path_buf(), msg: format!("not UTF-8 text: {e}") })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse() {
        assert_eq!(parse_size("512M"), Some(512 << 20));
        assert_eq!(parse_size("8G"), Some(8 << 30));
        assert_eq!(parse_size("1.5GiB"), Some(3 << 29));
        assert_eq!(parse_size("4096"), Some(4096));
        assert_eq!(parse_size("-1G"), None);
        assert_eq!(parse_size("lots"), None);
        assert_eq!(parse_size("0"), None);
    }

    #[test]
    fn default_is_positive() {
        assert!(default_max_memory() >= 1 << 20);
    }

    #[test]
    fn non_regular_files_are_refused() {
        let e = read_file(Path::new("/dev/zero")).unwrap_err();
        assert!(e.to_string().contains("not a regular file"), "{e}");
        let e = read_file(Path::new("/")).unwrap_err();
        assert!(e.to_string().contains("folder"), "{e}");
    }
}
