//! `tarn info` reads a cloud through the library and reports what it holds.

use std::process::Command;

fn tarn(args: &[&std::ffi::OsStr]) -> (bool, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_tarn"))
        .args(args)
        .env("RUST_BACKTRACE", "0")
        .output()
        .unwrap();
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn info_reports_points_returns_and_channels() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("c.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 3\nproperty double x\nproperty double y\n\
         property double z\nproperty uchar intensity\nend_header\n\
         500000.25 4000000.5 10 7\nnan 0 0 8\n500001.25 4000002.5 11 9\n",
    )
    .unwrap();
    let (ok, out, err) = tarn(&["info".as_ref(), path.as_os_str()]);
    assert!(ok, "{err}");
    assert!(out.contains("points    3 (unorganized)"), "{out}");
    assert!(
        out.contains("returns   2 valid, 1 missing (33.3 %)"),
        "{out}"
    );
    assert!(out.contains("channels  intensity"), "{out}");
    assert!(out.contains("x (map)   500000.250 .. 500001.250"), "{out}");
    assert!(
        out.contains("y (map)   4000000.500 .. 4000002.500"),
        "{out}"
    );
}

#[test]
fn info_fails_clearly_on_bad_input() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("bad.ply");
    std::fs::write(
        &path,
        "ply\nformat ascii 1.0\nelement vertex 2\nend_header\n",
    )
    .unwrap();
    let (ok, _, err) = tarn(&["info".as_ref(), path.as_os_str()]);
    assert!(!ok);
    assert!(
        err.contains("bad.ply") && err.contains("no property `x`"),
        "{err}"
    );
    let (ok, _, err) = tarn(&[
        "info".as_ref(),
        "scan.bin".as_ref(),
        "--rings".as_ref(),
        "0".as_ref(),
    ]);
    assert!(!ok);
    assert!(err.contains("scan.bin"), "{err}");
}
