//! The fuzz smoke run of the test command, on a stable toolchain: every committed corpus
//! file (`fuzz/corpus/<target>/`) and every crash regression (`fuzz/regressions/<target>/`)
//! goes through the same entry point as its `cargo fuzz` target (`tarn_sim::fuzzing`), and so
//! do truncations and byte mutations of each (a fixed-seed generator, so a run is
//! reproducible). A panic anywhere fails the test and names the input.

use std::path::{Path, PathBuf};

type Entry = fn(&[u8]) -> bool;

const TARGETS: [(&str, Entry); 10] = [
    ("ply", tarn_sim::fuzzing::ply),
    ("kitti", tarn_sim::fuzzing::kitti),
    ("mcap", tarn_sim::fuzzing::mcap),
    ("cdr", tarn_sim::fuzzing::cdr),
    ("scene_toml", tarn_sim::fuzzing::scene_toml),
    ("color_model_json", tarn_sim::fuzzing::color_model_json),
    ("cloud_build", tarn_sim::fuzzing::cloud_build),
    ("mapper_update", tarn_sim::fuzzing::mapper_update),
    ("exports", tarn_sim::fuzzing::exports),
    ("ros1_bag", tarn_sim::fuzzing::ros1_bag),
];

fn inputs(kind: &str, target: &str) -> Vec<PathBuf> {
    let dir = Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/../.."))
        .join("fuzz")
        .join(kind)
        .join(target);
    let mut v: Vec<PathBuf> = match std::fs::read_dir(&dir) {
        Ok(r) => r
            .map(|e| e.unwrap().path())
            .filter(|p| p.is_file())
            .collect(),
        Err(_) => Vec::new(),
    };
    v.sort();
    v
}

fn run_one(target: &str, f: Entry, what: &str, data: &[u8]) -> bool {
    match std::panic::catch_unwind(|| f(data)) {
        Ok(ok) => ok,
        Err(_) => panic!("fuzz target {target} panicked on {what}"),
    }
}

/// splitmix64
fn next(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

#[test]
fn corpus_regressions_and_mutations_never_panic() {
    for (target, f) in TARGETS {
        let corpus = inputs("corpus", target);
        assert!(
            !corpus.is_empty(),
            "fuzz/corpus/{target} has {} files",
            corpus.len()
        );
        let mut accepted = 0;
        for path in corpus.iter().chain(inputs("regressions", target).iter()) {
            let data = std::fs::read(path).unwrap();
            let name = path.display().to_string();
            accepted += run_one(target, f, &name, &data) as usize;
            // Mutations of the seeds and regressions; the fuzzer's own finds run as they are.
            let fname = path.file_name().unwrap().to_string_lossy();
            if !(fname.starts_with("seed-") || name.contains("regressions")) {
                continue;
            }
            let mut state = data.len() as u64 ^ 0x7461_726e;
            // Truncations at 8 places, and 24 inputs with 1..4 bytes changed.
            for k in 1..=8 {
                let cut = data.len() * k / 9;
                run_one(target, f, &format!("{name} cut at {cut}"), &data[..cut]);
            }
            for m in 0..24 {
                let mut d = data.clone();
                if d.is_empty() {
                    break;
                }
                for _ in 0..1 + m % 4 {
                    let i = (next(&mut state) % d.len() as u64) as usize;
                    d[i] = match next(&mut state) % 4 {
                        0 => 0,
                        1 => 0xff,
                        2 => d[i] ^ (1 << (next(&mut state) % 8)),
                        _ => next(&mut state) as u8,
                    };
                }
                run_one(target, f, &format!("{name} mutation {m}"), &d);
            }
        }
        // The corpus is not all rejects: the entry points reach past the first check.
        assert!(accepted >= 1, "{target}: no corpus file was accepted");
    }
}
