//! A transform buffer: the tree of frames over time, as ROS `tf2` keeps it.
//!
//! Dynamic transforms (`/tf`) are kept as time series per child frame and interpolated
//! (linear translation, slerp rotation); static ones (`/tf_static`) hold at all times.
//! A lookup outside the buffered time of a dynamic edge is an error, never an
//! extrapolation.

use std::collections::{HashMap, VecDeque};

use crate::geom::Pose;

use crate::ros::TransformStamped;

/// Why a transform could not be looked up.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum TfError {
    /// No transform connects the frame to anything.
    UnknownFrame(String),
    /// The two frames are in different trees.
    NotConnected {
        /// The frame coordinates were to be mapped to.
        target: String,
        /// The frame coordinates were to be mapped from.
        source: String,
    },
    /// The time is before the first or after the last transform of an edge.
    OutOfRange {
        /// Parent frame of the edge.
        parent: String,
        /// Child frame of the edge.
        child: String,
        /// The time asked for, nanoseconds.
        t_ns: i64,
        /// Stamp of the edge's first transform, nanoseconds.
        first_ns: i64,
        /// Stamp of the edge's last transform, nanoseconds.
        last_ns: i64,
    },
    /// The frame graph has a cycle or is deeper than any real robot.
    TooDeep(String),
}

impl std::fmt::Display for TfError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            TfError::UnknownFrame(s) => write!(f, "no transform for frame {s:?}"),
            TfError::NotConnected { target, source } => {
                write!(f, "frames {source:?} and {target:?} are not connected")
            }
            TfError::OutOfRange {
                parent,
                child,
                t_ns,
                first_ns,
                last_ns,
            } => write!(
                f,
                "{parent} → {child} at t = {:.9} s is outside the buffered time [{:.9}, {:.9}] s",
                *t_ns as f64 * 1e-9,
                *first_ns as f64 * 1e-9,
                *last_ns as f64 * 1e-9
            ),
            TfError::TooDeep(s) => write!(f, "frame tree from {s:?} is cyclic or too deep"),
        }
    }
}

impl std::error::Error for TfError {}

#[derive(Debug, Clone)]
struct Dynamic {
    parent: String,
    /// (time ns, child_to_parent), sorted by time.
    samples: VecDeque<(i64, Pose)>,
}

/// Transforms over time. Poses are `child_to_parent`.
#[derive(Debug, Clone, Default)]
pub struct TfBuffer {
    statics: HashMap<String, (String, Pose)>,
    dynamics: HashMap<String, Dynamic>,
}

const MAX_DEPTH: usize = 64;

/// Interpolates between two poses: linear in translation, slerp in rotation.
pub(crate) fn interpolate(a: &Pose, b: &Pose, s: f64) -> Pose {
    let t = a.translation.vector.lerp(&b.translation.vector, s);
    // try_slerp fails only for opposite quaternions (180° apart); nlerp is then as good
    // as anything.
    let r = a
        .rotation
        .try_slerp(&b.rotation, s, 1e-12)
        .unwrap_or_else(|| a.rotation.nlerp(&b.rotation, s));
    Pose::from_parts(t.into(), r)
}

impl TfBuffer {
    /// An empty buffer.
    pub fn new() -> Self {
        Self::default()
    }

    /// Adds a transform; `is_static` for `/tf_static`.
    pub fn insert(&mut self, t: &TransformStamped, is_static: bool) {
        let child = t.child_frame_id.trim_start_matches('/').to_string();
        let parent = t.header.frame_id.trim_start_matches('/').to_string();
        if is_static {
            self.statics.insert(child, (parent, t.child_to_parent));
            return;
        }
        let ns = t.header.stamp.to_nanos();
        let d = self.dynamics.entry(child).or_insert_with(|| Dynamic {
            parent: parent.clone(),
            samples: VecDeque::new(),
        });
        if d.parent != parent {
            // Re-parenting: tf2 keeps the latest; so do we.
            d.parent = parent;
            d.samples.clear();
        }
        match d.samples.back() {
            Some((last, _)) if *last < ns => d.samples.push_back((ns, t.child_to_parent)),
            None => d.samples.push_back((ns, t.child_to_parent)),
            _ => {
                let i = d.samples.partition_point(|(s, _)| *s < ns);
                if d.samples.get(i).is_some_and(|(s, _)| *s == ns) {
                    d.samples[i].1 = t.child_to_parent;
                } else {
                    d.samples.insert(i, (ns, t.child_to_parent));
                }
            }
        }
    }

    /// Forgets dynamic samples older than `t_ns`, keeping the last one before it so that
    /// lookups at `t_ns` itself still interpolate.
    pub(crate) fn prune_before(&mut self, t_ns: i64) {
        for d in self.dynamics.values_mut() {
            while d.samples.len() > 1 && d.samples[1].0 <= t_ns {
                d.samples.pop_front();
            }
        }
    }

    /// Number of dynamic samples held (for memory checks).
    pub fn len(&self) -> usize {
        self.dynamics
            .values()
            .map(|d| d.samples.len())
            .sum::<usize>()
            + self.statics.len()
    }

    /// Whether no transform is held, static or dynamic.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Latest time covered by the dynamic edge above `child`, if it is dynamic.
    pub fn latest(&self, child: &str) -> Option<i64> {
        self.dynamics
            .get(child)
            .and_then(|d| d.samples.back().map(|s| s.0))
    }

    /// Parent of `frame` and `frame_to_parent` at `t_ns`.
    fn edge(&self, frame: &str, t_ns: i64) -> Option<Result<(&str, Pose), TfError>> {
        if let Some((p, pose)) = self.statics.get(frame) {
            return Some(Ok((p.as_str(), *pose)));
        }
        let d = self.dynamics.get(frame)?;
        let (first, last) = (d.samples.front()?, d.samples.back()?);
        if t_ns < first.0 || t_ns > last.0 {
            return Some(Err(TfError::OutOfRange {
                parent: d.parent.clone(),
                child: frame.to_string(),
                t_ns,
                first_ns: first.0,
                last_ns: last.0,
            }));
        }
        let i = d.samples.partition_point(|(s, _)| *s < t_ns);
        let (tb, pb) = d.samples[i];
        let pose = if tb == t_ns || i == 0 {
            pb
        } else {
            let (ta, pa) = d.samples[i - 1];
            interpolate(&pa, &pb, (t_ns - ta) as f64 / (tb - ta) as f64)
        };
        Some(Ok((d.parent.as_str(), pose)))
    }

    /// Chain from `frame` to its root: (ancestor, frame_to_ancestor) for each ancestor,
    /// starting with (frame, identity).
    fn chain(&self, frame: &str, t_ns: i64) -> Result<Vec<(String, Pose)>, TfError> {
        let mut out = vec![(frame.to_string(), Pose::identity())];
        let mut cur = frame.to_string();
        let mut acc = Pose::identity();
        for _ in 0..MAX_DEPTH {
            match self.edge(&cur, t_ns) {
                None => return Ok(out),
                Some(Err(e)) => return Err(e),
                Some(Ok((parent, pose))) => {
                    acc = pose * acc;
                    cur = parent.to_string();
                    out.push((cur.clone(), acc));
                }
            }
        }
        Err(TfError::TooDeep(frame.to_string()))
    }

    /// `source_to_target` at `t_ns`: maps coordinates in `source` to `target`.
    pub fn lookup(&self, target: &str, source: &str, t_ns: i64) -> Result<Pose, TfError> {
        let target = target.trim_start_matches('/');
        let source = source.trim_start_matches('/');
        if target == source {
            return Ok(Pose::identity());
        }
        let known = |f: &str| {
            self.statics.contains_key(f)
                || self.dynamics.contains_key(f)
                || self.statics.values().any(|(p, _)| p == f)
                || self.dynamics.values().any(|d| d.parent == f)
        };
        for f in [source, target] {
            if !known(f) {
                return Err(TfError::UnknownFrame(f.to_string()));
            }
        }
        let cs = self.chain(source, t_ns)?;
        let ct = self.chain(target, t_ns)?;
        for (anc, s_to_anc) in &cs {
            if let Some((_, t_to_anc)) = ct.iter().find(|(a, _)| a == anc) {
                return Ok(t_to_anc.inverse() * s_to_anc);
            }
        }
        Err(TfError::NotConnected {
            target: target.to_string(),
            source: source.to_string(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::geom::pose_xyz_rpy;
    use proptest::prelude::*;

    fn ts(parent: &str, child: &str, ns: i64, p: Pose) -> TransformStamped {
        TransformStamped::new(parent, child, ns, p)
    }

    fn close(a: &Pose, b: &Pose) -> bool {
        (a.to_homogeneous() - b.to_homogeneous()).norm() < 1e-9
    }

    #[test]
    fn interpolates_midway_with_slerp() {
        let mut b = TfBuffer::new();
        b.insert(
            &ts(
                "map",
                "base_link",
                0,
                pose_xyz_rpy(0.0, 0.0, 0.0, 0.0, 0.0, 0.0),
            ),
            false,
        );
        b.insert(
            &ts(
                "map",
                "base_link",
                2_000_000_000,
                pose_xyz_rpy(2.0, 4.0, 0.0, 0.0, 0.0, 1.0),
            ),
            false,
        );
        let p = b.lookup("map", "base_link", 1_000_000_000).unwrap();
        assert!(
            close(&p, &pose_xyz_rpy(1.0, 2.0, 0.0, 0.0, 0.0, 0.5)),
            "{p}"
        );
    }

    #[test]
    fn outside_buffer_is_an_error() {
        let mut b = TfBuffer::new();
        b.insert(&ts("map", "base_link", 10, Pose::identity()), false);
        b.insert(&ts("map", "base_link", 20, Pose::identity()), false);
        assert!(matches!(
            b.lookup("map", "base_link", 21),
            Err(TfError::OutOfRange { .. })
        ));
        assert!(matches!(
            b.lookup("map", "base_link", 9),
            Err(TfError::OutOfRange { .. })
        ));
        assert!(b.lookup("map", "base_link", 20).is_ok());
        assert!(matches!(
            b.lookup("map", "nowhere", 15),
            Err(TfError::UnknownFrame(_))
        ));
    }

    #[test]
    fn chains_static_and_dynamic_and_inverts() {
        let mut b = TfBuffer::new();
        let base = pose_xyz_rpy(10.0, 0.0, 0.0, 0.0, 0.0, std::f64::consts::FRAC_PI_2);
        let lidar = pose_xyz_rpy(1.0, 0.0, 2.0, 0.0, 0.0, 0.0);
        b.insert(&ts("map", "base_link", 0, base), false);
        b.insert(&ts("map", "base_link", 100, base), false);
        b.insert(&ts("base_link", "lidar", 0, lidar), true);
        let p = b.lookup("map", "lidar", 50).unwrap();
        assert!(close(&p, &(base * lidar)));
        let q = b.lookup("lidar", "map", 50).unwrap();
        assert!(close(&q, &(base * lidar).inverse()));
        // Lidar origin in map: base at (10,0), yawed 90°, so +1 m forward is +y.
        let o = p.translation.vector;
        assert!(
            (o.x - 10.0).abs() < 1e-12 && (o.y - 1.0).abs() < 1e-12 && (o.z - 2.0).abs() < 1e-12
        );
    }

    #[test]
    fn prune_keeps_bracketing_sample() {
        let mut b = TfBuffer::new();
        for i in 0..10 {
            b.insert(
                &ts(
                    "map",
                    "base_link",
                    i * 10,
                    pose_xyz_rpy(i as f64, 0.0, 0.0, 0.0, 0.0, 0.0),
                ),
                false,
            );
        }
        b.prune_before(45);
        assert!(b.lookup("map", "base_link", 45).is_ok());
        assert!(b.lookup("map", "base_link", 39).is_err());
        assert_eq!(b.len(), 6);
    }

    proptest! {
        /// Out-of-order insertion gives the same lookups, and lookups at sample times
        /// return the samples exactly.
        #[test]
        fn order_independent(yaws in proptest::collection::vec(-3.0f64..3.0, 2..8), t in 0.0f64..1.0, seed in any::<u64>()) {
            let poses: Vec<(i64, Pose)> = yaws.iter().enumerate()
                .map(|(i, y)| (i as i64 * 1000, pose_xyz_rpy(i as f64, -(i as f64), 0.5, 0.1, 0.0, *y))).collect();
            let mut a = TfBuffer::new();
            for (ns, p) in &poses { a.insert(&ts("map", "base_link", *ns, *p), false); }
            let mut shuffled = poses.clone();
            let n = shuffled.len();
            for i in 0..n { shuffled.swap(i, (seed as usize).wrapping_add(i * 7) % n); }
            let mut b = TfBuffer::new();
            for (ns, p) in &shuffled { b.insert(&ts("map", "base_link", *ns, *p), false); }
            let q = (t * (n - 1) as f64 * 1000.0) as i64;
            prop_assert!(close(&a.lookup("map", "base_link", q).unwrap(), &b.lookup("map", "base_link", q).unwrap()));
            for (ns, p) in &poses {
                prop_assert!(close(&a.lookup("map", "base_link", *ns).unwrap(), p));
            }
        }
    }
}
