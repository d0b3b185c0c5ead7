//! The export contract (docs/design.md, "Map export"): `map.ply`, `terrain.ply`,
//! `water.ply`, `map.png` (drawn by `io::render`, behind the `render` feature),
//! `report.json`. Every file is written to a temporary name beside its destination and
//! renamed into place only when complete, so a reader never sees a partial file.

use std::collections::HashMap;
use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};
use crate::files::{stop_point, write_atomic};
use crate::grid::CellKey;
use crate::hazard::{HazardMap, MapCell};

/// The files of one build, in the order they are moved into place when they cannot be moved
/// as one folder (`report.json`, which names the set, last).
pub(crate) const OUTPUT_FILES: [&str; 5] = [
    "map.ply",
    "terrain.ply",
    "water.ply",
    "map.png",
    "report.json",
];

fn sync_dir(dir: &Path) -> Result<()> {
    // A directory is fsynced through a read-only handle on Unix; elsewhere this is a no-op.
    #[cfg(unix)]
    File::open(dir)
        .and_then(|f| f.sync_all())
        .map_err(|e| Error::io(dir, e))?;
    #[cfg(not(unix))]
    let _ = dir;
    Ok(())
}

/// An exclusive `flock` on `f`, waiting for it (`wait`) or failing at once when another
/// open file holds it. Released when every descriptor of that open file is closed, so a
/// killed process's locks go with it.
#[cfg(unix)]
fn flock(f: &File, wait: bool) -> std::io::Result<()> {
    use std::os::fd::AsRawFd;
    let op = libc::LOCK_EX | if wait { 0 } else { libc::LOCK_NB };
    // SAFETY: a descriptor `f` owns, open for the call; no memory is passed.
    if unsafe { libc::flock(f.as_raw_fd(), op) } == 0 {
        Ok(())
    } else {
        Err(std::io::Error::last_os_error())
    }
}

/// Without `flock` no staging folder is known to be abandoned: none is swept.
#[cfg(not(unix))]
fn flock(_: &File, wait: bool) -> std::io::Result<()> {
    if wait {
        Ok(())
    } else {
        Err(std::io::ErrorKind::WouldBlock.into())
    }
}

/// Atomically exchanges two directories (Linux `renameat2(RENAME_EXCHANGE)`); `Ok(false)`
/// where the system or the file system does not offer it.
#[cfg(target_os = "linux")]
fn exchange(a: &Path, b: &Path) -> std::io::Result<bool> {
    use std::os::unix::ffi::OsStrExt;
    let ca = std::ffi::CString::new(a.as_os_str().as_bytes())?;
    let cb = std::ffi::CString::new(b.as_os_str().as_bytes())?;
    // SAFETY: both paths are valid NUL-terminated strings that outlive the call.
    let r = unsafe {
        libc::syscall(
            libc::SYS_renameat2,
            libc::AT_FDCWD,
            ca.as_ptr(),
            libc::AT_FDCWD,
            cb.as_ptr(),
            libc::RENAME_EXCHANGE,
        )
    };
    if r == 0 {
        return Ok(true);
    }
    let e = std::io::Error::last_os_error();
    match e.raw_os_error() {
        Some(libc::ENOSYS | libc::EINVAL | libc::ENOTSUP) => Ok(false),
        _ => Err(e),
    }
}

#[cfg(not(target_os = "linux"))]
fn exchange(_: &Path, _: &Path) -> std::io::Result<bool> {
    Ok(false)
}

/// The outputs of one build, written into a staging folder beside the output folder and
/// moved into place together by [`Staging::commit`], so that a reader of the output folder
/// sees the previous set or the new one, never a mix, and a build that fails or is
/// interrupted before the commit leaves the previous outputs byte for byte (dropping a
/// `Staging` removes its folder).
///
/// The staging folder is `PARENT/.NAME.tarn-stage-XXXXXX` (same file system, so the moves
/// are renames). At the commit every file and the folder are fsynced; then:
///
/// - no output folder yet: the staging folder is renamed to it;
/// - an output folder holding only tarn's output files (`map.ply`, `terrain.ply`,
///   `water.ply`, `map.png`, `report.json`): the two folders are exchanged in one step (`renameat2(RENAME_EXCHANGE)` on Linux; elsewhere the old
///   folder is renamed aside first, so that for a moment there is no folder, never a
///   mixed one), and the old one is removed;
/// - an output folder that also holds other things (the default run keeps `sim/` in it):
///   those are left alone and the files are renamed into it one by one, `report.json`
///   last; each file is whole, and a reader that takes `report.json` as the mark of a
///   finished set sees one.
///
/// The output folder's parent is fsynced last.
///
/// A build killed outright (`SIGKILL`, power loss) cannot drop its staging folder. Each
/// staging folder is therefore locked (`flock`) while its build runs, and a new build of
/// the same output folder removes every staging folder of that name whose lock nobody
/// holds ([`Staging::swept`]); a concurrent build's folder is locked and left alone.
pub struct Staging {
    out: PathBuf,
    dir: Option<tempfile::TempDir>,
    /// Holds the staging folder's lock until the commit or the drop.
    _lock: File,
    swept: Vec<PathBuf>,
}

impl Staging {
    /// Creates the staging folder for the output folder `out` (and `out`'s parent if needed).
    pub fn new(out: &Path) -> Result<Self> {
        // An output folder reached through a symbolic link is replaced where it lies; the
        // link stays.
        let resolved;
        let out = match std::fs::symlink_metadata(out) {
            Ok(m) if m.file_type().is_symlink() => {
                resolved = std::fs::canonicalize(out).map_err(|e| Error::io(out, e))?;
                resolved.as_path()
            }
            _ => out,
        };
        let parent = match out.parent() {
            Some(d) if !d.as_os_str().is_empty() => d.to_path_buf(),
            _ => PathBuf::from("."),
        };
        std::fs::create_dir_all(&parent).map_err(|e| Error::io(&parent, e))?;
        let name = out
            .file_name()
            .map_or("out".into(), |n| n.to_string_lossy().into_owned());
        let prefix = format!(".{name}.tarn-stage-");
        let dir = tempfile::Builder::new()
            .prefix(&prefix)
            .tempdir_in(&parent)
            .map_err(|e| Error::io(&parent, e))?;
        let lock = File::open(dir.path()).map_err(|e| Error::io(dir.path(), e))?;
        flock(&lock, true).map_err(|e| Error::io(dir.path(), e))?;
        let swept = sweep_stale(&parent, &prefix, dir.path());
        // An ordinary folder once in place (tempfile makes it owner-only).
        #[cfg(unix)]
        {
            use std::os::unix::fs::PermissionsExt;
            std::fs::set_permissions(dir.path(), std::fs::Permissions::from_mode(0o755))
                .map_err(|e| Error::io(dir.path(), e))?;
        }
        Ok(Staging {
            out: out.to_path_buf(),
            dir: Some(dir),
            _lock: lock,
            swept,
        })
    }

    /// Staging folders of earlier builds of the same output folder that were stopped before
    /// they could remove them (killed outright), removed when this one was created.
    pub fn swept(&self) -> &[PathBuf] {
        &self.swept
    }

    /// Where the files of this build are written.
    pub fn path(&self) -> &Path {
        self.dir.as_ref().expect("until commit").path()
    }

    /// Moves the staged files into the output folder together (see [`Staging`]).
    pub fn commit(mut self) -> Result<()> {
        let stage = self.dir.take().expect("commit runs once");
        let names: Vec<std::ffi::OsString> = std::fs::read_dir(stage.path())
            .map_err(|e| Error::io(stage.path(), e))?
            .map(|e| e.map(|e| e.file_name()))
            .collect::<std::io::Result<_>>()
            .map_err(|e| Error::io(stage.path(), e))?;
        for n in &names {
            let p = stage.path().join(n);
            File::open(&p)
                .and_then(|f| f.sync_all())
                .map_err(|e| Error::io(&p, e))?;
        }
        sync_dir(stage.path())?;
        let out = &self.out;
        let parent = stage
            .path()
            .parent()
            .map_or(PathBuf::from("."), Path::to_path_buf);
        if !out.exists() {
            let stage = stage.keep();
            std::fs::rename(&stage, out).map_err(|e| Error::io(out, e))?;
            return sync_dir(&parent);
        }
        let ours = |n: &std::ffi::OsStr| OUTPUT_FILES.iter().any(|f| n == *f);
        let only_ours = std::fs::read_dir(out)
            .map_err(|e| Error::io(out, e))?
            .all(|e| e.is_ok_and(|e| ours(&e.file_name()) && e.path().is_file()));
        if only_ours {
            let stage_path = stage.keep();
            let old = if exchange(&stage_path, out).map_err(|e| Error::io(out, e))? {
                // The old outputs now sit in the staging folder's place.
                stage_path
            } else {
                let aside = parent.join(format!(
                    "{}.old",
                    stage_path.file_name().unwrap_or_default().to_string_lossy()
                ));
                std::fs::rename(out, &aside).map_err(|e| Error::io(out, e))?;
                std::fs::rename(&stage_path, out).map_err(|e| Error::io(out, e))?;
                aside
            };
            sync_dir(&parent)?;
            // Unlocked now: another build of the same folder may have swept it already.
            match std::fs::remove_dir_all(&old) {
                Err(e) if e.kind() != std::io::ErrorKind::NotFound => {
                    return Err(Error::io(&old, e))
                }
                _ => return Ok(()),
            }
        }
        let mut order: Vec<&std::ffi::OsString> = names.iter().collect();
        order.sort_by_key(|n| n.as_os_str() == "report.json");
        for n in order {
            let to = out.join(n);
            std::fs::rename(stage.path().join(n), &to).map_err(|e| Error::io(&to, e))?;
        }
        sync_dir(out)?;
        drop(stage);
        sync_dir(&parent)
    }
}

/// Removes the folders in `parent` named `prefix…` (other than `own`) whose lock no build
/// holds: staging folders of builds that were killed before they could remove them.
/// Best effort: a folder that cannot be read, locked or removed is left where it is.
fn sweep_stale(parent: &Path, prefix: &str, own: &Path) -> Vec<PathBuf> {
    let Ok(entries) = std::fs::read_dir(parent) else {
        return Vec::new();
    };
    let mut swept = Vec::new();
    for e in entries.flatten() {
        let path = e.path();
        let ours = e.file_name().to_string_lossy().starts_with(prefix);
        if !ours || path == own || !e.file_type().is_ok_and(|t| t.is_dir()) {
            continue;
        }
        // Held by a running build: `WouldBlock`. Kept until the folder is gone.
        let Ok(f) = File::open(&path) else { continue };
        if flock(&f, false).is_ok() && std::fs::remove_dir_all(&path).is_ok() {
            swept.push(path);
        }
    }
    swept.sort();
    swept
}

/// Beyond this distance (metres) of the map frame's origin a `float` coordinate is no
/// longer within 0.5 mm of the value it stands for (its step is 2^-10 m below 2^14 m, and
/// doubles beyond); `map.ply`, `terrain.ply` and `water.ply` then store `double` x y z.
pub(crate) const FLOAT_COORDINATE_LIMIT_M: f64 = 16384.0;

/// Whether vertices at these map-frame coordinates need `double` x y z (one coordinate at
/// 16 384 m or more from the origin).
pub fn needs_double(points: impl IntoIterator<Item = [f64; 3]>) -> bool {
    points
        .into_iter()
        .any(|p| p.iter().any(|c| c.abs() >= FLOAT_COORDINATE_LIMIT_M))
}

/// The header lines declaring x y z (`double` or `float`), with a comment saying why when
/// they are `double`.
fn xyz_header(double: bool) -> String {
    if double {
        format!(
            "comment coordinates double: the map frame's x y z, beyond {FLOAT_COORDINATE_LIMIT_M} m a float would lose millimetres\n\
             property double x\nproperty double y\nproperty double z\n"
        )
    } else {
        "property float x\nproperty float y\nproperty float z\n".to_string()
    }
}

fn write_xyz(w: &mut impl Write, p: [f64; 3], double: bool) -> std::io::Result<()> {
    for v in p {
        if double {
            w.write_all(&v.to_le_bytes())?;
        } else {
            w.write_all(&(v as f32).to_le_bytes())?;
        }
    }
    Ok(())
}

/// One header comment line of free text (line breaks would end the comment).
fn comment_line(text: &str) -> String {
    let t: String = text
        .chars()
        .map(|c| if c.is_control() { ' ' } else { c })
        .collect();
    format!("comment {t}\n")
}

/// `map.ply`: binary little-endian, one vertex per observed cell, the contract's schema:
/// x y z are the cell centre in the map frame, `float`, or `double` when the map reaches
/// 16 384 m from the origin (UTM-like coordinates).
pub fn write_map_ply(path: &Path, map: &HazardMap) -> Result<()> {
    write_map_ply_with(path, map, &[])
}

/// [`write_map_ply`] with extra header comment lines (e.g. the mark of a map built from a
/// damaged input: `damaged input: …`).
pub(crate) fn write_map_ply_with(path: &Path, map: &HazardMap, comments: &[String]) -> Result<()> {
    let double = needs_double(map.cells.iter().map(|c| [c.x, c.y, c.z]));
    let extra: String = comments.iter().map(|c| comment_line(c)).collect();
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment tarn map: one vertex per observed cell\n\
             comment class 0 unknown 1 ground 2 water 3 vegetation 4 obstacle 5 snow/ice\n\
             comment hazard 0 free 1 shallow water 2 deep or unknown-depth water 3 obstacle\n\
             comment resolution {}\n{extra}element vertex {}\n{}\
             property float elevation_std\nproperty float water\nproperty float depth\n\
             property uchar class\nproperty uchar hazard\n\
             property uchar red\nproperty uchar green\nproperty uchar blue\nend_header\n",
            map.resolution,
            map.cells.len(),
            xyz_header(double),
        )?;
        let mut rec = Vec::with_capacity(41);
        for (i, c) in map.cells.iter().enumerate() {
            stop_point(i)?;
            rec.clear();
            write_xyz(&mut rec, [c.x, c.y, c.z], double)?;
            for v in [c.elevation_std as f32, c.water, c.depth] {
                rec.extend_from_slice(&v.to_le_bytes());
            }
            let [r, g, b] = c.class.colour();
            rec.extend_from_slice(&[c.class as u8, c.hazard as u8, r, g, b]);
            w.write_all(&rec)?;
        }
        Ok(())
    })
}

/// Triangles of the terrain mesh over observed cells: each 2×2 block of cells gives two
/// triangles when all four are observed, one when three are, none otherwise, so no
/// triangle ever spans an unknown cell. Counter-clockwise seen from above (normals up).
pub fn terrain_triangles(map: &HazardMap) -> Vec<[u32; 3]> {
    terrain_triangles_stoppable(map).expect("no stop point fails without a stop request")
}

/// [`terrain_triangles`], ending early with an error when a stop is requested.
fn terrain_triangles_stoppable(map: &HazardMap) -> std::io::Result<Vec<[u32; 3]>> {
    let mut index: HashMap<CellKey, u32> = HashMap::with_capacity(map.cells.len());
    for (i, c) in map.cells.iter().enumerate() {
        stop_point(i)?;
        index.insert(c.key, i as u32);
    }
    let mut tris = Vec::new();
    for (i, c) in map.cells.iter().enumerate() {
        stop_point(i)?;
        let k = c.key;
        let at = |dx, dy| index.get(&CellKey::new(k.x + dx, k.y + dy)).copied();
        // The block whose lower-left corner is this cell...
        let (a, b, cc, d) = (at(0, 0), at(1, 0), at(1, 1), at(0, 1));
        // ...and the block whose lower-left corner is missing while this cell is its
        // lower-right one (no observed cell would visit it otherwise).
        if let (None, Some(b), Some(c), Some(d)) = (at(-1, 0), at(0, 0), at(0, 1), at(-1, 1)) {
            tris.push([b, c, d]);
        }
        match (a, b, cc, d) {
            (Some(a), Some(b), Some(c), Some(d)) => {
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
            (Some(a), Some(b), Some(c), None) => tris.push([a, b, c]),
            (Some(a), Some(b), None, Some(d)) => tris.push([a, b, d]),
            (Some(a), None, Some(c), Some(d)) => tris.push([a, c, d]),
            _ => {}
        }
    }
    Ok(tris)
}

/// Writes a binary PLY triangle mesh with per-vertex colours and class (`float` x y z).
pub fn write_mesh_ply(
    path: &Path,
    comment: &str,
    vertices: &[([f32; 3], [u8; 3], u8)],
    triangles: &[[u32; 3]],
) -> Result<()> {
    let v: Vec<_> = vertices
        .iter()
        .map(|(p, rgb, c)| (p.map(f64::from), *rgb, *c))
        .collect();
    write_mesh(path, comment, &v, triangles, false)
}

/// A triangle mesh in the map frame: `double` x y z where a `float` would lose
/// millimetres ([`needs_double`]), `float` otherwise.
pub(crate) fn write_map_mesh_ply(
    path: &Path,
    comment: &str,
    vertices: &[([f64; 3], [u8; 3], u8)],
    triangles: &[[u32; 3]],
) -> Result<()> {
    let double = needs_double(vertices.iter().map(|v| v.0));
    write_mesh(path, comment, vertices, triangles, double)
}

fn write_mesh(
    path: &Path,
    comment: &str,
    vertices: &[([f64; 3], [u8; 3], u8)],
    triangles: &[[u32; 3]],
    double: bool,
) -> Result<()> {
    if let Some(bad) = triangles
        .iter()
        .flatten()
        .find(|&&i| i as usize >= vertices.len())
    {
        return Err(Error::invalid(
            "mesh",
            format!("triangle index {bad} beyond {} vertices", vertices.len()),
        ));
    }
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment {comment}\nelement vertex {}\n{}\
             property uchar red\nproperty uchar green\nproperty uchar blue\nproperty uchar class\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            vertices.len(),
            xyz_header(double),
            triangles.len()
        )?;
        for (i, (p, rgb, class)) in vertices.iter().enumerate() {
            stop_point(i)?;
            write_xyz(w, *p, double)?;
            w.write_all(rgb)?;
            w.write_all(&[*class])?;
        }
        for t in triangles {
            w.write_all(&[3])?;
            for &i in t {
                w.write_all(&(i as i32).to_le_bytes())?;
            }
        }
        Ok(())
    })
}

/// `terrain.ply`: the terrain surface over observed cells, coloured by class, in the map
/// frame.
pub(crate) fn write_terrain_ply(path: &Path, map: &HazardMap) -> Result<()> {
    let verts: Vec<_> = map
        .cells
        .iter()
        .map(|c| ([c.x, c.y, c.z], c.class.colour(), c.class as u8))
        .collect();
    let tris = terrain_triangles_stoppable(map)
        .map_err(|_| Error::Interrupted(format!("writing {}", path.display())))?;
    write_map_mesh_ply(path, "tarn terrain surface", &verts, &tris)
}

/// Colour of a water-mesh vertex `d` metres below the surface: the top sheet light to dark
/// blue with the depth below it (violet where unknown), the bottom sandy.
fn water_vertex_colour(top: bool, known: bool) -> [u8; 3] {
    match (top, known) {
        (true, true) => [40, 120, 230],
        (true, false) => [150, 60, 200],
        (false, _) => [150, 120, 80],
    }
}

/// `water.ply`: the triangle mesh of every body's fitted water surface (DESIGN.md
/// contract), binary little-endian. Bodies whose depths are all known are closed solids
/// (surface, bottom at surface − depth, meeting at the shoreline: see
/// [`crate::water::body_mesh`]); others are their open top sheet. Vertex properties: `x y z`,
/// `red green blue`, `int body` (the body id), `float depth` (below the surface at that
/// vertex: 0 on the top sheet).
pub(crate) fn write_water_ply(path: &Path, map: &HazardMap) -> Result<()> {
    let mut verts: Vec<([f64; 3], [u8; 3], i32, f32)> = Vec::new();
    let mut tris: Vec<[u32; 3]> = Vec::new();
    for b in &map.bodies {
        let m = crate::water::body_mesh(b, map.resolution, &b.surface.evaluator());
        let base = verts.len() as u32;
        let known = b.depth.unknown_cells == 0;
        let bottom_vertex: std::collections::HashSet<u32> =
            m.bottom.iter().flatten().copied().collect();
        let top_vertex: std::collections::HashSet<u32> = m.top.iter().flatten().copied().collect();
        for (i, (v, d)) in m.vertices.iter().zip(&m.vertex_depth).enumerate() {
            let i = i as u32;
            let top = top_vertex.contains(&i) || !bottom_vertex.contains(&i);
            verts.push((*v, water_vertex_colour(top, known), b.id as i32, *d as f32));
        }
        tris.extend(m.top.iter().chain(&m.bottom).map(|t| t.map(|i| i + base)));
    }
    let double = needs_double(verts.iter().map(|v| v.0));
    write_atomic(path, |w| {
        write!(
            w,
            "ply\nformat binary_little_endian 1.0\ncomment tarn water surfaces: one mesh per body, \
             closed where every depth is known\nelement vertex {}\n{}\
             property uchar red\nproperty uchar green\nproperty uchar blue\n\
             property int body\nproperty float depth\n\
             element face {}\nproperty list uchar int vertex_indices\nend_header\n",
            verts.len(),
            xyz_header(double),
            tris.len()
        )?;
        for (p, rgb, body, depth) in &verts {
            write_xyz(w, *p, double)?;
            w.write_all(rgb)?;
            w.write_all(&body.to_le_bytes())?;
            w.write_all(&depth.to_le_bytes())?;
        }
        for t in &tris {
            w.write_all(&[3])?;
            for &i in t {
                w.write_all(&(i as i32).to_le_bytes())?;
            }
        }
        Ok(())
    })
}

/// Writes `map.ply`, `terrain.ply`, `water.ply` and (with feature `render`) `map.png` into
/// `dir` (created if needed).
pub fn write_map_files(dir: &Path, map: &HazardMap) -> Result<()> {
    write_map_files_marked(dir, map, &[], &[])
}

/// [`write_map_files`], with `marks` as extra comment lines in `map.ply`'s header and the
/// vehicle's `path` (map-frame x, y, metres) drawn in `map.png`.
pub fn write_map_files_marked(
    dir: &Path,
    map: &HazardMap,
    marks: &[String],
    path: &[[f64; 2]],
) -> Result<()> {
    std::fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
    // The files are independent: written side by side (each atomically), the first error
    // in this order reported.
    let ((map_ply, water_ply), (terrain_ply, png)) = rayon::join(
        || {
            (
                write_map_ply_with(&dir.join("map.ply"), map, marks),
                write_water_ply(&dir.join("water.ply"), map),
            )
        },
        || {
            rayon::join(
                || write_terrain_ply(&dir.join("terrain.ply"), map),
                || write_png(dir, map, path),
            )
        },
    );
    map_ply.and(terrain_ply).and(water_ply).and(png)
}

#[cfg(feature = "render")]
fn write_png(dir: &Path, map: &HazardMap, path: &[[f64; 2]]) -> Result<()> {
    super::render::write_map_png(&dir.join("map.png"), map, path)
}

#[cfg(not(feature = "render"))]
fn write_png(_dir: &Path, _map: &HazardMap, _path: &[[f64; 2]]) -> Result<()> {
    Ok(())
}

/// Summary of a [`MapCell`] slice used by reports.
pub fn elevation_range(cells: &[MapCell]) -> Option<(f64, f64)> {
    cells.iter().map(|c| c.z).fold(None, |acc, z| match acc {
        None => Some((z, z)),
        Some((lo, hi)) => Some((lo.min(z), hi.max(z))),
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use crate::hazard::{Class, Hazard};

    /// A dry ground cell `(x, y)` of a 10 cm map at elevation `z`.
    pub(crate) fn cell(x: i64, y: i64, z: f64) -> MapCell {
        MapCell {
            key: CellKey::new(x, y),
            x: (x as f64 + 0.5) * 0.1,
            y: (y as f64 + 0.5) * 0.1,
            z,
            elevation_std: 0.01,
            water: 0.0,
            depth: 0.0,
            class: Class::Ground,
            hazard: Hazard::Free,
            hits: 1,
            below: 0,
        }
    }

    #[test]
    fn no_triangle_spans_an_unknown_cell() {
        // A 3×3 block with the centre unknown: each 2×2 block has three observed cells and
        // gives the one triangle between them, which only touches the unknown cell's corner.
        let mut cells = vec![];
        for y in 0..3 {
            for x in 0..3 {
                if (x, y) != (1, 1) {
                    cells.push(cell(x, y, 0.0));
                }
            }
        }
        let map = HazardMap {
            resolution: 0.1,
            cells,
            bodies: vec![],
        };
        let tris = terrain_triangles(&map);
        assert_eq!(tris.len(), 4, "{tris:?}");
        // A row with a gap: no triangle at all.
        let gap = HazardMap {
            resolution: 0.1,
            cells: vec![
                cell(0, 0, 0.0),
                cell(2, 0, 0.0),
                cell(0, 1, 0.0),
                cell(2, 1, 0.0),
            ],
            bodies: vec![],
        };
        assert!(terrain_triangles(&gap).is_empty());
        let full = HazardMap {
            resolution: 0.1,
            cells: (0..3)
                .flat_map(|y| (0..3).map(move |x| cell(x, y, 0.0)))
                .collect(),
            bodies: vec![],
        };
        let tris = terrain_triangles(&full);
        assert_eq!(tris.len(), 8);
        // Counter-clockwise from above: positive signed area.
        for t in tris {
            let p = t.map(|i| (full.cells[i as usize].x, full.cells[i as usize].y));
            let area =
                (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[2].0 - p[0].0) * (p[1].1 - p[0].1);
            assert!(area > 0.0);
        }
    }

    fn staged(out: &Path, text: &str) {
        let stage = Staging::new(out).unwrap();
        for f in OUTPUT_FILES {
            std::fs::write(stage.path().join(f), text).unwrap();
        }
        stage.commit().unwrap();
    }

    #[test]
    fn staged_outputs_replace_the_set_and_leave_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        let entries = || {
            let mut v: Vec<String> = std::fs::read_dir(dir.path())
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            v.sort();
            v
        };
        // A new folder, then a folder of tarn's files replaced as one.
        staged(&out, "one");
        staged(&out, "two");
        assert_eq!(entries(), ["out"]);
        for f in OUTPUT_FILES {
            assert_eq!(std::fs::read_to_string(out.join(f)).unwrap(), "two");
        }
        // A folder holding something else keeps it; the files are replaced.
        std::fs::create_dir(out.join("sim")).unwrap();
        std::fs::write(out.join("sim/log.mcap"), "log").unwrap();
        staged(&out, "three");
        assert_eq!(entries(), ["out"]);
        assert_eq!(
            std::fs::read_to_string(out.join("sim/log.mcap")).unwrap(),
            "log"
        );
        assert_eq!(
            std::fs::read_to_string(out.join("map.ply")).unwrap(),
            "three"
        );
        // Through a symbolic link: the folder it points to is replaced, the link stays.
        #[cfg(unix)]
        {
            let link = dir.path().join("link");
            std::os::unix::fs::symlink(&out, &link).unwrap();
            staged(&link, "via link");
            assert!(std::fs::symlink_metadata(&link)
                .unwrap()
                .file_type()
                .is_symlink());
            assert_eq!(
                std::fs::read_to_string(out.join("map.ply")).unwrap(),
                "via link"
            );
            std::fs::remove_file(&link).unwrap();
        }
        // Dropped before the commit: nothing changes, nothing is left.
        let before = std::fs::read_to_string(out.join("map.ply")).unwrap();
        let stage = Staging::new(&out).unwrap();
        std::fs::write(stage.path().join("map.ply"), "four").unwrap();
        drop(stage);
        assert_eq!(entries(), ["out"]);
        assert_eq!(
            std::fs::read_to_string(out.join("map.ply")).unwrap(),
            before
        );
    }

    #[test]
    fn a_killed_builds_staging_folder_is_swept_and_a_running_ones_is_not() {
        let dir = tempfile::tempdir().unwrap();
        let out = dir.path().join("out");
        staged(&out, "one");
        // What a build killed outright leaves: a staging folder with partial files, its
        // lock gone with the process.
        let dead = dir.path().join(".out.tarn-stage-AbC123");
        std::fs::create_dir(&dead).unwrap();
        std::fs::write(dead.join("map.ply"), "half").unwrap();
        // Another output folder's staging, and a running build's: both stay.
        let other = dir.path().join(".other.tarn-stage-XyZ789");
        std::fs::create_dir(&other).unwrap();
        let running = Staging::new(&out).unwrap();
        assert_eq!(running.swept(), std::slice::from_ref(&dead));
        assert!(!dead.exists() && other.exists());
        let second = Staging::new(&out).unwrap();
        assert!(second.swept().is_empty());
        assert!(running.path().exists());
        std::fs::write(second.path().join("map.ply"), "two").unwrap();
        second.commit().unwrap();
        drop(running);
        let mut left: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        left.sort();
        assert_eq!(left, [".other.tarn-stage-XyZ789", "out"]);
        assert_eq!(std::fs::read_to_string(out.join("map.ply")).unwrap(), "two");
    }

    /// Where a binary PLY's body starts: after its `end_header` line.
    fn body_start(bytes: &[u8]) -> usize {
        bytes
            .windows(11)
            .position(|w| w == b"end_header\n")
            .unwrap()
            + 11
    }

    #[test]
    fn map_ply_coordinates_are_double_where_float_loses_millimetres() {
        let far = HazardMap {
            resolution: 0.1,
            cells: vec![cell(5_000_003, 45_000_007, 312.5)],
            bodies: vec![],
        };
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("map.ply");
        write_map_ply(&p, &far).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let h = body_start(&bytes);
        let head = String::from_utf8_lossy(&bytes[..h]);
        assert!(head.contains("property double x\nproperty double y\nproperty double z\n"));
        assert_eq!(bytes.len() - h, 41);
        let d = |o: usize| f64::from_le_bytes(bytes[h + o..h + o + 8].try_into().unwrap());
        let c = &far.cells[0];
        assert_eq!((d(0), d(8), d(16)), (c.x, c.y, c.z));
        let back = crate::io::read_map_ply(&p).unwrap();
        assert_eq!((back.cells[0].x, back.cells[0].y), (c.x, c.y));
        assert_eq!(back.cells[0].key, c.key);
        assert!(!needs_double([[16383.9, -16383.9, 0.0]]));
        assert!(needs_double([[0.0, -16384.0, 0.0]]));
    }

    #[test]
    fn map_ply_has_the_contract_layout() {
        let map = HazardMap {
            resolution: 0.1,
            cells: vec![cell(3, -2, 1.5)],
            bodies: vec![],
        };
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("map.ply");
        write_map_ply(&p, &map).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        let h = body_start(&bytes);
        assert_eq!(bytes.len() - h, 29);
        let f = |o: usize| f32::from_le_bytes(bytes[h + o..h + o + 4].try_into().unwrap());
        assert_eq!(f(0), 0.35);
        assert_eq!(f(4), -0.15);
        assert_eq!(f(8), 1.5);
        assert_eq!(bytes[h + 24], 1);
    }

    #[test]
    fn water_ply_without_bodies_is_an_empty_valid_mesh() {
        let map = HazardMap::new(0.1, vec![cell(0, 0, 0.0)]);
        let dir = tempfile::tempdir().unwrap();
        write_map_files(dir.path(), &map).unwrap();
        let bytes = std::fs::read(dir.path().join("water.ply")).unwrap();
        let text = String::from_utf8_lossy(&bytes);
        assert!(text.contains("element vertex 0\n") && text.contains("element face 0\n"));
        assert!(text.ends_with("end_header\n"));
    }
}
