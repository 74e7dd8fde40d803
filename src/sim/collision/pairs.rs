//! Which pairs of links are checked: all but the allowed ones. Allowed pairs come from the
//! SRDF's `<disable_collisions>` where there is one; otherwise they are computed as MoveIt's
//! setup assistant computes them: adjacent links (a joint's parent and child), pairs in
//! collision at the home pose, pairs in collision at (nearly) every sampled configuration,
//! and pairs never in collision at any.

use std::collections::BTreeMap;

use rand::SeedableRng;
use rand::rngs::StdRng;

use crate::sim::kinematics::KinematicChain;

/// Why a pair of links is not checked (MoveIt's reasons).
#[derive(
    Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, serde::Serialize, serde::Deserialize,
)]
pub enum Reason {
    /// A joint's parent and child.
    Adjacent,
    /// In collision at the home pose.
    Default,
    /// In collision at nearly every sampled configuration.
    Always,
    /// Never in collision at any sampled configuration.
    Never,
    /// Said so by the user (the SRDF names another reason, or an override file).
    User,
}

impl Reason {
    /// The SRDF's `reason` attribute (another reason: the user's).
    pub fn from_srdf(reason: &str) -> Self {
        match reason {
            "Adjacent" => Reason::Adjacent,
            "Default" => Reason::Default,
            "Always" => Reason::Always,
            "Never" => Reason::Never,
            _ => Reason::User,
        }
    }
}

/// The allowed pairs, by link name (each pair with its names in sorted order).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct AllowedPairs {
    pub pairs: BTreeMap<(String, String), Reason>,
}

impl AllowedPairs {
    fn key(a: &str, b: &str) -> (String, String) {
        if a <= b {
            (a.to_string(), b.to_string())
        } else {
            (b.to_string(), a.to_string())
        }
    }

    pub fn allow(&mut self, a: &str, b: &str, reason: Reason) {
        self.pairs.entry(Self::key(a, b)).or_insert(reason);
    }

    /// Why the pair `a`, `b` is allowed (None: it is checked).
    pub fn reason(&self, a: &str, b: &str) -> Option<Reason> {
        self.pairs.get(&Self::key(a, b)).copied()
    }

    pub fn allows(&self, a: &str, b: &str) -> bool {
        a == b || self.pairs.contains_key(&Self::key(a, b))
    }

    /// From an SRDF's `(link1, link2, reason)` entries.
    pub fn from_srdf(entries: &[(String, String, String)]) -> Self {
        let mut allowed = Self::default();
        for (a, b, r) in entries {
            allowed.allow(a, b, Reason::from_srdf(r));
        }
        allowed
    }
}

/// How the allowed pairs are computed where no SRDF gives them.
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PairSampling {
    /// Random configurations sampled within the joint ranges (MoveIt's default: 10,000).
    pub samples: usize,
    /// A pair in collision at at least this share of them is "always" in collision.
    pub always_share: f64,
    pub seed: u64,
}

impl Default for PairSampling {
    fn default() -> Self {
        Self {
            samples: 10_000,
            always_share: 0.95,
            seed: 0,
        }
    }
}

/// Which pairs of link indices collide at some link frames.
pub type CollidingPairs<'a> =
    dyn Fn(&[nalgebra::Isometry3<f64>]) -> Vec<(usize, usize)> + Sync + 'a;

/// The allowed pairs of `chain`'s links as MoveIt's setup assistant computes them, with
/// `collide(frames)` saying which pairs of link indices are in collision at some link frames
/// (links without geometry never are). Ctrl-C ends the sampling within a configuration.
pub fn compute(
    chain: &KinematicChain,
    sampling: &PairSampling,
    collide: &CollidingPairs,
) -> crate::core::error::Result<AllowedPairs> {
    use rayon::prelude::*;
    let names = &chain.links;
    let mut allowed = AllowedPairs::default();
    for j in &chain.joints {
        allowed.allow(&names[j.parent], &names[j.child], Reason::Adjacent);
    }
    let ranges = chain.joint_ranges();
    // Home: every joint at 0, or at the limit nearest 0.
    let home: Vec<f64> = ranges.iter().map(|r| 0f64.clamp(r[0], r[1])).collect();
    for (a, b) in collide(&chain.link_frames(&home)) {
        allowed.allow(&names[a], &names[b], Reason::Default);
    }
    let mut rng = StdRng::seed_from_u64(sampling.seed);
    let configurations: Vec<Vec<f64>> = (0..sampling.samples)
        .map(|_| crate::sim::trajectory::uniform_in(&mut rng, &ranges))
        .collect();
    let counts: BTreeMap<(usize, usize), usize> = configurations
        .par_iter()
        .map(|q| {
            if crate::core::interrupt::requested() {
                return Vec::new();
            }
            collide(&chain.link_frames(q))
        })
        .fold(BTreeMap::new, |mut m, pairs| {
            for p in pairs {
                *m.entry(p).or_insert(0) += 1;
            }
            m
        })
        .reduce(BTreeMap::new, |mut a, b| {
            for (k, v) in b {
                *a.entry(k).or_insert(0) += v;
            }
            a
        });
    crate::core::interrupt::check(|| "stopped sampling which pairs of links collide".into())?;
    let n = configurations.len().max(1) as f64;
    for (&(a, b), &c) in &counts {
        if c as f64 >= sampling.always_share * n {
            allowed.allow(&names[a], &names[b], Reason::Always);
        }
    }
    for a in 0..names.len() {
        for b in a + 1..names.len() {
            if !counts.contains_key(&(a, b)) {
                allowed.allow(&names[a], &names[b], Reason::Never);
            }
        }
    }
    Ok(allowed)
}
