//! The core library is what a vehicle embeds: its dependency tree holds no command-line,
//! progress-bar, plotting, font or simulator crate (those live in `tarn-cli` and
//! `tarn-sim`), no log storage (MCAP, SQLite, bz2, lz4: `tarn-log`), and the picture's font
//! only with the `render` feature.

use std::process::Command;

fn normal_deps(features: &[&str]) -> Vec<String> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let mut cmd = Command::new(cargo);
    cmd.current_dir(env!("CARGO_MANIFEST_DIR")).args([
        "tree",
        "--offline",
        "-p",
        "tarn",
        "-e",
        "normal",
        "--prefix",
        "none",
        "--format",
        "{p}",
    ]);
    for f in features {
        cmd.args(["--features", f]);
    }
    let out = cmd.output().expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8_lossy(&out.stdout)
        .lines()
        .filter_map(|l| l.split_whitespace().next().map(str::to_string))
        .collect()
}

const NOT_IN_THE_CORE: [&str; 14] = [
    "clap",
    "indicatif",
    "plotters",
    "dejavu",
    "ab_glyph",
    "font8x8",
    "ctrlc",
    "tarn-sim",
    "tarn-cli",
    "tarn-log",
    "mcap",
    "rusqlite",
    "bzip2",
    "lz4",
];

#[test]
fn the_core_crate_compiles_no_cli_plot_font_simulator_or_log_storage() {
    let deps = normal_deps(&[]);
    assert!(deps.iter().any(|d| d == "nalgebra"), "{deps:?}");
    for name in NOT_IN_THE_CORE {
        assert!(
            !deps.iter().any(|d| d == name),
            "{name} is in the core's tree"
        );
    }
}

#[test]
fn the_picture_brings_only_its_font() {
    let deps = normal_deps(&["render"]);
    assert!(deps.iter().any(|d| d == "font8x8"), "{deps:?}");
    for name in NOT_IN_THE_CORE.iter().filter(|n| **n != "font8x8") {
        assert!(
            !deps.iter().any(|d| d == name),
            "{name} is in the core's tree"
        );
    }
}
