//! The storage of a grid's cells: one 64-byte elevation record a cell ([`Elev`]), the
//! evidence's event counts as a layer, and the level and depth evidence that few cells have
//! in slots apart ([`Layers`]).

use super::{CellStats, Evidence, EVIDENCE_BYTES_PER_CELL, EVIDENCE_COUNTS};

/// Event counts in the dense layer: the lidar's, the reflections' and the colour camera's
/// (the first of [`Evidence::counts`]).
pub(crate) const DENSE_COUNTS: usize = 7;
/// Event counts of the infrared cameras (SWIR dark/lit, MWIR water/dry: the rest of
/// [`Evidence::counts`]), in a layer allocated when one first votes.
const IR_COUNTS: usize = EVIDENCE_COUNTS - DENSE_COUNTS;

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

/// The evidence few cells get (water-level samples, bottom returns): stored apart from
/// the window's layers, in a slot of [`Layers::rare`] for each cell that has any.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub(crate) struct Rare {
    level_sum: i64,
    depth_gain_level: i64,
    level_n: u32,
    /// Depth count, Σ depth mm, Σ gain.
    depth: [u32; 3],
}

impl Rare {
    #[inline]
    fn of(e: &Evidence) -> Self {
        Rare {
            level_sum: e.level_sum_mm,
            depth_gain_level: e.depth_gain_level_sum,
            level_n: e.level_n,
            depth: [e.depth_n, e.depth_sum_mm, e.depth_gain_sum],
        }
    }

    #[inline]
    fn write_to(&self, e: &mut Evidence) {
        e.level_n = self.level_n;
        e.level_sum_mm = self.level_sum;
        [e.depth_n, e.depth_sum_mm, e.depth_gain_sum] = self.depth;
        e.depth_gain_level_sum = self.depth_gain_level;
    }
}

/// [`Layers::rare_slot`] of a cell without level or depth evidence.
const NO_RARE: u32 = u32::MAX;

/// Storage of [`CellStats`]: the elevation statistics as one record a cell, the evidence
/// event counts as a layer, the level and depth evidence of the few cells that have any
/// in slots.
#[derive(Debug, Clone)]
pub(crate) struct Layers {
    /// Whether the cell holds anything (`!CellStats::is_empty`), kept by every writer: the
    /// water stage asks it of every cell of the window every frame, and one byte a cell is
    /// read far faster than the records it stands for.
    pub(super) occupied: Vec<bool>,
    pub elev: Vec<Elev>,
    /// Evidence event counts in [`Evidence::counts`] order, the first [`DENSE_COUNTS`].
    pub ev_counts: Vec<[u16; DENSE_COUNTS]>,
    /// The infrared cameras' counts (the rest): empty until a SWIR or MWIR camera first
    /// votes (most rigs have none), then one a cell.
    ev_ir: Vec<[u16; IR_COUNTS]>,
    /// The slot in `rare` of each cell's level and depth evidence; [`NO_RARE`] without any.
    rare_slot: Vec<u32>,
    /// Level and depth evidence of the cells that have any (water cells, reflections,
    /// bottom returns): a few percent of a window.
    rare: Vec<Rare>,
    /// Slots of `rare` that no cell holds.
    free: Vec<u32>,
}

impl PartialEq for Layers {
    /// The same cells (whatever slots their level and depth evidence is in).
    fn eq(&self, o: &Self) -> bool {
        self.occupied == o.occupied
            && self.elev == o.elev
            && self.ev_counts == o.ev_counts
            && (0..self.ev_counts.len()).all(|i| self.ir_at(i) == o.ir_at(i))
            && (0..self.rare_slot.len()).all(|i| self.rare_at(i) == o.rare_at(i))
    }
}

impl Layers {
    pub(super) fn new(n: usize) -> Self {
        Layers {
            occupied: vec![false; n],
            elev: vec![Elev::default(); n],
            ev_counts: vec![[0; DENSE_COUNTS]; n],
            ev_ir: Vec::new(),
            rare_slot: vec![NO_RARE; n],
            rare: Vec::new(),
            free: Vec::new(),
        }
    }

    /// Bytes of the dense layers per cell: 1 for occupancy, 64 for the elevation record,
    /// the rest evidence (the level and depth evidence in slots comes on top,
    /// [`Layers::heap_bytes`]).
    pub(crate) const BYTES_PER_CELL: usize =
        1 + std::mem::size_of::<Elev>() + EVIDENCE_BYTES_PER_CELL;

    /// Bytes allocated by the layers (their capacities), the slots of level and depth
    /// evidence included.
    pub(super) fn heap_bytes(&self) -> usize {
        fn b<T>(v: &Vec<T>) -> usize {
            v.capacity() * std::mem::size_of::<T>()
        }
        b(&self.occupied)
            + b(&self.elev)
            + b(&self.ev_counts)
            + b(&self.ev_ir)
            + b(&self.rare_slot)
            + b(&self.rare)
            + b(&self.free)
    }

    /// The infrared cameras' counts of cell `i` (zero before any voted).
    #[inline]
    fn ir_at(&self, i: usize) -> [u16; IR_COUNTS] {
        self.ev_ir.get(i).copied().unwrap_or_default()
    }

    /// The level and depth evidence of cell `i` (empty without any).
    #[inline]
    fn rare_at(&self, i: usize) -> Rare {
        match self.rare_slot[i] {
            NO_RARE => Rare::default(),
            s => self.rare[s as usize],
        }
    }

    #[inline]
    pub(crate) fn get_ev(&self, i: usize) -> Evidence {
        let mut e = Evidence::default();
        let mut c = [0; EVIDENCE_COUNTS];
        c[..DENSE_COUNTS].copy_from_slice(&self.ev_counts[i]);
        c[DENSE_COUNTS..].copy_from_slice(&self.ir_at(i));
        e.set_counts(c);
        let s = self.rare_slot[i];
        if s != NO_RARE {
            self.rare[s as usize].write_to(&mut e);
        }
        e
    }

    #[inline]
    pub(crate) fn set_ev(&mut self, i: usize, e: &Evidence) {
        self.occupied[i] = !self.elev[i].no_points() || !e.is_empty();
        let c = e.counts();
        let (dense, ir) = c.split_at(DENSE_COUNTS);
        self.ev_counts[i] = dense.try_into().expect("DENSE_COUNTS counts");
        let ir: [u16; IR_COUNTS] = ir.try_into().expect("IR_COUNTS counts");
        if self.ev_ir.is_empty() && ir != [0; IR_COUNTS] {
            self.ev_ir = vec![[0; IR_COUNTS]; self.ev_counts.len()];
        }
        if let Some(v) = self.ev_ir.get_mut(i) {
            *v = ir;
        }
        let r = Rare::of(e);
        let s = self.rare_slot[i];
        if r == Rare::default() {
            if s != NO_RARE {
                self.free.push(s);
                self.rare_slot[i] = NO_RARE;
            }
        } else if s != NO_RARE {
            self.rare[s as usize] = r;
        } else {
            let s = match self.free.pop() {
                Some(s) => s,
                None => {
                    self.rare.push(Rare::default());
                    (self.rare.len() - 1) as u32
                }
            };
            self.rare[s as usize] = r;
            self.rare_slot[i] = s;
        }
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
