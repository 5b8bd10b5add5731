//! Replays the fuzz corpus (`fuzz/corpus/<target>/*`) and every committed crash reproducer
//! (`tests/data/fuzz/<target>/*`) through the fuzz targets' entry points, as an ordinary
//! stable test: a crash once found and fixed stays fixed, without libFuzzer.

use std::path::{Path, PathBuf};
use svetlo::fuzzing::TARGETS;

fn files(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir).map(|d| d.filter_map(|e| e.ok().map(|e| e.path())).filter(|p| p.is_file()).collect()).unwrap_or_default();
    v.sort();
    v
}

#[test]
fn corpus_and_reproducers_replay_without_a_crash() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let mut total = 0;
    for (name, entry) in TARGETS {
        let corpus = files(&root.join("../../fuzz/corpus").join(name));
        let repro = files(&root.join("tests/data/fuzz").join(name));
        assert!(!corpus.is_empty(), "fuzz/corpus/{name} has no seeds");
        for f in corpus.iter().chain(&repro) {
            let bytes = std::fs::read(f).unwrap();
            entry(&bytes);
            total += 1;
        }
    }
    eprintln!("replayed {total} inputs");
}
