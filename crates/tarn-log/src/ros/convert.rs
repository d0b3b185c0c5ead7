//! Conversions between ROS messages and tarn's own types: `PointCloud2` ↔ [`PointCloud`],
//! `Image` → [`Image`], `CameraInfo` ↔ [`CameraModel`].
//!
//! Errors are plain messages; the log reader adds the file and message location.

use super::msgs::{datatype, CameraInfoMsg, Header, ImageMsg, PointCloud2Msg, PointField};
use crate::geom::{CameraModel, Distortion, PointCloud};
use crate::sensor::{Image, Pixels};

fn read_scalar(data: &[u8], at: usize, dt: u8, big: bool) -> f64 {
    macro_rules! rd {
        ($t:ty, $n:expr) => {{
            let a: [u8; $n] = data[at..at + $n].try_into().expect("checked by caller");
            if big {
                <$t>::from_be_bytes(a) as f64
            } else {
                <$t>::from_le_bytes(a) as f64
            }
        }};
    }
    match dt {
        datatype::INT8 => data[at] as i8 as f64,
        datatype::UINT8 => data[at] as f64,
        datatype::INT16 => rd!(i16, 2),
        datatype::UINT16 => rd!(u16, 2),
        datatype::INT32 => rd!(i32, 4),
        datatype::UINT32 => rd!(u32, 4),
        datatype::FLOAT32 => rd!(f32, 4),
        datatype::FLOAT64 => rd!(f64, 8),
        _ => f64::NAN,
    }
}

/// Checked accessor for one scalar field of a PointCloud2.
#[derive(Clone, Copy)]
struct FieldReader {
    offset: usize,
    datatype: u8,
}

fn field(msg: &PointCloud2Msg, name: &str) -> Result<Option<FieldReader>, String> {
    let Some(f) = msg.fields.iter().find(|f| f.name == name) else {
        return Ok(None);
    };
    let size = datatype::size(f.datatype)
        .ok_or_else(|| format!("field {name:?} has unknown datatype {}", f.datatype))?;
    let end = f.offset as usize + size * (f.count.max(1) as usize);
    if end > msg.point_step as usize {
        return Err(format!(
            "field {name:?} (offset {}, {} × {size} bytes) exceeds point_step {}",
            f.offset,
            f.count.max(1),
            msg.point_step
        ));
    }
    Ok(Some(FieldReader {
        offset: f.offset as usize,
        datatype: f.datatype,
    }))
}

/// Decodes a `PointCloud2` into a [`PointCloud`] in the message's frame (pose identity,
/// sensor at the frame origin, stamp from the header).
///
/// Any field order, datatype and endianness; `x`, `y`, `z` are required; `intensity`,
/// `reflectivity` and a packed `rgb`/`rgba` float are mapped when present. A point with a
/// non-finite coordinate or with x = y = z = 0 is a missing return and becomes NaN.
/// An unorganized cloud (height 1) with a `ring` field is organized by it
/// ([`organize_by_ring`]).
pub fn pointcloud2_to_cloud(msg: &PointCloud2Msg) -> Result<PointCloud, String> {
    let (h, w) = (msg.height as usize, msg.width as usize);
    let ps = msg.point_step as usize;
    let rs = msg.row_step as usize;
    let row_bytes = w
        .checked_mul(ps)
        .ok_or_else(|| format!("width {w} × point_step {ps} overflows"))?;
    if rs < row_bytes {
        return Err(format!(
            "row_step {rs} is less than width {w} × point_step {ps} = {row_bytes}"
        ));
    }
    let need = if h == 0 || w == 0 {
        0
    } else {
        (h - 1)
            .checked_mul(rs)
            .and_then(|v| v.checked_add(row_bytes))
            .ok_or_else(|| format!("height {h} × row_step {rs} overflows"))?
    };
    if need > msg.data.len() {
        return Err(format!(
            "declared sizes exceed the data: height {h}, width {w}, point_step {ps}, row_step {rs} need {need} bytes, data has {}",
            msg.data.len()
        ));
    }
    let fx = field(msg, "x")?;
    let fy = field(msg, "y")?;
    let fz = field(msg, "z")?;
    let (Some(fx), Some(fy), Some(fz)) = (fx, fy, fz) else {
        let names: Vec<&str> = msg.fields.iter().map(|f| f.name.as_str()).collect();
        return Err(format!("fields {names:?} lack one of x, y, z"));
    };
    let fi = field(msg, "intensity")?;
    let fr = field(msg, "reflectivity")?;
    let frgb = match field(msg, "rgb")? {
        Some(f) => Some(f),
        None => field(msg, "rgba")?,
    };
    let big = msg.is_bigendian;
    let d = &msg.data;
    let n = h * w;
    let mut xyz = Vec::with_capacity(n);
    let mut inten = fi.map(|_| Vec::with_capacity(n));
    let mut refl = fr.map(|_| Vec::with_capacity(n));
    let mut rgb = frgb.map(|_| Vec::with_capacity(n));
    let fast_xyz = !big
        && [fx, fy, fz].iter().all(|f| f.datatype == datatype::FLOAT32)
        && fy.offset == fx.offset + 4
        && fz.offset == fx.offset + 8;
    for row in 0..h {
        for col in 0..w {
            let base = row * rs + col * ps;
            let p = if fast_xyz {
                let o = base + fx.offset;
                let g =
                    |k: usize| f32::from_le_bytes(d[o + k..o + k + 4].try_into().expect("checked"));
                [g(0), g(4), g(8)]
            } else {
                [
                    read_scalar(d, base + fx.offset, fx.datatype, big) as f32,
                    read_scalar(d, base + fy.offset, fy.datatype, big) as f32,
                    read_scalar(d, base + fz.offset, fz.datatype, big) as f32,
                ]
            };
            let missing = p.iter().any(|v| !v.is_finite()) || p == [0.0; 3];
            xyz.push(if missing { [f32::NAN; 3] } else { p });
            if let (Some(f), Some(v)) = (fi, inten.as_mut()) {
                v.push(read_scalar(d, base + f.offset, f.datatype, big) as f32);
            }
            if let (Some(f), Some(v)) = (fr, refl.as_mut()) {
                v.push(read_scalar(d, base + f.offset, f.datatype, big) as f32);
            }
            if let (Some(f), Some(v)) = (frgb, rgb.as_mut()) {
                // PCL packs 0x00RRGGBB into the bits of a float32 (or a uint32).
                let o = base + f.offset;
                let a: [u8; 4] = d[o..o + 4].try_into().expect("checked");
                let bits = if big {
                    u32::from_be_bytes(a)
                } else {
                    u32::from_le_bytes(a)
                };
                v.push([(bits >> 16) as u8, (bits >> 8) as u8, bits as u8]);
            }
        }
    }
    let mut c = PointCloud::organized(h.max(1), if h == 0 { 0 } else { w }, xyz)
        .map_err(|e| e.to_string())?;
    c.intensity = inten;
    c.reflectivity = refl;
    c.rgb = rgb;
    c.stamp = msg.header.stamp.to_sec();
    if h == 1 && w > 1 {
        if let Some(fr) = field(msg, "ring")? {
            let rings: Vec<f64> = (0..w)
                .map(|col| read_scalar(d, col * ps + fr.offset, fr.datatype, big))
                .collect();
            c = organize_by_ring(&c, &rings)?;
        }
    }
    Ok(c)
}

/// Most rings an unorganized cloud's `ring` field may name.
pub(crate) const MAX_RINGS: usize = 1024;

fn wrap_pi(a: f64) -> f64 {
    let t = std::f64::consts::TAU;
    let r = a.rem_euclid(t);
    if r > std::f64::consts::PI {
        r - t
    } else {
        r
    }
}

/// Organizes an unorganized scan (one row) into rows by `ring[i]` (the ring of point `i`,
/// as Velodyne and Ouster drivers publish it) and columns by azimuth, so that the scan
/// lines the lidar cues walk exist.
///
/// When every ring holds the same number of points (a driver that keeps missing returns
/// as NaN or zero points), each ring's points keep their order: column `k` is the ring's
/// `k`-th point. Otherwise (a driver that drops missing returns) columns are azimuth bins:
/// the bin width is the median azimuth step between successive returns of a ring, the
/// columns run in the scan's direction from the first return of the fullest ring, and a
/// slot no return falls in is a missing return (NaN). Of two returns in one slot the first
/// is kept. Per-point channels move with their points (0 in an empty slot).
pub fn organize_by_ring(cloud: &PointCloud, ring: &[f64]) -> Result<PointCloud, String> {
    let n = cloud.len();
    if ring.len() != n {
        return Err(format!("{} ring values for {n} points", ring.len()));
    }
    let lens = [
        ("intensity", cloud.intensity.as_ref().map(Vec::len)),
        ("reflectivity", cloud.reflectivity.as_ref().map(Vec::len)),
        ("rgb", cloud.rgb.as_ref().map(Vec::len)),
    ];
    for (name, len) in lens {
        if len.is_some_and(|l| l != n) {
            return Err(format!("{name} has {len:?} values for {n} points"));
        }
    }
    let mut by_ring: Vec<Vec<usize>> = Vec::new();
    for (i, &r) in ring.iter().enumerate() {
        if !(r.is_finite() && r >= 0.0 && r.fract() == 0.0 && (r as usize) < MAX_RINGS) {
            return Err(format!(
                "point {i} has ring {r}: not a ring number (0..{MAX_RINGS})"
            ));
        }
        let r = r as usize;
        if by_ring.len() <= r {
            by_ring.resize_with(r + 1, Vec::new);
        }
        by_ring[r].push(i);
    }
    let rows = by_ring.len().max(1);
    let max_count = by_ring.iter().map(Vec::len).max().unwrap_or(0);
    let same = by_ring.iter().all(|v| v.len() == max_count);
    let azimuth = |i: usize| {
        let [x, y, _] = cloud.xyz[i];
        (y as f64).atan2(x as f64)
    };
    // slots[r * cols + c] = the point there.
    let (cols, slots): (usize, Vec<Option<usize>>) = if same {
        (
            max_count,
            by_ring.iter().flatten().map(|&i| Some(i)).collect(),
        )
    } else {
        // Signed azimuth steps between successive returns of each ring.
        let mut steps: Vec<f64> = Vec::new();
        for v in &by_ring {
            let valid: Vec<usize> = v.iter().copied().filter(|&i| cloud.is_valid(i)).collect();
            for w in valid.windows(2) {
                let d = wrap_pi(azimuth(w[1]) - azimuth(w[0]));
                if d.abs() > 1e-9 {
                    steps.push(d);
                }
            }
        }
        let dir = if steps.iter().filter(|d| **d < 0.0).count() * 2 > steps.len() {
            -1.0
        } else {
            1.0
        };
        let mut mags: Vec<f64> = steps.iter().map(|d| d * dir).filter(|d| *d > 0.0).collect();
        mags.sort_by(f64::total_cmp);
        let step = mags.get(mags.len() / 2).copied().unwrap_or(0.0);
        let cols = if step > 0.0 {
            ((std::f64::consts::TAU / step).round() as usize).clamp(max_count, max_count * 8)
        } else {
            max_count
        };
        if rows.saturating_mul(cols) > n.saturating_mul(8).max(4096) {
            return Err(format!(
                "{rows} rings × {cols} azimuth steps of {step:.3e} rad is too many slots for {n} points"
            ));
        }
        let fullest = by_ring
            .iter()
            .max_by_key(|v| v.len())
            .and_then(|v| v.iter().copied().find(|&i| cloud.is_valid(i)));
        let mut slots = vec![None; rows * cols];
        match (fullest, step > 0.0) {
            (Some(first), true) => {
                let az0 = azimuth(first);
                for (r, v) in by_ring.iter().enumerate() {
                    for &i in v.iter().filter(|&&i| cloud.is_valid(i)) {
                        let a = (dir * (azimuth(i) - az0)).rem_euclid(std::f64::consts::TAU);
                        let c = ((a / step).round() as usize) % cols;
                        slots[r * cols + c].get_or_insert(i);
                    }
                }
            }
            _ => {
                for (r, v) in by_ring.iter().enumerate() {
                    for (c, &i) in v.iter().enumerate() {
                        slots[r * cols + c] = Some(i);
                    }
                }
            }
        }
        (cols, slots)
    };
    let xyz = slots
        .iter()
        .map(|s| s.map_or([f32::NAN; 3], |i| cloud.xyz[i]))
        .collect();
    let mut out = PointCloud::organized(rows, cols, xyz).map_err(|e| e.to_string())?;
    let pick = |v: &Vec<f32>| slots.iter().map(|s| s.map_or(0.0, |i| v[i])).collect();
    out.intensity = cloud.intensity.as_ref().map(pick);
    out.reflectivity = cloud.reflectivity.as_ref().map(pick);
    out.rgb = cloud
        .rgb
        .as_ref()
        .map(|v| slots.iter().map(|s| s.map_or([0; 3], |i| v[i])).collect());
    out.frame_to_map = cloud.frame_to_map;
    out.sensor_origin = cloud.sensor_origin;
    out.stamp = cloud.stamp;
    Ok(out)
}

/// Encodes a [`PointCloud`] as a little-endian `PointCloud2` with float32 `x y z`, then
/// float32 `intensity` and `reflectivity` when present. Missing returns stay NaN.
pub fn cloud_to_pointcloud2(cloud: &PointCloud, header: Header) -> PointCloud2Msg {
    let mut fields = Vec::new();
    let mut push = |name: &str, offset: u32| {
        fields.push(PointField {
            name: name.into(),
            offset,
            datatype: datatype::FLOAT32,
            count: 1,
        })
    };
    push("x", 0);
    push("y", 4);
    push("z", 8);
    let mut step = 12;
    if cloud.intensity.is_some() {
        push("intensity", step);
        step += 4;
    }
    if cloud.reflectivity.is_some() {
        push("reflectivity", step);
        step += 4;
    }
    let mut data = Vec::with_capacity(cloud.len() * step as usize);
    for i in 0..cloud.len() {
        for v in cloud.xyz[i] {
            data.extend_from_slice(&v.to_le_bytes());
        }
        if let Some(v) = &cloud.intensity {
            data.extend_from_slice(&v[i].to_le_bytes());
        }
        if let Some(v) = &cloud.reflectivity {
            data.extend_from_slice(&v[i].to_le_bytes());
        }
    }
    PointCloud2Msg {
        header,
        height: cloud.rows as u32,
        width: cloud.cols as u32,
        fields,
        is_bigendian: false,
        point_step: step,
        row_step: step * cloud.cols as u32,
        data,
        is_dense: cloud.valid_count() == cloud.len(),
    }
}

/// Decodes an `Image` with encoding rgb8, bgr8, mono8 or mono16 (8UC1/16UC1 accepted as
/// aliases) and any row step ≥ width × bytes per pixel.
pub fn decode_image(msg: &ImageMsg) -> Result<Image, String> {
    let (h, w, step) = (msg.height as usize, msg.width as usize, msg.step as usize);
    let bpp = match msg.encoding.as_str() {
        "rgb8" | "bgr8" => 3,
        "mono8" | "8UC1" => 1,
        "mono16" | "16UC1" => 2,
        e => {
            return Err(format!(
                "unsupported image encoding {e:?} (rgb8, bgr8, mono8, mono16)"
            ))
        }
    };
    if step < w * bpp {
        return Err(format!(
            "step {step} is less than width {w} × {bpp} bytes per pixel"
        ));
    }
    let need = step.checked_mul(h).ok_or("step × height overflows")?;
    if need > msg.data.len() {
        return Err(format!(
            "step {step} × height {h} = {need} bytes exceeds the data ({} bytes)",
            msg.data.len()
        ));
    }
    let rows = (0..h).map(|r| &msg.data[r * step..r * step + w * bpp]);
    let pixels = match msg.encoding.as_str() {
        "rgb8" => Pixels::Rgb8(
            rows.flat_map(|r| r.chunks_exact(3).map(|p| [p[0], p[1], p[2]]))
                .collect(),
        ),
        "bgr8" => Pixels::Rgb8(
            rows.flat_map(|r| r.chunks_exact(3).map(|p| [p[2], p[1], p[0]]))
                .collect(),
        ),
        "mono8" | "8UC1" => Pixels::Mono8(rows.flat_map(|r| r.iter().copied()).collect()),
        _ => {
            let big = msg.is_bigendian != 0;
            Pixels::Mono16(
                rows.flat_map(|r| {
                    r.chunks_exact(2).map(move |p| {
                        if big {
                            u16::from_be_bytes([p[0], p[1]])
                        } else {
                            u16::from_le_bytes([p[0], p[1]])
                        }
                    })
                })
                .collect(),
            )
        }
    };
    Ok(Image {
        width: w,
        height: h,
        pixels,
        frame_id: msg.header.frame_id.clone(),
        stamp: msg.header.stamp.to_sec(),
    })
}

/// Encodes an [`Image`] as a tightly packed `Image` message (rgb8, mono8 or little-endian
/// mono16).
pub fn encode_image(img: &Image, header: Header) -> ImageMsg {
    let (encoding, bpp, data): (&str, usize, Vec<u8>) = match &img.pixels {
        Pixels::Rgb8(p) => ("rgb8", 3, p.iter().flatten().copied().collect()),
        Pixels::Mono8(p) => ("mono8", 1, p.clone()),
        Pixels::Mono16(p) => (
            "mono16",
            2,
            p.iter().flat_map(|v| v.to_le_bytes()).collect(),
        ),
    };
    ImageMsg {
        header,
        height: img.height as u32,
        width: img.width as u32,
        encoding: encoding.into(),
        is_bigendian: 0,
        step: (img.width * bpp) as u32,
        data,
    }
}

/// A camera model from `CameraInfo` (plumb_bob / rational-free equidistant, or none).
pub fn camera_from_info(msg: &CameraInfoMsg) -> Result<CameraModel, String> {
    let distortion = match msg.distortion_model.as_str() {
        "plumb_bob" => {
            let mut c = [0.0; 5];
            for (i, v) in msg.d.iter().take(5).enumerate() {
                c[i] = *v;
            }
            if msg.d.len() > 5 && msg.d[5..].iter().any(|v| *v != 0.0) {
                return Err(format!(
                    "plumb_bob with {} non-zero coefficients; only k1 k2 p1 p2 k3 are supported",
                    msg.d.len()
                ));
            }
            Distortion::PlumbBob(c)
        }
        "equidistant" => {
            if msg.d.len() < 4 {
                return Err(format!(
                    "equidistant needs 4 coefficients, got {}",
                    msg.d.len()
                ));
            }
            Distortion::Equidistant([msg.d[0], msg.d[1], msg.d[2], msg.d[3]])
        }
        "" if msg.d.iter().all(|v| *v == 0.0) => Distortion::None,
        m => {
            return Err(format!(
                "unsupported distortion model {m:?} (plumb_bob, equidistant)"
            ))
        }
    };
    CameraModel::new(
        msg.width as usize,
        msg.height as usize,
        [msg.k[0], msg.k[4], msg.k[2], msg.k[5]],
        distortion,
        msg.header.frame_id.clone(),
    )
    .map_err(|e| e.to_string())
}

/// A `CameraInfo` message for a camera model (R identity, P = [K | 0]).
pub fn camera_to_info(cam: &CameraModel, header: Header) -> CameraInfoMsg {
    let [fx, fy, cx, cy] = cam.intrinsics();
    let (model, d) = match cam.distortion {
        Distortion::None => ("plumb_bob", vec![0.0; 5]),
        Distortion::PlumbBob(c) => ("plumb_bob", c.to_vec()),
        Distortion::Equidistant(c) => ("equidistant", c.to_vec()),
    };
    CameraInfoMsg {
        header,
        height: cam.height as u32,
        width: cam.width as u32,
        distortion_model: model.into(),
        d,
        k: [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0],
        r: [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0],
        p: [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0],
        binning_x: 0,
        binning_y: 0,
        roi: Default::default(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ros::msgs::Time;
    use proptest::prelude::*;

    #[test]
    fn ring_numbers_must_be_small_whole_numbers() {
        let c = PointCloud::unorganized(vec![[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]);
        for bad in [-1.0, 0.5, f64::NAN, MAX_RINGS as f64] {
            let e = organize_by_ring(&c, &[0.0, bad]).unwrap_err();
            assert!(e.contains("not a ring number"), "{e}");
        }
        assert!(organize_by_ring(&c, &[0.0]).is_err());
        let mut short = c.clone();
        short.intensity = Some(vec![1.0]);
        assert!(organize_by_ring(&short, &[0.0, 0.0]).is_err());
    }

    #[test]
    fn rings_of_equal_count_keep_their_order_and_channels() {
        // Two rings of three points, published interleaved.
        let xyz: Vec<[f32; 3]> = (0..6).map(|i| [1.0 + i as f32, 0.5, 0.0]).collect();
        let mut c = PointCloud::unorganized(xyz.clone());
        c.intensity = Some((0..6).map(|i| i as f32).collect());
        let rings = [1.0, 0.0, 1.0, 0.0, 1.0, 0.0];
        let o = organize_by_ring(&c, &rings).unwrap();
        assert_eq!((o.rows, o.cols), (2, 3));
        assert_eq!(o.xyz, vec![xyz[1], xyz[3], xyz[5], xyz[0], xyz[2], xyz[4]]);
        assert_eq!(o.intensity.unwrap(), vec![1.0, 3.0, 5.0, 0.0, 2.0, 4.0]);
    }

    #[test]
    fn dropped_returns_leave_empty_azimuth_bins() {
        // 8 columns at 45° steps; ring 1 lacks columns 2 and 5.
        let at = |c: usize, z: f32| {
            let a = c as f64 * std::f64::consts::FRAC_PI_4;
            [10.0 * a.cos() as f32, 10.0 * a.sin() as f32, z]
        };
        let mut xyz = Vec::new();
        let mut rings = Vec::new();
        for r in 0..2 {
            for c in 0..8 {
                if r == 1 && (c == 2 || c == 5) {
                    continue;
                }
                xyz.push(at(c, r as f32));
                rings.push(r as f64);
            }
        }
        let o = organize_by_ring(&PointCloud::unorganized(xyz), &rings).unwrap();
        assert_eq!((o.rows, o.cols), (2, 8));
        for c in 0..8 {
            assert_eq!(o.xyz[c], at(c, 0.0));
            let slot = o.xyz[8 + c];
            if c == 2 || c == 5 {
                assert!(slot[0].is_nan());
            } else {
                assert_eq!(slot, at(c, 1.0));
            }
        }
    }

    fn put(data: &mut [u8], at: usize, dt: u8, big: bool, v: f64) {
        macro_rules! w {
            ($t:ty) => {{
                let b = if big {
                    (v as $t).to_be_bytes()
                } else {
                    (v as $t).to_le_bytes()
                };
                data[at..at + b.len()].copy_from_slice(&b);
            }};
        }
        match dt {
            datatype::INT8 => w!(i8),
            datatype::UINT8 => w!(u8),
            datatype::INT16 => w!(i16),
            datatype::UINT16 => w!(u16),
            datatype::INT32 => w!(i32),
            datatype::UINT32 => w!(u32),
            datatype::FLOAT32 => w!(f32),
            _ => w!(f64),
        }
    }

    fn hdr() -> Header {
        Header {
            stamp: Time {
                sec: 3,
                nanosec: 500_000_000,
            },
            frame_id: "lidar".into(),
        }
    }

    proptest! {
        /// Any field order, datatypes, endianness, padding and row padding decode to the
        /// values that were packed.
        #[test]
        fn any_layout_decodes(
            big in any::<bool>(), h in 1usize..4, w in 1usize..5, order in Just([0usize, 1, 2, 3, 4]).prop_shuffle(),
            xyz_dt in prop_oneof![Just(datatype::FLOAT32), Just(datatype::FLOAT64), Just(datatype::INT16)],
            int_dt in 1u8..=8, gap in 0usize..3, row_pad in 0usize..7,
            vals in proptest::collection::vec(-100i16..100, 60),
        ) {
            let names = ["x", "y", "z", "intensity", "reflectivity"];
            let mut fields = Vec::new();
            let mut off = 0usize;
            for &k in &order {
                let dt = if k < 3 { xyz_dt } else { int_dt };
                fields.push(PointField { name: names[k].into(), offset: off as u32, datatype: dt, count: 1 });
                off += datatype::size(dt).unwrap() + gap;
            }
            let ps = off;
            let rs = ps * w + row_pad;
            let mut data = vec![0u8; rs * h];
            let value = |i: usize, k: usize| {
                let v = vals[(i * 5 + k) % vals.len()] as f64;
                if k >= 3 && matches!(int_dt, datatype::UINT8 | datatype::UINT16 | datatype::UINT32) { v.abs() } else if k >= 3 && matches!(int_dt, datatype::INT8) { v.clamp(-100.0, 100.0) } else { v }
            };
            for r in 0..h { for c in 0..w {
                let i = r * w + c;
                for f in &fields {
                    let k = names.iter().position(|n| *n == f.name).unwrap();
                    put(&mut data, r * rs + c * ps + f.offset as usize, f.datatype, big, value(i, k));
                }
            }}
            let msg = PointCloud2Msg { header: hdr(), height: h as u32, width: w as u32, fields,
                is_bigendian: big, point_step: ps as u32, row_step: rs as u32, data, is_dense: false };
            let c = pointcloud2_to_cloud(&msg).unwrap();
            prop_assert_eq!((c.rows, c.cols), (h, w));
            prop_assert!((c.stamp - 3.5).abs() < 1e-12);
            for i in 0..h * w {
                let p = [value(i, 0) as f32, value(i, 1) as f32, value(i, 2) as f32];
                if p == [0.0; 3] { prop_assert!(!c.is_valid(i)); } else { prop_assert_eq!(c.xyz[i], p); }
                prop_assert_eq!(c.intensity.as_ref().unwrap()[i], value(i, 3) as f32);
                prop_assert_eq!(c.reflectivity.as_ref().unwrap()[i], value(i, 4) as f32);
            }
        }

        #[test]
        fn cloud_round_trip(n in 1usize..20, rows in 1usize..3, seed in any::<u32>()) {
            let xyz: Vec<[f32; 3]> = (0..n * rows).map(|i| {
                if (i as u32 + seed) % 5 == 0 { [f32::NAN; 3] } else { [i as f32, seed as f32 * 1e-3, -(i as f32)] }
            }).collect();
            let mut c = PointCloud::organized(rows, n, xyz).unwrap();
            c.intensity = Some((0..n * rows).map(|i| i as f32 * 2.0).collect());
            c.stamp = 3.5;
            let back = pointcloud2_to_cloud(&cloud_to_pointcloud2(&c, hdr())).unwrap();
            prop_assert_eq!((back.rows, back.cols), (rows, n));
            for i in 0..n * rows {
                prop_assert_eq!(back.is_valid(i), c.is_valid(i));
                if c.is_valid(i) { prop_assert_eq!(back.xyz[i], c.xyz[i]); }
            }
            prop_assert_eq!(back.intensity, c.intensity);
        }

        #[test]
        fn image_any_step(w in 1usize..6, h in 1usize..5, pad in 0usize..5, enc in 0usize..4, seed in any::<u8>()) {
            let (name, bpp) = [("rgb8", 3), ("bgr8", 3), ("mono8", 1), ("mono16", 2)][enc];
            let step = w * bpp + pad;
            let data: Vec<u8> = (0..step * h).map(|i| (i as u8).wrapping_mul(31).wrapping_add(seed)).collect();
            let msg = ImageMsg { header: hdr(), height: h as u32, width: w as u32, encoding: name.into(),
                is_bigendian: 0, step: step as u32, data: data.clone() };
            let img = decode_image(&msg).unwrap();
            for r in 0..h { for c in 0..w {
                let b = &data[r * step + c * bpp..];
                let i = r * w + c;
                match &img.pixels {
                    Pixels::Rgb8(p) if name == "rgb8" => prop_assert_eq!(p[i], [b[0], b[1], b[2]]),
                    Pixels::Rgb8(p) => prop_assert_eq!(p[i], [b[2], b[1], b[0]]),
                    Pixels::Mono8(p) => prop_assert_eq!(p[i], b[0]),
                    Pixels::Mono16(p) => prop_assert_eq!(p[i], u16::from_le_bytes([b[0], b[1]])),
                }
            }}
            if name != "bgr8" {
                let again = decode_image(&encode_image(&img, hdr())).unwrap();
                prop_assert_eq!(again, img);
            }
        }
    }

    #[test]
    fn zero_xyz_is_a_missing_return() {
        let mut c = PointCloud::organized(1, 2, vec![[0.0; 3], [1.0, 2.0, 3.0]]).unwrap();
        c.stamp = 0.0;
        let back = pointcloud2_to_cloud(&cloud_to_pointcloud2(&c, hdr())).unwrap();
        assert!(!back.is_valid(0));
        assert!(back.xyz[0][0].is_nan());
        assert_eq!(back.xyz[1], [1.0, 2.0, 3.0]);
    }

    #[test]
    fn cloud_sizes_exceeding_data_are_an_error() {
        let c = PointCloud::organized(2, 3, vec![[1.0; 3]; 6]).unwrap();
        let mut m = cloud_to_pointcloud2(&c, hdr());
        m.height = 3;
        let e = pointcloud2_to_cloud(&m).unwrap_err();
        assert!(
            e.contains("exceed") && e.contains("need 108 bytes, data has 72"),
            "{e}"
        );
        let mut m = cloud_to_pointcloud2(&c, hdr());
        m.point_step = 8; // x y z float32 need 12
        assert!(pointcloud2_to_cloud(&m)
            .unwrap_err()
            .contains("exceeds point_step"));
        let mut m = cloud_to_pointcloud2(&c, hdr());
        m.row_step = 10;
        assert!(pointcloud2_to_cloud(&m).unwrap_err().contains("row_step"));
        let mut m = cloud_to_pointcloud2(&c, hdr());
        m.fields.retain(|f| f.name != "z");
        assert!(pointcloud2_to_cloud(&m).unwrap_err().contains("lack"));
    }

    #[test]
    fn image_step_times_height_exceeding_data_is_an_error() {
        let msg = ImageMsg {
            header: hdr(),
            height: 4,
            width: 2,
            encoding: "mono8".into(),
            is_bigendian: 0,
            step: 3,
            data: vec![0; 11],
        };
        let e = decode_image(&msg).unwrap_err();
        assert!(
            e.contains("step 3 × height 4 = 12 bytes exceeds the data (11 bytes)"),
            "{e}"
        );
        let msg = ImageMsg {
            step: 1,
            data: vec![0; 100],
            ..msg
        };
        assert!(decode_image(&msg).unwrap_err().contains("less than width"));
        let msg = ImageMsg {
            encoding: "yuv422".into(),
            ..msg
        };
        assert!(decode_image(&msg).unwrap_err().contains("unsupported"));
    }

    #[test]
    fn camera_info_round_trip() {
        for d in [
            Distortion::PlumbBob([0.1, -0.02, 0.001, 0.0, 0.003]),
            Distortion::Equidistant([0.01, 0.002, 0.0, -0.001]),
        ] {
            let cam =
                CameraModel::new(640, 480, [500.0, 501.0, 320.0, 240.0], d, "cam_optical").unwrap();
            let back = camera_from_info(&camera_to_info(&cam, hdr())).unwrap();
            assert_eq!(back.distortion, cam.distortion);
            assert_eq!(back.intrinsics(), cam.intrinsics());
            assert_eq!((back.width, back.height), (640, 480));
        }
    }
}
