//! The hazard map as ROS 2 messages in an MCAP file (`map.mcap`) that Foxglove, `ros2 bag
//! play` and any `ros2msg`-aware reader open: a `grid_map_msgs/msg/GridMap` with every
//! layer and a `nav_msgs/msg/OccupancyGrid` of the hazards.
//!
//! **GridMap** (grid_map's own conventions, as `GridMapRosConverter::toMessage` writes):
//! - `info.pose` is the centre of the map in the header's frame, orientation identity;
//!   `info.length_x`, `info.length_y` its extent, `info.resolution` the cell size.
//! - grid_map index `(row i, column j)` is the cell whose centre is at
//!   `x = pose.x + length_x/2 − (i + ½)·resolution`,
//!   `y = pose.y + length_y/2 − (j + ½)·resolution`: row 0 is the row of largest x,
//!   column 0 the column of largest y.
//! - each layer is a `std_msgs/Float32MultiArray` in Eigen's column-major order,
//!   `data[j·rows + i]`, with `layout.dim[0] = {"column_index", cols, rows·cols}` and
//!   `layout.dim[1] = {"row_index", rows, rows}`; rows = cells along x, cols = along y.
//! - `outer_start_index = inner_start_index = 0`: the buffer is not circularly shifted.
//! - unobserved cells are NaN in every layer; `basic_layers = ["elevation"]`.
//!
//! Layers: `elevation`, `elevation_std`, `water_probability`, `class`, `hazard`, `depth`
//! ([`Layer`]); class and hazard hold the codes of `map.ply` as floats.
//!
//! **OccupancyGrid** (`nav_msgs` conventions): row-major from the cell at `info.origin`
//! (the map's lower-left corner, min x and min y), x along `width`: the GridMap's cell
//! order reversed, as grid_map's `toOccupancyGrid` converts it. Values, from the
//! hazard of each cell ([`occupancy_of`]): free 0, shallow water within fording depth 50,
//! deep or unknown-depth water 100, obstacle 100, unobserved −1.
//!
//! Both messages carry a `std_msgs/Header` naming the map's frame and stamped with the map's
//! log time, which is also the MCAP log time of both messages.

use std::path::Path;

use crate::error::Result;
use crate::hazard::{Hazard, HazardMap};
use crate::mcap_log::{LogWriter, WriteOptions};
use crate::ros::cdr::{CdrReader, CdrResult, CdrWriter, Endian};
use crate::ros::msgs::{with_deps, HEADER_DEF, TIME_DEF};
use crate::ros::{Header, Time};
use tarn::io::{Layer, MapRaster};

/// MCAP schema names of the messages written here.
pub mod schema_name {
    /// `grid_map_msgs/msg/GridMap`.
    pub const GRID_MAP: &str = "grid_map_msgs/msg/GridMap";
    /// `nav_msgs/msg/OccupancyGrid`.
    pub const OCCUPANCY_GRID: &str = "nav_msgs/msg/OccupancyGrid";
}

/// Topic of the grid map in `map.mcap`.
pub const GRID_MAP_TOPIC: &str = "/tarn/grid_map";
/// Topic of the occupancy grid in `map.mcap`.
pub const OCCUPANCY_TOPIC: &str = "/tarn/occupancy";

/// Occupancy of a free cell (the values of [`occupancy_of`] follow).
pub const OCCUPANCY_FREE: i8 = 0;
/// Shallow water within fording depth.
pub const OCCUPANCY_SHALLOW_WATER: i8 = 50;
/// Deep or unknown-depth water, or an obstacle.
pub const OCCUPANCY_LETHAL: i8 = 100;
/// An unobserved cell.
pub const OCCUPANCY_UNKNOWN: i8 = -1;

/// The occupancy of a cell: its hazard, or unobserved (`None`).
pub fn occupancy_of(hazard: Option<Hazard>) -> i8 {
    match hazard {
        None => OCCUPANCY_UNKNOWN,
        Some(Hazard::Free) => OCCUPANCY_FREE,
        Some(Hazard::ShallowWater) => OCCUPANCY_SHALLOW_WATER,
        Some(Hazard::DeepWater) | Some(Hazard::Obstacle) => OCCUPANCY_LETHAL,
    }
}

/// `geometry_msgs/msg/Pose`: position, then orientation as x, y, z, w.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseMsg {
    /// Position, metres (ROS field `position`: x, y, z).
    pub position: [f64; 3],
    /// Orientation quaternion x, y, z, w (ROS field `orientation`).
    pub orientation: [f64; 4],
}

impl PoseMsg {
    /// A pose at `position` with the identity orientation.
    pub fn at(position: [f64; 3]) -> Self {
        PoseMsg {
            position,
            orientation: [0.0, 0.0, 0.0, 1.0],
        }
    }

    fn write(&self, w: &mut CdrWriter) {
        for v in self.position.iter().chain(&self.orientation) {
            w.f64(*v);
        }
    }

    fn read(r: &mut CdrReader) -> CdrResult<Self> {
        Ok(PoseMsg {
            position: r.f64_array()?,
            orientation: r.f64_array()?,
        })
    }
}

fn write_time(w: &mut CdrWriter, t: Time) {
    w.i32(t.sec);
    w.u32(t.nanosec);
}

fn read_time(r: &mut CdrReader) -> CdrResult<Time> {
    Ok(Time {
        sec: r.i32()?,
        nanosec: r.u32()?,
    })
}

fn write_header(w: &mut CdrWriter, h: &Header) {
    write_time(w, h.stamp);
    w.string(&h.frame_id);
}

fn read_header(r: &mut CdrReader) -> CdrResult<Header> {
    Ok(Header {
        stamp: read_time(r)?,
        frame_id: r.string()?,
    })
}

/// `std_msgs/msg/MultiArrayDimension`.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct MultiArrayDimension {
    /// Name of the dimension (ROS field `label`).
    pub label: String,
    /// Elements along the dimension (ROS field `size`).
    pub size: u32,
    /// Elements spanned by one step of the enclosing dimension (ROS field `stride`).
    pub stride: u32,
}

/// `std_msgs/msg/Float32MultiArray` (its `MultiArrayLayout` inlined).
#[derive(Debug, Clone, PartialEq)]
pub struct Float32MultiArray {
    /// Dimensions, outermost first (ROS field `layout.dim`).
    pub dim: Vec<MultiArrayDimension>,
    /// Padding elements before the data (ROS field `layout.data_offset`).
    pub data_offset: u32,
    /// The values (ROS field `data`).
    pub data: Vec<f32>,
}

impl Float32MultiArray {
    fn write(&self, w: &mut CdrWriter) {
        w.u32(self.dim.len() as u32);
        for d in &self.dim {
            w.string(&d.label);
            w.u32(d.size);
            w.u32(d.stride);
        }
        w.u32(self.data_offset);
        w.u32(self.data.len() as u32);
        for v in &self.data {
            w.f32(*v);
        }
    }

    fn read(r: &mut CdrReader) -> CdrResult<Self> {
        let n = r.seq_len(12, "layout.dim")?;
        let dim = (0..n)
            .map(|_| {
                Ok(MultiArrayDimension {
                    label: r.string()?,
                    size: r.u32()?,
                    stride: r.u32()?,
                })
            })
            .collect::<CdrResult<_>>()?;
        let data_offset = r.u32()?;
        let n = r.seq_len(4, "data")?;
        let data = (0..n).map(|_| r.f32()).collect::<CdrResult<_>>()?;
        Ok(Float32MultiArray {
            dim,
            data_offset,
            data,
        })
    }
}

/// `grid_map_msgs/msg/GridMap` (ROS 2; its `GridMapInfo` inlined).
#[derive(Debug, Clone, PartialEq)]
pub struct GridMapMsg {
    /// ROS field `header`: stamp and map frame.
    pub header: Header,
    /// Cell side, metres (ROS field `info.resolution`).
    pub resolution: f64,
    /// Extent along x, metres (ROS field `info.length_x`).
    pub length_x: f64,
    /// Extent along y, metres (ROS field `info.length_y`).
    pub length_y: f64,
    /// Centre of the map in the header's frame (ROS field `info.pose`).
    pub pose: PoseMsg,
    /// Layer names, one per `data` entry (ROS field `layers`).
    pub layers: Vec<String>,
    /// Layers whose NaN marks a cell invalid (ROS field `basic_layers`).
    pub basic_layers: Vec<String>,
    /// Layer values in grid_map's column-major order, NaN unobserved (ROS field `data`).
    pub data: Vec<Float32MultiArray>,
    /// Circular buffer offset along rows, 0 here (ROS field `outer_start_index`).
    pub outer_start_index: u16,
    /// Circular buffer offset along columns, 0 here (ROS field `inner_start_index`).
    pub inner_start_index: u16,
}

fn write_strings(w: &mut CdrWriter, v: &[String]) {
    w.u32(v.len() as u32);
    for s in v {
        w.string(s);
    }
}

fn read_strings(r: &mut CdrReader, what: &str) -> CdrResult<Vec<String>> {
    let n = r.seq_len(4, what)?;
    (0..n).map(|_| r.string()).collect()
}

impl GridMapMsg {
    /// The CDR payload (encapsulation header included) in byte order `endian`.
    pub fn encode(&self, endian: Endian) -> Vec<u8> {
        let cells: usize = self.data.iter().map(|d| d.data.len()).sum();
        let mut w = CdrWriter::with_capacity(endian, 4 * cells + 512);
        write_header(&mut w, &self.header);
        w.f64(self.resolution);
        w.f64(self.length_x);
        w.f64(self.length_y);
        self.pose.write(&mut w);
        write_strings(&mut w, &self.layers);
        write_strings(&mut w, &self.basic_layers);
        w.u32(self.data.len() as u32);
        for d in &self.data {
            d.write(&mut w);
        }
        w.u16(self.outer_start_index);
        w.u16(self.inner_start_index);
        w.finish()
    }

    /// Decodes a CDR payload. Fails on a cut or malformed payload.
    pub fn decode(buf: &[u8]) -> CdrResult<Self> {
        let mut r = CdrReader::new(buf)?;
        let header = read_header(&mut r)?;
        let (resolution, length_x, length_y) = (r.f64()?, r.f64()?, r.f64()?);
        let pose = PoseMsg::read(&mut r)?;
        let layers = read_strings(&mut r, "layers")?;
        let basic_layers = read_strings(&mut r, "basic_layers")?;
        let n = r.seq_len(12, "data")?;
        let data = (0..n)
            .map(|_| Float32MultiArray::read(&mut r))
            .collect::<CdrResult<_>>()?;
        Ok(GridMapMsg {
            header,
            resolution,
            length_x,
            length_y,
            pose,
            layers,
            basic_layers,
            data,
            outer_start_index: r.u16()?,
            inner_start_index: r.u16()?,
        })
    }

    /// The GridMap of `raster`, every [`Layer`], in grid_map's conventions (module docs).
    pub fn from_raster(raster: &MapRaster, header: Header) -> Self {
        let res = raster.resolution();
        let (rows, cols) = (raster.nx, raster.ny);
        let [x0, y0] = raster.corner_min();
        let (length_x, length_y) = (rows as f64 * res, cols as f64 * res);
        let data = Layer::ALL
            .iter()
            .map(|&layer| {
                let mut v = Vec::with_capacity(rows * cols);
                // Column-major: column j (y, from the largest) outer, row i (x) inner.
                for j in 0..cols {
                    for i in 0..rows {
                        v.push(raster.value(layer, rows - 1 - i, cols - 1 - j));
                    }
                }
                Float32MultiArray {
                    dim: vec![
                        MultiArrayDimension {
                            label: "column_index".into(),
                            size: cols as u32,
                            stride: (rows * cols) as u32,
                        },
                        MultiArrayDimension {
                            label: "row_index".into(),
                            size: rows as u32,
                            stride: rows as u32,
                        },
                    ],
                    data_offset: 0,
                    data: v,
                }
            })
            .collect();
        GridMapMsg {
            header,
            resolution: res,
            length_x,
            length_y,
            pose: PoseMsg::at([x0 + 0.5 * length_x, y0 + 0.5 * length_y, 0.0]),
            layers: Layer::ALL.iter().map(|l| l.name().to_string()).collect(),
            basic_layers: vec![Layer::Elevation.name().to_string()],
            data,
            outer_start_index: 0,
            inner_start_index: 0,
        }
    }
}

/// `nav_msgs/msg/OccupancyGrid` (its `MapMetaData` inlined).
#[derive(Debug, Clone, PartialEq)]
pub struct OccupancyGridMsg {
    /// ROS field `header`: stamp and map frame.
    pub header: Header,
    /// Time the map was made, the header's stamp here (ROS field `info.map_load_time`).
    pub map_load_time: Time,
    /// Cell side, metres (ROS field `info.resolution`).
    pub resolution: f32,
    /// Cells along x (ROS field `info.width`).
    pub width: u32,
    /// Cells along y (ROS field `info.height`).
    pub height: u32,
    /// Lower-left corner of cell (0, 0) in the header's frame (ROS field `info.origin`).
    pub origin: PoseMsg,
    /// Occupancy per cell, row major from `origin` with x along `width`: 0 free, 50
    /// shallow water, 100 lethal, −1 unobserved (ROS field `data`).
    pub data: Vec<i8>,
}

impl OccupancyGridMsg {
    /// The CDR payload (encapsulation header included) in byte order `endian`.
    pub fn encode(&self, endian: Endian) -> Vec<u8> {
        let mut w = CdrWriter::with_capacity(endian, self.data.len() + 256);
        write_header(&mut w, &self.header);
        write_time(&mut w, self.map_load_time);
        w.f32(self.resolution);
        w.u32(self.width);
        w.u32(self.height);
        self.origin.write(&mut w);
        let bytes: Vec<u8> = self.data.iter().map(|&v| v as u8).collect();
        w.bytes(&bytes);
        w.finish()
    }

    /// Decodes a CDR payload. Fails on a cut or malformed payload.
    pub fn decode(buf: &[u8]) -> CdrResult<Self> {
        let mut r = CdrReader::new(buf)?;
        Ok(OccupancyGridMsg {
            header: read_header(&mut r)?,
            map_load_time: read_time(&mut r)?,
            resolution: r.f32()?,
            width: r.u32()?,
            height: r.u32()?,
            origin: PoseMsg::read(&mut r)?,
            data: r.bytes("data")?.iter().map(|&b| b as i8).collect(),
        })
    }

    /// The occupancy of `raster`'s hazards ([`occupancy_of`]), row-major from its
    /// lower-left corner.
    pub fn from_raster(raster: &MapRaster, header: Header) -> Self {
        let mut data = Vec::with_capacity(raster.nx * raster.ny);
        for iy in 0..raster.ny {
            for ix in 0..raster.nx {
                data.push(occupancy_of(raster.cell(ix, iy).map(|c| c.hazard)));
            }
        }
        let [x0, y0] = raster.corner_min();
        OccupancyGridMsg {
            map_load_time: header.stamp,
            header,
            resolution: raster.resolution() as f32,
            width: raster.nx as u32,
            height: raster.ny as u32,
            origin: PoseMsg::at([x0, y0, 0.0]),
            data,
        }
    }
}

const HEADER: (&str, &str) = ("std_msgs/Header", HEADER_DEF);
const TIME: (&str, &str) = ("builtin_interfaces/Time", TIME_DEF);
const POSE: (&str, &str) = (
    "geometry_msgs/Pose",
    "geometry_msgs/Point position\ngeometry_msgs/Quaternion orientation\n",
);
const POINT: (&str, &str) = ("geometry_msgs/Point", "float64 x\nfloat64 y\nfloat64 z\n");
const QUATERNION: (&str, &str) = (
    "geometry_msgs/Quaternion",
    "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n",
);

/// The `ros2msg` schema text of [`schema_name::GRID_MAP`] or
/// [`schema_name::OCCUPANCY_GRID`], dependencies after it as `ros2 bag` writes them.
pub fn schema_text(schema: &str) -> Option<String> {
    Some(match schema {
        schema_name::GRID_MAP => with_deps(
            "std_msgs/Header header\ngrid_map_msgs/GridMapInfo info\nstring[] layers\n\
             string[] basic_layers\nstd_msgs/Float32MultiArray[] data\n\
             uint16 outer_start_index\nuint16 inner_start_index\n",
            &[
                HEADER,
                TIME,
                (
                    "grid_map_msgs/GridMapInfo",
                    "float64 resolution\nfloat64 length_x\nfloat64 length_y\n\
                     geometry_msgs/Pose pose\n",
                ),
                POSE,
                POINT,
                QUATERNION,
                (
                    "std_msgs/Float32MultiArray",
                    "std_msgs/MultiArrayLayout layout\nfloat32[] data\n",
                ),
                (
                    "std_msgs/MultiArrayLayout",
                    "std_msgs/MultiArrayDimension[] dim\nuint32 data_offset\n",
                ),
                (
                    "std_msgs/MultiArrayDimension",
                    "string label\nuint32 size\nuint32 stride\n",
                ),
            ],
        ),
        schema_name::OCCUPANCY_GRID => with_deps(
            "std_msgs/Header header\nnav_msgs/MapMetaData info\nint8[] data\n",
            &[
                HEADER,
                TIME,
                (
                    "nav_msgs/MapMetaData",
                    "builtin_interfaces/Time map_load_time\nfloat32 resolution\n\
                     uint32 width\nuint32 height\ngeometry_msgs/Pose origin\n",
                ),
                POSE,
                POINT,
                QUATERNION,
            ],
        ),
        _ => return None,
    })
}

/// How `map.mcap` is written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct RosMapOptions {
    /// The frame the map's coordinates are in (the headers' `frame_id`).
    pub frame_id: String,
    /// Log time of the map, nanoseconds: the headers' stamp and the messages' log time.
    pub stamp_ns: u64,
}

impl Default for RosMapOptions {
    fn default() -> Self {
        RosMapOptions {
            frame_id: "map".into(),
            stamp_ns: 0,
        }
    }
}

/// Writes `map` as one GridMap on [`GRID_MAP_TOPIC`] and one OccupancyGrid on
/// [`OCCUPANCY_TOPIC`] into a `ros2`-profile MCAP at `path` (zstd chunks, summary). The
/// file appears only when complete.
pub fn write_ros_map(path: &Path, map: &HazardMap, opts: &RosMapOptions) -> Result<()> {
    let raster = MapRaster::new(map)?;
    let header = Header::new(&opts.frame_id, opts.stamp_ns.min(i64::MAX as u64) as i64);
    let wopts = WriteOptions::default();
    let mut w = LogWriter::create(path, &wopts)?;
    let grid = GridMapMsg::from_raster(&raster, header.clone()).encode(wopts.endian);
    let text = schema_text(schema_name::GRID_MAP).expect("known schema");
    w.write_raw(
        GRID_MAP_TOPIC,
        schema_name::GRID_MAP,
        &text,
        opts.stamp_ns,
        &grid,
    )?;
    drop(grid);
    let occ = OccupancyGridMsg::from_raster(&raster, header).encode(wopts.endian);
    let text = schema_text(schema_name::OCCUPANCY_GRID).expect("known schema");
    w.write_raw(
        OCCUPANCY_TOPIC,
        schema_name::OCCUPANCY_GRID,
        &text,
        opts.stamp_ns,
        &occ,
    )?;
    w.finish()?;
    // The log writer's temporary file is owner-only; map.mcap is an ordinary output.
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        std::fs::set_permissions(path, std::fs::Permissions::from_mode(0o644))
            .map_err(|e| crate::error::Error::io(path, e))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mcap_log::LogReader;
    use tarn::grid::CellKey;
    use tarn::hazard::{Class, Hazard, MapCell};

    fn cell(kx: i64, ky: i64, z: f64, hazard: Hazard) -> MapCell {
        let (x, y) = tarn::grid::centre_of(0.5, CellKey::new(kx, ky));
        let free = hazard == Hazard::Free;
        MapCell {
            key: CellKey::new(kx, ky),
            x,
            y,
            z,
            elevation_std: 0.01,
            water: if free { 0.1 } else { 0.9 },
            depth: if hazard == Hazard::DeepWater {
                f32::NAN
            } else {
                0.0
            },
            class: if free { Class::Ground } else { Class::Water },
            hazard,
            hits: 1,
            below: 0,
        }
    }

    fn map() -> HazardMap {
        // 3 cells along x (keys 4..=6), 2 along y (keys -1..=0), one unobserved.
        HazardMap {
            resolution: 0.5,
            cells: vec![
                cell(4, -1, 1.0, Hazard::Free),
                cell(5, -1, 2.0, Hazard::ShallowWater),
                cell(6, -1, 3.0, Hazard::DeepWater),
                cell(4, 0, 4.0, Hazard::Obstacle),
                cell(6, 0, 6.0, Hazard::Free),
            ],
            bodies: Vec::new(),
        }
    }

    #[test]
    fn grid_map_follows_grid_maps_index_convention() {
        let m = map();
        let r = MapRaster::new(&m).unwrap();
        let g = GridMapMsg::from_raster(&r, Header::new("odom", 7));
        assert_eq!((g.length_x, g.length_y), (1.5, 1.0));
        assert_eq!(g.pose.position, [2.75, 0.0, 0.0]);
        let e = &g.data[0];
        assert_eq!(e.dim[0].label, "column_index");
        assert_eq!((e.dim[0].size, e.dim[0].stride), (2, 6));
        assert_eq!(e.dim[1].label, "row_index");
        assert_eq!((e.dim[1].size, e.dim[1].stride), (3, 3));
        // Every cell where grid_map's index arithmetic puts it.
        let rows = e.dim[1].size as usize;
        for c in &m.cells {
            let i = ((g.pose.position[0] + 0.5 * g.length_x - c.x) / g.resolution - 0.5).round();
            let j = ((g.pose.position[1] + 0.5 * g.length_y - c.y) / g.resolution - 0.5).round();
            assert_eq!(e.data[j as usize * rows + i as usize], c.z as f32);
        }
        // The unobserved cell (key 5, 0): row 1, column 0.
        assert!(e.data[1].is_nan());
        assert_eq!(g.layers[2], "water_probability");
    }

    #[test]
    fn occupancy_maps_hazards() {
        let m = map();
        let r = MapRaster::new(&m).unwrap();
        let o = OccupancyGridMsg::from_raster(&r, Header::new("map", 0));
        assert_eq!((o.width, o.height), (3, 2));
        assert_eq!(o.origin.position, [2.0, -0.5, 0.0]);
        assert_eq!(o.data, vec![0, 50, 100, 100, -1, 0]);
    }

    #[test]
    fn occupancy_order_is_grid_maps_reversed() {
        // grid_map's own toOccupancyGrid writes cell k of a column-major layer to
        // occupancy index n − 1 − k; both messages must agree on every cell.
        let m = map();
        let r = MapRaster::new(&m).unwrap();
        let g = GridMapMsg::from_raster(&r, Header::default());
        let o = OccupancyGridMsg::from_raster(&r, Header::default());
        let hazard = &g.data[4].data;
        let n = hazard.len();
        for (k, h) in hazard.iter().enumerate() {
            let want = match *h {
                h if h.is_nan() => occupancy_of(None),
                0.0 => occupancy_of(Some(Hazard::Free)),
                1.0 => occupancy_of(Some(Hazard::ShallowWater)),
                2.0 => occupancy_of(Some(Hazard::DeepWater)),
                _ => occupancy_of(Some(Hazard::Obstacle)),
            };
            assert_eq!(o.data[n - 1 - k], want, "cell {k}");
        }
    }

    #[test]
    fn messages_round_trip_both_endians() {
        let m = map();
        let r = MapRaster::new(&m).unwrap();
        let g = GridMapMsg::from_raster(&r, Header::new("map", 1_700_000_000_123_456_789));
        let o = OccupancyGridMsg::from_raster(&r, Header::new("map", 5));
        for e in [Endian::Little, Endian::Big] {
            let d = GridMapMsg::decode(&g.encode(e)).unwrap();
            // NaN != NaN: compare bits.
            assert_eq!(format!("{d:?}"), format!("{g:?}"));
            assert_eq!(OccupancyGridMsg::decode(&o.encode(e)).unwrap(), o);
        }
    }

    #[test]
    fn map_mcap_carries_both_messages_with_schemas() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("map.mcap");
        let opts = RosMapOptions {
            frame_id: "utm".into(),
            stamp_ns: 42_000_000_001,
        };
        write_ros_map(&path, &map(), &opts).unwrap();
        let mut seen = Vec::new();
        for msg in LogReader::open(&path).unwrap() {
            let msg = msg.unwrap();
            assert_eq!(msg.log_time, opts.stamp_ns);
            assert_eq!(msg.channel.schema_encoding, "ros2msg");
            let header = match msg.channel.topic.as_str() {
                GRID_MAP_TOPIC => GridMapMsg::decode(&msg.data).unwrap().header,
                OCCUPANCY_TOPIC => OccupancyGridMsg::decode(&msg.data).unwrap().header,
                t => panic!("unexpected topic {t}"),
            };
            assert_eq!(header, Header::new("utm", 42_000_000_001));
            seen.push(msg.channel.topic.clone());
        }
        // The schema texts, as a generic reader sees them.
        let bytes = std::fs::read(&path).unwrap();
        for m in mcap::MessageStream::new(&bytes).unwrap() {
            let m = m.unwrap();
            let s = m.channel.schema.as_ref().unwrap();
            assert_eq!(s.data.as_ref(), schema_text(&s.name).unwrap().as_bytes());
        }
        assert_eq!(seen, [GRID_MAP_TOPIC, OCCUPANCY_TOPIC]);
    }
}
