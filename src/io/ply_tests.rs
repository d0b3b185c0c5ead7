//! Tests of the PLY reader, with a tiny independent PLY writer.

use super::*;
use nalgebra::Point3;
use proptest::prelude::*;

// ------------------------------------------------------------------------------------
// A tiny PLY writer for the tests (independent of the reader's decoding code).

#[derive(Clone, Debug)]
pub(super) enum V {
    S(f64),
    L(Vec<f64>),
}

#[derive(Clone, Debug)]
pub(super) struct P {
    pub name: String,
    /// Scalar type name, or the item type of a list.
    pub ty: String,
    /// Count type of a list property.
    pub list: Option<String>,
}

pub(super) fn p(name: &str, ty: &str) -> P {
    P {
        name: name.into(),
        ty: ty.into(),
        list: None,
    }
}

pub(super) fn pl(name: &str, count: &str, item: &str) -> P {
    P {
        name: name.into(),
        ty: item.into(),
        list: Some(count.into()),
    }
}

#[derive(Clone, Debug)]
pub(super) struct E {
    pub name: String,
    pub props: Vec<P>,
    pub rows: Vec<Vec<V>>,
}

fn enc(ty: &str, v: f64, big: bool, out: &mut Vec<u8>) {
    macro_rules! put {
        ($x:expr) => {{
            let x = $x;
            out.extend_from_slice(&if big {
                x.to_be_bytes()
            } else {
                x.to_le_bytes()
            });
        }};
    }
    match ty {
        "char" | "int8" => put!(v as i8),
        "uchar" | "uint8" => put!(v as u8),
        "short" | "int16" => put!(v as i16),
        "ushort" | "uint16" => put!(v as u16),
        "int" | "int32" => put!(v as i32),
        "uint" | "uint32" => put!(v as u32),
        "float" | "float32" => put!(v as f32),
        "double" | "float64" => put!(v),
        _ => panic!("test writer: unknown type {ty}"),
    }
}

fn txt(ty: &str, v: f64) -> String {
    match ty {
        "float" | "float32" => format!("{}", v as f32),
        "double" | "float64" => format!("{v}"),
        _ => format!("{}", v as i64),
    }
}

/// Writes a PLY file: `format` is `ascii`, `binary_little_endian` or `binary_big_endian`;
/// `extra_header` lines go right after the format line.
pub(super) fn write_ply(format: &str, extra_header: &[&str], elements: &[E]) -> Vec<u8> {
    let mut h = format!("ply\nformat {format} 1.0\n");
    for l in extra_header {
        h += l;
        h += "\n";
    }
    for e in elements {
        h += &format!("element {} {}\n", e.name, e.rows.len());
        for p in &e.props {
            match &p.list {
                Some(c) => h += &format!("property list {c} {} {}\n", p.ty, p.name),
                None => h += &format!("property {} {}\n", p.ty, p.name),
            }
        }
    }
    h += "end_header\n";
    let mut out = h.into_bytes();
    let big = format == "binary_big_endian";
    for e in elements {
        for row in &e.rows {
            let mut words = Vec::new();
            for (p, v) in e.props.iter().zip(row) {
                match (v, &p.list) {
                    (V::S(x), None) => {
                        if format == "ascii" {
                            words.push(txt(&p.ty, *x));
                        } else {
                            enc(&p.ty, *x, big, &mut out);
                        }
                    }
                    (V::L(xs), Some(c)) => {
                        if format == "ascii" {
                            words.push(xs.len().to_string());
                            words.extend(xs.iter().map(|x| txt(&p.ty, *x)));
                        } else {
                            enc(c, xs.len() as f64, big, &mut out);
                            for x in xs {
                                enc(&p.ty, *x, big, &mut out);
                            }
                        }
                    }
                    _ => panic!("test writer: value does not match property {}", p.name),
                }
            }
            if format == "ascii" {
                out.extend_from_slice(words.join(" ").as_bytes());
                out.push(b'\n');
            }
        }
    }
    out
}

fn xyz_element(ty: &str, pts: &[[f64; 3]]) -> E {
    E {
        name: "vertex".into(),
        props: vec![p("x", ty), p("y", ty), p("z", ty)],
        rows: pts
            .iter()
            .map(|q| q.iter().map(|&c| V::S(c)).collect())
            .collect(),
    }
}

fn faces(n: usize) -> E {
    E {
        name: "face".into(),
        props: vec![pl("vertex_indices", "uchar", "int")],
        rows: (0..n)
            .map(|i| vec![V::L(vec![i as f64, (i + 1) as f64, (i + 2) as f64])])
            .collect(),
    }
}

const FORMATS: [&str; 3] = ["ascii", "binary_little_endian", "binary_big_endian"];
const TYPES: [&str; 16] = [
    "char", "uchar", "short", "ushort", "int", "uint", "float", "double", "int8", "uint8", "int16",
    "uint16", "int32", "uint32", "float32", "float64",
];

fn read(bytes: &[u8]) -> Result<PointCloud> {
    read_from_bytes(bytes, "test.ply")
}

fn err(bytes: &[u8]) -> (String, String) {
    match read(bytes) {
        Err(Error::Format {
            location, message, ..
        }) => (location, message),
        other => panic!("expected a format error, got {other:?}"),
    }
}

/// Map-frame coordinates of every point (NaN for missing returns).
fn in_map(c: &PointCloud) -> Vec<[f64; 3]> {
    (0..c.len())
        .map(|i| {
            let q = c.point_in_map(i);
            [q.x, q.y, q.z]
        })
        .collect()
}

// ------------------------------------------------------------------------------------
// Round trips

#[test]
fn every_format_and_coordinate_type_round_trips() {
    // Values every type can hold (unsigned types: non-negative).
    for ty in TYPES {
        let signed = !ty.starts_with('u');
        let pts: Vec<[f64; 3]> = (0..7)
            .map(|i| {
                let s = if signed && i % 2 == 1 { -1.0 } else { 1.0 };
                [s * i as f64, 2.0 * i as f64 + 1.0, (100 - i) as f64]
            })
            .collect();
        for f in FORMATS {
            let bytes = write_ply(f, &[], &[xyz_element(ty, &pts)]);
            let c = read(&bytes).unwrap_or_else(|e| panic!("{f} {ty}: {e}"));
            assert_eq!(c.len(), pts.len(), "{f} {ty}");
            assert_eq!((c.rows, c.cols), (1, pts.len()));
            assert_eq!(in_map(&c), pts, "{f} {ty}");
            assert!(c.intensity.is_none() && c.reflectivity.is_none() && c.rgb.is_none());
            c.validate().unwrap();
        }
    }
}

#[test]
fn fractional_float_and_double_round_trip_exactly() {
    let pts = [
        [0.1f32 as f64, -2.75, 1e-3f32 as f64],
        [123.456f32 as f64, 7.0, -0.5],
    ];
    for f in FORMATS {
        for ty in ["float", "double"] {
            let c = read(&write_ply(f, &[], &[xyz_element(ty, &pts)])).unwrap();
            let got = in_map(&c);
            for (g, w) in got.iter().zip(&pts) {
                for k in 0..3 {
                    assert!((g[k] - w[k]).abs() < 1e-6, "{f} {ty}: {g:?} vs {w:?}");
                }
            }
        }
    }
}

#[test]
fn float_cloud_near_the_origin_is_stored_unshifted() {
    let pts = [[1.5, 2.5, -3.25], [100.0, 0.0, 0.0]];
    let c = read(&write_ply(
        "binary_little_endian",
        &[],
        &[xyz_element("float", &pts)],
    ))
    .unwrap();
    assert_eq!(c.frame_to_map, Pose::identity());
    assert_eq!(c.sensor_origin, Point3::origin());
    assert_eq!(c.xyz[0], [1.5, 2.5, -3.25]);
}

#[test]
fn optional_channels_are_read_with_any_type() {
    for f in FORMATS {
        for (cty, scale) in [
            ("uchar", 1.0),
            ("float", 1.0 / 255.0),
            ("double", 1.0 / 255.0),
        ] {
            let vertex = E {
                name: "vertex".into(),
                props: vec![
                    p("x", "float"),
                    p("intensity", "ushort"),
                    p("y", "float"),
                    p("z", "float"),
                    p("reflectivity", "float"),
                    p("red", cty),
                    p("green", cty),
                    p("blue", cty),
                ],
                rows: (0..5)
                    .map(|i| {
                        let i = i as f64;
                        vec![
                            V::S(i),
                            V::S(1000.0 + i),
                            V::S(-i),
                            V::S(2.0 * i),
                            V::S(0.25 * i),
                            V::S(10.0 * i * scale),
                            V::S((200.0 + i) * scale),
                            V::S(255.0 * scale),
                        ]
                    })
                    .collect(),
            };
            let c = read(&write_ply(f, &[], &[vertex])).unwrap();
            assert_eq!(c.xyz[3], [3.0, -3.0, 6.0]);
            assert_eq!(c.intensity.as_deref().unwrap()[4], 1004.0);
            assert_eq!(c.reflectivity.as_deref().unwrap()[2], 0.5);
            assert_eq!(c.rgb.as_deref().unwrap()[4], [40, 204, 255], "{f} {cty}");
            c.validate().unwrap();
        }
    }
}

#[test]
fn float_colours_are_clamped_to_the_unit_range() {
    let vertex = E {
        name: "vertex".into(),
        props: ["x", "y", "z", "red", "green", "blue"]
            .iter()
            .map(|n| p(n, "float"))
            .collect(),
        rows: vec![vec![
            V::S(0.0),
            V::S(0.0),
            V::S(1.0),
            V::S(-0.5),
            V::S(2.0),
            V::S(0.5),
        ]],
    };
    let c = read(&write_ply("binary_little_endian", &[], &[vertex])).unwrap();
    assert_eq!(c.rgb.unwrap()[0], [0, 255, 128]);
}

#[test]
fn partial_colour_is_ignored() {
    let vertex = E {
        name: "vertex".into(),
        props: ["x", "y", "z", "red", "green"]
            .iter()
            .map(|n| p(n, "uchar"))
            .collect(),
        rows: vec![vec![V::S(1.0), V::S(2.0), V::S(3.0), V::S(4.0), V::S(5.0)]],
    };
    let c = read(&write_ply("ascii", &[], &[vertex])).unwrap();
    assert!(c.rgb.is_none());
    assert_eq!(c.xyz, vec![[1.0, 2.0, 3.0]]);
}

#[test]
fn other_elements_and_list_properties_are_skipped() {
    let pts = [[1.0, 2.0, 3.0], [4.0, 5.0, 6.0], [7.0, 8.0, 9.0]];
    let mut vertex = xyz_element("float", &pts);
    // A list property in the middle of the vertex and a scalar we do not use.
    vertex.props.insert(1, pl("neighbours", "uint", "double"));
    vertex.props.push(p("confidence", "double"));
    for (k, row) in vertex.rows.iter_mut().enumerate() {
        row.insert(1, V::L((0..k).map(|j| j as f64 * 0.5).collect()));
        row.push(V::S(0.9));
    }
    let edge = E {
        name: "edge".into(),
        props: vec![p("vertex1", "int"), p("vertex2", "int")],
        rows: vec![vec![V::S(0.0), V::S(1.0)]; 4],
    };
    for f in FORMATS {
        let bytes = write_ply(f, &[], &[faces(3), vertex.clone(), edge.clone(), faces(2)]);
        let c = read(&bytes).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!(in_map(&c), pts, "{f}");
    }
}

#[test]
fn non_finite_points_keep_their_slot_as_nan() {
    let pts = [
        [1.0, 2.0, 3.0],
        [f64::NAN, 0.0, 0.0],
        [0.0, f64::INFINITY, 1.0],
        [0.0, 0.0, f64::NEG_INFINITY],
        [4.0, 5.0, 6.0],
    ];
    for f in FORMATS {
        for ty in ["float", "double"] {
            let c = read(&write_ply(f, &[], &[xyz_element(ty, &pts)])).unwrap();
            assert_eq!(c.len(), 5);
            assert_eq!(c.valid_count(), 2, "{f} {ty}");
            for i in 1..4 {
                assert!(c.xyz[i].iter().all(|v| v.is_nan()), "{f} {ty} point {i}");
            }
            assert_eq!(in_map(&c)[4], [4.0, 5.0, 6.0]);
        }
    }
}

#[test]
fn zero_range_or_zero_xyz_is_a_missing_return_only_with_a_range_property() {
    let mut vertex = xyz_element(
        "float",
        &[[1.0, 0.0, 0.0], [0.0, 0.0, 0.0], [2.0, 0.0, 0.0]],
    );
    vertex.props.push(p("range", "uint"));
    vertex.rows[0].push(V::S(0.0)); // range 0: missing although xyz is not zero
    vertex.rows[1].push(V::S(7.0)); // zero xyz: missing
    vertex.rows[2].push(V::S(2000.0));
    let c = read(&write_ply("binary_little_endian", &[], &[vertex])).unwrap();
    assert!(!c.is_valid(0) && !c.is_valid(1) && c.is_valid(2));

    let plain = xyz_element("float", &[[0.0, 0.0, 0.0], [2.0, 0.0, 0.0]]);
    let c = read(&write_ply("binary_little_endian", &[], &[plain])).unwrap();
    assert_eq!(c.valid_count(), 2);
}

#[test]
fn a_cloud_5000_km_away_keeps_millimetres() {
    // UTM-like coordinates in double: f32 alone would have 0.5 m steps here.
    let base = [5_000_123.456_7, 4_000_321.987_6, 312.345_6];
    let pts: Vec<[f64; 3]> = (0..50)
        .map(|i| {
            let t = i as f64;
            [
                base[0] + 0.0137 * t,
                base[1] - 0.0291 * t,
                base[2] + 0.0013 * t * t,
            ]
        })
        .collect();
    for f in FORMATS {
        let c = read(&write_ply(f, &[], &[xyz_element("double", &pts)])).unwrap();
        let o = c.frame_to_map.translation.vector;
        assert_eq!([o.x, o.y, o.z], [5_000_123.0, 4_000_322.0, 312.0], "{f}");
        assert!(c.xyz.iter().flatten().all(|v| v.abs() < 10.0));
        for (g, w) in in_map(&c).iter().zip(&pts) {
            for k in 0..3 {
                assert!((g[k] - w[k]).abs() < 1e-4, "{f}: {g:?} vs {w:?}");
            }
        }
        // The sensor (the file's origin) stays where it was.
        let s = c.sensor_origin_in_map();
        assert!(s.coords.norm() < 1e-6);
    }
}

#[test]
fn a_far_float_cloud_is_shifted_without_loss() {
    let pts: Vec<[f64; 3]> = (0..10)
        .map(|i| [(6.0e6 + 0.5 * i as f64) as f32 as f64, 1.25, -7.0e3])
        .collect();
    let c = read(&write_ply(
        "binary_big_endian",
        &[],
        &[xyz_element("float", &pts)],
    ))
    .unwrap();
    assert_ne!(c.frame_to_map, Pose::identity());
    assert_eq!(in_map(&c), pts);
}

#[test]
fn declared_layout_makes_an_organized_cloud() {
    let pts: Vec<[f64; 3]> = (0..6).map(|i| [i as f64, 0.0, 1.0]).collect();
    for decl in ["obj_info width 3 height 2", "comment width 3 height 2"] {
        for f in FORMATS {
            let c = read(&write_ply(f, &[decl], &[xyz_element("float", &pts)])).unwrap();
            assert_eq!((c.rows, c.cols), (2, 3));
            assert_eq!(c.xyz[c.index(1, 0)], [3.0, 0.0, 1.0]);
        }
    }
    // An unrelated comment, or no declaration: unorganized.
    let c = read(&write_ply(
        "ascii",
        &["comment made by hand"],
        &[xyz_element("float", &pts)],
    ))
    .unwrap();
    assert_eq!((c.rows, c.cols), (1, 6));
    let (loc, msg) = err(&write_ply(
        "ascii",
        &["obj_info width 4 height 2"],
        &[xyz_element("float", &pts)],
    ));
    assert_eq!(loc, "header line 3");
    assert!(
        msg.contains("width 4 height 2") && msg.contains("6 vertices"),
        "{msg}"
    );
}

#[test]
fn empty_vertex_element_gives_an_empty_cloud() {
    let c = read(&write_ply(
        "binary_little_endian",
        &[],
        &[xyz_element("float", &[])],
    ))
    .unwrap();
    assert!(c.is_empty());
}

#[test]
fn crlf_header_and_ascii_body() {
    let text = "ply\r\nformat ascii 1.0\r\nelement vertex 2\r\nproperty float x\r\n\
                property float y\r\nproperty float z\r\nend_header\r\n1 2 3\r\n4 5 6\r\n";
    let c = read(text.as_bytes()).unwrap();
    assert_eq!(c.xyz, vec![[1.0, 2.0, 3.0], [4.0, 5.0, 6.0]]);
}

#[test]
fn the_result_does_not_depend_on_the_thread_count() {
    let pts: Vec<[f64; 3]> = (0..50_000)
        .map(|i| {
            let t = i as f64;
            if i % 11 == 0 {
                [f64::NAN, 0.0, 0.0]
            } else {
                [1.0e5 + t.sin() * 30.0, t * 1e-3, (t * 0.37).cos()]
            }
        })
        .collect();
    let mut vertex = xyz_element("double", &pts);
    vertex.props.push(p("intensity", "float"));
    for (k, row) in vertex.rows.iter_mut().enumerate() {
        row.push(V::S(k as f64 * 0.25));
    }
    let bytes = write_ply("binary_little_endian", &[], &[vertex]);
    let bits = |c: &PointCloud| {
        let xyz: Vec<u32> = c.xyz.iter().flatten().map(|v| v.to_bits()).collect();
        (xyz, c.intensity.clone(), c.frame_to_map)
    };
    let with = |threads| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| bits(&read(&bytes).unwrap()))
    };
    let one = with(1);
    assert_eq!(one, with(3));
    assert_eq!(one, with(8));
    // Point 0 is missing; point 1 (x = 1e5 + 30 sin 1) sets the origin.
    assert_eq!(one.2.translation.vector.x, 100_025.0);
}

#[test]
fn a_comment_that_is_not_utf8_is_skipped() {
    let mut b = b"ply\nformat ascii 1.0\ncomment scanned in M\xfcnchen\n".to_vec();
    b.extend_from_slice(
        b"element vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
          end_header\n1 2 3\n",
    );
    assert_eq!(read(&b).unwrap().xyz, vec![[1.0, 2.0, 3.0]]);
}

// ------------------------------------------------------------------------------------
// Bad input

const XYZ_HEADER: &str = "ply\nformat binary_little_endian 1.0\nelement vertex 2\n\
                          property float x\nproperty float y\nproperty float z\nend_header\n";

fn with_header(h: &str) -> Vec<u8> {
    let mut b = h.as_bytes().to_vec();
    b.extend(std::iter::repeat_n(0u8, 24));
    b
}

#[test]
fn empty_file() {
    let (loc, msg) = err(b"");
    assert_eq!(loc, "byte 0");
    assert!(msg.contains("empty"), "{msg}");
}

#[test]
fn bad_magic() {
    let (loc, msg) = err(b"\x89PNG\r\n\x1a\n....");
    assert_eq!(loc, "line 1");
    assert!(msg.contains("not a PLY"), "{msg}");
    assert!(err(b"plyx\nformat ascii 1.0\n").1.contains("not a PLY"));
}

#[test]
fn unknown_format() {
    let (loc, msg) = err(&with_header(
        &XYZ_HEADER.replace("binary_little_endian", "binary_middle"),
    ));
    assert_eq!(loc, "header line 2");
    assert!(msg.contains("unknown format `binary_middle`"), "{msg}");
    let (_, msg) = err(&with_header(&XYZ_HEADER.replace("1.0", "2.0")));
    assert!(msg.contains("version"), "{msg}");
}

#[test]
fn missing_format_line() {
    let (_, msg) = err(&with_header(
        &XYZ_HEADER.replace("format binary_little_endian 1.0\n", ""),
    ));
    assert!(msg.contains("no `format`"), "{msg}");
}

#[test]
fn bad_property_lines() {
    for (bad, want) in [
        ("property float", "expected `property"),
        ("property quad x", "unknown property type `quad`"),
        (
            "property list float int x",
            "list count type must be an integer",
        ),
        ("property list uchar int", "expected `property"),
    ] {
        let h = XYZ_HEADER.replace("property float x", bad);
        let (loc, msg) = err(&with_header(&h));
        assert_eq!(loc, "header line 4", "{bad}");
        assert!(msg.contains(want), "{bad}: {msg}");
    }
    let h = XYZ_HEADER.replace("property float x", "property float y");
    let (loc, msg) = err(&with_header(&h));
    assert_eq!(loc, "header line 5");
    assert!(
        msg.contains("property `y` appears twice in element `vertex`"),
        "{msg}"
    );
    let h = XYZ_HEADER.replace("element vertex 2\n", "");
    assert!(err(&with_header(&h)).1.contains("before any `element`"));
    let h = XYZ_HEADER.replace("element vertex 2", "element vertex many");
    assert!(err(&with_header(&h)).1.contains("bad element count `many`"));
    let h = XYZ_HEADER.replace("end_header", "end_header now");
    assert!(err(&with_header(&h)).1.contains("after end_header"));
    let h = XYZ_HEADER.replace("end_header", "endheader");
    assert!(err(&with_header(&h))
        .1
        .contains("unknown header keyword `endheader`"));
}

#[test]
fn missing_end_header() {
    let h = XYZ_HEADER.replace("end_header\n", "");
    let (loc, msg) = err(h.as_bytes());
    assert!(loc.starts_with("header line"), "{loc}");
    assert!(msg.contains("ends before `end_header`"), "{msg}");
    // Binary bytes where the header should continue.
    let mut b = h.into_bytes();
    b.extend_from_slice(&[0xff, 0xfe, 0x00, 0x80, b'\n']);
    let (loc, msg) = err(&b);
    assert_eq!(loc, "header line 7");
    assert!(msg.contains("not text"), "{msg}");
}

#[test]
fn missing_vertex_element_or_coordinate() {
    let h = XYZ_HEADER.replace("element vertex", "element point");
    let (loc, msg) = err(&with_header(&h));
    assert_eq!(loc, "header");
    assert!(msg.contains("no `vertex` element"), "{msg}");
    for c in ["x", "y", "z"] {
        let h = XYZ_HEADER.replace(&format!("property float {c}\n"), "property float w\n");
        let (loc, msg) = err(&with_header(&h));
        assert_eq!(loc, "header line 3");
        assert!(msg.contains(&format!("no property `{c}`")), "{msg}");
    }
    let h = XYZ_HEADER.replace("property float z", "property list uchar float z");
    assert!(err(&with_header(&h)).1.contains("is a list"));
    let h = XYZ_HEADER.replace(
        "end_header",
        "element vertex 1\nproperty float x\nend_header",
    );
    assert!(err(&with_header(&h)).1.contains("second `vertex`"));
}

#[test]
fn truncated_binary_body() {
    let pts = [[1.0, 2.0, 3.0]; 10];
    let full = write_ply("binary_little_endian", &[], &[xyz_element("float", &pts)]);
    let header_len = full.len() - 120;
    let (loc, msg) = err(&full[..full.len() - 1]);
    assert_eq!(loc, format!("byte {header_len}"));
    assert!(
        msg.contains("10 `vertex` records") && msg.contains("119 bytes"),
        "{msg}"
    );

    // A truncated face list after the vertices.
    let mut b = write_ply(
        "binary_little_endian",
        &[],
        &[xyz_element("float", &pts), faces(3)],
    );
    b.truncate(b.len() - 2);
    let (_, msg) = err(&b);
    assert!(
        msg.contains("truncated") && msg.contains("`face` record 2"),
        "{msg}"
    );
}

#[test]
fn a_header_claiming_a_trillion_vertices_is_refused_before_allocating() {
    let h = XYZ_HEADER.replace("element vertex 2", "element vertex 1000000000000");
    let (loc, msg) = err(&with_header(&h));
    assert!(loc.starts_with("byte "), "{loc}");
    assert!(
        msg.contains("1000000000000 `vertex` records") && msg.contains("only 24 bytes"),
        "{msg}"
    );
    // Also for ascii, and for a skipped element before the vertices.
    let h = "ply\nformat ascii 1.0\nelement vertex 99999999999999\nproperty float x\n\
             property float y\nproperty float z\nend_header\n1 2 3\n";
    assert!(err(h.as_bytes()).1.contains("99999999999999"));
    let h = XYZ_HEADER.replace(
        "element vertex",
        "element face 18446744073709551615\nproperty list uchar int i\nelement vertex",
    );
    assert!(err(&with_header(&h))
        .1
        .contains("18446744073709551615 `face` records"));
}

#[test]
fn a_huge_list_length_is_a_truncation_not_an_allocation() {
    let mut vertex = xyz_element("float", &[[1.0, 2.0, 3.0]]);
    vertex.props.push(pl("n", "uint", "double"));
    vertex.rows[0].push(V::L(vec![]));
    let mut b = write_ply("binary_little_endian", &[], &[vertex]);
    let l = b.len();
    b[l - 4..].copy_from_slice(&u32::MAX.to_le_bytes());
    assert!(err(&b).1.contains("truncated"));
}

#[test]
fn ascii_line_errors_name_the_line() {
    let head = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                property uchar z\nend_header\n";
    // Body starts at line 8.
    for (body, line, want) in [
        (
            "1 2 3\n4 5\n6 7 8\n",
            9,
            "too few values for `vertex` record 1: property `z`",
        ),
        (
            "1 2 3\n4 5 6\n6 seven 8\n",
            10,
            "`seven` is not a valid float for property `y`",
        ),
        ("1 2 3\n4 5 300\n6 7 8\n", 9, "`300` is not a valid uchar"),
        (
            "1 2 3 4\n4 5 6\n6 7 8\n",
            8,
            "too many values for `vertex` record 0",
        ),
        (
            "1 2 3\n4 5 6\n",
            10,
            "the file ends after 2 of 3 `vertex` records",
        ),
    ] {
        let (loc, msg) = err(format!("{head}{body}").as_bytes());
        assert_eq!(loc, format!("line {line}"), "{body:?}: {msg}");
        assert!(msg.contains(want), "{body:?}: {msg}");
    }
}

#[test]
fn ascii_list_errors() {
    let head = "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar int n\n\
                property float x\nproperty float y\nproperty float z\nend_header\n";
    assert!(err(format!("{head}3 1 2 1 2 3\n").as_bytes())
        .1
        .contains("too few values"));
    assert!(err(format!("{head}-1 1 2 3\n").as_bytes())
        .1
        .contains("not a valid uchar"));
    assert!(err(format!("{head}2 1 2.5 1 2 3\n").as_bytes())
        .1
        .contains("`2.5` is not a valid int"));
    let c = read(format!("{head}2 1 2 7 8 9\n").as_bytes()).unwrap();
    assert_eq!(c.xyz, vec![[7.0, 8.0, 9.0]]);
}

#[test]
fn unreadable_file_is_an_io_error_naming_the_path() {
    let e = super::read(Path::new("/nonexistent/dir/cloud.ply")).unwrap_err();
    assert!(matches!(e, Error::Io { .. }));
    assert!(e.to_string().contains("/nonexistent/dir/cloud.ply"));
}

// ------------------------------------------------------------------------------------
// Properties

fn coord() -> impl Strategy<Value = f64> {
    prop_oneof![
        8 => -1000.0f64..1000.0,
        1 => Just(f64::NAN),
        1 => (-100i32..100).prop_map(|v| v as f64),
    ]
}

#[derive(Debug, Clone)]
struct Case {
    format: &'static str,
    ty: &'static str,
    pts: Vec<[f64; 3]>,
    intensity: Option<Vec<f64>>,
    rgb: Option<Vec<[u8; 3]>>,
    faces_before: usize,
    faces_after: usize,
    extra_list: bool,
}

fn case() -> impl Strategy<Value = Case> {
    (
        prop::sample::select(FORMATS.to_vec()),
        prop::sample::select(vec!["float", "double", "float32", "float64"]),
        prop::collection::vec([coord(), coord(), coord()], 0..60),
        any::<bool>(),
        any::<bool>(),
        0usize..4,
        0usize..4,
        any::<bool>(),
    )
        .prop_flat_map(|(format, ty, pts, has_i, has_rgb, fb, fa, extra_list)| {
            let n = pts.len();
            (
                Just((format, ty, pts, fb, fa, extra_list)),
                if has_i {
                    prop::collection::vec(0u16..=u16::MAX, n)
                        .prop_map(Some)
                        .boxed()
                } else {
                    Just(None).boxed()
                },
                if has_rgb {
                    prop::collection::vec(any::<[u8; 3]>(), n)
                        .prop_map(Some)
                        .boxed()
                } else {
                    Just(None).boxed()
                },
            )
        })
        .prop_map(
            |((format, ty, pts, faces_before, faces_after, extra_list), i, rgb)| Case {
                format,
                ty,
                pts,
                intensity: i.map(|v| v.into_iter().map(f64::from).collect()),
                rgb,
                faces_before,
                faces_after,
                extra_list,
            },
        )
}

fn case_bytes(c: &Case) -> Vec<u8> {
    let mut props = vec![p("x", c.ty), p("y", c.ty), p("z", c.ty)];
    if c.extra_list {
        props.insert(2, pl("tags", "ushort", "short"));
    }
    if c.intensity.is_some() {
        props.push(p("intensity", "ushort"));
    }
    if c.rgb.is_some() {
        props.extend([p("red", "uchar"), p("green", "uchar"), p("blue", "uchar")]);
    }
    let rows = (0..c.pts.len())
        .map(|k| {
            let mut r: Vec<V> = c.pts[k].iter().map(|&v| V::S(v)).collect();
            if c.extra_list {
                r.insert(2, V::L((0..k % 3).map(|j| -(j as f64)).collect()));
            }
            if let Some(i) = &c.intensity {
                r.push(V::S(i[k]));
            }
            if let Some(rgb) = &c.rgb {
                r.extend(rgb[k].iter().map(|&v| V::S(v as f64)));
            }
            r
        })
        .collect();
    let vertex = E {
        name: "vertex".into(),
        props,
        rows,
    };
    write_ply(
        c.format,
        &[],
        &[faces(c.faces_before), vertex, faces(c.faces_after)],
    )
}

proptest! {
    #[test]
    fn random_clouds_round_trip(c in case()) {
        let cloud = read(&case_bytes(&c)).unwrap();
        prop_assert_eq!(cloud.len(), c.pts.len());
        cloud.validate().unwrap();
        let single = c.ty == "float" || c.ty == "float32";
        for (k, (g, w)) in in_map(&cloud).iter().zip(&c.pts).enumerate() {
            if w.iter().any(|v| v.is_nan()) {
                prop_assert!(!cloud.is_valid(k));
                continue;
            }
            for a in 0..3 {
                let want = if single { w[a] as f32 as f64 } else { w[a] };
                prop_assert!((g[a] - want).abs() < 1e-4, "{:?} vs {:?}", g, w);
            }
        }
        prop_assert_eq!(
            cloud.intensity.map(|v| v.into_iter().map(f64::from).collect::<Vec<_>>()),
            c.intensity.clone()
        );
        prop_assert_eq!(cloud.rgb, c.rgb.clone());
    }

    /// Damaged files give a result or an error, never a panic.
    #[test]
    fn damaged_files_never_panic(
        c in case(),
        cut in any::<prop::sample::Index>(),
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..4),
    ) {
        let mut b = case_bytes(&c);
        for (i, v) in flips {
            let k = i.index(b.len());
            b[k] = v;
        }
        let keep = cut.index(b.len() + 1);
        let _ = read(&b[..keep]);
    }
}

// ------------------------------------------------------------------------------------
// The real RELLIS-3D Ouster scan (test data, read in place; see shared/data/README.txt).

pub(crate) const RELLIS_PLY: &str = concat!(
    env!("CARGO_MANIFEST_DIR"),
    "/../shared/data/rellis3d-puddle-frame/frame000104-1581624663_170.ply"
);

#[test]
fn rellis_raw_ply() {
    let Some(path) = crate::io::test_data(RELLIS_PLY) else {
        return;
    };
    let c = super::read(path).unwrap();
    assert_eq!(c.len(), 131_072);
    assert_eq!(c.len() - c.valid_count(), 53_364);
    assert_eq!((c.rows, c.cols), (1, 131_072));
    assert_eq!(c.frame_to_map, Pose::identity());
    let refl = c.reflectivity.as_deref().unwrap();
    let int = c.intensity.as_deref().unwrap();
    assert!(c.rgb.is_none());
    // Values read independently with Python's struct module ('<ffffIHBHI', 29 B/point).
    assert_eq!(c.xyz[70_000], [-6.675_836_6, 1.835_561_2, -1.010_906_2]);
    assert_eq!((int[70_000], refl[70_000]), (502.0, 2447.0));
    assert_eq!(c.xyz[131_071], [1.419_177_3, 0.079_786_14, -0.419_397_68]);
    assert_eq!((int[131_071], refl[131_071]), (47.0, 10.0));
    assert!(!c.is_valid(0));
    assert_eq!(refl.iter().map(|&r| r as u64).sum::<u64>(), 123_454_055);
    assert_eq!(int.iter().map(|&v| v as f64).sum::<f64>(), 18_586_647.0);
}
