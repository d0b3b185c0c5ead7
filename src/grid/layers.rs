//! The storage of a grid's cells: one 64-byte elevation record a cell ([`Elev`]) and the
//! evidence as structure-of-arrays ([`Layers`]).

use super::{CellStats, Evidence, EVIDENCE_BYTES_PER_CELL, EVIDENCE_COUNTS};

/// The elevation statistics of one cell ([`CellStats`] without its evidence), laid out
/// in exactly one 64-byte cache line: everything ingest reads and writes for a cell (the
/// prior surface its gate tests points against, and the merge of a batch) is one line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(C, align(64))]
pub(crate) struct Elev {
    pub hits: u32,
    pub below: u32,
    pub zmin: i32,
    pub zmax: i32,
    pub sw: u64,
    pub swv: u64,
    pub swz: i128,
    pub swzz: i128,
}

impl Default for Elev {
    fn default() -> Self {
        Elev::of(&CellStats::default())
    }
}

impl Elev {
    /// The elevation statistics of `c`.
    #[inline]
    pub fn of(c: &CellStats) -> Self {
        Elev {
            hits: c.hits,
            below: c.below,
            zmin: c.zmin,
            zmax: c.zmax,
            sw: c.sw,
            swv: c.swv,
            swz: c.swz,
            swzz: c.swzz,
        }
    }

    /// As [`CellStats`], with empty evidence.
    #[inline]
    pub fn stats(&self) -> CellStats {
        let mut c = CellStats::default();
        self.write_to(&mut c);
        c
    }

    /// Sets `c`'s elevation statistics to these, keeping its evidence.
    #[inline]
    pub(crate) fn write_to(&self, c: &mut CellStats) {
        c.hits = self.hits;
        c.below = self.below;
        c.sw = self.sw;
        c.swv = self.swv;
        c.swz = self.swz;
        c.swzz = self.swzz;
        c.zmin = self.zmin;
        c.zmax = self.zmax;
    }

    /// Fuses one quantized measurement (the arithmetic behind [`CellStats::add`]).
    #[inline]
    pub fn add(&mut self, z_mm: i32, w: u32, q: u32) {
        // |w·z| < 2^55 fits i64; the square needs one widening multiply.
        let wz = w as i64 * z_mm as i64;
        self.hits += 1;
        self.sw += w as u64;
        self.swv += q as u64;
        self.swz += wz as i128;
        self.swzz += wz as i128 * z_mm as i128;
        self.zmin = self.zmin.min(z_mm);
        self.zmax = self.zmax.max(z_mm);
    }

    /// The elevation part of [`CellStats::merge`].
    #[inline]
    pub fn merge(&mut self, o: &Elev) {
        self.hits += o.hits;
        self.below += o.below;
        self.sw += o.sw;
        self.swv += o.swv;
        self.swz += o.swz;
        self.swzz += o.swzz;
        self.zmin = self.zmin.min(o.zmin);
        self.zmax = self.zmax.max(o.zmax);
    }

    /// True when no point was recorded (fused or below the surface).
    #[inline]
    pub(crate) fn no_points(&self) -> bool {
        self.hits == 0 && self.below == 0
    }
}

/// Storage of [`CellStats`]: the elevation statistics as one record a cell, the evidence
/// as structure-of-arrays.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Layers {
    /// Whether the cell holds anything (`!CellStats::is_empty`), kept by every writer: the
    /// water stage asks it of every cell of the window every frame, and one byte a cell is
    /// read far faster than the records it stands for.
    pub(super) occupied: Vec<bool>,
    pub elev: Vec<Elev>,
    /// Evidence event counts in [`Evidence::counts`] order.
    pub ev_counts: Vec<[u16; EVIDENCE_COUNTS]>,
    pub ev_level_n: Vec<u32>,
    pub ev_level_sum: Vec<i64>,
    /// Evidence: depth count, Σ depth mm, Σ gain; Σ gain · level.
    pub ev_depth: Vec<[u32; 3]>,
    pub ev_depth_gain_level: Vec<i64>,
}

impl Layers {
    pub(super) fn new(n: usize) -> Self {
        Layers {
            occupied: vec![false; n],
            elev: vec![Elev::default(); n],
            ev_counts: vec![[0; EVIDENCE_COUNTS]; n],
            ev_level_n: vec![0; n],
            ev_level_sum: vec![0; n],
            ev_depth: vec![[0; 3]; n],
            ev_depth_gain_level: vec![0; n],
        }
    }

    /// Bytes of layer storage per cell: 1 for occupancy, 64 for the elevation record, the
    /// rest evidence.
    pub(crate) const BYTES_PER_CELL: usize =
        1 + std::mem::size_of::<Elev>() + EVIDENCE_BYTES_PER_CELL;

    /// Bytes allocated by the layers (their capacities).
    pub(super) fn heap_bytes(&self) -> usize {
        fn b<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        b(&self.occupied)
            + b(&self.elev)
            + b(&self.ev_counts)
            + b(&self.ev_level_n)
            + b(&self.ev_level_sum)
            + b(&self.ev_depth)
            + b(&self.ev_depth_gain_level)
    }

    #[inline]
    pub(crate) fn get_ev(&self, i: usize) -> Evidence {
        let d = self.ev_depth[i];
        let mut e = Evidence {
            level_n: self.ev_level_n[i],
            level_sum_mm: self.ev_level_sum[i],
            depth_n: d[0],
            depth_sum_mm: d[1],
            depth_gain_sum: d[2],
            depth_gain_level_sum: self.ev_depth_gain_level[i],
            ..Evidence::default()
        };
        e.set_counts(self.ev_counts[i]);
        e
    }

    #[inline]
    pub(crate) fn set_ev(&mut self, i: usize, e: &Evidence) {
        self.occupied[i] = !self.elev[i].no_points() || !e.is_empty();
        self.ev_counts[i] = e.counts();
        self.ev_level_n[i] = e.level_n;
        self.ev_level_sum[i] = e.level_sum_mm;
        self.ev_depth[i] = [e.depth_n, e.depth_sum_mm, e.depth_gain_sum];
        self.ev_depth_gain_level[i] = e.depth_gain_level_sum;
    }

    /// The elevation statistics of cell `i` only (no evidence, no extremes): all that
    /// [`CellStats::mean_mm`], [`CellStats::elevation_std_m`] and
    /// [`CellStats::range_bound_std_m`] read.
    #[inline]
    pub(crate) fn elevation_stats(&self, i: usize) -> CellStats {
        let e = &self.elev[i];
        CellStats {
            hits: e.hits,
            below: e.below,
            sw: e.sw,
            swv: e.swv,
            swz: e.swz,
            swzz: e.swzz,
            ..CellStats::default()
        }
    }

    #[inline]
    pub fn get(&self, i: usize) -> CellStats {
        CellStats {
            ev: self.get_ev(i),
            ..self.elev[i].stats()
        }
    }

    #[inline]
    pub fn set(&mut self, i: usize, c: &CellStats) {
        self.elev[i] = Elev::of(c);
        self.set_ev(i, &c.ev);
    }

    #[inline]
    pub(crate) fn merge_at(&mut self, i: usize, c: &CellStats) {
        self.elev[i].merge(&Elev::of(c));
        self.occupied[i] |= c.hits != 0 || c.below != 0;
        if !c.ev.is_empty() {
            self.merge_ev_at(i, &c.ev);
        }
    }

    #[inline]
    pub(crate) fn merge_ev_at(&mut self, i: usize, e: &Evidence) {
        let mut m = self.get_ev(i);
        m.merge(e);
        self.set_ev(i, &m);
    }

    #[inline]
    pub(crate) fn is_empty_at(&self, i: usize) -> bool {
        !self.occupied[i]
    }
}
