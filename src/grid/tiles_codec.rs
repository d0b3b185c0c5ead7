//! The tile set file format: a [`TileMap`] as compact, versioned bytes, for moving partial
//! maps between processes (one log's tiles built on one machine, merged on another).
//!
//! Everything is little-endian. Version 4:
//!
//! | bytes | field |
//! | --- | --- |
//! | 8 | magic `TARNTILE` |
//! | 4 | version, `u32` = 4 |
//! | 4 | cells per tile side, `u32` = [`TILE_CELLS`] |
//! | 8 | resolution (m), `f64` |
//! | 8 | reference height `z_ref` (m), `f64` |
//! | 16 | the colour labels' false alarms ([`FalseAlarms`]): dry samples, of them water, `u64` each |
//! | 16 | the SWIR labels' false alarms, the same |
//! | 8 | number of tiles, `u64` |
//! | … | the tiles, in increasing `(tx, ty)` |
//! | 4 | CRC-32 (IEEE) of every byte before it |
//!
//! A tile: `tx: i64`, `ty: i64`, observed cells `n: u32` (1..=4096), then its `n` cells in
//! increasing index (`cy · 64 + cx`). A cell: `index: u16`, `flags: u8`, then the blocks
//! the flags name, in this order:
//!
//! - bit 0, elevation (60 bytes): `hits: u32`, `sw: u64`, `swv: u64`, `swz: i128`,
//!   `swzz: i128`, `zmin: i32`, `zmax: i32`;
//! - bit 1, below-surface points: `below: u32`;
//! - bit 2, water evidence (54 bytes): the 11 `u16` event counts in
//!   [`Evidence::counts`] order, `level_n: u32`, `level_sum_mm: i64`, `depth_n: u32`,
//!   `depth_sum_mm: u32`, `depth_gain_sum: u32`, `depth_gain_level_sum: i64`.
//!
//! A block is written exactly when its part of the cell is not empty (not its default), so
//! the encoding is canonical: equal maps give equal bytes, whatever order their cells were
//! merged in. A dry cell costs 63–67 bytes, a cell with water evidence 117–121.
//!
//! Version 3 is read too: it is version 4 without the SWIR labels' false alarms (none).
//!
//! Reading checks everything: the magic, the version, the CRC, every length against the
//! bytes that remain (so a corrupt count cannot make it allocate more than the input's
//! size), the order of tiles and cells, unknown flag bits, empty blocks, and the resolution
//! and reference height as a [`TileMap`] requires them; an error names the byte offset.

use super::{Tile, TileMap, TILE_CELLS};
use crate::error::{Error, Result};
use crate::grid::{CellStats, Evidence, FalseAlarms, LabelFalseAlarms, EVIDENCE_COUNTS};

/// The first eight bytes of a tile set.
pub const TILESET_MAGIC: &[u8; 8] = b"TARNTILE";
/// The version written; it and version 3 are read.
pub const TILESET_VERSION: u32 = 4;

/// The header of the oldest version read (3), the shortest.
const HEADER: usize = 8 + 4 + 4 + 8 + 8 + 16 + 8;
const TILE_HEADER: usize = 8 + 8 + 4;
const CELL_MIN: usize = 2 + 1 + 4;
const ELEVATION: u8 = 1;
const BELOW: u8 = 2;
const EVIDENCE: u8 = 4;

fn elevation_part(c: &CellStats) -> CellStats {
    CellStats {
        below: 0,
        ev: Evidence::default(),
        ..*c
    }
}

fn write_cell(out: &mut Vec<u8>, index: usize, c: &CellStats) {
    let has_elevation = elevation_part(c) != CellStats::default();
    let mut flags = 0;
    if has_elevation {
        flags |= ELEVATION;
    }
    if c.below != 0 {
        flags |= BELOW;
    }
    if !c.ev.is_empty() {
        flags |= EVIDENCE;
    }
    out.extend_from_slice(&(index as u16).to_le_bytes());
    out.push(flags);
    if has_elevation {
        out.extend_from_slice(&c.hits.to_le_bytes());
        out.extend_from_slice(&c.sw.to_le_bytes());
        out.extend_from_slice(&c.swv.to_le_bytes());
        out.extend_from_slice(&c.swz.to_le_bytes());
        out.extend_from_slice(&c.swzz.to_le_bytes());
        out.extend_from_slice(&c.zmin.to_le_bytes());
        out.extend_from_slice(&c.zmax.to_le_bytes());
    }
    if c.below != 0 {
        out.extend_from_slice(&c.below.to_le_bytes());
    }
    if !c.ev.is_empty() {
        let e = &c.ev;
        for n in e.counts() {
            out.extend_from_slice(&n.to_le_bytes());
        }
        out.extend_from_slice(&e.level_n.to_le_bytes());
        out.extend_from_slice(&e.level_sum_mm.to_le_bytes());
        out.extend_from_slice(&e.depth_n.to_le_bytes());
        out.extend_from_slice(&e.depth_sum_mm.to_le_bytes());
        out.extend_from_slice(&e.depth_gain_sum.to_le_bytes());
        out.extend_from_slice(&e.depth_gain_level_sum.to_le_bytes());
    }
}

/// A cursor over little-endian input that never reads past its end; its errors name the
/// `format` the bytes were meant to be and the byte where they went wrong.
pub(crate) struct ByteReader<'a> {
    pub(crate) bytes: &'a [u8],
    pub(crate) pos: usize,
    /// What the bytes are meant to be ("tile set", "region map").
    pub(crate) format: &'static str,
}

fn corrupt(pos: usize, message: impl std::fmt::Display) -> Error {
    Error::invalid("tile set", format!("at byte {pos}: {message}"))
}

impl<'a> ByteReader<'a> {
    pub(crate) fn take<const N: usize>(&mut self, what: &str) -> Result<[u8; N]> {
        let end = self.pos.checked_add(N).filter(|&e| e <= self.bytes.len());
        let Some(end) = end else {
            return Err(Error::invalid(
                self.format,
                format!(
                    "at byte {}: {what}: {N} bytes needed, {} left",
                    self.pos,
                    self.remaining()
                ),
            ));
        };
        let mut a = [0u8; N];
        a.copy_from_slice(&self.bytes[self.pos..end]);
        self.pos = end;
        Ok(a)
    }

    pub(crate) fn remaining(&self) -> usize {
        self.bytes.len() - self.pos
    }

    pub(crate) fn u8(&mut self, what: &str) -> Result<u8> {
        self.take::<1>(what).map(|[b]| b)
    }
    fn u16(&mut self, what: &str) -> Result<u16> {
        self.take(what).map(u16::from_le_bytes)
    }
    pub(crate) fn u32(&mut self, what: &str) -> Result<u32> {
        self.take(what).map(u32::from_le_bytes)
    }
    fn i32(&mut self, what: &str) -> Result<i32> {
        self.take(what).map(i32::from_le_bytes)
    }
    pub(crate) fn u64(&mut self, what: &str) -> Result<u64> {
        self.take(what).map(u64::from_le_bytes)
    }
    pub(crate) fn i64(&mut self, what: &str) -> Result<i64> {
        self.take(what).map(i64::from_le_bytes)
    }
    fn i128(&mut self, what: &str) -> Result<i128> {
        self.take(what).map(i128::from_le_bytes)
    }
    pub(crate) fn f64(&mut self, what: &str) -> Result<f64> {
        self.take(what).map(f64::from_le_bytes)
    }
    pub(crate) fn f32(&mut self, what: &str) -> Result<f32> {
        self.take(what).map(f32::from_le_bytes)
    }

    fn cell(&mut self) -> Result<(u16, CellStats)> {
        let at = self.pos;
        let index = self.u16("cell index")?;
        if index as i64 >= TILE_CELLS * TILE_CELLS {
            return Err(corrupt(at, format!("cell index {index} beyond the tile")));
        }
        let flags = self.take::<1>("cell flags")?[0];
        if flags == 0 || flags & !(ELEVATION | BELOW | EVIDENCE) != 0 {
            return Err(corrupt(at + 2, format!("cell flags {flags:#04x}")));
        }
        let mut c = CellStats::default();
        if flags & ELEVATION != 0 {
            c.hits = self.u32("hits")?;
            c.sw = self.u64("sw")?;
            c.swv = self.u64("swv")?;
            c.swz = self.i128("swz")?;
            c.swzz = self.i128("swzz")?;
            c.zmin = self.i32("zmin")?;
            c.zmax = self.i32("zmax")?;
            if c == CellStats::default() {
                return Err(corrupt(at, "an elevation block that is empty"));
            }
        }
        if flags & BELOW != 0 {
            c.below = self.u32("below")?;
            if c.below == 0 {
                return Err(corrupt(at, "a below-surface count of 0"));
            }
        }
        if flags & EVIDENCE != 0 {
            let mut counts = [0u16; EVIDENCE_COUNTS];
            for n in &mut counts {
                *n = self.u16("evidence count")?;
            }
            let e = &mut c.ev;
            e.set_counts(counts);
            e.level_n = self.u32("level_n")?;
            e.level_sum_mm = self.i64("level_sum_mm")?;
            e.depth_n = self.u32("depth_n")?;
            e.depth_sum_mm = self.u32("depth_sum_mm")?;
            e.depth_gain_sum = self.u32("depth_gain_sum")?;
            e.depth_gain_level_sum = self.i64("depth_gain_level_sum")?;
            if e.is_empty() {
                return Err(corrupt(at, "an evidence block that is empty"));
            }
        }
        Ok((index, c))
    }
}

impl TileMap {
    /// The map in the tile set format (module documentation): canonical, so two maps
    /// holding the same cells give the same bytes.
    pub fn to_bytes(&self) -> Vec<u8> {
        let mut out = Vec::with_capacity(HEADER + 4 + self.observed_count() * 60);
        out.extend_from_slice(TILESET_MAGIC);
        out.extend_from_slice(&TILESET_VERSION.to_le_bytes());
        out.extend_from_slice(&(TILE_CELLS as u32).to_le_bytes());
        out.extend_from_slice(&self.resolution.to_le_bytes());
        out.extend_from_slice(&self.z_ref.to_le_bytes());
        for a in [&self.false_alarms.colour, &self.false_alarms.swir] {
            out.extend_from_slice(&a.samples.to_le_bytes());
            out.extend_from_slice(&a.water.to_le_bytes());
        }
        out.extend_from_slice(&(self.tiles.len() as u64).to_le_bytes());
        for (&(tx, ty), tile) in &self.tiles {
            out.extend_from_slice(&tx.to_le_bytes());
            out.extend_from_slice(&ty.to_le_bytes());
            out.extend_from_slice(&(tile.observed() as u32).to_le_bytes());
            for (i, c) in tile.cells() {
                write_cell(&mut out, i, c);
            }
        }
        let crc = crc32fast::hash(&out);
        out.extend_from_slice(&crc.to_le_bytes());
        out
    }

    /// Reads bytes written by [`TileMap::to_bytes`]; anything else is an error naming the
    /// byte where it went wrong.
    pub fn from_bytes(bytes: &[u8]) -> Result<TileMap> {
        if bytes.len() < HEADER + 4 {
            return Err(corrupt(
                bytes.len(),
                format!("{} bytes, shorter than a tile set's header", bytes.len()),
            ));
        }
        if &bytes[..8] != TILESET_MAGIC {
            return Err(corrupt(0, "not a tile set (magic is not TARNTILE)"));
        }
        let (body, crc) = bytes.split_at(bytes.len() - 4);
        let mut r = ByteReader {
            bytes: body,
            pos: 8,
            format: "tile set",
        };
        let version = r.u32("version")?;
        if version != TILESET_VERSION && version != 3 {
            return Err(corrupt(
                8,
                format!("version {version}; this tarn reads versions 3 and {TILESET_VERSION}"),
            ));
        }
        let mut crc_bytes = [0u8; 4];
        crc_bytes.copy_from_slice(crc);
        let (want, got) = (u32::from_le_bytes(crc_bytes), crc32fast::hash(body));
        if want != got {
            return Err(corrupt(
                body.len(),
                format!("CRC {want:#010x} recorded, {got:#010x} computed: the bytes are damaged"),
            ));
        }
        let side = r.u32("tile side")?;
        if side as i64 != TILE_CELLS {
            return Err(corrupt(
                12,
                format!("tiles of {side} cells a side; this tarn uses {TILE_CELLS}"),
            ));
        }
        let resolution = r.f64("resolution")?;
        let z_ref = r.f64("z_ref")?;
        let mut map = TileMap::new(resolution, z_ref).map_err(|e| corrupt(16, e))?;
        let mut alarms = |camera: &str| {
            let at = r.pos;
            let a = FalseAlarms {
                samples: r.u64(&format!("{camera} false alarm samples"))?,
                water: r.u64(&format!("{camera} false alarms"))?,
            };
            if a.water > a.samples {
                return Err(corrupt(
                    at,
                    format!("more {camera} false alarms than samples"),
                ));
            }
            Ok(a)
        };
        map.false_alarms = LabelFalseAlarms {
            colour: alarms("colour")?,
            swir: if version >= 4 {
                alarms("SWIR")?
            } else {
                FalseAlarms::default()
            },
        };
        let at = r.pos;
        let tiles = r.u64("tile count")?;
        if tiles > (r.remaining() / (TILE_HEADER + CELL_MIN)) as u64 {
            return Err(corrupt(
                at,
                format!(
                    "{tiles} tiles cannot fit in the {} bytes left",
                    r.remaining()
                ),
            ));
        }
        let mut last: Option<(i64, i64)> = None;
        for _ in 0..tiles {
            let at = r.pos;
            let key = (r.i64("tile x")?, r.i64("tile y")?);
            if last.is_some_and(|l| l >= key) {
                return Err(corrupt(at, format!("tile {key:?} out of order")));
            }
            last = Some(key);
            let at = r.pos;
            let n = r.u32("tile cell count")? as usize;
            if n == 0 || n as i64 > TILE_CELLS * TILE_CELLS || n > r.remaining() / CELL_MIN {
                return Err(corrupt(
                    at,
                    format!("{n} cells in tile {key:?} ({} bytes left)", r.remaining()),
                ));
            }
            let mut tile = Tile::new();
            let mut prev: Option<u16> = None;
            for _ in 0..n {
                let at = r.pos;
                let (i, c) = r.cell()?;
                if prev.is_some_and(|p| p >= i) {
                    return Err(corrupt(
                        at,
                        format!("cell {i} of tile {key:?} out of order"),
                    ));
                }
                prev = Some(i);
                tile.merge(i as usize, &c);
            }
            map.tiles.insert(key, tile);
        }
        if r.remaining() != 0 {
            return Err(corrupt(
                r.pos,
                format!("{} bytes after the last tile", r.remaining()),
            ));
        }
        Ok(map)
    }

    /// The tile keys `(tx, ty)` holding observed cells, in increasing order.
    pub fn tile_keys(&self) -> Vec<(i64, i64)> {
        self.tiles.keys().copied().collect()
    }

    /// A new map (same resolution and reference height) of the tiles whose key `keep`
    /// accepts, without the false alarms (they describe the logs, not the tiles).
    pub fn select(&self, keep: impl Fn((i64, i64)) -> bool) -> TileMap {
        TileMap {
            resolution: self.resolution,
            z_ref: self.z_ref,
            tiles: self
                .tiles
                .iter()
                .filter(|(&k, _)| keep(k))
                .map(|(&k, t)| (k, t.clone()))
                .collect(),
            false_alarms: LabelFalseAlarms::default(),
        }
    }

    /// Splits the map into `parts` maps (at least one) by tile key: every tile goes whole
    /// to part [`TileMap::part_of`], the false alarms to part 0. Merging the parts gives
    /// the map back; merging the same
    /// part of many maps reduces one region independently of the others.
    pub fn partition(&self, parts: usize) -> Vec<TileMap> {
        let parts = parts.max(1);
        let mut out: Vec<TileMap> = (0..parts)
            .map(|_| TileMap {
                resolution: self.resolution,
                z_ref: self.z_ref,
                tiles: Default::default(),
                false_alarms: LabelFalseAlarms::default(),
            })
            .collect();
        for (&k, t) in &self.tiles {
            out[Self::part_of(k, parts)].tiles.insert(k, t.clone());
        }
        out[0].false_alarms = self.false_alarms;
        out
    }

    /// The part (of `parts`) that tile `key` belongs to in [`TileMap::partition`]: a fixed
    /// hash of the key, the same in every process.
    pub fn part_of(key: (i64, i64), parts: usize) -> usize {
        let h = (key.0 as u64)
            .wrapping_mul(0x9E37_79B9_7F4A_7C15)
            .rotate_left(29)
            ^ (key.1 as u64).wrapping_mul(0xC2B2_AE3D_27D4_EB4F);
        (h.rotate_left(17).wrapping_mul(0x1656_67B1_9E37_79F9) % parts.max(1) as u64) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::grid::CellKey;
    use proptest::prelude::*;

    /// One contribution: a cell key in a small area (so contributions collide, cross tile
    /// borders, and fill tile (0, 0) past the 256 cells where it turns dense), elevation
    /// points, below count and evidence.
    fn contribution() -> impl Strategy<Value = (CellKey, CellStats)> {
        (
            (-8i64..56, -4i64..20),
            prop::collection::vec((-5000i32..5000, 1u32..100_000), 0..3),
            0u32..3,
            prop::option::of((
                prop::array::uniform11(prop::num::u16::ANY),
                0u32..5,
                -10_000i64..10_000,
                0u32..5,
            )),
        )
            .prop_map(|((x, y), pts, below, ev)| {
                let mut c = CellStats::default();
                for (z, w) in pts {
                    c.add(z, w);
                }
                c.below = below;
                if let Some((counts, level_n, level_sum_mm, depth_n)) = ev {
                    c.ev.set_counts(counts);
                    c.ev.level_n = level_n;
                    c.ev.level_sum_mm = level_sum_mm;
                    c.ev.depth_n = depth_n;
                    c.ev.depth_sum_mm = depth_n * 700;
                }
                (CellKey::new(x, y), c)
            })
    }

    fn map_of(cells: &[(CellKey, CellStats)]) -> TileMap {
        let mut m = TileMap::new(0.1, 2.5).unwrap();
        for (k, c) in cells {
            m.add(*k, c);
        }
        m
    }

    /// Merges maps pairwise in the order `order` picks them, as a reduction tree would.
    fn tree_merge(mut maps: Vec<TileMap>, picks: &[usize]) -> TileMap {
        let mut p = picks.iter().cycle();
        while maps.len() > 1 {
            let i = p.next().map_or(0, |&i| i % maps.len());
            let a = maps.swap_remove(i);
            let j = p.next().map_or(0, |&j| j % maps.len());
            maps[j].merge(&a).unwrap();
        }
        maps.pop().unwrap()
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(64))]

        /// Any split of the contributions into chunks, merged in any order and tree, gives
        /// the bytes of one pass over all of them; the bytes read back to the same map.
        #[test]
        fn any_split_and_merge_order_is_one_pass(
            cells in prop::collection::vec(contribution(), 0..700),
            cuts in prop::collection::vec(0usize..700, 0..6),
            shuffle in prop::collection::vec(0usize..1000, 0..400),
            picks in prop::collection::vec(0usize..1000, 1..20),
        ) {
            let one_pass = map_of(&cells);
            let bytes = one_pass.to_bytes();
            // Chunks: contiguous runs at the cuts, then the order of contributions inside
            // and across chunks shuffled.
            let mut cuts: Vec<usize> = cuts.into_iter().map(|c| c.min(cells.len())).collect();
            cuts.push(0);
            cuts.push(cells.len());
            cuts.sort();
            let mut chunks: Vec<Vec<(CellKey, CellStats)>> =
                cuts.windows(2).map(|w| cells[w[0]..w[1]].to_vec()).collect();
            for (i, s) in shuffle.iter().enumerate() {
                let n = chunks.len();
                let (a, b) = (i % n, s % n);
                if let Some(x) = chunks[a].pop() {
                    if a != b {
                        chunks[b].push(x);
                    } else {
                        chunks[a].insert(0, x);
                    }
                }
            }
            prop_assert_eq!(chunks.iter().map(Vec::len).sum::<usize>(), cells.len());
            let parts: Vec<TileMap> = chunks.iter().map(|c| map_of(c)).collect();
            // Each part through the byte format, as between processes.
            let parts: Vec<TileMap> = parts
                .iter()
                .map(|m| TileMap::from_bytes(&m.to_bytes()).unwrap())
                .collect();
            let merged = tree_merge(parts, &picks);
            // (Compared without Debug output: a failing map prints thousands of lines.)
            prop_assert!(merged == one_pass, "merged chunks differ from the one pass");
            prop_assert!(merged.to_bytes() == bytes, "bytes differ");
            let back = TileMap::from_bytes(&bytes).unwrap();
            prop_assert!(back.to_bytes() == bytes, "bytes differ after a round trip");
            // Partitioned by tile key and merged back: the same map.
            let k = 1 + picks[0] % 5;
            let regions = one_pass.partition(k);
            prop_assert_eq!(regions.len(), k);
            prop_assert!(tree_merge(regions, &picks).to_bytes() == bytes, "partitions differ");
        }

        /// Damaged bytes are an error, never a panic or a huge allocation.
        #[test]
        fn damaged_bytes_are_errors(
            cells in prop::collection::vec(contribution(), 1..50),
            at in 0usize..100_000,
            xor in 1u8..=255,
            cut in 0usize..100_000,
        ) {
            let bytes = map_of(&cells).to_bytes();
            let mut flipped = bytes.clone();
            let i = at % flipped.len();
            flipped[i] ^= xor;
            prop_assert!(TileMap::from_bytes(&flipped).is_err());
            let cut = cut % bytes.len();
            prop_assert!(TileMap::from_bytes(&bytes[..cut]).is_err());
        }
    }

    #[test]
    fn errors_name_what_is_wrong() {
        let mut m = TileMap::new(0.1, 0.0).unwrap();
        m.add(CellKey::new(3, -70), &{
            let mut c = CellStats::default();
            c.add(100, 65536);
            c
        });
        let bytes = m.to_bytes();
        assert_eq!(bytes.len(), HEADER + 16 + TILE_HEADER + 3 + 60 + 4);
        // The false alarms travel with the cells.
        let mut a = m.clone();
        a.add_false_alarms(&LabelFalseAlarms {
            colour: FalseAlarms {
                samples: 7,
                water: 2,
            },
            swir: FalseAlarms {
                samples: 5,
                water: 1,
            },
        });
        assert_eq!(TileMap::from_bytes(&a.to_bytes()).unwrap(), a);
        assert_ne!(a, m);
        let e = TileMap::from_bytes(b"PLY\n").unwrap_err().to_string();
        assert!(e.contains("shorter than a tile set's header"), "{e}");
        let mut v = bytes.clone();
        v[0] = b'X';
        let e = TileMap::from_bytes(&v).unwrap_err().to_string();
        assert!(e.contains("magic"), "{e}");
        let mut v = bytes.clone();
        v[8] = 5;
        let e = TileMap::from_bytes(&v).unwrap_err().to_string();
        assert!(e.contains("version 5"), "{e}");
        // More false alarms than samples, with a valid CRC.
        let mut v = bytes[..bytes.len() - 4].to_vec();
        v[32..40].copy_from_slice(&5u64.to_le_bytes());
        v[40..48].copy_from_slice(&6u64.to_le_bytes());
        let crc = crc32fast::hash(&v);
        v.extend_from_slice(&crc.to_le_bytes());
        let e = TileMap::from_bytes(&v).unwrap_err().to_string();
        assert!(
            e.contains("at byte 32: more colour false alarms than samples"),
            "{e}"
        );
        let mut v = bytes[..bytes.len() - 4].to_vec();
        v[48..56].copy_from_slice(&1u64.to_le_bytes());
        v[56..64].copy_from_slice(&2u64.to_le_bytes());
        let crc = crc32fast::hash(&v);
        v.extend_from_slice(&crc.to_le_bytes());
        let e = TileMap::from_bytes(&v).unwrap_err().to_string();
        assert!(
            e.contains("at byte 48: more SWIR false alarms than samples"),
            "{e}"
        );
        // Version 3, without the SWIR false alarms, reads as none.
        let v4 = a.to_bytes();
        let mut v = [
            &v4[..8],
            &3u32.to_le_bytes(),
            &v4[12..48],
            &v4[64..v4.len() - 4],
        ]
        .concat();
        let crc = crc32fast::hash(&v);
        v.extend_from_slice(&crc.to_le_bytes());
        let old = TileMap::from_bytes(&v).unwrap();
        assert_eq!(old.false_alarms().colour, a.false_alarms().colour);
        assert_eq!(old.false_alarms().swir, FalseAlarms::default());
        assert_eq!(old.observed_count(), a.observed_count());
        // A tile count of 2^40 with a valid CRC: refused before any allocation.
        let mut v = bytes[..bytes.len() - 4].to_vec();
        v[64..72].copy_from_slice(&(1u64 << 40).to_le_bytes());
        let crc = crc32fast::hash(&v);
        v.extend_from_slice(&crc.to_le_bytes());
        let e = TileMap::from_bytes(&v).unwrap_err().to_string();
        assert!(e.contains("cannot fit"), "{e}");
        let mut v = bytes.clone();
        let n = v.len();
        v[n - 10] ^= 1;
        let e = TileMap::from_bytes(&v).unwrap_err().to_string();
        assert!(e.contains("CRC"), "{e}");
        // Different resolutions do not merge.
        let other = TileMap::new(0.2, 0.0).unwrap();
        assert!(m.clone().merge(&other).is_err());
    }
}
